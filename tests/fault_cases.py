"""The project's fault suite: every library effect hidden in turn, lookalike pairs both
ways, two faults at once — simulated with known truth, diagnosed, tallied.

Used by ``tests/test_fault_library.py`` (asserts the rates) and by
``scripts/confusion_matrix.py`` (prints the matrix the README shows).

Every case: a rotor (two parameter sets), the engineer's starting model (what the
rotor has minus the hidden effects), a run-up from rest to speed 3 (rate 0.02, through
the critical ``1/sqrt(1 - ip)``) or a coast-down from speed 3, ``dt = 0.02``, noise
5e-4 on the six inclination channels, three seeds.  The diagnosis is right when it adds
exactly the hidden effects and every hidden effect's size is within 5 % of the truth (the
relative error of the vector of its non-angle parameters: the quadratic stiffness' four
coefficients together) and its angles within 0.05 rad.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass, field

from rotor_env.effects import EFFECTS, PHYSICAL_EFFECTS
from rotor_env.params import RotorParams
from rotor_env.simulator import RunUp, simulate

NOISE = 5e-4
SEEDS = (1, 2, 3)
RUNS = {
    "run-up": (RunUp(rate=0.02), 150.0),
    "coast-down": (RunUp(rate=-0.02, speed0=3.0), 125.0),
}
#: the healthy part of the two parameter sets (linear, symmetric, no friction)
ROTORS = {
    "A": {"ip": 0.3, "tau": 0.02, "beta": 0.0, "c": 0.03},
    "B": {"ip": 0.2, "tau": 0.03, "beta": 1.5, "c": 0.05},
}
#: the hidden effect's values per parameter set (Table-1-like sizes, other phases and signs)
HIDDEN = {
    "asymmetry": ({"D": 0.03}, {"D": -0.04}),
    "nonlinear_stiffness": ({"k30": 0.05, "k21": 0.04, "k12": 0.03, "k03": 0.02},
                            {"k30": -0.04, "k21": 0.03, "k12": 0.05, "k03": -0.03}),
    "structural_damping": ({"h": 0.01}, {"h": 0.006}),
    "stiffness": ({"k": 1.1}, {"k": 0.92}),
    "static_load": ({"load_y": -0.01, "load_x": 0.0}, {"load_y": 0.004, "load_x": -0.008}),
    "shaft_bow": ({"bow": 0.01, "bow_phase": 1.0}, {"bow": 0.006, "bow_phase": -2.0}),
    "support_anisotropy": ({"support_anisotropy": 0.05}, {"support_anisotropy": -0.08}),
    "cross_coupled_stiffness": ({"cross_coupling": 0.015}, {"cross_coupling": 0.025}),
    "misalignment": ({"misalignment": 0.005, "misalignment_phase": -0.5},
                     {"misalignment": 0.003, "misalignment_phase": 2.0, "misalignment_back": 0.004,
                      "misalignment_back_phase": 0.3}),
    "breathing_crack": ({"dk_crack": 0.1, "breathing_depth": 1.0, "breathing_phase": 0.5},
                        {"dk_crack": 0.15, "breathing_depth": 0.8, "breathing_phase": -1.0}),
    # the orbit peaks at 0.15-0.27 around the critical (A: 0.17 run-up, 0.15 coast-down; B:
    # 0.27, 0.18): it touches for a third to two thirds of the record and stays stable
    # (test_fault_library.test_rub_cases_rub_and_stay_stable)
    "rub": ({"rub_stiffness": 0.5, "rub_friction": 0.2, "rub_clearance": 0.04},
            {"rub_stiffness": 1.0, "rub_friction": 0.1, "rub_clearance": 0.06}),
}
#: a breathing crack breathes under a side load (gravity): the engineer's model has it
NEEDS_LOAD = {"breathing_crack": {"load_y": -0.01}}
CRACKS = {"asymmetry", "breathing_crack"}
ANGLES = {"beta", "bow_phase", "misalignment_phase", "misalignment_back_phase", "breathing_phase"}


@dataclass(frozen=True)
class Case:
    """One diagnosis with known truth."""

    name: str
    hidden: tuple[str, ...]             # the effects the diagnosis must add
    truth: dict                         # all parameter values of the simulated rotor
    effects: tuple[str, ...]            # the simulated rotor's effects
    start_model: tuple[str, ...]
    run: str
    seed: int
    rotor: str
    checked: tuple[str, ...] = field(default=())  # parameters compared with the truth

    def simulate(self):
        run_up, t_end = RUNS[self.run]
        values = {k: v for k, v in self.truth.items() if k != "ip"}
        params = RotorParams(ip=self.truth["ip"], values=values, effects=self.effects)
        return simulate(params, t_end=t_end, dt=0.02, run_up=run_up, noise=NOISE, seed=self.seed)


def _values(rotor: str, extra: dict) -> dict:
    zero = {p.name: 0.0 for e in PHYSICAL_EFFECTS for p in EFFECTS[e].parameters}
    zero["k"] = 1.0
    return {**zero, **ROTORS[rotor], **extra}


def _case(name: str, hidden: tuple[str, ...], extra: dict, start: tuple[str, ...], run: str, seed: int,
          rotor: str, checked: tuple[str, ...]) -> Case:
    effects = tuple(dict.fromkeys((*PHYSICAL_EFFECTS, *start, *hidden)))
    return Case(name, hidden, _values(rotor, extra), effects, start, run, seed, rotor, checked)


def hidden_effect_cases() -> list[Case]:
    """Every library effect hidden in turn: 2 parameter sets x 3 seeds x run-up/coast-down."""
    out = []
    for effect, sets in HIDDEN.items():
        for rotor, vals in zip(ROTORS, sets, strict=True):
            load = NEEDS_LOAD.get(effect, {})
            start = ("unbalance", "viscous_damping", *(("static_load",) if load else ()))
            checked = tuple(k for k in vals if effect != "static_load" or k in vals)
            for run in RUNS:
                for seed in SEEDS:
                    out.append(_case(effect, (effect,), {**vals, **load}, start, run, seed, rotor, checked))
    return out


def lookalike_cases() -> list[Case]:
    """The lookalike pairs the other way round, and two faults at once (run-up, rotor A)."""
    out = []
    for seed in SEEDS:
        # unbalance vs bow: the engineer forgot the unbalance; a bow must not take its place
        out.append(_case("unbalance (vs bow)", ("unbalance",), {}, ("viscous_damping",), "run-up", seed, "A",
                         ("tau", "beta")))
        # damping vs cross-coupling: viscous damping missing; not a (negative) cross-coupling
        out.append(_case("viscous_damping (vs cross-coupling)", ("viscous_damping",), {}, ("unbalance",),
                         "run-up", seed, "A", ("c",)))
        # an open crack with a side load (its classic 2x) vs misalignment and breathing
        out.append(_case("asymmetry + side load (vs misalignment, breathing)", ("asymmetry",),
                         {"D": 0.03, "load_y": -0.01}, ("unbalance", "viscous_damping", "static_load"),
                         "run-up", seed, "A", ("D",)))
        # two faults at once
        out.append(_case("shaft_bow + support_anisotropy", ("shaft_bow", "support_anisotropy"),
                         {"bow": 0.008, "bow_phase": 0.5, "support_anisotropy": 0.05},
                         ("unbalance", "viscous_damping"), "run-up", seed, "A", ("bow", "support_anisotropy")))
        out.append(_case("misalignment + asymmetry", ("misalignment", "asymmetry"),
                         {"misalignment": 0.005, "misalignment_phase": 1.0, "D": 0.03},
                         ("unbalance", "viscous_damping"), "run-up", seed, "A", ("misalignment", "D")))
    return out


@dataclass
class Outcome:
    case: Case
    named: tuple[str, ...]
    verdict: str
    errors: dict      # parameter -> relative error (angles: absolute, rad)
    right: bool
    physical: dict = field(default_factory=dict)  # the identified parameters of the final model


def run_suite(cases: list[Case] | None = None, jobs: int = 2, progress: bool = False) -> list[Outcome]:
    """Every case (default: the whole suite) in ``jobs`` worker processes, in order."""
    from concurrent.futures import ProcessPoolExecutor

    cases = hidden_effect_cases() + lookalike_cases() if cases is None else cases
    with ProcessPoolExecutor(jobs) as pool:
        out = pool.map(run_case, cases, chunksize=4)
        if progress:
            from tqdm.auto import tqdm

            out = tqdm(out, total=len(cases), desc="fault suite", unit="case")
        return list(out)


def outcome_to_json(o: Outcome) -> dict:
    """An outcome as JSON-able data (the suite's result shared between test processes)."""
    return {"case": asdict(o.case), "named": list(o.named), "verdict": o.verdict, "errors": o.errors,
            "right": o.right, "physical": o.physical}


def outcome_from_json(d: dict) -> Outcome:
    c = d["case"]
    case = Case(c["name"], tuple(c["hidden"]), c["truth"], tuple(c["effects"]), tuple(c["start_model"]), c["run"],
                c["seed"], c["rotor"], tuple(c["checked"]))
    return Outcome(case, tuple(d["named"]), d["verdict"], d["errors"], d["right"], d["physical"])


def run_case(case: Case) -> Outcome:
    from rotor_env.diagnosis import diagnose

    meas = case.simulate()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        d = diagnose(meas, model=case.start_model, ip=case.truth["ip"])
    if d.verdict == "not_identifiable":
        return Outcome(case, (), d.verdict, {}, False)
    phys = {**d.after.physical}
    errors = {}
    sizes = [p for p in case.checked if p not in ANGLES]
    for p in case.checked:
        true, got = case.truth[p], phys.get(p, math.nan)
        if p in ANGLES:
            errors[p] = abs(math.remainder(got - true, 2 * math.pi))
    # the sizes of one effect as one vector (the quadratic stiffness' four coefficients):
    # a 5 % error of the vector, not of its smallest component
    by_effect: dict[str, list[str]] = {}
    for p in sizes:
        owner = next(e for e in EFFECTS.values() if p in e.parameter_names)
        by_effect.setdefault(owner.name, []).append(p)
    for names in by_effect.values():
        true = [case.truth[p] for p in names]
        got = [phys.get(p, math.nan) for p in names]
        norm = math.sqrt(sum(v * v for v in true))
        err = math.sqrt(sum((g - t) ** 2 for g, t in zip(got, true, strict=True)))
        errors["|" + ",".join(names) + "|"] = err / norm if norm else err
    within = all((e <= 0.05) for e in errors.values())
    named = tuple(d.missing)
    right = set(named) == set(case.hidden) and within and d.verdict == "explained_after_adding"
    return Outcome(case, named, d.verdict, errors, right, phys)


def confusion(outcomes: list[Outcome]) -> tuple[list[str], list[str], dict]:
    """Rows: the truth (case name); columns: what the diagnosis named (``+``-joined; the
    verdict when it named nothing)."""
    rows = list(dict.fromkeys(o.case.name for o in outcomes))
    label = {id(o): (" + ".join(sorted(o.named)) if o.named else o.verdict) for o in outcomes}
    cols = sorted({label[id(o)] for o in outcomes})
    counts = {(r, c): 0 for r in rows for c in cols}
    for o in outcomes:
        counts[(o.case.name, label[id(o)])] += 1
    return rows, cols, counts
