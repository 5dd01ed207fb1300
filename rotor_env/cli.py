"""The ``rotor-id`` command line."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence

from .batch import argparse_type, diagnose_file, inertia_ratio, model_list, table_amplitude_unit


def _cmd_identifier_demo(args: argparse.Namespace) -> int:
    from identifier import demo

    demo.run()
    return 0


def _cmd_warm_up(args: argparse.Namespace) -> int:
    import time

    from .warmup import warm_up

    t0 = time.perf_counter()
    seconds = warm_up(progress=sys.stderr.isatty())
    stages = ", ".join(f"{name} {s:.1f} s" for name, s in seconds.items())
    print(f"rotor-id warm-up: the diagnosis's kernels are compiled and cached ({stages}; "
          f"{time.perf_counter() - t0:.1f} s in all)")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from .walkthrough import run_walkthrough

    run_walkthrough(args.out, force=args.force, seed=args.seed)
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
        if out.is_dir():
            raise _UsageError(f"{out} is a directory, not an output file")
        if out.suffix.lower() not in (".csv", ".parquet"):
            raise _UsageError(f"{out}: a measurement file is .csv or .parquet, not {out.suffix or 'without a suffix'}")
        if out.exists() and not args.force:
            raise _UsageError(f"{out} already exists; use --force to overwrite it")
        from .outputs import check_writable

        check_writable(out, overwrite=args.force)  # a read-only folder: said before simulating
        if not out.parent.is_dir():
            raise _UsageError(f"cannot write {out}: directory {out.parent} does not exist")
        values = _load_params_file(args.params) if args.params else {}
        crack = values.pop("crack", None)
        values.update(_parse_set(args.set or []))
        if args.crack is not None:
            crack = _parse_crack(args.crack)
        ip = values.pop("ip", 0.3)
        if args.rig or args.vectors:
            if not args.rig:
                raise _UsageError("--vectors needs --rig RIG.yaml (the probes to track)")
            return _simulate_rig(args, values, ip, crack, out)
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
    except MemoryError:
        return fail(f"not enough memory for {args.t_end:g} / {args.dt:g} samples; shorten --t-end or raise --dt")
    except OSError as exc:
        return fail(f"cannot write {out}: {exc.strerror or exc}")
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
        description="Simulate the accelerating rotor (docs/PHYSICS.md) from rest and write the ten "
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
    g = p.add_argument_group("rig recordings (engineering units)")
    g.add_argument("--rig", metavar="RIG.yaml", help="write what this rig records: time in s, keyphasor, probes "
                   "(--noise is then in the rig's displacement unit)")
    g.add_argument("--vectors", action="store_true", help="with --rig: write the order-tracked 1X/2X table instead")
    g.add_argument("--natural-rpm", type=float, default=1650.0, help="natural frequency in rpm (default 1650)")
    g.add_argument("--rpm", default="300:3000", metavar="FROM:TO", help="speed range (default 300:3000; "
                   "3000:300 is a coast-down)")
    g.add_argument("--rpm-per-s", type=float, default=230.0, help="sweep rate (default 230 rpm/s)")
    g.add_argument("--sample-rate", type=float, default=5000.0, help="samples per second (default 5000)")
    g.add_argument("--runout", metavar="AMP[:PHASE]", help="probe-track runout: 1X amplitude (rig unit) and phase "
                   "(degrees)")
    g.add_argument("--flicker-hz", type=float, default=0.0, metavar="HZ",
                   help="the probes' 1/f noise corner: their noise density the white --noise's times 1 + HZ / f "
                        "(default 0: white)")
    p.set_defaults(func=_cmd_simulate)


# ---------------------------------------------------------------------- paper
def _cmd_paper(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from .paper import run_paper, table2

    out = Path(args.out) if args.out else None
    if out is not None:
        from .outputs import OutputFolder

        OutputFolder.check(out, force=args.force)  # said before the computation
    cases = run_paper(None, seed=args.seed, progress=sys.stderr.isatty() and not args.json)
    if out is not None:
        from .paper import plot_figures, write_tables

        folder = OutputFolder(out, force=args.force)
        with folder.staging() as tmp:
            plot_figures(cases, tmp)
            write_tables(cases, tmp)
            (tmp / "table2_t300.json").write_text(json.dumps(table2(cases), indent=2))
    if args.json:
        print(json.dumps(table2(cases, 300.0)))
    else:
        for name, case in cases.items():
            r = case.reading(300.0)
            cells = ", ".join(
                f"{k}={v['estimate']:.4f}" + (f" (F {v['F']:.4g}, {'sig' if v['significant'] else 'n.s.'})" if "F" in v else "")
                for k, v in r.items()
            )
            print(f"case {name} ({case.label}) at t = 300: {cells}")
        if out is not None:
            print(f"figures and Table 2 written to {out}/ (fig3_response.png, fig4_parameters.png, "
                  "fig5_significance.png, table2.md, table2.csv)")
    return 0


def _add_paper_parser(sub) -> None:
    p = sub.add_parser("paper", help="re-run Zhou & Shi (2004)'s numerical study with the online estimator")
    p.add_argument("--out", metavar="DIR", help="write Fig. 3-5 (PNG) and Table 2 (Markdown, CSV) here")
    p.add_argument("--json", action="store_true", help="print Table 2 at t = 300 as JSON")
    p.add_argument("--seed", type=int, default=0, help="seed of the noise on y (default 0)")
    p.add_argument("--force", action="store_true", help="replace the files of a previous run in --out (never "
                   "files rotor-id did not write)")
    p.set_defaults(func=_cmd_paper)


# ---------------------------------------------------------------------- diagnose / fit
def _load(args):
    from .diagnosis import load_user_effect
    from .measurements.files import load_measurements

    user = [load_user_effect(spec).name for spec in (args.effect or [])]
    return load_measurements(args.file), user


def _cmd_diagnose(args: argparse.Namespace) -> int:
    from pathlib import Path

    from .diagnosis import DEFAULT_MODEL, LIBRARY_CANDIDATES, diagnose
    from .outputs import check_writable

    # check every output target before the computation (a read-only folder, a folder
    # where a file should go: said now, not after the diagnosis has run)
    if args.report:
        if Path(args.report).suffix.lower() not in (".html", ".htm"):
            raise _UsageError(f"--report {args.report}: the report is HTML; name it .html")
        check_writable(args.report, overwrite=args.force)
    if args.figures:
        from .outputs import OutputFolder

        # a folder rotor-id did not write is refused now, before the computation; with
        # --force only the figures of a previous run (the marker's list) are replaced
        OutputFolder.check(args.figures, force=args.force)
    if args.vectors or args.rig:
        result = _diagnose_measured(args)
    else:
        from .progress import step

        step(f"reading {args.file}")
        meas, user = _load(args)
        model = model_list(args.model, DEFAULT_MODEL)
        candidates = [c for c in (*LIBRARY_CANDIDATES, *user) if c not in model]
        result = diagnose(meas, model, candidates=candidates, ip=args.ip, alpha=args.alpha, slow_roll=args.slow_roll,
                          progress=sys.stderr.isatty() and not args.json)
    if args.figures:
        from .outputs import OutputFolder

        folder = OutputFolder(args.figures, force=args.force)
        with folder.staging() as tmp:
            result.save_figures(tmp)
    if args.report:
        result.report(args.report, overwrite=args.force)
    if args.json:
        print(result.to_json())
    else:
        print(result.summary())
        if args.figures:
            print(f"\nfigures written to {args.figures}/")
        if args.report:
            print(f"report written to {args.report}")
    return 0


def _diagnose_measured(args: argparse.Namespace):
    """``diagnose --vectors`` (an order-tracked table) or ``diagnose --rig`` (raw waveforms)."""
    if args.effect:
        raise _UsageError("--effect (a user effect) works on dimensionless files, not yet with --vectors/--rig")
    return diagnose_file(args.file, model=args.model, ip=args.ip, alpha=args.alpha, vectors=args.vectors,
                         rig=args.rig, amp_unit=args.amp_unit, phase=args.phase,
                         progress=sys.stderr.isatty() and not args.json)


def _simulate_rig(args: argparse.Namespace, values: dict, ip: float, crack, out) -> int:
    """``simulate --rig``: waveforms (keyphasor, probes) or, with ``--vectors``, the 1X/2X table."""
    import numpy as np

    from .effects import EFFECTS
    from .measurements.rig import load_rig
    from .outputs import atomic_write
    from .params import RotorParams
    from .rig_simulation import simulate_rig

    rig = load_rig(args.rig)
    # a rig run is a healthy rotor (stiffness, damping, unbalance) plus the effects whose
    # parameters --set / --params / --crack name: not the paper's crack-and-friction rotor
    effects = ["stiffness", "viscous_damping", "unbalance"]
    effects += [n for n, e in EFFECTS.items() if n not in effects and n != "unbalance_in_phase"
                and any(pn in values for pn in e.parameter_names)]
    if crack is not None and "asymmetry" not in effects:
        effects.append("asymmetry")
    unknown = [k for k in values if not any(k in EFFECTS[e].parameter_names for e in effects)]
    if unknown:
        raise _UsageError(f"unknown parameter(s) {unknown}")
    params = RotorParams(ip=0.0 if rig.model == "translation" else ip, values=values, effects=tuple(effects),
                         crack=crack)
    rpm_from, rpm_to = _parse_range(args.rpm)
    if not (math.isfinite(args.flicker_hz) and args.flicker_hz >= 0):
        raise _UsageError(f"--flicker-hz must be a finite number >= 0 (Hz), got {args.flicker_hz!r}")
    runout, runout_phase = (0.0, 0.0)
    if args.runout:
        parts = args.runout.split(":")
        runout = _parse_number(parts[0], "--runout amplitude")
        runout_phase = _parse_number(parts[1], "--runout phase") if len(parts) > 1 else 0.0
    run = simulate_rig(rig, params, natural_rpm=args.natural_rpm, rpm_from=rpm_from, rpm_to=rpm_to,
                       rpm_per_s=math.copysign(abs(args.rpm_per_s), rpm_to - rpm_from),
                       sample_rate=args.sample_rate, noise=args.noise or 0.0, runout=runout,
                       runout_phase_deg=runout_phase, flicker_hz=args.flicker_hz, seed=args.seed)
    if args.vectors:
        table = run.vectors(rig)
        table.to_csv(out, phase="lag", overwrite=args.force)
        print(f"wrote {len(table.speed)} revolutions of 1X/2X vectors (amplitude in {rig.amp_unit}, phase lag in "
              f"degrees) to {out}")
        return 0
    cols = run.file_columns()
    names = list(cols)
    data = np.column_stack([cols[n] for n in names])

    def write(tmp) -> None:
        if str(out).lower().endswith(".parquet"):
            import pyarrow as pa
            import pyarrow.parquet as pq

            pq.write_table(pa.table({n: data[:, j] for j, n in enumerate(names)}), tmp)
        else:
            np.savetxt(tmp, data, delimiter=",", header=",".join(names), comments="", fmt="%.10g")

    atomic_write(out, write, overwrite=args.force)
    print(f"wrote {len(data)} samples ({data[-1, 0]:.3f} s at {args.sample_rate:g} Hz, {rpm_from:g} to {rpm_to:g} "
          f"rpm, natural frequency {args.natural_rpm:g} rpm) to {out}")
    return 0


def _parse_range(text: str) -> tuple[float, float]:
    parts = text.split(":")
    if len(parts) != 2:
        raise _UsageError(f"--rpm {text!r}: expected FROM:TO (e.g. 300:3000; 3000:300 for a coast-down)")
    return _parse_number(parts[0], "--rpm FROM"), _parse_number(parts[1], "--rpm TO")


def _cmd_fit(args: argparse.Namespace) -> int:
    try:
        return _fit(args)
    except KeyboardInterrupt:
        print("rotor-id fit: interrupted", file=sys.stderr)
        return 130
    except MemoryError:
        print(f"rotor-id fit: error: not enough memory to fit {args.file}; decimate the record", file=sys.stderr)
        return 1


def _fit(args: argparse.Namespace) -> int:
    import json

    from .diagnosis import fit
    from .regression import RegressionSpec
    from .results import jsonable

    meas, _ = _load(args)
    model = model_list(args.model, ())
    RegressionSpec(effects=tuple(model))  # refuses a model that cannot be fitted (two effects, one tau)
    comp = fit(meas, model, ip=args.ip)
    _check_finite_fit(comp, args.file)
    out = {
        "model": list(comp.model),
        "coefficients": comp.coefficient_dict(),
        "standard_errors": dict(zip(comp.columns, map(float, comp.standard_errors), strict=True)),
        "physical": comp.physical,
        "rms": comp.rms,
        "r2": comp.r2,
        "fit_percent": comp.fit_percent,
        "fit_bands": comp.fit_bands,
        "significance": {k: {kk: v[kk] for kk in ("F", "log10_p", "significant", "testable")}
                         for k, v in comp.significance.items()},
        "standard_errors_kind": "HAC (Newey-West, Bartlett kernel, Andrews bandwidth)",
        "errors_in_variables_bias": (None if comp.eiv_bias is None else
                                     dict(zip(comp.columns, map(float, comp.eiv_bias), strict=True))),
    }
    if args.json:
        print(json.dumps(jsonable(out)))
        return 0
    print(f"model: {', '.join(comp.model)}")
    print(f"equation error RMS {comp.rms:.4g}, R^2 {comp.r2:.5f}; free-run fit {comp.fit_percent:.1f} %")
    for c, v, se in zip(comp.columns, comp.coefficients, comp.standard_errors, strict=True):
        print(f"  {c:<14}{v: .6g} ± {1.96 * se:.2g}")
    print("  (± : 95 % intervals from HAC standard errors; values corrected for the sensor noise in the "
          "regressors)" if comp.eiv_bias is not None else "  (± : 95 % intervals from HAC standard errors)")
    print("effects tested last:")
    for k, v in comp.significance.items():
        verdict = "significant" if v["significant"] else ("not testable" if not v["testable"] else "not significant")
        print(f"  {k:<22} F = {v['F']:.4g}, log10 p = {v['log10_p']:.4g}: {verdict}")
    return 0


def _check_finite_fit(comp, file) -> None:
    """A fit whose numbers are not finite is an error, never a result (``RMS inf, R^2 nan``)."""
    values = {"rms": comp.rms, "r2": comp.r2, "fit_percent": comp.fit_percent,
              **{f"coefficient {c}": v for c, v in zip(comp.columns, comp.coefficients, strict=True)},
              **{f"standard error {c}": v for c, v in zip(comp.columns, comp.standard_errors, strict=True)}}
    bad = [k for k, v in values.items() if not math.isfinite(float(v))]
    if bad:
        raise ValueError(f"{file}: the fit is not finite ({', '.join(bad[:4])}): the data overflow the model's "
                         "numbers; check the file for huge values")


def _add_diagnose_parsers(sub) -> None:
    from .effects import EFFECTS

    names = ", ".join(sorted(EFFECTS))
    for cmd, helptext in (("diagnose", "compare a model with measurements and find the missing effect"),
                          ("fit", "fit one model and report coefficients, errors and significance")):
        p = sub.add_parser(cmd, help=helptext, description=f"{helptext}. Effects: {names}.")
        p.add_argument("file", metavar="FILE", help="measurement file (CSV or Parquet)")
        p.add_argument("--model", metavar="A,B,...",
                       help="comma-separated effects" + (" (default: unbalance,viscous_damping)" if cmd == "diagnose" else ""),
                       required=cmd == "fit")
        if cmd == "diagnose":
            p.add_argument("--ip", type=argparse_type(inertia_ratio), default=None,
                           help="inertia ratio I_p/I_t (default: estimated from the data; a given one the "
                           "data contradict is kept, with a warning)")
        else:
            p.add_argument("--ip", type=argparse_type(inertia_ratio), default=0.3, help="inertia ratio I_p/I_t (default 0.3)")
        p.add_argument("--effect", action="append", metavar="MODULE:NAME",
                       help="a user effect: a column function or an Effect (repeatable)")
        p.add_argument("--json", action="store_true", help="print the result as one JSON object")
        if cmd == "diagnose":
            p.add_argument("--alpha", type=float, default=0.05, help="significance level (default 0.05)")
            p.add_argument("--slow-roll", type=float, default=None, metavar="SPEED",
                           help="subtract the probe runout read below this speed (slow-roll compensation)")
            p.add_argument("--report", metavar="OUT.html", help="write a self-contained HTML report")
            p.add_argument("--figures", metavar="DIR", help="write the figures (PNG) to this folder")
            p.add_argument("--force", action="store_true", help="overwrite --report / --figures")
            g = p.add_argument_group("measured rig data")
            g.add_argument("--rig", metavar="RIG.yaml", help="FILE holds raw waveforms (time in s, keyphasor, probes) "
                           "described by this rig file (docs/MEASUREMENTS.md)")
            g.add_argument("--vectors", action="store_true", help="FILE is an order-tracked table: rpm, amp, "
                           "phase_deg (or NAME_amp, NAME_phase_deg per probe), optional t")
            g.add_argument("--amp-unit", default="um", type=argparse_type(table_amplitude_unit),
                           help="amplitude unit of the table: um, mil, mm or m, and how it is measured when not "
                                "zero to peak: 'mil pp' (peak to peak, the usual proximity-probe display), "
                                "'um rms' (default um, zero to peak)")
            g.add_argument("--phase", default="lag", choices=("lag", "lead"),
                           help="phase convention: lag = instrument x = A cos(phi - phase) (default), "
                                "lead = angle of X with x = Re(X e^{i phi})")
            p.set_defaults(func=_cmd_diagnose)
        else:
            p.set_defaults(func=_cmd_fit)


def _version() -> str:
    """The installed distribution's version (``rotor-id --version``)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("rotor-id")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rotor-id",
        description="Online identification of the physical effects of an accelerating rotor.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("demo", help="the main walkthrough: diagnose a rotor with a hidden crack")
    p.add_argument("--out", default="out/walkthrough", metavar="DIR",
                   help="folder for the data, figures and report (default out/walkthrough)")
    p.add_argument("--seed", type=int, default=1, help="seed of the measurement noise (default 1)")
    p.add_argument("--force", action="store_true", help="replace the walkthrough's previous output")
    p.set_defaults(func=_cmd_demo)
    p = sub.add_parser("identifier-demo", help="the recursive-QR identifier on a known linear system")
    p.set_defaults(func=_cmd_identifier_demo)
    p = sub.add_parser("warm-up", help="compile the rig diagnosis's kernels once per machine (40-50 s the first "
                       "time, seconds after): the first record then runs at its warm speed",
                       description="Simulate a short rig run-up and diagnose it and its 1X table, so that numba "
                       "compiles and caches every kernel (rotor_env/warmup.py). scripts/run-demo.sh runs it.")
    p.set_defaults(func=_cmd_warm_up)
    _add_simulate_parser(sub)
    _add_paper_parser(sub)
    _add_diagnose_parsers(sub)
    from .monitor.cli import add_monitor_parser

    add_monitor_parser(sub)
    from .fleet import add_batch_parser

    add_batch_parser(sub)
    from .balance.cli import add_balance_parser

    add_balance_parser(sub)
    _add_plugin_parsers(sub)
    return parser


