"""Speed of ``rotor_env.diagnosis.diagnose`` on a 40 000-sample file.

The data: the paper's Table-1 run (t in [0, 400], dt = 0.01: 40 001 rows) with
Gaussian noise of std 5e-4 on the six inclination channels, written to a temporary
CSV and read back with ``load_measurements`` (as ``rotor-id diagnose FILE`` does).
The diagnosis starts from its default model (unbalance, viscous damping) with every
library candidate.

Timed in this process, in this order:

* the loader (best of ``--repeat``);
* the first ``diagnose`` call, which includes numba's compilation of the free-run
  simulator and estimator kernels (reported separately, not counted against the
  target);
* ``diagnose`` after that warm-up (best and median of ``--repeat``): the number the
  target (< 5 s) is about;
* ``diagnose`` with the paper's five candidates only (the library before the field
  faults: the ratio is what the whole library costs), with ``ip`` unknown (estimated
  from the data), and on a probe runout (every candidate ranked and checked);
* the peer: one batch ``numpy.linalg.lstsq`` of the full model (every library
  effect, both equations stacked, as the diagnosis regresses) on the same data,
  regression building and solve timed separately (best of ``--repeat``).

With ``--baseline REV`` (a git revision, e.g. the commit before a speed change) the same
diagnosis is also timed on that revision's code, checked out into a temporary worktree
and run in a subprocess on the same file in the same run: the ratio is the speed-up.

    python benchmarks/diagnosis_speed.py            # prints a Markdown table
    python benchmarks/diagnosis_speed.py --baseline b5d27cf
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rotor_env.diagnosis import DEFAULT_MODEL, LIBRARY_CANDIDATES, diagnose
from rotor_env.measurements.files import load_measurements
from rotor_env.params import RotorParams
from rotor_env.regression import build_regression
from rotor_env.simulator import simulate

TARGET_S = 5.0


def timed(fn, repeat: int) -> tuple[list[float], object]:
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return times, result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--noise", type=float, default=5e-4, help="noise std on the inclination channels")
    ap.add_argument("--seed", type=int, default=0, help="seed of the noise")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs of each step (best of)")
    ap.add_argument("--baseline", metavar="REV", help="also time the diagnosis at this git revision (same data)")
    args = ap.parse_args(argv)

    params = RotorParams()  # Table 1
    meas = simulate(params, t_end=400.0, dt=0.01, noise=args.noise, seed=args.seed)
    candidates = [c for c in LIBRARY_CANDIDATES if c not in DEFAULT_MODEL]

    baseline = None
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "table1_noisy.csv"
        meas.to_file(path)
        size_mb = path.stat().st_size / 1e6
        load_times, loaded = timed(lambda: load_measurements(path), args.repeat)
        if args.baseline:
            baseline = _time_revision(args.baseline, path, Path(tmp), params.ip, args.repeat)
    assert np.array_equal(loaded.data, meas.data)

    t0 = time.perf_counter()
    first = diagnose(loaded, DEFAULT_MODEL, candidates=candidates, ip=params.ip)
    first_s = time.perf_counter() - t0
    diag_times, result = timed(
        lambda: diagnose(loaded, DEFAULT_MODEL, candidates=candidates, ip=params.ip), args.repeat
    )
    assert result.missing == first.missing

    # the same with the paper's library only (the candidates before the field faults were
    # declared): what the bigger library costs
    paper = [c for c in ("asymmetry", "nonlinear_stiffness", "structural_damping", "stiffness", "static_load")
             if c in candidates]
    paper_times, _ = timed(lambda: diagnose(loaded, DEFAULT_MODEL, candidates=paper, ip=params.ip), args.repeat)
    # ip unknown: estimated from the data (the default of `rotor-id diagnose`)
    est_times, est = timed(lambda: diagnose(loaded, DEFAULT_MODEL, candidates=candidates), args.repeat)
    # a measurement fault: a probe runout (1x of constant amplitude in the measured angles,
    # on the linear Jeffcott rotor): every candidate is ranked and checked
    jeffcott = params.replace(D=0.0, k30=0.0, k21=0.0, k12=0.0, k03=0.0, h=0.0)
    runout = _with_runout(simulate(jeffcott, t_end=400.0, dt=0.01), args.noise, args.seed)
    fault_times, fault = timed(lambda: diagnose(runout, DEFAULT_MODEL, candidates=candidates, ip=params.ip),
                               args.repeat)

    full = (*DEFAULT_MODEL, *candidates)
    build_times, reg = timed(
        lambda: build_regression(loaded, full, ip=params.ip, equation="both"), args.repeat
    )
    solve_times, _ = timed(lambda: np.linalg.lstsq(reg.X, reg.y, rcond=None), args.repeat)

    best = min(diag_times)
    rows = [
        ("load_measurements (CSV, 40 001 x 10)", min(load_times), f"{size_mb:.1f} MB file"),
        ("diagnose, first call (incl. numba compile)", first_s, "not counted against the target"),
        ("diagnose, after warm-up: best", best,
         f"target < {TARGET_S:g} s: {'met' if best < TARGET_S else 'NOT met'}"),
        ("diagnose, after warm-up: median", statistics.median(diag_times), f"{args.repeat} runs"),
        ("diagnose, the paper's 5 candidates only: best", min(paper_times),
         f"whole library / paper's = {best / min(paper_times):.2f}x"),
        ("diagnose, ip estimated (no ip given): best", min(est_times),
         f"ip = {est.ip:.4f}; target: {'met' if min(est_times) < TARGET_S else 'NOT met'}"),
        ("diagnose, probe runout (the bow's lookalike): best", min(fault_times),
         f"verdict {fault.verdict}, added: {', '.join(fault.missing) or 'nothing'}; target: {'met' if min(fault_times) < TARGET_S else 'NOT met'}"),
        *([(f"diagnose at {args.baseline} (same file, same run, its own code): best", baseline["best"],
            f"this revision is {baseline['best'] / best:.2f}x faster; it found: "
            f"{', '.join(baseline['missing']) or 'nothing'}")] if baseline else []),
        ("peer: build_regression, full model, both eqs", min(build_times),
         f"{reg.X.shape[0]} x {reg.X.shape[1]}"),
        ("peer: one numpy.linalg.lstsq, full model", min(solve_times), "same regression"),
    ]
    print(f"Diagnosis speed — {len(loaded)} samples, noise {args.noise:g} (seed {args.seed}), "
          f"start model {', '.join(DEFAULT_MODEL)}, candidates {', '.join(candidates)}")
    print(f"found missing: {', '.join(result.missing) or 'nothing'} (verdict {result.verdict})")
    print(f"{platform.python_implementation()} {platform.python_version()}, numpy {np.__version__}, "
          f"{os.cpu_count()} CPUs, {platform.machine()}")
    print()
    print("| step | time (s) | note |")
    print("|---|---:|---|")
    for step, secs, note in rows:
        print(f"| {step} | {secs:.3f} | {note} |")
    peer = min(build_times) + min(solve_times)
    print()
    print(f"diagnose / (build + one lstsq) = {best / peer:.0f}x; "
          f"diagnose / load = {best / min(load_times):.1f}x")
    return 0 if max(best, min(est_times), min(fault_times)) < TARGET_S else 1


_BASELINE_SNIPPET = """
import json, sys, time
from rotor_env.diagnosis import DEFAULT_MODEL, LIBRARY_CANDIDATES, diagnose
try:
    from rotor_env.measurements.files import load_measurements
