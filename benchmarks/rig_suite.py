"""The broad rig suite: simulated rig recordings with known truth through ``diagnose_rig``.

Every record is what a data acquisition system writes (keyphasor notch, proximity probes
with their noise), written to a Parquet file next to its rig description and read back
with ``load_waveforms`` / ``load_rig`` -- the path ``rotor-id diagnose RUN --rig rig.yaml``
takes -- then diagnosed with the default model (unbalance, viscous damping) and the whole
library of candidates.

The records (drawn from ``--seed``, every draw reproducible):

* rigs: one plane in um, one plane in V (7.87 mV/um, API 670, on a -10 V gap), two planes
  (tilt; probes 5 mm and 8 mm either side of the disk, ip 0.3);
* natural frequency 1200-3000 rpm, damping ratio 1-4 %, unbalance giving a steady peak
  of 80-150 um (tilt: 16-30 mrad), run-up or coast-down between 0.25 and 1.8 times the
  natural frequency in 8-11 s, sample rate 2.5/5/10/20 kHz;
* probe noise 0.1 / 0.3 / 1 / 3 um (``--noise``), Gaussian, on every probe;
* every library fault (sizes after ``tests/fault_cases.py``, scaled to the record's
  healthy peak ``P`` where the fault is a displacement): ``asymmetry`` (|D| 0.02-0.04, its
  axis anywhere, i.e. the keyphasor at any angle to it), ``breathing_crack`` (dk 0.05-0.1
  under a side load, axis anywhere), ``hinge_crack`` (Gasch's switching crack, dk 0.05-0.1,
  under a side load of 0.05-0.5 P: from breathing with the whirl to breathing with the
  load), ``rub`` (clearance 0.45-0.75 P: touched around the
  critical), ``shaft_bow``, ``support_anisotropy`` (axis anywhere),
  ``cross_coupled_stiffness`` (0.3-0.6 of the damping: stable), ``misalignment``,
  ``nonlinear_stiffness``, ``static_load``; healthy rotors; probe runout (3-8 um) on a
  healthy rotor.

Outcome per record: what was named, the verdict, the noise floor against the true probe
noise, the crack's size and axis errors, the wall time.  Printed: the detection table
against probe noise, the per-fault table, every failure, the time per record.

    python benchmarks/rig_suite.py --quick                    # 6 records, ~2 min
    python benchmarks/rig_suite.py --reps 1 --workers 2       # 4 noises x 13 kinds
    python benchmarks/rig_suite.py --noise 0.3 --faults asymmetry,rub --reps 3
    python benchmarks/rig_suite.py --noise 0.5 --artefacts    # with mains hum and a scratch on every track
    python benchmarks/rig_suite.py --noise 0.5 --drift 20     # the probes' mean moving by 20 um (centreline, thermal)
    python benchmarks/rig_suite.py --noise 0.5 --flicker 100  # 1/f probe noise with its corner at 100 Hz
    python benchmarks/rig_suite.py --noise 0.5 --vectors      # each record's 1X/2X table diagnosed instead of its waveforms
    python benchmarks/rig_suite.py --report seed1.json seed2.json   # the tables of saved runs together
"""

from __future__ import annotations

import os
import sys

# one BLAS / numba thread per worker: set before numpy loads (spawned workers inherit it)
# only where numba is not loaded yet (imported by the tests it is: a changed NUMBA_NUM_THREADS
# then makes numba refuse to compile once its thread pool runs)
if "numba" not in sys.modules:
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

import argparse
import json
import math
import platform
import statistics
import tempfile
import time
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

FAULTS = ("asymmetry", "breathing_crack", "hinge_crack", "rub", "shaft_bow", "support_anisotropy",
          "cross_coupled_stiffness", "misalignment", "nonlinear_stiffness", "static_load")
KINDS = (*FAULTS, "healthy", "runout")
CRACKS = ("asymmetry", "breathing_crack", "hinge_crack")
NOISES_UM = (0.1, 0.3, 1.0, 3.0)
RIGS = ("one-plane um", "one-plane V", "two-plane")
SAMPLE_RATES = (2500.0, 5000.0, 10000.0, 20000.0)
SENSITIVITY_MV_PER_UM = 7.87
#: two-plane rig: probe planes either side of the disk (m), and the disk's inertia ratio
TILT_PLANES = {"A": -0.005, "B": 0.008}
TILT_IP = 0.3
#: dimensionless displacement per rig: one plane in LENGTH_UNIT (1 mm: 0.1 = 100 um), a tilt
#: in rad (0.02 rad = 160 um at the far plane); the tilt rig's unbalance is 5x smaller.  Not
#: smaller: the library bounds a rub's clearance to >= 0.005 (rad for a tilt), so a real
#: tilt of ~1 mrad could not be given a rub the diagnosis may accept
AMPLITUDE_SCALE = {"one-plane um": 1.0, "one-plane V": 1.0, "two-plane": 0.2}


