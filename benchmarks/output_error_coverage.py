"""Coverage of the output-error fit's 95 % intervals on noisy displacements.

Simulated run-ups (seeded, dimensionless) of a rotor with unbalance and viscous damping,
plus one hidden effect per study (a crack with its axis off the keyphasor notch, a shaft
bow), Gaussian noise on both tilts; each record fitted by
:func:`rotor_env.diagnosis.output_error.fit_output_error` with the right model, and each
parameter's interval ``value +- 1.96 se`` (HAC sandwich) checked against the truth.

Prints, per study and parameter, the share of intervals that cover the truth with its
exact (Clopper-Pearson) 95 % range, and the mean |error| / se.  What the intervals
cover: the parameters of the best model in the class fitted, under the noise of the
record (not a model error).

    python benchmarks/output_error_coverage.py --seeds 200 --workers 2
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from concurrent.futures import ProcessPoolExecutor

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

STUDIES = {
    "healthy": ({}, (), {"unbalance.tau_cos_beta": 0.005 * math.cos(0.3), "unbalance.tau_sin_beta": 0.005 * math.sin(0.3),
                         "viscous_damping.c": 0.05}),
    "crack at 40 deg": ({"D": 0.03, "D_axis": math.radians(40)}, ("asymmetry",),
                        {"asymmetry.D": 0.03, "asymmetry.D_axis": math.radians(40), "viscous_damping.c": 0.05}),
    "bow": ({"bow": 0.006, "bow_phase": 1.0}, ("shaft_bow",),
            {"shaft_bow.bow_cos": 0.006 * math.cos(1.0), "shaft_bow.bow_sin": 0.006 * math.sin(1.0),
             "viscous_damping.c": 0.05}),
}


def one(args):
    study, seed, noise = args
    from rotor_env.diagnosis.output_error import ShootingGrid, fit_output_error
    from rotor_env.params import RotorParams
    from rotor_env.simulator import RunUp, Simulator

    extra, effects, truth = STUDIES[study]
    vals = {"tau": 0.005, "beta": 0.3, "c": 0.05, "k": 1.0, **extra}
    p = RotorParams(ip=0.0, effects=("stiffness", "unbalance", "viscous_damping", *effects), values=vals)
    rate = 0.006
    m = Simulator(p).run(t_end=1.3 / rate, dt=0.03, run_up=RunUp(rate=rate, speed0=0.4))
    rng = np.random.default_rng(seed)
    thx = m.theta_x + rng.normal(0.0, noise, len(m.t))
    thy = m.theta_y + rng.normal(0.0, noise, len(m.t))
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    start = {"unbalance": {"tau": 0.004, "beta": 0.0}, "viscous_damping": {"c": 0.04}}
    if "asymmetry" in effects:
        start["asymmetry"] = {"D": 0.02, "D_axis": math.radians(30)}
    f = fit_output_error(grid, ("unbalance", "viscous_damping", *effects), start)
    out = {}
    for name, value in truth.items():
        i = f.names.index(name)
        out[name] = (float(f.values[i]), float(f.std_errors[i]), value)
    return study, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--noise", type=float, default=1e-3)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    jobs = [(s, 1000 + k, args.noise) for s in STUDIES for k in range(args.seeds)]
    res: dict = {}
    with ProcessPoolExecutor(args.workers) as pool:
        for study, out in pool.map(one, jobs):
            for name, (v, se, truth) in out.items():
                res.setdefault((study, name), []).append((v, se, truth))
    print(f"95 % intervals of the output-error fit, {args.seeds} seeds per study, noise {args.noise:g} "
          "(dimensionless tilt)\n")
    print("| study | parameter | coverage | exact 95 % range | mean abs(error)/se |")
    print("|---|---|---|---|---|")
    for (study, name), rows in res.items():
        a = np.array(rows)
        hit = np.abs(a[:, 0] - a[:, 2]) <= 1.96 * a[:, 1]
        k, n = int(hit.sum()), len(hit)
        lo = stats.beta.ppf(0.025, k, n - k + 1) if k > 0 else 0.0
        hi = stats.beta.ppf(0.975, k + 1, n - k) if k < n else 1.0
        z = float(np.mean(np.abs(a[:, 0] - a[:, 2]) / a[:, 1]))
        print(f"| {study} | {name} | {k}/{n} = {k / n:.1%} | {lo:.1%}-{hi:.1%} | {z:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
