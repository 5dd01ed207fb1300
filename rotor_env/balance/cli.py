"""``rotor-id balance``: influence-coefficient balancing from a 1X table with a run column."""

from __future__ import annotations

import argparse
import sys

from ..batch import argparse_type, table_amplitude_unit

__all__ = ["add_balance_parser"]


def add_balance_parser(sub) -> None:
    """Register ``balance`` on the ``rotor-id`` sub-command parser."""
    p = sub.add_parser(
        "balance",
        help="influence-coefficient balancing: unbalance in g·mm and correction weights from 1X vectors",
        description="Fit influence coefficients by weighted least squares to the runs of TABLE (the 1X table of "
        "`diagnose --vectors` plus a `run` column; rows of one run and speed are repeats) with the trial weights "
        "of RUNS.yaml; report every run's total unbalance, the reference's correction, the predicted residual "
        "vibration, and where the linear model fails (docs/BALANCING.md).",
    )
    p.add_argument("table", metavar="TABLE", help="1X vector table with a run column (.csv or .parquet)")
    p.add_argument("--runs", required=True, metavar="RUNS.yaml", help="planes, reference run, trial weights")
    p.add_argument("--amp-unit", default="um", type=argparse_type(table_amplitude_unit),
                   help="amplitude unit (um, mil, mm, m; 'mil pp' for peak to peak, 'um rms'; default um, zero to peak)")
    p.add_argument("--phase", default="lag", choices=["lag", "lead"],
                   help="phase convention of the table; weight angles are counted the same way (default lag)")
    p.add_argument("--rig", metavar="RIG.yaml", help="probe angles for the model-based unbalance (optional)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--report", metavar="OUT.html", help="write an HTML report")
    p.add_argument("--force", action="store_true", help="overwrite the report if it exists")
    p.set_defaults(func=_cmd_balance)


def _cmd_balance(args: argparse.Namespace) -> int:
    from ..measurements.rig import RigError, load_rig
    from ..outputs import check_writable
    from . import BalanceError, balance

    try:
        if args.report:
            check_writable(args.report, overwrite=args.force)  # before the computation
        angles = planes = None
        if args.rig:
            import math

            rig_probes = load_rig(args.rig).probes
            angles = {p.name: math.degrees(p.angle) for p in rig_probes}
            planes = {p.name: p.plane for p in rig_probes}
        res = balance(args.table, args.runs, amp_unit=args.amp_unit, phase=args.phase, probe_angles=angles,
                      probe_planes=planes)
        if args.report:
            res.report(args.report, overwrite=args.force)
    except (BalanceError, RigError, FileExistsError, ValueError) as exc:
        print(f"rotor-id balance: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(res.to_json(indent=1))
    else:
        print(res.summary())
        if args.report:
            print(f"report: {args.report}")
    return 0
