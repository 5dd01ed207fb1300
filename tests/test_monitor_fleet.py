"""Many streams on Ray (``rotor-id monitor A B ...``, ``rotor_env.monitor.fleet``): each
stream's events equal a plain single-process monitor's on the same file; a malformed
stream errors alone."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytest.importorskip("ray")

from rotor_env.measurements.stream import StreamReader
from rotor_env.monitor.core import Monitor, MonitorConfig
from rotor_env.monitor.fleet import monitor_streams
from rotor_env.monitor.scenarios import with_crack

OPTIONS = {"arl0": 1e6, "block": 200}


@pytest.fixture(scope="module")
def streams(tmp_path_factory):
    folder = tmp_path_factory.mktemp("streams")
    crack = folder / "crack.csv"
    with_crack(0.0, 0.04, t_c=250.0, t_end=290.0).with_noise(2e-4, seed=1).to_file(crack)
    bad = folder / "bad.csv"
    lines = crack.read_text().splitlines()
    lines[9001] = lines[9001].replace(",", ",x", 1)  # a malformed value mid-stream
    bad.write_text("\n".join(lines) + "\n")
    return crack, bad


def _plain(path, **options) -> list[dict]:
    """The reference: one Monitor fed by the StreamReader in this process."""
    monitor, events = None, []
    for chunk in StreamReader(path):
        if monitor is None:
            monitor = Monitor(MonitorConfig(**options))
        events.extend(monitor.update(chunk))
    return json.loads(json.dumps([*events, monitor.summary()]))


def test_cli_several_files(streams):
    """``rotor-id monitor A B --json-lines``: each stream's lines are the one-stream command's."""
    crack, bad = streams
    cmd = [sys.executable, "-m", "rotor_env.cli", "monitor", "--json-lines", "--arl0", "1e6"]
    many = subprocess.run([*cmd, str(crack), str(bad)], capture_output=True, text=True, timeout=600)
    assert many.returncode == 2, many.stderr[-2000:]  # one stream had an error
    lines = [json.loads(x) for x in many.stdout.splitlines()]
    mine = [{k: v for k, v in e.items() if k != "stream"} for e in lines if e["stream"] == str(crack)]
    reference = _plain(crack, arl0=1e6, status_every=10.0)
    assert mine == reference
    alarms = [e for e in reference if e["event"] in ("appeared", "changed")]
    assert [e["effect"] for e in alarms] == ["asymmetry"] and 250.0 <= alarms[0]["t_alarm"] < 260.0
    errors = [e for e in lines if e["stream"] == str(bad) and e["event"] == "error"]
    assert len(errors) == 1 and errors[0]["line"] == 9002 and "'x" in errors[0]["message"]
    # the bad stream's samples before its bad line are summarised, not lost
    (summary,) = [e for e in lines if e["stream"] == str(bad) and e["event"] == "summary"]
    assert summary["samples"] > 8000
    refused = subprocess.run([*cmd, "--report", "x.html", str(crack), str(bad)], capture_output=True, text=True,
                             timeout=120)
    assert refused.returncode != 0 and "--report" in refused.stderr


def test_the_same_stream_twice_is_refused(streams):
    with pytest.raises(ValueError, match="twice"):
        monitor_streams([str(streams[0]), str(streams[0])], OPTIONS, workers=1, emit=lambda e: None)
