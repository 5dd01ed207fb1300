"""The fault suite's confusion matrix (rows: truth, columns: what the diagnosis named).

    .venv/bin/python scripts/confusion_matrix.py [--jobs N] [--only ROW ...]

Runs every case of ``tests/fault_cases.py`` (every library effect hidden in turn with two
parameter sets, three noise seeds, run-up and coast-down; lookalike pairs the other way
round; two faults at once) and prints a Markdown table, the share right and the cracks
named for rotors without one.
"""

from __future__ import annotations

import os

# one BLAS thread per worker process (set before numpy loads): --jobs processes with a
# multithreaded BLAS each oversubscribe the cores (the suite ran ~3x slower that way)
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

import fault_cases as FC  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--only", action="append", metavar="ROW",
                    help="run only the cases of this row (truth; repeatable), e.g. --only rub")
    args = ap.parse_args(argv)
    cases = FC.hidden_effect_cases() + FC.lookalike_cases()
    if args.only:
        unknown = set(args.only) - {c.name for c in cases}
        if unknown:
            ap.error(f"no such row: {', '.join(sorted(unknown))}")
        cases = [c for c in cases if c.name in args.only]
    outcomes = FC.run_suite(cases, jobs=args.jobs, progress=True)
    rows, cols, counts = FC.confusion(outcomes)
    print("| truth \\ named | " + " | ".join(cols) + " |")
    print("|---|" + "---:|" * len(cols))
    for r in rows:
        print(f"| {r} | " + " | ".join(str(counts[(r, c)] or "") for c in cols) + " |")
    right = sum(o.right for o in outcomes)
    false_cracks = [o for o in outcomes if set(o.named) & FC.CRACKS and not set(o.case.hidden) & FC.CRACKS]
    print(f"\nright (exactly the hidden effects, parameters within 5 %): {right} of {len(outcomes)} "
          f"({100 * right / len(outcomes):.1f} %); cracks named for rotors without one: {len(false_cracks)}")
    for o in outcomes:
        if not o.right:
            print(f"  wrong: {o.case.name} [{o.case.rotor}, {o.case.run}, seed {o.case.seed}]: named "
                  f"{list(o.named)}, verdict {o.verdict}, errors { {k: round(v, 4) for k, v in o.errors.items()} }")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
