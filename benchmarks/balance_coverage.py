"""Coverage of the balancing intervals over many seeds (the test keeps 40 of them).

For a linear rotor (:class:`rotor_env.balance.simulate.DiskRotor`, one and two planes) with
random reference unbalances and random trial weights (2-15 g at 100 mm, any angle; one
trial per plane plus one run with weights on random planes), three repeat acquisitions
per run at 1200, 1500 and 2000 rpm with 1 um of circular noise: the share of seeds whose
95 % intervals hold the truth — the reference's unbalance (magnitude and angle), every
run's, the influence coefficients' magnitudes — and how often a misfit is flagged.

    python benchmarks/balance_coverage.py [--seeds 1000]

Prints one JSON object per number of planes, with the binomial 95 % interval of each share.
"""

from __future__ import annotations

import argparse
import json
import time

from scipy import stats

from rotor_env.balance.simulate import coverage_study


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=1000)
    ap.add_argument("--noise-um", type=float, default=1.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    for planes in (1, 2):
        t0 = time.perf_counter()
        out = coverage_study(range(args.seeds), planes=planes, noise_um=args.noise_um, repeats=args.repeats)
        n = args.seeds * planes
        # Clopper-Pearson interval of the reference's coverage (independent across seeds)
        band = {}
        for key in ("ref_g_mm", "ref_deg"):
            k = round(out[key] * n)
            band[key] = [float(stats.beta.ppf(0.025, k, n - k + 1)), float(stats.beta.ppf(0.975, k + 1, n - k))]
        print(json.dumps({"planes": planes, "seeds": args.seeds, "noise_um": args.noise_um,
                          "repeats": args.repeats, **{k: (v if v is None or isinstance(v, int) else round(float(v), 4)) for k, v in out.items()},
                          "clopper_pearson_95": band, "seconds": round(time.perf_counter() - t0, 1)}))


if __name__ == "__main__":
    main()
