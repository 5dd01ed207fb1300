"""Issue 22, item 8: the local Ray a command starts dies with it, also after ``kill -9``
(main: the raylet's dashboard and runtime-env agents outlived a killed batch by a minute
or more, orphaned)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

DRIVER = textwrap.dedent("""
    import sys, time
    from rotor_env.ray_cluster import init_ray, stop_ray
    import ray
    init_ray(1, None)  # as `rotor-id batch` and the monitor's fleet start it
    print(ray.get(ray.remote(lambda: "ready").remote()), flush=True)
    if sys.argv[1] == "stop":
        stop_ray()
        print("stopped", flush=True)
    time.sleep(600)
""")


def _table() -> dict[int, tuple[int, str, bytes]]:
    """pid -> (parent pid, state, command line) of every process."""
    out = {}
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            stat = Path(f"/proc/{name}/stat").read_bytes().rsplit(b")", 1)[1].split()
            cmd = Path(f"/proc/{name}/cmdline").read_bytes().replace(b"\0", b" ")
        except OSError:
            continue
        out[int(name)] = (int(stat[1]), stat[0].decode(), cmd)
    return out


def _ray_descendants(root: int) -> dict[int, bytes]:
    procs = _table()
    children: dict[int, list[int]] = {}
    for pid, (ppid, _, _) in procs.items():
        children.setdefault(ppid, []).append(pid)
    out, stack = {}, [root]
    while stack:
        for pid in children.get(stack.pop(), []):
            stack.append(pid)
            cmd = procs[pid][2]
            if cmd.startswith(b"ray::") or (b"/ray/" in cmd and b"import os, select" not in cmd):
                out[pid] = cmd
    return out


def _alive(pids) -> list[int]:
    procs = _table()
    return [p for p in pids if p in procs and procs[p][1] not in ("Z", "X")]


def _kill_leftovers(pids) -> None:
    for p in _alive(pids):  # the test's own processes only (found under its driver)
        try:
            os.kill(p, signal.SIGKILL)
        except OSError:
            pass


@pytest.mark.parametrize("end", ["kill -9", "stop"])
def test_local_ray_dies_with_its_driver(end):
    pytest.importorskip("ray")
    driver = subprocess.Popen([sys.executable, "-c", DRIVER, "stop" if end == "stop" else "run"], cwd=ROOT,
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    seen: dict[int, bytes] = {}
    try:
        assert driver.stdout.readline().strip() == "ready"
        # the agents start with the raylet; wait until both are there
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            seen.update(_ray_descendants(driver.pid))
            titles = b" ".join(seen.values())
            if b"ray::DashboardAgent" in titles and b"ray::RuntimeEnvAgent" in titles:
                break
            time.sleep(0.2)
        assert b"raylet" in b" ".join(seen.values()), seen
        if end == "stop":
            assert driver.stdout.readline().strip() == "stopped"
            time.sleep(0.5)
        else:
            time.sleep(1.0)  # the watchdog notes the processes twice a second
            driver.send_signal(signal.SIGKILL)
            driver.wait(timeout=30)
        deadline = time.monotonic() + 8.0
        while _alive(seen) and time.monotonic() < deadline:
            time.sleep(0.2)
        left = {p: seen[p][:60] for p in _alive(seen)}
        assert left == {}, f"Ray processes outlived their driver ({end}): {left}"
    finally:
        if driver.poll() is None:
            driver.kill()
        _kill_leftovers(seen)
