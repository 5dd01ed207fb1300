"""The bigger fuzz run of issue 22: N seeded mutations per kind (rig YAML, 1X tables,
monitor streams), a share of the tables diagnosed in full, in a child process with its
address space capped.  ``python scripts/fuzz_inputs.py [N] [SEED]`` prints the counts and
every failure (input, reason, trace) as JSON; exit 1 when any, 2 on a bad argument.  CI
runs 60 a kind (tests/test_attack_fuzz.py)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def _positive(kind):
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text[:40]!r} is not a number") from None
        if not value > 0:
            raise argparse.ArgumentTypeError(f"{text[:40]!r} must be above zero")
        return value
    return parse


def _share(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text[:40]!r} is not a number") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"{text[:40]!r} is not a share in [0, 1]")
    return value


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="fuzz_inputs.py", description=__doc__.split("\n\n")[0])
    p.add_argument("n", nargs="?", type=_positive(int), default=1000, help="mutations per kind (default 1000)")
    p.add_argument("seed", nargs="?", type=int, default=0, help="the mutations' seed (default 0)")
    p.add_argument("--memory-gb", type=_positive(float), default=4.0, help="address-space cap of the child (4)")
    p.add_argument("--timeout", type=_positive(float), default=6 * 3600.0, help="wall-clock limit, s (6 h)")
    p.add_argument("--per-case", type=_positive(float), default=120.0, help="limit per mutation, s (120)")
    p.add_argument("--full-share", type=_share, default=0.05, help="share of tables diagnosed in full (0.05)")
    args = p.parse_args(argv)

    import attack_fuzz

    out = attack_fuzz.run_in_subprocess(args.n, args.seed, memory_gb=args.memory_gb, timeout_s=args.timeout,
                                        per_case_s=args.per_case, full_share=args.full_share)
    print(json.dumps(out, indent=1))
    return 1 if out["failures"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
