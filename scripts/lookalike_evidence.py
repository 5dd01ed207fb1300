"""One diagnosis per lookalike pair: the JSON evidence that told the hidden effect from its lookalike.

    .venv/bin/python scripts/lookalike_evidence.py [--seed N]

For each pair of the fault library (bow vs unbalance, misalignment vs crack, breathing vs
open crack, support anisotropy vs shaft asymmetry, rub vs stiffness and quadratic
stiffness, cross-coupling vs damping) the first effect is hidden in a run-up of the fault
suite's rotor A (``tests/fault_cases.py``, noise as there) and diagnosed; printed per pair:
what was named, the verdict, and the result's ``lookalikes`` entry for it (the JSON of
``rotor-id diagnose --json``: declared orders, the residual's order lines before it was
added, and each lookalike with the evidence that decided).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

import fault_cases as FC

PAIRS = {
    "shaft_bow": "bow vs unbalance",
    "misalignment": "misalignment vs crack",
    "breathing_crack": "breathing vs open crack",
    "support_anisotropy": "support anisotropy vs shaft asymmetry",
    "rub": "rub vs stiffness / quadratic stiffness",
    "cross_coupled_stiffness": "cross-coupling vs damping",
}


def _rounded(x, digits: int = 4):
    if isinstance(x, float):
        return float(f"{x:.{digits}g}")
    if isinstance(x, dict):
        return {k: _rounded(v, digits) for k, v in x.items()}
    if isinstance(x, list):
        return [_rounded(v, digits) for v in x]
    return x


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--seed", type=int, default=FC.SEEDS[0], help="noise seed of the cases")
    ap.add_argument("--indent", type=int, default=None, help="indent the JSON (default: one line per pair)")
    args = ap.parse_args(argv)
    from rotor_env.diagnosis import diagnose

    cases = {c.name: c for c in FC.hidden_effect_cases()
             if c.rotor == "A" and c.run == "run-up" and c.seed == args.seed}
    for effect, pair in PAIRS.items():
        case = cases[effect]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            d = diagnose(case.simulate(), model=case.start_model, ip=case.truth["ip"])
        out = d.to_dict()
        evidence = [ev for ev in out.get("lookalikes") or [] if ev.get("effect") == effect]
        print(json.dumps(_rounded({"pair": pair, "hidden": effect,
                                   "truth": {k: case.truth[k] for k in case.checked},
                                   "named": out["missing"], "verdict": out["verdict"],
                                   "lookalikes": evidence}), indent=args.indent))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
