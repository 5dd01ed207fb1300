"""Speed of the order-tracked vector diagnosis (``rotor-id diagnose TABLE --vectors``) on an
800-revolution 1X table, against an older revision's code in the same run.

The table: a one-plane rig (X/Y probes at +-45 deg) run up from 300 to 3000 rpm at 93 rpm/s
through its 1650 rpm critical (zeta 0.02) with a shaft bow, 0.3 um probe noise at 3 kHz,
order-tracked per revolution (797 rows, 1X only), written to a temporary CSV and read back
as the command does.  Each code base diagnoses it in its own subprocess: the table is
loaded, then ``diagnose_vectors`` is timed (best of ``--repeat``, after one warm-up call
that pays numba's compilation); the criticals and damping ratios of both are printed, so
the same answer is seen with the time.

    python benchmarks/vector_speed.py                    # this checkout against main
    python benchmarks/vector_speed.py --baseline 7622279 --repeat 3
    python benchmarks/vector_speed.py --with-2x --baseline e6226ea   # its 1X/2X table: the cracks tried too

The baseline's code is exported with ``git archive`` into a temporary folder (no worktree).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 5.0

_SNIPPET = r"""
import json, sys, time
from rotor_env.diagnosis.from_vectors import diagnose_vectors
from rotor_env.measurements.vectors import load_vector_table
table = load_vector_table(sys.argv[1], angles={"x": 45.0, "y": -45.0})
times = []
for _ in range(int(sys.argv[2]) + 1):  # the first call compiles (numba): not counted unless alone
    t0 = time.perf_counter()
    out = diagnose_vectors(table).to_dict()
    times.append(time.perf_counter() - t0)
print(json.dumps({"first_s": times[0], "best_s": min(times[1:] or times), "criticals": out["criticals"],
                  "missing": out["missing"], "verdict": out["verdict"], "rows": len(table.speed)}))
"""


def write_table(path: Path, orders: tuple[int, ...] = (1,)) -> None:
    from rotor_env.measurements.rig import load_rig
    from rotor_env.params import RotorParams
    from rotor_env.rig_simulation import simulate_rig

    rig_path = path.with_suffix(".yaml")
    rig_path.write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
    rig = load_rig(rig_path)
    params = RotorParams(ip=0.0, values={"c": 0.04, "tau": 0.005, "beta": 0.6, "bow": 0.004},
                         effects=("stiffness", "viscous_damping", "unbalance", "shaft_bow"))
    run = simulate_rig(rig, params, rpm_per_s=93.0, sample_rate=3000.0, noise=0.3, seed=1)
    run.vectors(rig, orders).to_csv(path, overwrite=True)


def time_code(code_root: Path, table: Path, repeat: int) -> dict:
    env = {**os.environ, "PYTHONPATH": str(code_root), "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", _SNIPPET, str(table), str(repeat)], env=env, cwd=code_root,
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"the diagnosis with the code in {code_root} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def export(rev: str, into: Path) -> Path:
    archive = into / "code.tar"
    with open(archive, "wb") as fh:
        subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", rev], stdout=fh, check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(into / "code", filter="data")
    return into / "code"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default="main", help="git revision to compare with (default: main)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="timed calls after the warm-up (best is reported); 0: the first call only (numba's "
                         "kernels cached on disk from an earlier run: about the warm time)")
    ap.add_argument("--with-2x", action="store_true",
                    help="the same run's 1X and 2X columns (what `rotor-id simulate --vectors` writes): the crack "
                         "and misalignment candidates are tried on the 2X as well")
    args = ap.parse_args(argv)
    orders = (1, 2) if args.with_2x else (1,)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        table = tmp / "run800.csv"
        write_table(table, orders)
        new = time_code(ROOT, table, args.repeat)
        old = time_code(export(args.baseline, tmp), table, args.repeat)
    print(f"# vector diagnosis of an 800-revolution {'1X/2X' if args.with_2x else '1X'} table ({new['rows']} rows), "
          f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, one thread")
    print()
    print("| code | diagnosis (s, warm) | first call (s) | criticals (rpm, damping ratio) | missing | verdict |")
    print("|---|---|---|---|---|---|")
    for name, r in (("this checkout", new), (f"{args.baseline}", old)):
        crit = ", ".join(f"{c['rpm']:.4f} / {c['damping_ratio']:.6f}" for c in r["criticals"])
        print(f"| {name} | {r['best_s']:.2f} | {r['first_s']:.2f} | {crit} | {', '.join(r['missing'])} | "
              f"{r['verdict']} |")
    print()
    print(f"speed-up x{old['best_s'] / new['best_s']:.1f}; target <= {TARGET_S:g} s: "
          f"{'met' if new['best_s'] <= TARGET_S else 'not met'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