@dataclass(frozen=True)
class RecordSpec:
    """One record of the suite: everything but the fault's sizes, which are drawn from
    ``seed`` once the healthy rotor's peak is known."""

    index: int
    seed: int
    fault: str           #: a library effect, "healthy" or "runout"
    noise_um: float      #: probe noise (std, um; for the volt rig too)
    rig: str             #: one of RIGS
    natural_rpm: float
    zeta: float          #: damping ratio
    sample_rate: float   #: Hz
    direction: str       #: "run-up" | "coast-down"
    #: fault parameters fixed instead of drawn (name, value), e.g. (("D_axis", 0.7),)
    fixed: tuple[tuple[str, float], ...] = ()
    #: the sweep's duration (s), drawn from [8, 11] when 0
    duration_s: float = 0.0
    #: instrument artefacts on the probes (``--artefacts``): mains hum at 50 or 60 Hz with its
    #: third harmonic, and a scratch on every track
    artefacts: bool = False
    #: the probes' slowly moving mean (``--drift``, um): each plane's centreline lifting with
    #: the speed squared by this much, each probe's gap drifting linearly by up to half of it
    drift_um: float = 0.0
    #: the probes' 1/f noise corner (``--flicker``, Hz): their noise density the white
    #: noise's times ``1 + corner / f``
    flicker_hz: float = 0.0
    #: diagnose the record's order-tracked 1X/2X table (``--vectors``: ``rotor-id diagnose
    #: TABLE --vectors --rig``) instead of its waveforms
    vectors: bool = False


