"""Coverage of the balancing intervals over many seeds (tests/test_balance.py keeps a few).

For a linear rotor (:class:`rotor_env.balance.simulate.DiskRotor`, one and two planes) with
random reference unbalances (200-1500 g·mm) and random trial weights (2-15 g at 100 mm, any
angle; one trial per plane plus one run with weights on random planes), repeat acquisitions
per run at 1200, 1500 and 2000 rpm with circular noise: the share of seeds whose 95 %
intervals hold the truth — the reference's unbalance (magnitude and angle: the profile-
likelihood intervals, the JSON's symmetric half-widths that enclose them, and the
first-order intervals of the two-stage estimate for comparison), split by the trial
weights' signal-to-noise, the influence coefficients' magnitudes, and how often a misfit is
flagged (a false alarm here).

    python benchmarks/balance_coverage.py [--seeds 400] [--settings 1:3,5:2,10:2] [--planes 1,2]

``--settings``: ``NOISE_UM:REPEATS`` pairs.  Prints one JSON line per planes and setting, with
the Clopper-Pearson 95 % interval of each reference share (one Bernoulli per seed and plane).
"""

from __future__ import annotations

import argparse
import json
import time

from scipy import stats

from rotor_env.balance.simulate import coverage_study


def clopper_pearson(k: int, n: int) -> list[float]:
    lo = float(stats.beta.ppf(0.025, k, n - k + 1)) if k > 0 else 0.0
    hi = float(stats.beta.ppf(0.975, k + 1, n - k)) if k < n else 1.0
    return [round(lo, 4), round(hi, 4)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=400)
    ap.add_argument("--settings", default="1:3,5:2,10:2", help="NOISE_UM:REPEATS pairs, comma-separated")
    ap.add_argument("--planes", default="1,2")
    ap.add_argument("--every-run", action="store_true", help="also every calibration run's unbalance (slower)")
    args = ap.parse_args()
    for planes in (int(p) for p in args.planes.split(",")):
        for setting in args.settings.split(","):
            noise, repeats = setting.split(":")
            t0 = time.perf_counter()
            out = coverage_study(range(args.seeds), planes=planes, noise_um=float(noise), repeats=int(repeats),
                                 every_run=args.every_run)
            counts = out.pop("counts")
            band = {k: clopper_pearson(round(out[k] * counts[k]), counts[k])
                    for k in out if k.startswith("ref_") and out[k] is not None}
            print(json.dumps({"planes": planes, "noise_um": float(noise), "repeats": int(repeats),
                              **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in out.items()},
                              "n": {k: counts[k] for k in ("ref_g_mm", "ref_g_mm_low_snr", "influence")},
                              "clopper_pearson_95": band, "seconds": round(time.perf_counter() - t0, 1)}),
                  flush=True)


if __name__ == "__main__":
    main()
