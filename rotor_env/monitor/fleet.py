"""Many streams at once on Ray: one generator task per stream, events merged as they come.

``rotor-id monitor A.csv B.csv ... [--follow] [--workers N] [--address ADDR]`` watches
every stream in its own Ray task (a *streaming generator*: each event is handed to the
driver as soon as the task yields it, while the task goes on reading its stream).  The
driver waits on all of them at once (``ray.wait`` over the generators) and prints each
event, tagged with its ``stream``, in the order they arrive.  A stream that ends (or
with ``--follow`` stays idle past ``--idle-exit``) yields its summary; a stream whose
data are malformed yields an ``error`` event naming the line and the others go on.

Each task holds one :class:`~rotor_env.monitor.core.Monitor`, single-threaded: N
streams need N CPUs to keep up in real time (Ray queues the rest until a CPU frees,
which for live streams means they wait: give ``--workers`` at least the number of
streams, or a cluster with ``--address``).  The same code runs on one machine (Ray's
local mode) and on a cluster.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

from ..measurements.files import MeasurementError

__all__ = ["monitor_streams", "open_stream", "watch_stream"]


def open_stream(source, *, rig=None, natural_rpm: float | None = None, follow: bool = False,
                idle_exit: float | None = None):
    """``(reader, ip, time scale)``: a dimensionless :class:`~rotor_env.measurements.stream.StreamReader`,
    or with ``rig`` a :class:`~rotor_env.measurements.rig_stream.RigStream` (its ``clock`` turns the
    monitor's times and speeds back to s and rpm; options in seconds scale by ``w_ref``)."""
    if rig is None:
        from ..measurements.stream import StreamReader

        return StreamReader(source, follow=follow, idle_exit=idle_exit), 0.3, 1.0
    from ..measurements.rig_stream import RigStream, natural_rpm_required

    if natural_rpm is None:
        raise ValueError(natural_rpm_required())
    reader = RigStream(source, rig, natural_rpm, follow=follow, idle_exit=idle_exit)
    return reader, rig.ip, reader.w_ref


def watch_stream(source: str, config, *, rig=None, natural_rpm: float | None = None, follow: bool = False,
                 idle_exit: float | None = None, name: str | None = None) -> Iterator[dict]:
    """The events of one stream (each tagged ``stream``; with ``rig``, with s and rpm too),
    then its summary, or an ``error`` event naming the bad line and then the summary of
    the samples before it.

    ``config``: a :class:`~rotor_env.monitor.core.MonitorConfig`'s fields as a dict, or
    ``config(dt, ip, time_scale) -> MonitorConfig`` when the options depend on the
    stream's step (a window in time units; what ``rotor-id monitor`` passes).
    """
    from ..measurements.stream import read_ahead
    from .core import Monitor, MonitorConfig

    name = name or str(source)
    monitor = None
    reader = None

    def tag(event: dict) -> dict:
        clock = getattr(reader, "clock", None)
        return {"stream": name, **(clock.annotate(event) if clock is not None else event)}

    try:
        reader, ip, scale = open_stream(source, rig=rig, natural_rpm=natural_rpm, follow=follow,
                                        idle_exit=idle_exit)
        for chunk in read_ahead(reader):
            if monitor is None:
                dt = float(chunk[1, 0] - chunk[0, 0]) if chunk.shape[0] > 1 else 0.01
                cfg = config(dt, ip, scale) if callable(config) else MonitorConfig(**{"ip": ip, **config})
                monitor = Monitor(cfg)
            for event in monitor.update(chunk):
                yield tag(event)
    except MeasurementError as exc:
        line = getattr(reader, "error_line", None) or (reader.line + 1 if reader is not None else None)
        yield tag({"event": "error", "message": str(exc), "line": line,
                   "samples": monitor.samples if monitor is not None else 0})
    if monitor is not None:
        yield tag(monitor.summary())


def monitor_streams(sources: list[str], config, *, rig=None, natural_rpm: float | None = None,
                    follow: bool = False, idle_exit: float | None = None, workers: int = 1,
                    address: str | None = None, emit: Callable[[dict], None] = print) -> list[dict]:
    """Watch every source in its own Ray task (:func:`watch_stream`; ``config`` as there);
    ``emit`` each event as it arrives.

    Returns per stream ``{"stream", "summary", "error"}`` (the summary covers the
    samples before an error).  Streams are named by their path; two sources with the
    same name are refused.
    """
    import ray

    from ..ray_cluster import init_ray, stop_ray

    names = [str(Path(s)) for s in sources]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"the same stream given twice: {dup}")
    started = init_ray(workers, address)
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(watch_stream)
        gens = {}
        for src, name in zip(sources, names, strict=True):
            g = remote.remote(src, config, rig=rig, natural_rpm=natural_rpm, follow=follow, idle_exit=idle_exit,
                              name=name)
            gens[g] = name
        results = {n: {"stream": n, "summary": None, "error": None} for n in names}
        pending = list(gens)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for g in ready:
                try:
                    ref = next(g)
                except StopIteration:
                    continue
                try:
                    event = ray.get(ref)
                except ray.exceptions.RayTaskError as exc:  # a bug, not bad data: report it, go on
                    event = {"stream": gens[g], "event": "error", "message": f"the stream's task failed: {exc}"}
                    emit(event)
                    results[gens[g]]["error"] = event["message"]
                    continue
                emit(event)
                if event["event"] == "summary":
                    results[gens[g]]["summary"] = event
                elif event["event"] == "error":
                    results[gens[g]]["error"] = event["message"]
                pending.append(g)
        return [results[n] for n in names]
    finally:
        if started:
            stop_ray()
