"""The ``rotor-id`` command line."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence


def _cmd_demo(args: argparse.Namespace) -> int:
    from identifier import demo

    demo.run()
    return 0


# ---------------------------------------------------------------------- simulate
class _UsageError(Exception):
    """A bad command-line input: reported as one line, exit code 2."""


def _parse_number(text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise _UsageError(f"{what}: {text!r} is not a number") from None


def _parse_set(items: Sequence[str]) -> dict[str, float]:
    """``["c=0.05", "h=0"]`` -> ``{"c": 0.05, "h": 0.0}`` (later ones win)."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if not sep or not name or not value:
            raise _UsageError(f"--set {item!r}: expected NAME=VALUE, e.g. --set D=0.05")
        if name == "crack":
            raise _UsageError("--set crack=...: a crack is set with --crack TIME:D")
        out[name] = _parse_number(value, f"--set {name}")
    return out


def _parse_crack(text: str):
    from .params import Crack

    time, sep, d = text.partition(":")
    if not sep or not time.strip() or not d.strip():
        raise _UsageError(f"--crack {text!r}: expected TIME:D, e.g. --crack 250:0.08")
    return Crack(_parse_number(time, "--crack TIME"), _parse_number(d, "--crack D"))


def _load_params_file(path: str) -> dict:
    """The JSON object of ``--params`` (parameter names -> numbers, optional crack)."""
    import json

    from .params import Crack

    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise _UsageError(f"--params {path}: no such file") from None
    except IsADirectoryError:
        raise _UsageError(f"--params {path}: is a directory, not a JSON file") from None
    except json.JSONDecodeError as exc:
        raise _UsageError(f"--params {path}: invalid JSON: {exc}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise _UsageError(f"--params {path}: cannot read: {exc}") from None
    if not isinstance(data, dict):
        raise _UsageError(
            f"--params {path}: expected a JSON object of parameter names to numbers, "
            f"got a JSON {type(data).__name__}"
        )
    crack = data.pop("crack", None)
    if crack is not None:
        if not (isinstance(crack, dict) and set(crack) == {"time", "D"}):
            raise _UsageError(
                f'--params {path}: "crack" must be an object {{"time": T, "D": D}}, got {crack!r}'
            )
        data["crack"] = Crack(crack["time"], crack["D"])
    for name, value in data.items():
        if name != "crack" and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise _UsageError(f"--params {path}: parameter {name!r} must be a number, got {value!r}")
    return data


def _cmd_simulate(args: argparse.Namespace) -> int:
    import math
    from pathlib import Path

    from .params import RotorParams
    from .simulator import RunUp, SimulationError, simulate

    def fail(message: str, code: int = 2) -> int:
        print(f"rotor-id simulate: error: {message}", file=sys.stderr)
        return code

    out = Path(args.out)
    try:
        if out.exists() and not args.force:
            raise _UsageError(f"{out} already exists; use --force to overwrite it")
        if out.is_dir():
            raise _UsageError(f"{out} is a directory, not an output file")
        if not out.parent.is_dir():
            raise _UsageError(f"cannot write {out}: directory {out.parent} does not exist")
        values = _load_params_file(args.params) if args.params else {}
        crack = values.pop("crack", None)
        values.update(_parse_set(args.set or []))
        if args.crack is not None:
            crack = _parse_crack(args.crack)
        ip = values.pop("ip", 0.3)
        params = RotorParams(ip=ip, values=values, crack=crack)
        run_up = RunUp(rate=args.run_up)
        if args.noise is not None and not (math.isfinite(args.noise) and args.noise >= 0):
            raise _UsageError(f"--noise must be a finite number >= 0, got {args.noise!r}")
        meas = simulate(
            params,
            t_end=args.t_end,
            dt=args.dt,
            run_up=run_up,
            noise=args.noise,
            seed=args.seed,
            progress=sys.stderr.isatty(),
        )
        path = meas.to_file(out, overwrite=args.force)
    except (_UsageError, ValueError, FileExistsError) as exc:
        return fail(str(exc))
    except SimulationError as exc:
        return fail(str(exc), code=1)
    except ImportError as exc:
        return fail(f"cannot write {out}: {exc} (Parquet needs pyarrow)")
    except OSError as exc:
        return fail(f"cannot write {out}: {exc}")
    except KeyboardInterrupt:
        return fail("interrupted", code=130)
    amp = (meas.theta_x**2 + meas.theta_y**2) ** 0.5
    i = int(amp.argmax())
    noise = f", noise std {args.noise:g} (seed {args.seed})" if args.noise else ""
    print(
        f"wrote {len(meas)} rows to {path} (t 0 to {meas.t[-1]:.6g}, dt {args.dt:g}{noise}); "
        f"peak |theta| = {amp[i]:.4g} at t = {meas.t[i]:.2f}"
    )
    return 0


def _add_simulate_parser(sub) -> None:
    from .params import RotorParams

    p = sub.add_parser(
        "simulate",
        help="simulate a run-up and write the measurements (CSV or Parquet)",
        description="Simulate the accelerating rotor (PHYSICS.md) from rest and write the ten "
        "measurement columns to OUT: CSV, or Parquet when OUT ends in .parquet. "
        f"Parameters (default: the paper's Table 1): {', '.join(RotorParams.known_names())}.",
    )
    p.add_argument("out", metavar="OUT", help="output file (.csv, or .parquet)")
    p.add_argument(
        "--set", action="append", metavar="NAME=VALUE", default=[],
        help="set one parameter (repeatable; applied after --params), e.g. --set D=0 --set ip=0.25",
    )
    p.add_argument(
        "--params", metavar="FILE.json",
        help='a JSON object of parameters, e.g. {"h": 0, "crack": {"time": 250, "D": 0.08}}',
    )
    p.add_argument("--run-up", type=float, default=0.01, metavar="RATE",
                   help="spin acceleration phi'' from rest (default 0.01)")
    p.add_argument("--dt", type=float, default=0.01, help="sample interval (default 0.01)")
    p.add_argument("--t-end", type=float, default=400.0, metavar="T",
                   help="simulate t in [0, T] (default 400)")
    p.add_argument("--noise", type=float, metavar="STD",
                   help="Gaussian noise of this std on the six inclination channels")
    p.add_argument("--seed", type=int, help="seed of the noise (reproducible)")
    p.add_argument("--crack", metavar="T:D", help="a crack at time T: the asymmetry D jumps to D")
    p.add_argument("--force", action="store_true", help="overwrite OUT if it exists")
    p.set_defaults(func=_cmd_simulate)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rotor-id",
        description="Online identification of the physical effects of an accelerating rotor.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="the main walkthrough")
    p.set_defaults(func=_cmd_demo)
    _add_simulate_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileExistsError, FileNotFoundError) as exc:
        print(f"rotor-id {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
