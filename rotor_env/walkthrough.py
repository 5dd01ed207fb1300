"""The main walkthrough: a rotor with a hidden crack, diagnosed from its measurements.

1. A run-up is simulated with sensor noise; the rotor has unbalance, viscous damping,
   dry friction (structural damping) — and a crack that opens at ``t = 250`` (the
   asymmetry ``D`` jumps from 0 to 0.05).  The file is all the engineer gets.
2. The engineer's model knows the first three effects, not the crack.
3. :func:`rotor_env.diagnosis.diagnose` compares the model with the measurements,
   shows where it fails, names the missing effect and its onset, adds it and reports
   the error before and after; figures and an HTML report go to the output folder.
"""

from __future__ import annotations

from pathlib import Path

from .diagnosis import diagnose
from .measurements.files import load_measurements
from .outputs import OutputFolder
from .params import Crack, RotorParams
from .simulator import simulate

HIDDEN = RotorParams().replace(D=0.0, k30=0.0, k21=0.0, k12=0.0, k03=0.0, crack=Crack(250.0, 0.05))
START_MODEL = ("unbalance", "viscous_damping", "structural_damping")
NOISE = 5e-4


def true_coefficients(params: RotorParams, model, t) -> dict:
    """The simulated rotor's regression coefficients of ``model``'s effects over ``t``
    (constants, and a step where the crack opens): the parameter tracks' dashed truth.
    An effect the rotor does not have is truly 0."""
    import numpy as np

    from .effects import EFFECTS

    t = np.asarray(t, dtype=float)
    out = {}
    for name in model:
        eff = EFFECTS[name]
        if not all(p in params.values for p in eff.parameter_names):
            out.update(dict.fromkeys(eff.coefficients, 0.0))
            continue
        before = params.coefficients(name)
        after = params.coefficients(name, params.crack.time) if params.crack is not None else before
        for c, b, a in zip(eff.coefficients, before, after, strict=True):
            out[c] = float(b) if a == b else np.where(t >= params.crack.time, float(a), float(b))
    return out


def run_walkthrough(out: str | Path = "out/walkthrough", *, force: bool = False, seed: int = 1, print_fn=print):
    # --force replaces only the files a previous walkthrough wrote (listed in the folder's
    # marker); a folder with anything else in it is refused, force or not
    folder = OutputFolder(out, force=force)
    out = folder.path
    data_path = folder.file("run_up.csv")
    print_fn("rotor-id walkthrough: a rotor with a hidden crack\n")
    print_fn(f"1. simulating a run-up (t 0-400, dt 0.01, noise std {NOISE:g} on the six inclination "
             f"channels, seed {seed}) -> {data_path}")
    simulate(HIDDEN, noise=NOISE, seed=seed).to_file(data_path, overwrite=True)
    meas = load_measurements(data_path)
    print_fn(f"2. the engineer's model: {', '.join(START_MODEL)} (no crack)\n")
    print_fn("3. diagnosing ...\n")
    result = diagnose(meas, START_MODEL, ip=HIDDEN.ip)
    result.truth = true_coefficients(HIDDEN, result.model, result.data.meas.t)
    print_fn(result.summary())
    for name in result.FIGURES:
        folder.file(f"figures/{name}.png")
    figs = result.save_figures(out / "figures")
    report = result.report(folder.file("report.html"), overwrite=True)
    folder.write_text("diagnosis.json", result.to_json(indent=2))
    print_fn(f"\nfigures: {', '.join(str(p) for p in figs)}")
    print_fn(f"report:  {report}")
    print_fn(f"JSON:    {out / 'diagnosis.json'}")
    print_fn(f"\ntruth: the crack opened at t = {HIDDEN.crack.time:g} with D = {HIDDEN.crack.D:g}")
    return result
