"""``rotor-id monitor``: watch a measurement stream, raise alarms when an effect appears or changes."""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["add_monitor_parser"]


def add_monitor_parser(sub) -> None:
    """Register ``monitor`` on the ``rotor-id`` sub-command parser."""
    p = sub.add_parser(
        "monitor",
        help="watch a measurement stream on line; alarm when an effect appears, changes or disappears",
        description="Read a measurement stream (CSV or Parquet, the columns diagnose reads) in chunks, identify "
        "the model recursively (forgetting or a sliding window) and run a CUSUM per effect whose threshold "
        "follows from the target in-control ARL (samples between false alarms). JSON lines: status lines, "
        "appeared/changed/disappeared events (the effect isolated on the block after the crossing: each effect's "
        "change alone fitted to it; an 'unattributed' event lists the effects it cannot tell apart), a summary at "
        "the end. With --rig RIG.yaml and --natural-rpm N the "
        "stream holds a rig's SI waveforms (time in s, keyphasor or speed, probes), made dimensionless on the fly; "
        "events then carry s and rpm too.",
    )
    p.add_argument("files", nargs="+", metavar="FILE|-",
                   help="measurement file, or - for standard input; several files: each watched in its own Ray task "
                        "(events tagged with their stream, merged as they arrive)")
    p.add_argument("--rig", metavar="RIG.yaml", help="FILE holds a rig's SI waveforms described by this rig file "
                   "(docs/MEASUREMENTS.md); needs --natural-rpm")
    p.add_argument("--natural-rpm", type=float, metavar="N", help="with --rig: the rotor's natural frequency in rpm, "
                   "the model's time scale (natural_frequency_rpm of `rotor-id diagnose RUN --rig RIG --json`)")
    p.add_argument("--model", metavar="A,B,...", help="effects identified and watched "
                   "(default: unbalance,asymmetry,viscous_damping,nonlinear_stiffness,structural_damping)")
    p.add_argument("--ip", type=float, help="inertia ratio I_p/I_t (default 0.3; with --rig the rig's)")
    mem = p.add_mutually_exclusive_group()
    mem.add_argument("--forgetting", type=float, metavar="LAMBDA",
                     help="forgetting factor per sample (default 0.9995: a memory of 2000 samples)")
    mem.add_argument("--window", type=float, metavar="T", help="a sliding window of T time units (with --rig: "
                     "seconds) instead")
    p.add_argument("--arl0", type=float, default=None, metavar="N",
                   help="target in-control average run length, samples between false alarms (default 1e7)")
    p.add_argument("--block", type=int, default=None, metavar="N", help="samples per block of evidence (default 200)")
    p.add_argument("--status-every", type=float, metavar="T",
                   help="a status line every T time units (default 10; with --rig: seconds, default 1; 0: none)")
    p.add_argument("--follow", action="store_true", help="wait for rows appended to FILE (like tail -f)")
    p.add_argument("--idle-exit", type=float, metavar="SECONDS",
                   help="with --follow: end after this long without new rows (default: never)")
    p.add_argument("--json-lines", action="store_true", help="print JSON lines instead of the live view")
    p.add_argument("--report", metavar="OUT.html", help="write an HTML report of the run at the end")
    p.add_argument("--state", metavar="OUT.npz", help="save the monitor's state at the end (resume with --resume)")
    p.add_argument("--resume", metavar="STATE.npz", help="continue from a saved state")
    p.add_argument("--force", action="store_true", help="overwrite --report / --state")
    p.add_argument("--workers", type=int, metavar="N",
                   help="several files: Ray CPUs on this machine (default: one per stream, so live streams keep up)")
    p.add_argument("--address", metavar="ADDR", help="several files: a Ray cluster's address (default: local Ray)")
    p.set_defaults(func=run_monitor)


