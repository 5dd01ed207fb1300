"""Fleet diagnosis: ``rotor-id batch`` on Ray against a plain sequential loop.

Simulates ``--n`` small run-ups (different seeds; every third one cracks), then times,
each in a fresh process from the command line to the last result (interpreter start,
imports, numba's cached kernels, the diagnoses):

* ``sequential``: one process, ``for f in files: diagnose_file(f)``; again with one BLAS/OpenMP
  thread (``OMP_NUM_THREADS=1``, what Ray gives a task of one CPU);
* ``ray W``: ``rotor-id batch FOLDER --out RESULTS --workers W`` for each ``--workers W``
  (Ray's local mode), or on the cluster at ``--address``.

Prints a Markdown table: wall seconds, recordings per second, the speed-up over the
sequential loop, and whether every verdict and missing-effect list equals the sequential
one.  The Ray overhead on one worker is the ``ray 1`` row's time over the sequential.

    python benchmarks/batch.py [--n 200] [--workers 1,2] [--address ADDR] [--runs seq,seq1,ray]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BIN = Path(sys.executable).parent
#: the command line tool; ``python -m rotor_env.cli`` where the package is on the path but not installed
ROTOR_ID = [str(BIN / "rotor-id")] if (BIN / "rotor-id").exists() else [sys.executable, "-m", "rotor_env.cli"]


def make_fleet(folder: Path, n: int) -> None:
    from rotor_env.params import Crack, RotorParams
    from rotor_env.simulator import RunUp, simulate

    for i in range(n):
        crack = Crack(40.0, 0.05) if i % 3 == 2 else None
        meas = simulate(RotorParams(values={"h": 0.0}, crack=crack), t_end=80.0, dt=0.02, run_up=RunUp(rate=0.04),
                        noise=5e-4, seed=i)
        meas.to_file(folder / f"machine_{i:04d}.csv")


def sequential(folder: str, out: str) -> None:
    """The plain loop (run in its own process by the benchmark)."""
    from rotor_env.batch import diagnose_file

    rows = {}
    for f in sorted(Path(folder).glob("*.csv")):
        try:
            r = diagnose_file(f).to_dict()
            rows[f.stem] = {"verdict": r["verdict"], "missing": list(r["missing"])}
        except Exception as exc:
            rows[f.stem] = {"verdict": "error", "missing": [], "error": str(exc)}
    Path(out).write_text(json.dumps(rows))


def timed(cmd: list[str], env: dict | None = None) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="recordings (default 200)")
    ap.add_argument("--workers", default="1,2", help="comma-separated worker counts (default 1,2)")
    ap.add_argument("--address", help="a Ray cluster to run the batch on (the workers are then its CPUs)")
    ap.add_argument("--runs", default="seq,seq1,ray", help="which runs: seq (the loop), seq1 (the loop with "
                    "OMP_NUM_THREADS=1), ray (default all)")
    ap.add_argument("--sequential-only", metavar="FOLDER:OUT", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.sequential_only:
        folder, out = args.sequential_only.split(":")
        sequential(folder, out)
        return
    work = Path(tempfile.mkdtemp(prefix="rotor-id-batch-bench-"))
    fleet = work / "fleet"
    fleet.mkdir()
    t = time.perf_counter()
    make_fleet(fleet, args.n)
    print(f"{args.n} recordings of 4001 samples (t 0-80, run-up 0.04; every third cracks) simulated in "
          f"{time.perf_counter() - t:.1f} s; {os.cpu_count()} CPUs\n", flush=True)
    which = set(args.runs.split(","))
    print("| run | wall (s) | recordings/s | speed-up vs sequential | same verdicts |")
    print("|---|---|---|---|---|")
    truth, t_seq = None, None
    for tag, name, env in (("seq", "sequential loop", None),
                           ("seq1", "sequential loop, OMP_NUM_THREADS=1", dict(os.environ, OMP_NUM_THREADS="1"))):
        if tag not in which:
            continue
        path = work / f"{tag}.json"
        wall = timed([sys.executable, __file__, "--sequential-only", f"{fleet}:{path}"], env)
        rows = json.loads(path.read_text())
        same = "—" if truth is None else ("yes" if rows == truth else "NO")
        truth = truth or rows
        t_seq = t_seq or wall
        print(f"| {name} | {wall:.1f} | {args.n / wall:.2f} | ×{t_seq / wall:.2f} | {same} |", flush=True)
    if "ray" not in which:
        return
    if truth is None:
        raise SystemExit("--runs: the Ray runs are compared with a sequential one (seq or seq1)")
    counts = [int(w) for w in args.workers.split(",")]
    runs = [("cluster", None)] if args.address else [(f"ray, {w} worker{'s' * (w > 1)}", w) for w in counts]
    for name, w in runs:
        out = work / f"results_{w or 'cluster'}"
        cmd = [*ROTOR_ID, "batch", str(fleet), "--out", str(out)]
        cmd += ["--address", args.address] if args.address else ["--workers", str(w)]
        wall = timed(cmd)
        import pyarrow.parquet as pq

        rows = {r["recording"]: r for r in pq.read_table(out / "results.parquet").to_pylist()}
        same = all(rows[k]["verdict"] == v["verdict"] and list(rows[k]["missing"]) == v["missing"]
                   for k, v in truth.items() if v["verdict"] != "error")
        print(f"| {name} | {wall:.1f} | {args.n / wall:.2f} | ×{t_seq / wall:.2f} | {'yes' if same else 'NO'} |",
              flush=True)
    print(f"\n(the Ray overhead on one worker: the 'ray, 1 worker' row's wall time over the sequential loop's; "
          f"files in {work})")


if __name__ == "__main__":
    main()
