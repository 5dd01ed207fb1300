"""How often the parameter-constancy test says "not the same" on rotors that did not change.

Healthy one-plane rig records (keyphasor, X/Y probes at +-45 deg, um) from the package's rig
simulator, natural frequency and damping varied, run-up and coast-down alternating; each fitted
with its true model (unbalance + damping) by output error, then tested by
``rotor_env.diagnosis.change.parameter_constancy`` as the diagnosis does (``method="auto"``: the
information's own path where the record has eight blocks per parameter, else the textbook form;
the table says which) and with the textbook Brownian-bridge form (``method="bridge"``) on the
same fit.  A valid 5 % test says "not the same" on about 5 % of them, and its p-values spread
evenly over (0, 1).

    python benchmarks/change_size.py                     # 20 records, 20 kHz, 0.5 um
    python benchmarks/change_size.py --rate 2500 --noise 0.1 --records 10
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--records", type=int, default=20)
    ap.add_argument("--rate", type=float, default=20000.0, help="sample rate, Hz")
    ap.add_argument("--noise", type=float, default=0.5, help="probe noise, um")
    ap.add_argument("--rig", default="one-plane um")
    ap.add_argument("--seed", type=int, default=7770)
    args = ap.parse_args(argv)

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import rig_suite as rs

    from rotor_env.diagnosis.change import parameter_constancy
    from rotor_env.diagnosis.from_rig import waveform_grid
    from rotor_env.diagnosis.output_error import equation_error_start, fit_output_error
    from rotor_env.measurements.rig import load_rig
    from rotor_env.measurements.waveforms import load_waveforms

    rows, methods = [], []
    print("| record | direction | natural rpm | zeta | auto: method | LM | p | s | bridge: LM | p | s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in range(args.records):
        spec = rs.RecordSpec(index=r, seed=args.seed * 100 + r, fault="healthy", noise_um=args.noise, rig=args.rig,
                             natural_rpm=1300.0 + 100.0 * (r % 15), zeta=0.01 + 0.002 * (r % 10),
                             sample_rate=args.rate, direction=("run-up", "coast-down")[r % 2])
        with tempfile.TemporaryDirectory() as tmp:
            rig_path, data_path, _ = rs.make_record(spec, Path(tmp))
            record = load_waveforms(data_path, load_rig(rig_path))
        grid, _ = waveform_grid(record, 2 * math.pi * spec.natural_rpm / 60)
        model = ("unbalance", "viscous_damping")
        fit = fit_output_error(grid, model, equation_error_start(grid, model))
        out, used = [], ""
        for method in ("auto", "bridge"):
            t0 = time.perf_counter()
            c = parameter_constancy(fit, method=method)
            out.append((c.statistic, c.p_value, time.perf_counter() - t0))
            used = used or c.method
        rows.append(out)
        methods.append(used)
        print(f"| {r} | {spec.direction} | {spec.natural_rpm:.0f} | {spec.zeta:.3f} | {used} | {out[0][0]:.1f} | "
              f"{out[0][1]:.3f} | {out[0][2]:.2f} | {out[1][0]:.1f} | {out[1][1]:.3f} | {out[1][2]:.2f} |", flush=True)
    p = np.array([[o[1] for o in row] for row in rows])
    print()
    print(f"{args.records} constant rotors, {args.rate:g} Hz, {args.noise:g} um")
    print("| method | 'not the same' at 5 % | at 10 % | p-values min-max | mean p (0.5 if valid) |")
    print("|---|---|---|---|---|")
    n_blocks = sum(m == "blocks" for m in methods)
    for j, name in enumerate((f"auto ({n_blocks} by blocks, the rest textbook)", "bridge (textbook) on all")):
        print(f"| {name} | {np.sum(p[:, j] < 0.05)}/{len(p)} | {np.sum(p[:, j] < 0.10)}/{len(p)} | "
              f"{p[:, j].min():.3f}-{p[:, j].max():.3f} | {p[:, j].mean():.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