def _config(args, dt: float, *, ip: float = 0.3, time_scale: float = 1.0):
    """The monitor's options; ``time_scale``: the options' time unit in the stream's (``w_ref``
    for a rig stream, whose options are in seconds)."""
    from ..effects import get_effect
    from .core import MonitorConfig

    every = args.status_every if args.status_every is not None else (1.0 if args.rig else 10.0)
    block = args.block if args.block is not None else 200
    opts: dict = {"ip": args.ip if args.ip is not None else ip, "arl0": args.arl0 if args.arl0 is not None else 1e7,
                  "block": block, "status_every": every * time_scale or None}
    if args.model:
        names = [m.strip() for m in args.model.split(",") if m.strip()]
        for n in names:
            get_effect(n)
        opts["effects"] = tuple(names)
    if args.forgetting is not None:
        opts["forgetting"] = args.forgetting
    if args.window is not None:
        opts["window"] = max(block, int(round(args.window * time_scale / dt)))
    return MonitorConfig(**opts)


def run_monitor(args: argparse.Namespace) -> int:
    from ..measurements.files import MeasurementError
    from ..measurements.stream import read_ahead
    from ..outputs import check_writable
    from .core import ALARM_EVENTS, Monitor, interrupts_held
    from .fleet import open_stream

    rig = None
    if args.rig:
        from ..measurements.rig import load_rig
        from ..measurements.rig_stream import natural_rpm_required

        if args.natural_rpm is None:
            raise ValueError(natural_rpm_required())
        if args.resume:
            raise ValueError("--resume with --rig: a rig stream's time starts at its first whole revolution, so a "
                             "saved monitor cannot continue on another rig file; monitor the whole stream")
        rig = load_rig(args.rig)
    elif args.natural_rpm is not None:
        raise ValueError("--natural-rpm goes with --rig RIG.yaml (SI rig data); a dimensionless stream has no time scale")
    if len(args.files) > 1:
        return _run_many(args, rig)
    if args.workers is not None or args.address:
        raise ValueError("--workers/--address are for several streams (one Ray task each); one stream runs here")
    args.file = args.files[0]
    if args.report:
        check_writable(args.report, overwrite=args.force)
    if args.state:
        if not str(args.state).endswith(".npz"):
            raise ValueError(f"--state {args.state}: state files end in .npz")
        check_writable(args.state, overwrite=args.force)
    if args.resume:
        # the saved state carries its model and detector: options that would change them are refused,
        # never silently ignored
        given = [o for o, v in (("--model", args.model), ("--ip", args.ip), ("--forgetting", args.forgetting),
                                ("--window", args.window), ("--arl0", args.arl0), ("--block", args.block)) if v is not None]
        if given:
            raise ValueError(f"--resume continues the saved monitor with its own settings; {', '.join(given)} cannot "
                             "change them (start a new monitor without --resume to use them)")
    live = None
    if not args.json_lines:
        from .live import LiveView

        live = LiveView(args.file)

    alarms_out = 0  # the monitor's alarm events written so far

    def emit(event: dict) -> None:
        nonlocal alarms_out
        clock = getattr(reader, "clock", None)
        if clock is not None:
            event = clock.annotate(event)
        # one line written whole: Ctrl-C in a blocked write cut a status line and glued the
        # summary to it
        with interrupts_held():
            if live is not None:
                live.show(event)
            else:
                sys.stdout.write(json.dumps(event) + "\n")
                sys.stdout.flush()
            alarms_out += event["event"] in ALARM_EVENTS

    reader, ip, scale = open_stream(args.file, rig=rig, natural_rpm=args.natural_rpm, follow=args.follow,
                                    idle_exit=args.idle_exit)
    monitor = Monitor.load(args.resume) if args.resume else None
    if monitor is not None:
        alarms_out = len(monitor.events)  # the saved run's, written by it
    status = 0
    try:
        for chunk in read_ahead(reader):  # parsing overlaps the monitor's work
            if monitor is None:
                dt = float(chunk[1, 0] - chunk[0, 0]) if chunk.shape[0] > 1 else 0.01
                monitor = Monitor(_config(args, dt, ip=ip, time_scale=scale))
            if live is not None and live.monitor is None:
                live.start(monitor, clock=getattr(reader, "clock", None))
            for event in monitor.update(chunk):
                emit(event)
    except MeasurementError as exc:
        # the rows before the bad line were processed: the monitor keeps that state
        print(f"rotor-id monitor: error: {exc}", file=sys.stderr)
        if monitor is None:  # a bad line before any good row: an error event and a summary all the same
            monitor = Monitor(_config(args, 0.01, ip=ip, time_scale=scale))
        line = getattr(exc, "line", None) or getattr(reader, "error_line", None) or reader.line + 1
        emit({"event": "error", "message": str(exc), "line": line, "samples": monitor.samples})
        status = 2
    except KeyboardInterrupt:
        # the monitor stopped between two steps (Monitor.update): the alarms its last step
        # raised may not have been written yet; the summary and the state say the same time
        status = 130
        for event in (monitor.events[alarms_out:] if monitor is not None else []):
            emit(event)
    finally:
        if live is not None:
            live.stop()
    if monitor is None:
        if status == 0:
            print(f"rotor-id monitor: error: {reader.name}: the stream has a header but no data rows", file=sys.stderr)
        return status or 2
    summary = monitor.summary()
    if getattr(reader, "clock", None) is not None:
        summary = reader.clock.annotate(summary)  # s and rpm for the live view's summary too
    emit(summary)
    if live is not None:
        live.print_summary(summary)
    if args.state:
        monitor.save(args.state, overwrite=args.force)
    if args.report:
        from .report import write_report

        write_report(monitor, args.report, source=reader.name, overwrite=args.force,
                     clock=getattr(reader, "clock", None))
    return status