def build_specs(noises=NOISES_UM, kinds=KINDS, reps: int = 1, seed: int = 0, quick: bool = False) -> list[RecordSpec]:
    """The suite's records: every kind at every noise level ``reps`` times, the rig, the
    rotor and the run drawn from ``seed`` (rig kind and direction cycled so that each
    noise level sees all of them)."""
    rng = np.random.default_rng(seed)
    specs = []
    i = 0
    for noise in noises:
        for kind in kinds:
            for _ in range(reps):
                rig = RIGS[i % len(RIGS)]
                direction = ("run-up", "coast-down")[(i // len(RIGS)) % 2]
                fs = SAMPLE_RATES[int(rng.integers(len(SAMPLE_RATES)))]
                if quick:
                    fs = min(fs, 5000.0)
                specs.append(RecordSpec(
                    index=i, seed=seed * 100_000 + i, fault=kind, noise_um=float(noise), rig=rig,
                    natural_rpm=float(round(rng.uniform(1200.0, 3000.0), 1)),
                    zeta=float(round(rng.uniform(0.01, 0.04), 4)), sample_rate=fs, direction=direction))
                i += 1
    return specs


# ------------------------------------------------------------------ one record
def rig_description(kind: str) -> dict:
    """The rig file's content (as a user would write it)."""
    if kind == "two-plane":
        return {"keyphasor": "kp",
                "probes": [{"name": "xa", "angle_deg": 45, "plane": "A"}, {"name": "ya", "angle_deg": -45, "plane": "A"},
                           {"name": "xb", "angle_deg": 45, "plane": "B"}, {"name": "yb", "angle_deg": -45, "plane": "B"}],
                "planes": {p: {"axial_position_m": z} for p, z in TILT_PLANES.items()},
                "disk": {"ip": TILT_IP}, "units": {"displacement": "um"}}
    units = ({"displacement": "V", "sensitivity_mv_per_um": SENSITIVITY_MV_PER_UM} if kind == "one-plane V"
             else {"displacement": "um"})
    return {"keyphasor": "kp", "probes": {"x": 45, "y": -45}, "units": units}


def true_floor(spec: RecordSpec) -> float:
    """The probes' noise in the unit the diagnosis reports (um; a tilt rig: urad -- the tilt
    is the difference of two planes' orthogonal-probe displacements over their distance)."""
    if spec.rig == "two-plane":
        dz = TILT_PLANES["B"] - TILT_PLANES["A"]
        return spec.noise_um * math.sqrt(2.0) / dz
    return spec.noise_um


def _orbit_peak(run, rig) -> float:
    """The largest dimensionless orbit radius of a noise-free run (translation: in LENGTH_UNIT,
    tilt: rad), from the far plane's two orthogonal probes."""
    from rotor_env.measurements.waveforms import LENGTH_UNIT

    plane = max(rig.plane_names, key=lambda p: abs(rig.planes.get(p, 1.0)))
    members = [p for p in rig.probes if p.plane == plane]
    x, y = (rig.to_metres(run.columns[p.name] - np.mean(run.columns[p.name])) for p in members[:2])
    r = np.hypot(x, y)  # the probes are 90 degrees apart
    return float(r.max() / (abs(rig.planes[plane]) if rig.model == "tilt" else LENGTH_UNIT))


def fault_values(spec: RecordSpec, rng: np.random.Generator, peak: float, c: float, scale: float) -> dict:
    """The fault's parameters (dimensionless), the displacement-like ones scaled to the
    healthy run's orbit peak ``peak`` (tests/fault_cases.py: bow 0.06, misalignment 0.03,
    load 0.06, rub clearance 0.24-0.4 of a 0.15-0.27 peak; quadratic stiffness 0.02-0.05 at
    a peak 0.17, i.e. k A = 0.0034-0.0085 at the record's peak A)."""
    def sign() -> float:
        return float(rng.choice((-1.0, 1.0)))

    f = spec.fault
    if f == "asymmetry":
        return {"D": sign() * rng.uniform(0.02, 0.04), "D_axis": rng.uniform(0.0, math.pi)}
    if f == "breathing_crack":
        # a crack breathes under a side load (gravity)
        return {"dk_crack": rng.uniform(0.05, 0.1), "breathing_depth": rng.uniform(0.6, 1.0),
                "breathing_phase": rng.uniform(-math.pi, math.pi), "crack_axis": rng.uniform(0.0, 2 * math.pi),
                "load_y": -rng.uniform(0.04, 0.08) * peak, "load_x": 0.0}
    if f == "hinge_crack":
        # Gasch's hinge under a side load from a twentieth of the peak (it breathes with the
        # whirl through the critical) to half of it (with the load's direction, like gravity)
        return {"dk_hinge": rng.uniform(0.05, 0.1), "hinge_axis": rng.uniform(0.0, 2 * math.pi),
                "load_y": -rng.uniform(0.05, 0.5) * peak, "load_x": 0.0}
    if f == "rub":
        return {"rub_stiffness": rng.uniform(0.3, 1.0), "rub_friction": rng.uniform(0.1, 0.3),
                "rub_clearance": rng.uniform(0.45, 0.75) * peak}
    if f == "shaft_bow":
        return {"bow": rng.uniform(0.04, 0.08) * peak, "bow_phase": rng.uniform(-math.pi, math.pi)}
    if f == "support_anisotropy":
        return {"support_anisotropy": sign() * rng.uniform(0.04, 0.08), "support_axis": rng.uniform(0.0, math.pi)}
    if f == "cross_coupled_stiffness":
        # below the damping: a cross-coupling above c drives the forward mode unstable
        return {"cross_coupling": rng.uniform(0.3, 0.6) * c}
    if f == "misalignment":
        return {"misalignment": rng.uniform(0.02, 0.04) * peak, "misalignment_phase": rng.uniform(-math.pi, math.pi)}
    if f == "nonlinear_stiffness":
        # the quadratic moment k A^2 against the linear A at the peak A: k A = 0.02-0.05 of
        # 0.17 (tests/fault_cases.py: k 0.02-0.05 at a peak 0.17), whatever the length unit
        k = 0.17 / peak
        return {n: sign() * rng.uniform(0.02, 0.05) * k for n in ("k30", "k21", "k12", "k03")}
    if f == "static_load":
        a, th = rng.uniform(0.04, 0.08) * peak, rng.uniform(-math.pi, math.pi)
        return {"load_y": a * math.cos(th), "load_x": a * math.sin(th)}
    return {}


def _params(healthy: dict, extra: dict, ip: float):
    from rotor_env.effects import EFFECTS
    from rotor_env.params import RotorParams

    effects = ["stiffness", "viscous_damping", "unbalance"]
    effects += [n for n, e in EFFECTS.items() if n not in effects and n != "unbalance_in_phase"
                and any(pn in extra for pn in e.parameter_names)]
    return RotorParams(ip=ip, values={**healthy, **extra}, effects=tuple(effects))


def make_record(spec: RecordSpec, folder: Path) -> tuple[Path, Path, dict]:
    """Simulate ``spec``, write its rig description and waveform file into ``folder``;
    return the two paths and the truth."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from rotor_env.measurements.rig import load_rig
    from rotor_env.rig_simulation import simulate_rig

    rng = np.random.default_rng(spec.seed)
    rig_path = folder / f"rig{spec.index}.json"
    rig_path.write_text(json.dumps(rig_description(spec.rig)))
    rig = load_rig(rig_path)
    scale = AMPLITUDE_SCALE[spec.rig]
    c = 2.0 * spec.zeta
    healthy = {"c": c, "tau": scale * rng.uniform(0.08, 0.15) * c, "beta": rng.uniform(-math.pi, math.pi), "k": 1.0}
    lo, hi = 0.25 * spec.natural_rpm, 1.8 * spec.natural_rpm
    duration = rng.uniform(8.0, 11.0)
    rpm_per_s = (hi - lo) / (spec.duration_s or duration)
    a, b = (lo, hi) if spec.direction == "run-up" else (hi, lo)
    rpm_per_s = math.copysign(rpm_per_s, b - a)
    run_kw = dict(natural_rpm=spec.natural_rpm, rpm_from=a, rpm_to=b, rpm_per_s=rpm_per_s,
                  sample_rate=spec.sample_rate)
    # the healthy run's peak sets the displacement-like faults' sizes (a rub's clearance
    # below it: touched around the critical)
    peak = _orbit_peak(simulate_rig(rig, _params(healthy, {}, rig.ip), **run_kw, noise=0.0), rig)
    extra = {**fault_values(spec, rng, peak, c, scale), **dict(spec.fixed)}
    # each probe track its own runout (on a tilt rig the same runout on both planes would be a
    # parallel offset that the planes' difference cancels: no runout for the tilt model)
    planes = list(dict.fromkeys(p.plane for p in rig.probes))
    runout = {pl: float(rng.uniform(3.0, 8.0)) for pl in planes} if spec.fault == "runout" else 0.0
    runout_deg = {pl: float(rng.uniform(0.0, 360.0)) for pl in planes} if spec.fault == "runout" else 0.0
    art = {}
    if spec.artefacts:
        mains = float(rng.choice([50.0, 60.0]))
        art = {"lines": ((mains, float(rng.uniform(0.3, 1.5))), (3 * mains, float(rng.uniform(0.1, 0.5)))),
               "scratch": float(rng.uniform(1.0, 4.0))}
    if spec.drift_um:
        art["drift"] = spec.drift_um
    if spec.flicker_hz:
        art["flicker_hz"] = spec.flicker_hz
    run = simulate_rig(rig, _params(healthy, extra, rig.ip), **run_kw, noise=spec.noise_um, runout=runout,
                       runout_phase_deg=runout_deg, seed=spec.seed, **art)
    faulty_peak = _orbit_peak(simulate_rig(rig, _params(healthy, extra, rig.ip), **run_kw, noise=0.0), rig) \
        if spec.fault == "rub" else None
    data_path = folder / f"run{spec.index}.parquet"
    pq.write_table(pa.table(run.file_columns()), data_path)
    truth = {"healthy": healthy, "fault": extra, "ip": rig.ip, "healthy_peak": peak, "rpm_from": a, "rpm_to": b,
             "rpm_per_s": rpm_per_s, "duration_s": (b - a) / rpm_per_s, "samples": len(run.columns["t"]),
             "runout_um": runout, "runout_phase_deg": runout_deg, "faulty_peak": faulty_peak, "artefacts": art}
    return rig_path, data_path, truth


def _angle_error_deg(got: float, true: float, period: float) -> float:
    return float(math.degrees(math.remainder(got - true, period)))


def crack_errors(fault: str, truth: dict, params: dict) -> dict:
    """Size (relative) and axis (deg) errors of a named crack.  An open crack (``asymmetry``)
    named as a ``breathing_crack`` that does not breathe is the same moment
    (``dk/4 (z + conj(z) e^{2i phi})``: ``D = dk/4``, the weak axis 90 degrees from the stiff
    one): its errors are given too, marked ``"as": "breathing_crack"``."""
    if fault == "asymmetry" and ("asymmetry" in params or "breathing_crack" in params):
        if "asymmetry" in params:
            v = params["asymmetry"]["values"]
            D, ax, via = v["D"], v.get("D_axis", 0.0), "asymmetry"
        else:
            v = params["breathing_crack"]["values"]
            D, ax, via = v["dk_crack"] / 4.0, v.get("crack_axis", 0.0) + math.pi / 2, "breathing_crack"
        tD, tax = truth["D"], truth["D_axis"]
        # the same crack seen from its other axis: -D at 90 degrees
        if D < 0:
            D, ax = -D, ax + math.pi / 2
        if tD < 0:
            tD, tax = -tD, tax + math.pi / 2
        return {"size_error": abs(D / tD - 1.0), "axis_error_deg": abs(_angle_error_deg(ax, tax, math.pi)),
                "as": via}
    if fault == "breathing_crack" and "breathing_crack" in params:
        v = params["breathing_crack"]["values"]
        ax, ph = v.get("crack_axis", 0.0), v.get("breathing_phase", 0.0)
        # the moment turns with phi + axis for the breathing but with 2 (phi + axis) for the
        # open part: (axis + pi, breathing_phase + pi) is the same crack, so the axis is
        # compared modulo pi, with the breathing phase moved along
        if abs(_angle_error_deg(ax, truth["crack_axis"], 2 * math.pi)) > 90.0:
            ax, ph = ax + math.pi, ph + math.pi
        return {"size_error": abs(v["dk_crack"] / truth["dk_crack"] - 1.0),
                "axis_error_deg": abs(_angle_error_deg(ax, truth["crack_axis"], 2 * math.pi)),
                "breathing_phase_error_deg": abs(_angle_error_deg(ph, truth["breathing_phase"], 2 * math.pi)),
                "as": "breathing_crack"}
    if fault == "hinge_crack" and "hinge_crack" in params:
        v = params["hinge_crack"]["values"]
        # the hinge knows which side of the shaft opens: its axis is compared over a whole turn
        return {"size_error": abs(v["dk_hinge"] / truth["dk_hinge"] - 1.0),
                "axis_error_deg": abs(_angle_error_deg(v.get("hinge_axis", 0.0), truth["hinge_axis"], 2 * math.pi)),
                "as": "hinge_crack"}
    return {}


def _crack(o: dict) -> dict:
    """The crack errors of an outcome, recomputed from its stored parameters."""
    if "error" in o or "unstable" in o:
        return {}
    return crack_errors(o["spec"]["fault"], o["truth"]["fault"], o.get("parameters") or {})


def _diagnose_table(record, rig_path: Path, folder: Path) -> dict:
    """The record's 1X/2X table (order-tracked per revolution, as a DAQ's tracker writes it)
    diagnosed as ``rotor-id diagnose TABLE --vectors --rig RIG`` does, in the waveform
    diagnosis's JSON shape (``parameters``: effect -> values)."""
    from rotor_env.batch import diagnose_file
    from rotor_env.diagnosis.from_vectors import diagnose_vectors

    if record.rig.model == "tilt":
        # a two-plane rig's table is the disk's tilt (urad, along the model's axes), which no
        # DAQ writes and no table file holds (``rotor-id simulate --vectors`` refuses it):
        # diagnosed as the Python API does, with the rig's inertia ratio
        d = diagnose_vectors(record.vectors((1, 2)), ip=record.rig.ip).to_dict()
    else:
        path = folder / "vectors.csv"
        record.vectors((1, 2)).to_csv(path, phase="lag")
        d = diagnose_file(path, vectors=True, rig=rig_path).to_dict()
    d["parameters"] = {e: {"values": v} for e, v in (d.get("physical") or {}).items()}
    d["vectors"] = {"missing": d.get("missing"), "verdict": d.get("verdict")}
    return d


def run_record(spec: RecordSpec) -> dict:
    """Simulate, write, read back and diagnose one record; its outcome as JSON-able data."""
    import warnings

    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.measurements.rig import load_rig
    from rotor_env.measurements.waveforms import load_waveforms
    from rotor_env.results import jsonable
    from rotor_env.simulator import SimulationError

    out = {"spec": asdict(spec), "true_floor": true_floor(spec)}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="rig_suite_") as tmp:
        try:
            rig_path, data_path, truth = make_record(spec, Path(tmp))
        except SimulationError as exc:  # the drawn rotor diverged: no record, said apart from the product's errors
            out.update(unstable=str(exc), wall_s=time.perf_counter() - t0)
            return jsonable(out)
        try:
            out["truth"] = truth
            t1 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                record = load_waveforms(data_path, load_rig(rig_path))
                if spec.vectors:
                    d = _diagnose_table(record, rig_path, Path(tmp))
                else:
                    d = diagnose_rig(record).to_dict()
            out["diagnosis_s"] = time.perf_counter() - t1
        except Exception as exc:  # a record that fails is an outcome, not the suite's end
            out.update(error=f"{type(exc).__name__}: {exc}", wall_s=time.perf_counter() - t0)
            return jsonable(out)
    out["wall_s"] = time.perf_counter() - t0
    named = list(d.get("missing") or [])
    vec_missing = list((d.get("vectors") or {}).get("missing") or [])
    params = d.get("parameters") or {}
    out.update(named=named, verdict=d.get("verdict"), vectors_missing=vec_missing,
               vectors_verdict=(d.get("vectors") or {}).get("verdict"), noise_floor=d.get("noise_floor"),
               rms_before=d.get("rms_before"), rms_after=d.get("rms_after"), unit=d.get("unit"),
               parameters=params, rejected=d.get("rejected"), notes=d.get("notes"),
               undecidable=d.get("undecidable") or {},
               detectability={e: v.get("sentence") for e, v in (d.get("detectability") or {}).items()})
    # a table's floor is per revolution's vector, not the probes' noise: no ratio to read
    out["floor_ratio"] = (d["noise_floor"] / out["true_floor"]) if d.get("noise_floor") and not spec.vectors else None
    f = spec.fault
    out["crack_named_falsely"] = f not in CRACKS and any(c in named for c in CRACKS)
    if f == "healthy":
        out["right"] = not named
    elif f == "runout":
        # a table's diagnosis names runout among its own terms; the waveforms' carry the vectors' reading
        out["right"] = named == ["runout"] if spec.vectors else (not named and "runout" in vec_missing)
    else:
        out["right"] = f in named
    # every record's rotor is the same from start to end: how often the parameter-constancy
    # test (information, not a verdict) says otherwise
    out["change_said"] = bool((d.get("change") or {}).get("changed"))
    # what moved at the break, per effect (the sup-LM's share): is a named effect among them?
    out["change"] = {k: (d.get("change") or {}).get(k) for k in ("statistic", "p_value", "fraction", "moved")}
    # a runout record's table names runout (its own term), not a fault
    out["false_alarm"] = f in ("healthy", "runout") and bool(
        [n for n in named if not (spec.vectors and f == "runout" and n == "runout")])
    # a fault not named that the diagnosis says it cannot decide: the limit stated, not a miss
    out["said_undecidable"] = not out["right"] and f in out["undecidable"]
    out["crack"] = crack_errors(f, truth["fault"], params)
    out["candidates"] = d.get("candidates")
    return jsonable(out)


