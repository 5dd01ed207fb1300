"""Many streams on Ray (``rotor_env.monitor.fleet``): each stream's events equal a plain
single-process monitor's on the same file; a malformed stream errors alone."""

from __future__ import annotations

import pytest

pytest.importorskip("ray")

from rotor_env.monitor.core import Monitor, MonitorConfig
from rotor_env.monitor.fleet import monitor_streams
from rotor_env.monitor.scenarios import with_crack
from rotor_env.monitor.stream import StreamReader

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


def _plain(path) -> list[dict]:
    """The reference: one Monitor fed by the StreamReader in this process."""
    monitor, events = None, []
    for chunk in StreamReader(path):
        if monitor is None:
            monitor = Monitor(MonitorConfig(**OPTIONS))
        events.extend(monitor.update(chunk))
    return [*events, monitor.summary()]


def test_streams_on_ray_equal_the_plain_monitor_and_a_bad_one_errors_alone(streams):
    crack, bad = streams
    seen: list[dict] = []
    results = monitor_streams([str(crack), str(bad)], OPTIONS, workers=2, emit=seen.append)
    by_stream = {str(crack): [], str(bad): []}
    for e in seen:
        by_stream[e["stream"]].append({k: v for k, v in e.items() if k != "stream"})
    reference = _plain(crack)
    assert by_stream[str(crack)] == reference
    alarms = [e for e in reference if e["event"] in ("appeared", "changed")]
    assert [e["effect"] for e in alarms] == ["asymmetry"] and 250.0 <= alarms[0]["t_alarm"] < 260.0
    res = {r["stream"]: r for r in results}
    assert res[str(crack)]["error"] is None and res[str(crack)]["summary"]["alarms"] == 1
    err = res[str(bad)]["error"]
    assert err is not None and "line 9002" in err and "'x" in err
    # the bad stream's state before its bad line is summarised, not lost
    assert res[str(bad)]["summary"]["samples"] > 8000


def test_the_same_stream_twice_is_refused(streams):
    with pytest.raises(ValueError, match="twice"):
        monitor_streams([str(streams[0]), str(streams[0])], OPTIONS, workers=1, emit=lambda e: None)