class _StreamConfig:
    """``(dt, ip, time scale) -> MonitorConfig`` from the command's options (sent to Ray tasks)."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = argparse.Namespace(**vars(args))
        self.args.func = None  # the namespace travels to the workers

    def __call__(self, dt: float, ip: float, time_scale: float):
        return _config(self.args, dt, ip=ip, time_scale=time_scale)


def _run_many(args: argparse.Namespace, rig) -> int:
    """Several streams: one Ray task each (:mod:`rotor_env.monitor.fleet`), JSON lines or a
    line per event; a table of the streams at the end."""
    from .core import ALARM_EVENTS, alarm_words
    from .fleet import monitor_streams

    refused = [o for o, v in (("--report", args.report), ("--state", args.state), ("--resume", args.resume)) if v]
    if refused:
        raise ValueError(f"{', '.join(refused)}: for one stream; with several, run them one by one")
    if "-" in args.files:
        raise ValueError("standard input (-) is one stream: give files when watching several")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    workers = args.workers if args.workers is not None else len(args.files)

    def emit(event: dict) -> None:
        if args.json_lines:
            print(json.dumps(event), flush=True)
        elif event["event"] in (*ALARM_EVENTS, "error"):
            t = event.get("t_alarm_s", event.get("t_alarm"))
            unit = " s" if "t_alarm_s" in event else ""
            what = alarm_words(event) if event["event"] in ALARM_EVENTS else event.get("message")
            when = f" at t = {t:.6g}{unit}" if t is not None else ""
            print(f"{event['stream']}: {event['event']} {what}{when}", flush=True)

    try:
        results = monitor_streams(args.files, _StreamConfig(args), rig=rig, natural_rpm=args.natural_rpm,
                                  follow=args.follow, idle_exit=args.idle_exit, workers=workers,
                                  address=args.address, emit=emit)
    except KeyboardInterrupt:
        return 130
    if not args.json_lines:
        print("\n| stream | samples | alarms | events | error |\n|---|---|---|---|---|")
        for r in results:
            s = r["summary"] or {}
            evs = ", ".join(f"{e['event']} {alarm_words(e)} (t {e['t_alarm']:.6g})" for e in s.get("events", []))
            print(f"| {r['stream']} | {s.get('samples', 0)} | {s.get('alarms', 0)} | {evs or '—'} | "
                  f"{r['error'] or ''} |")
    return 2 if any(r["error"] for r in results) else 0