# ------------------------------------------------------------------ tables
def _fmt_range(xs: list[float], fmt: str = "{:.2f}") -> str:
    if not xs:
        return "-"
    return f"{fmt.format(statistics.median(xs))} ({fmt.format(min(xs))}-{fmt.format(max(xs))})"


def detection_table(outcomes: list[dict]) -> str:
    """Markdown: per probe noise, the detection rate, false alarms, false cracks, the
    floor's ratio to the true noise, the crack's errors."""
    lines = ["| probe noise (um) | faults named right | not named, said undecidable | false alarms (healthy, "
             "runout) | crack named for a non-crack fault | floor / true noise: median (range) | crack size error: "
             "median (max) | crack axis error (deg): median (max) | parameters said not constant (all rotors constant) | errors |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for key in sorted({_row_key(o) for o in outcomes}):
        rows = [o for o in outcomes if _row_key(o) == key]
        ok = [o for o in rows if "error" not in o and "unstable" not in o]
        unstable = sum("unstable" in o for o in rows)
        faults = [o for o in ok if o["spec"]["fault"] in FAULTS]
        clean = [o for o in ok if o["spec"]["fault"] in ("healthy", "runout")]
        noncrack = [o for o in faults if o["spec"]["fault"] not in CRACKS]
        ratios = [o["floor_ratio"] for o in ok if o.get("floor_ratio")]
        cracks = [_crack(o) for o in ok if o["right"] and o["spec"]["fault"] in CRACKS]
        sizes = [c["size_error"] * 100 for c in cracks if c]
        axes = [c["axis_error_deg"] for c in cracks if c]
        lines.append(
            f"| {_row_label(key)} | {sum(o['right'] for o in faults)}/{len(faults)} "
            f"| {sum(bool(o.get('said_undecidable')) for o in faults)}/{len(faults)} "
            f"| {sum(o['false_alarm'] for o in clean)}/{len(clean)} "
            f"| {sum(o['crack_named_falsely'] for o in noncrack)}/{len(noncrack)} "
            f"| {_fmt_range(ratios)} "
            f"| {(f'{statistics.median(sizes):.1f} % ({max(sizes):.1f} %)') if sizes else '-'} "
            f"| {(f'{statistics.median(axes):.1f} ({max(axes):.1f})') if axes else '-'} "
            f"| {sum(bool(o.get('change_said')) for o in ok)}/{len(ok)} "
            f"| {len(rows) - len(ok) - unstable}{f' ({unstable} not made: the simulator diverged)' if unstable else ''} |")
    return "\n".join(lines)


def _row_key(o: dict) -> tuple[float, bool, float, float, bool]:
    return (o["spec"]["noise_um"], bool(o["spec"].get("artefacts")), float(o["spec"].get("drift_um") or 0.0),
            float(o["spec"].get("flicker_hz") or 0.0), bool(o["spec"].get("vectors")))


def _row_label(key: tuple[float, bool, float, float, bool]) -> str:
    return (f"{key[0]:g}" + (" + hum, scratch" if key[1] else "")
            + (f" + {key[2]:g} drift" if key[2] else "") + (f" + 1/f below {key[3]:g} Hz" if key[3] else "")
            + (" (1X/2X table)" if key[4] else ""))


def per_fault_table(outcomes: list[dict]) -> str:
    """Markdown: per kind (rows) and noise (columns), right / records."""
    noises = sorted({_row_key(o) for o in outcomes})
    lines = ["| record | " + " | ".join(f"{_row_label(n)} um" for n in noises) + " |",
             "|---" * (len(noises) + 1) + "|"]
    for kind in KINDS:
        cells = []
        for n in noises:
            every = [o for o in outcomes if o["spec"]["fault"] == kind and _row_key(o) == n]
            rows = [o for o in every if "unstable" not in o]
            und = sum(bool(o.get("said_undecidable")) for o in rows)
            not_made = len(every) - len(rows)
            cells.append((f"{sum(bool(o.get('right')) for o in rows)}/{len(rows)}"
                          + (f" ({und} undecidable)" if und else "")
                          + (f" ({not_made} not made: the simulator diverged)" if not_made else "")) if every else "-")
        if any(c != "-" for c in cells):
            lines.append(f"| {kind} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def failures(outcomes: list[dict]) -> list[str]:
    out = []
    for o in sorted(outcomes, key=lambda o: o["spec"]["index"]):
        s = o["spec"]
        head = (f"#{s['index']} {s['fault']} at {s['noise_um']:g} um ({s['rig']}, {s['natural_rpm']:g} rpm, "
                f"zeta {s['zeta']:.3f}, {s['sample_rate'] / 1000:g} kHz, {s['direction']}, seed {s['seed']})")
        if "error" in o:
            out.append(f"{head}: ERROR {o['error']}")
            continue
        if "unstable" in o:
            out.append(f"{head}: not made, the simulator diverged ({o['unstable']})")
            continue
        cr = _crack(o)
        crack_bad = cr and (cr["size_error"] > 0.05 or cr["axis_error_deg"] > 5.0)
        if o["right"] and not crack_bad:
            continue
        fault = {k: round(v, 5) for k, v in (o["truth"]["fault"] or {}).items()}
        extra = (f"; crack (as {cr['as']}) size error {cr['size_error'] * 100:.1f} %, axis "
                 f"{cr['axis_error_deg']:.1f} deg" if cr else "")
        rejected = o.get("rejected") or {}
        if isinstance(rejected, list):  # a table's diagnosis lists its rules
            rejected = {r["effect"]: r["rule"] for r in rejected}
        rej = {k: v for k, v in rejected.items() if k == o["spec"]["fault"]}
        extra += f"; {o['spec']['fault']} turned down: {rej[o['spec']['fault']]}" if rej else ""
        und = (o.get("undecidable") or {}).get(o["spec"]["fault"])
        det = (o.get("detectability") or {}).get(o["spec"]["fault"])
        extra += f"; said: {und}" if und else (f"; detectability: {det}" if det else "")
        out.append(f"{head} {fault}: named {o['named'] or 'nothing'} (verdict {o['verdict']}; vectors "
                   f"{o['vectors_missing']}), floor {o['floor_ratio'] or math.nan:.2f}x{extra}")
    return out


def timing_lines(outcomes: list[dict]) -> list[str]:
    ok = [o for o in outcomes if "diagnosis_s" in o]
    if not ok:
        return []
    lines = []
    for rig in RIGS:
        rows = [o for o in ok if o["spec"]["rig"] == rig]
        if rows:
            d = [o["diagnosis_s"] for o in rows]
            rt = [o["diagnosis_s"] / o["truth"]["duration_s"] for o in rows]
            lines.append(f"{rig}: diagnosis {statistics.median(d):.1f} s median ({min(d):.1f}-{max(d):.1f} s), "
                         f"{statistics.median(rt):.2f}x real time median (max {max(rt):.2f}x), {len(rows)} records")
    w = [o["wall_s"] for o in ok]
    lines.append(f"all: wall {statistics.median(w):.1f} s per record median ({min(w):.1f}-{max(w):.1f} s; "
                 "simulation + file + diagnosis)")
    return lines


def report(outcomes: list[dict]) -> str:
    parts = ["Detection against probe noise", "", detection_table(outcomes), "", "Per record kind (right / records)",
             "", per_fault_table(outcomes), "", "Failures (not named right, or a crack's size > 5 % / axis > 5 deg):"]
    parts += [f"- {f}" for f in failures(outcomes)] or ["- none"]
    parts += ["", "Wall time per record"] + [f"- {t}" for t in timing_lines(outcomes)]
    return "\n".join(parts)


# ------------------------------------------------------------------ main
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="6 records (crack, rub, healthy at 0.3 and 1 um), <= 5 kHz")
    ap.add_argument("--noise", default=None, help="probe noise levels, um (comma-separated; default 0.1,0.3,1,3)")
    ap.add_argument("--faults", default=None, help=f"record kinds (comma-separated; default all: {','.join(KINDS)})")
    ap.add_argument("--reps", type=int, default=1, help="records per kind and noise level")
    ap.add_argument("--artefacts", action="store_true",
                    help="instrument artefacts on every record: mains hum (50 or 60 Hz, 0.3-1.5 um, and its third "
                         "harmonic) and a scratch on every track (1-4 um)")
    ap.add_argument("--drift", type=float, default=0.0, metavar="UM",
                    help="the probes' slowly moving mean on every record: each plane's centreline lifting by UM with "
                         "the speed squared, each probe's gap drifting linearly by up to UM/2")
    ap.add_argument("--flicker", type=float, default=0.0, metavar="HZ",
                    help="the probes' 1/f noise on every record: its density the white noise's times 1 + HZ / f")
    ap.add_argument("--vectors", action="store_true",
                    help="diagnose each record's order-tracked 1X/2X table (rotor-id diagnose TABLE --vectors --rig) "
                         "instead of its waveforms")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2, help="worker processes (one BLAS thread each)")
    ap.add_argument("--out", default="rig_suite.json", help="JSON of every outcome (rewritten after each record)")
    ap.add_argument("--medium", action="store_true",
                    help="every kind at 0.3 um, the crack (asymmetry) and the healthy rotor at every noise level "
                         "(17 records of the full plan, same seeds)")
    ap.add_argument("--resume", action="store_true",
                    help="keep the outcomes already in --out (same seed) and run only the records it lacks")
    ap.add_argument("--skip", default="", help="record indices not to run (comma-separated; e.g. run elsewhere)")
    ap.add_argument("--report", default=None, nargs="+", metavar="JSON",
                    help="print the tables of saved runs (several: their records together) and exit")
    args = ap.parse_args(argv)
    if args.report:
        outcomes = []
        for path in args.report:
            saved = json.loads(Path(path).read_text(encoding="utf-8"))
            print(f"{path}: {saved['meta']['command']} (started {saved['meta']['started_utc']}, "
                  f"{saved['meta']['machine']}, {saved['meta']['cpus']} CPUs, {len(saved['outcomes'])} records in "
                  f"{saved['meta']['elapsed_s']:.0f} s)")
            outcomes += saved["outcomes"]
        print()
        print(report(outcomes))
        return 0
    try:
        noises = tuple(float(x) for x in args.noise.split(",")) if args.noise else (
            (0.3, 1.0) if args.quick else NOISES_UM)
    except ValueError:
        ap.error(f"--noise {args.noise!r}: comma-separated numbers (um)")
    kinds = tuple(args.faults.split(",")) if args.faults else (
        ("asymmetry", "rub", "healthy") if args.quick else KINDS)
    bad = [k for k in kinds if k not in KINDS]
    if bad:
        ap.error(f"--faults: unknown {bad}; known: {', '.join(KINDS)}")
    if args.reps < 1 or args.workers < 1:
        ap.error("--reps and --workers must be >= 1")
    if any(not (math.isfinite(n) and n > 0) for n in noises):
        ap.error(f"--noise: positive numbers, got {noises}")
    specs = build_specs(noises, kinds, args.reps, args.seed, args.quick)
    if args.artefacts:
        from dataclasses import replace

        specs = [replace(s, artefacts=True) for s in specs]
    if args.drift:
        from dataclasses import replace

        if not (math.isfinite(args.drift) and args.drift > 0):
            ap.error(f"--drift: a positive number of um, got {args.drift}")
        specs = [replace(s, drift_um=args.drift) for s in specs]
    if args.flicker:
        from dataclasses import replace

        if not (math.isfinite(args.flicker) and args.flicker > 0):
            ap.error(f"--flicker: a positive corner frequency in Hz, got {args.flicker}")
        specs = [replace(s, flicker_hz=args.flicker) for s in specs]
    if args.vectors:
        from dataclasses import replace

        specs = [replace(s, vectors=True) for s in specs]
    if args.medium:
        # a subset of the full plan (same indices and seeds): what a loaded 2-core machine
        # diagnoses in about half an hour
        specs = [s for s in specs if s.noise_um == 0.3 or s.fault in ("asymmetry", "healthy")]
    try:
        skip = {int(x) for x in args.skip.split(",") if x.strip()}
    except ValueError:
        ap.error(f"--skip {args.skip!r}: comma-separated record indices")
    specs = [s for s in specs if s.index not in skip]
    out_path = Path(args.out)
    done: list[dict] = []
    if args.resume and out_path.is_file():
        saved = json.loads(out_path.read_text(encoding="utf-8"))
        want = {(s.index, s.seed) for s in specs}
        done = [o for o in saved["outcomes"] if (o["spec"]["index"], o["spec"]["seed"]) in want]
        have = {o["spec"]["index"] for o in done}
        specs = [s for s in specs if s.index not in have]
        print(f"resuming: {len(done)} outcomes kept from {out_path}", file=sys.stderr)
    started = datetime.now(timezone.utc)
    print(f"rig suite: {len(specs)} records, {args.workers} workers, seed {args.seed}, "
          f"{platform.node()} ({os.cpu_count()} CPUs), started {started:%Y-%m-%d %H:%M} UTC", file=sys.stderr)
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from multiprocessing import get_context

    outcomes: list[dict] = list(done)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers, mp_context=get_context("spawn")) as pool:
        # kind by kind (every noise level of a kind together): a run cut short still has
        # every noise level of the kinds it did
        order = sorted(specs, key=lambda s: (KINDS.index(s.fault), s.noise_um, s.index))
        if args.medium:  # the crack and the healthy rotor's noise sweep first, alternating
            order = sorted(specs, key=lambda s: (s.fault not in ("asymmetry", "healthy"), s.noise_um,
                                                 KINDS.index(s.fault)))
        futures = {pool.submit(run_record, s): s for s in order}
        for fut in as_completed(futures):
            o = fut.result()
            outcomes.append(o)
            s = o["spec"]
            status = ("ERROR " + o["error"]) if "error" in o else ("NOT MADE " + o["unstable"]) if "unstable" in o else (
                f"{'ok ' if o['right'] else 'MISS'} named {o['named']} floor {o['floor_ratio'] or math.nan:.2f}x "
                f"{o['diagnosis_s']:.0f} s")
            print(f"[{len(outcomes)}/{len(specs) + len(done)} {time.perf_counter() - t0:.0f} s] #{s['index']} {s['fault']} "
                  f"{s['noise_um']:g} um {s['rig']}: {status}", file=sys.stderr, flush=True)
            meta = {"command": " ".join(["python", "benchmarks/rig_suite.py", *(argv if argv is not None
                                                                               else sys.argv[1:])]),
                    "started_utc": started.isoformat(timespec="seconds"), "machine": platform.node(),
                    "cpus": os.cpu_count(), "workers": args.workers, "seed": args.seed,
                    "elapsed_s": time.perf_counter() - t0}
            out_path.write_text(json.dumps({"meta": meta, "outcomes": sorted(outcomes, key=lambda o: o["spec"]["index"])},
                                           indent=1))
    print(report(outcomes))
    print(f"\n{len(specs)} records in {time.perf_counter() - t0:.0f} s with {args.workers} workers; outcomes in "
          f"{out_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
