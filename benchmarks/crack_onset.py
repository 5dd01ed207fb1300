"""A crack that appears during a rig record: what the waveforms' output-error diagnosis says.

The record: a one-plane rig (X/Y probes at +-45 deg, um, keyphasor), 1650 rpm critical
(zeta 0.02), run up 300 -> 3000 rpm at 300 rpm/s, 10 kHz, 0.5 um probe noise; an open crack
``D`` (stiff axis 30 deg from the notch) appears at ``--at-rpm``.  With ``--side-load`` the rotor
also carries a static load (gravity), which turns the crack into a 2X forcing.  The batch
diagnosis fits one model to the whole record; its parameter-constancy test dates the break, and
where the parameters are not the same each side is diagnosed on its own (what appeared).

    python benchmarks/crack_onset.py                 # crack at 2400 rpm, no side load
    python benchmarks/crack_onset.py --side-load 0.01 --at-rpm 1200
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--at-rpm", type=float, default=2400.0, help="the crack appears at this speed")
    ap.add_argument("--D", type=float, default=0.03, help="the crack's asymmetry (dimensionless)")
    ap.add_argument("--side-load", type=float, default=0.0, help="static load load_y (dimensionless)")
    ap.add_argument("--noise", type=float, default=0.5, help="probe noise, um")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--json", help="also write the whole diagnosis (JSON) here")
    args = ap.parse_args(argv)

    import pyarrow as pa
    import pyarrow.parquet as pq

    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.measurements.rig import SPEED_UNITS, load_rig
    from rotor_env.measurements.waveforms import load_waveforms
    from rotor_env.params import Crack, RotorParams
    from rotor_env.rig_simulation import simulate_rig

    natural, rpm_from, rate = 1650.0, 300.0, 300.0
    with tempfile.TemporaryDirectory(prefix="crack_onset_") as tmp:
        folder = Path(tmp)
        (folder / "rig.yaml").write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
        rig = load_rig(folder / "rig.yaml")
        w_ref = natural * SPEED_UNITS["rpm"]
        t_crack = (args.at_rpm - rpm_from) / rate
        effects = ["stiffness", "viscous_damping", "unbalance", "asymmetry"]
        values = {"c": 0.04, "tau": 0.005, "D": 0.0, "D_axis": 0.5236}
        if args.side_load:
            effects.append("static_load")
            values["load_y"] = -abs(args.side_load)
        params = RotorParams(ip=0.0, values=values, effects=tuple(effects), crack=Crack(t_crack * w_ref, args.D))
        run = simulate_rig(rig, params, natural_rpm=natural, rpm_from=rpm_from, rpm_per_s=rate, sample_rate=10000.0,
                           noise=args.noise, seed=args.seed)
        pq.write_table(pa.table(run.file_columns()), folder / "run.parquet")
        record = load_waveforms(folder / "run.parquet", rig)
        t0 = time.perf_counter()
        d = diagnose_rig(record)
        seconds = time.perf_counter() - t0
    out = d.to_dict()
    print(f"crack D = {args.D:g} at {args.at_rpm:g} rpm ({t_crack:.2f} s), side load {args.side_load:g}, "
          f"{args.noise:g} um noise: verdict {out['verdict']}, named {out['missing'] or 'nothing'}, "
          f"residual {out['rms_ratio_after']:.3f}x the floor, {seconds:.1f} s")
    if out.get("change"):
        print(f"  {out['change']['sentence']}")
    if out.get("parts") and not out["parts"]["changed"]:
        print(f"  {out['parts']['sentence']}")
    if args.json:
        import json

        from rotor_env.results import jsonable

        Path(args.json).write_text(json.dumps(jsonable(out), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
