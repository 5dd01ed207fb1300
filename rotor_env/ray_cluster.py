"""Starting Ray for the batch diagnosis and the monitor's fleet (one place for both).

A local Ray started here dies with the command, also one killed with ``kill -9``.  Ray's
own node processes (GCS, raylet, monitors) share the driver's fate, but the raylet's
dashboard and runtime-env agents do not: they wait on the dead GCS for a minute or more.
So :func:`init_ray` starts a small watchdog (Linux: it reads ``/proc``) in its own
session, away from the terminal's signals.  It notes the driver's Ray processes twice a
second and, when the driver's end of a pipe closes (at :func:`stop_ray`, or when the
driver dies however it dies), kills the ones still there.  A cluster at ``address`` is
not ours: nothing is watched or stopped there.
"""

from __future__ import annotations

import subprocess
import sys

__all__ = ["WATCHDOG", "init_ray", "stop_ray"]

#: the watchdog's program (``python -c WATCHDOG DRIVER_PID``): stdin is the driver's pipe
WATCHDOG = r"""
import os, select, signal, sys

signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the driver's to handle
driver = int(sys.argv[1])
me = os.getpid()


def table():
    # pid -> (parent pid, start time, command line) of every process we can read
    out = {}
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as fh:
                stat = fh.read().rsplit(b")", 1)[1].split()
            with open(f"/proc/{name}/cmdline", "rb") as fh:
                cmd = fh.read().replace(b"\0", b" ")
        except OSError:
            continue
        out[int(name)] = (int(stat[1]), stat[19], cmd)
    return out


def is_ray(cmd):
    return cmd.startswith(b"ray::") or b"/ray/" in cmd


seen = {}  # pid -> start time of the driver's Ray processes (a pid reused later is not killed)
while True:
    ready = select.select([0], [], [], 0.5)[0]
    procs = table()
    children = {}
    for pid, (ppid, _, _) in procs.items():
        children.setdefault(ppid, []).append(pid)
    stack = [driver]
    while stack:
        for pid in children.get(stack.pop(), []):
            if pid != me:
                stack.append(pid)
                if is_ray(procs[pid][2]):
                    seen[pid] = procs[pid][1]
    if ready and not os.read(0, 4096):
        break  # the driver closed the pipe: it stopped Ray, or it is gone
procs = table()
for pid, start in seen.items():
    if pid in procs and procs[pid][1] == start:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
"""

_watchdog: subprocess.Popen | None = None


def init_ray(workers: int, address: str | None):
    """Ray's local mode with ``workers`` CPUs, or the cluster at ``address``.  Returns
    True when this call started Ray (and so should stop it with :func:`stop_ray`)."""
    import logging
    import os

    import ray

    if ray.is_initialized():
        return False
    kwargs = {"include_dashboard": False, "log_to_driver": False, "logging_level": logging.ERROR}
    if address:
        ray.init(address=address, **kwargs)
        return True
    global _watchdog
    if sys.platform.startswith("linux") and _watchdog is None:
        # before ray.init: it notes the agents from their start
        _watchdog = subprocess.Popen([sys.executable, "-c", WATCHDOG, str(os.getpid())], stdin=subprocess.PIPE,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                                     close_fds=True)
    ray.init(num_cpus=workers, **kwargs)
    return True


def stop_ray() -> None:
    """``ray.shutdown()``, then the watchdog kills what Ray's shutdown left (its agents)."""
    import ray

    global _watchdog
    try:
        ray.shutdown()
    finally:
        dog, _watchdog = _watchdog, None
        if dog is not None:
            dog.stdin.close()
            try:
                dog.wait(timeout=10)
            except subprocess.TimeoutExpired:
                dog.kill()