except ImportError:  # a revision before the readers moved into rotor_env.measurements
    from rotor_env.io import load_measurements
path, ip, repeat = sys.argv[1], float(sys.argv[2]), int(sys.argv[3])
m = load_measurements(path)
cands = [c for c in LIBRARY_CANDIDATES if c not in DEFAULT_MODEL]
r = diagnose(m, DEFAULT_MODEL, candidates=cands, ip=ip)
times = []
for _ in range(repeat):
    t0 = time.perf_counter()
    diagnose(m, DEFAULT_MODEL, candidates=cands, ip=ip)
    times.append(time.perf_counter() - t0)
print(json.dumps({"best": min(times), "missing": list(r.missing)}))
"""


def _time_revision(rev: str, csv: Path, tmp: Path, ip: float, repeat: int) -> dict:
    """The warm diagnosis of ``csv`` with the code of git revision ``rev`` (a temporary worktree)."""
    root = Path(__file__).resolve().parents[1]
    tree = tmp / "baseline"
    try:
        subprocess.run(["git", "-C", str(root), "worktree", "add", "--detach", str(tree), rev], check=True,
                       capture_output=True, text=True)
    except (OSError, subprocess.CalledProcessError) as exc:
        raise SystemExit(f"--baseline {rev}: cannot check it out with git ({getattr(exc, 'stderr', exc)})") from None
    try:
        env = {**os.environ, "PYTHONPATH": str(tree)}
        out = subprocess.run([sys.executable, "-c", _BASELINE_SNIPPET, str(csv), repr(ip), str(repeat)], env=env,
                             cwd=tree, check=True, capture_output=True, text=True)
        return json.loads(out.stdout.strip().splitlines()[-1])
    finally:
        subprocess.run(["git", "-C", str(root), "worktree", "remove", "--force", str(tree)], capture_output=True)


def _with_runout(clean, noise: float, seed: int, r: float = 0.015, gamma: float = 2.0):
    """``clean`` as a probe with runout reads it: ``z += r e^{i(phi + gamma)}`` with the
    consistent rates and accelerations, then sensor noise."""
    from rotor_env.measurements import Measurements

    d = clean.data.copy()
    psi, w, a = clean.phi + gamma, clean.phi_dot, clean.phi_ddot
    s, c = np.sin(psi), np.cos(psi)
    d[:, 4] += r * s                       # theta_x
    d[:, 5] += r * c                       # theta_y
    d[:, 6] += r * w * c                   # theta_x_dot
    d[:, 7] += -r * w * s                  # theta_y_dot
    d[:, 8] += r * (a * c - w * w * s)     # theta_x_ddot
    d[:, 9] += r * (-a * s - w * w * c)    # theta_y_ddot
    return Measurements(d).with_noise(noise, seed=seed)


if __name__ == "__main__":
    raise SystemExit(main())