def _add_plugin_parsers(sub) -> None:
    """Commands of packages built on rotor_env (``agents``: train, evaluate).

    They register under the entry-point group ``rotor_id.commands`` so that this
    package never imports them (dependencies point one way: agents -> rotor_env).
    """
    from importlib.metadata import entry_points

    for ep in entry_points(group="rotor_id.commands"):
        try:
            ep.load()(sub)
        except ImportError as exc:  # e.g. the agents extra (Stable-Baselines3) not installed
            p = sub.add_parser(ep.name, help=f"(unavailable: {exc})")
            p.set_defaults(func=lambda args, exc=exc: _unavailable(args, exc))


def _unavailable(args, exc) -> int:
    print(f"rotor-id {args.command}: needs the 'agents' extra (pip install 'rotor-id[agents]'): {exc}",
          file=sys.stderr)
    return 2


#: commands without progress lines: the monitor streams its own status lines
QUIET_COMMANDS = frozenset({"monitor"})


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.command in QUIET_COMMANDS:
            return int(args.func(args) or 0)
        from .progress import Progress

        # a bar in a terminal, a line on stderr every ~10 s otherwise (rotor_env/progress.py)
        with Progress(f"rotor-id {args.command}"):
            return int(args.func(args) or 0)
    except (_UsageError, ValueError, OSError) as exc:
        print(f"rotor-id {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"rotor-id {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
