"""The bigger fuzz run of issue 22: N seeded mutations per kind (rig YAML, 1X tables,
monitor streams), 5 % of the tables diagnosed in full, in a child process with its address
space capped.  ``python scripts/fuzz_inputs.py [N] [SEED]`` prints the counts and every
failure (input, reason, trace) as JSON; exit 1 when any.  CI runs 60 a kind
(tests/test_attack_fuzz.py)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import attack_fuzz


def main() -> int:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    out = attack_fuzz.run_in_subprocess(n, seed, memory_gb=4.0, timeout_s=6 * 3600, per_case_s=120,
                                        full_share=0.05)
    print(json.dumps(out, indent=1))
    return 1 if out["failures"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
