"""Issue 22, items 4, 5 and 8 (the monitor): a bad line never takes the alarm raised before
it, the error names the right line, CR-only files and damaged state files are handled,
and options --resume would ignore are refused."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from rotor_env.measurements.files import MeasurementError
from rotor_env.monitor import Monitor, StreamReader
from rotor_env.monitor.scenarios import with_crack


@pytest.fixture(scope="module")
def crack_file(tmp_path_factory):
    """The issue-15 example: D 0.03 -> 0.04 at t = 250 (noise-free), alarm at t 250-256."""
    meas = with_crack(0.03, 0.04, rotor="table1")
    path = tmp_path_factory.mktemp("mon") / "run.csv"
    type(meas)(meas.data, None).to_file(path)
    return path


def _run(path, **reader):
    """Monitor the file in one read block; returns (monitor, the error or None)."""
    mon = Monitor()
    try:
        for chunk in StreamReader(path, **reader):
            list(mon.update(chunk))
    except MeasurementError as exc:
        return mon, exc
    return mon, None


@pytest.mark.parametrize("bad", ["nan", "backwards", "duplicate", "tilt"])
def test_a_bad_line_after_the_alarm_keeps_the_alarm_and_names_its_line(tmp_path, crack_file, bad):
    lines = crack_file.read_text().splitlines(keepends=True)
    k = 13501  # t = 270 (dt 0.02): after the alarm, in the same read block
    cells = lines[k].rstrip("\n").split(",")
    if bad == "nan":
        cells[2] = "nan"
    elif bad == "backwards":
        cells[0] = repr(float(cells[0]) - 1.0)
    elif bad == "duplicate":
        cells[0] = lines[k - 1].split(",")[0]
    else:
        cells[4] = "1.5"  # theta_x
    lines[k] = ",".join(cells) + "\n"
    path = tmp_path / "bad.csv"
    path.write_text("".join(lines))
    mon, exc = _run(path, chunk_bytes=1 << 26)
    assert exc is not None and f"line {k + 1}," in str(exc)
    assert getattr(exc, "line", None) == k + 1
    assert mon.samples == k - 1  # every row before the bad one
    assert mon.summary()["alarms"] == 1


def test_cr_only_line_endings_read_like_lf(tmp_path, crack_file):
    text = crack_file.read_text()
    head = "".join(text.splitlines(keepends=True)[:3001])
    lf, cr = tmp_path / "lf.csv", tmp_path / "cr.csv"
    lf.write_text(head)
    cr.write_bytes(head.replace("\n", "\r").encode())
    a = np.concatenate(list(StreamReader(lf)))
    b = np.concatenate(list(StreamReader(cr, chunk_bytes=4096)))  # a CRLF split between reads too
    np.testing.assert_array_equal(a, b)


def test_a_huge_line_is_refused_with_its_number(tmp_path, crack_file):
    lines = crack_file.read_text().splitlines(keepends=True)[:2001]
    lines.insert(1001, "1" * (1 << 20) + "\n")
    path = tmp_path / "long.csv"
    path.write_text("".join(lines))
    mon, exc = _run(path)
    assert exc is not None and "line 1002: longer than" in str(exc)
    assert mon.samples == 1000


@pytest.mark.parametrize("damage", ["truncate", "flip"])
def test_a_damaged_state_file_is_a_clear_error(tmp_path, damage):
    mon = Monitor()
    path = mon.save(tmp_path / "state.npz")
    data = bytearray(path.read_bytes())
    if damage == "truncate":
        data = data[: len(data) // 2]
    else:
        for i in range(40, len(data), 97):
            data[i] ^= 0x5A
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=r"not a monitor state file|not valid|missing|non-finite|version"):
        Monitor.load(path)


def _cli(args, **kw):
    return subprocess.run([sys.executable, "-m", "rotor_env.cli", "monitor", *args], capture_output=True,
                          text=True, timeout=120, **kw)


def test_cli_header_only_bad_state_name_and_resume_options(tmp_path, crack_file):
    header = crack_file.read_text().splitlines()[0] + "\n"
    out = _cli(["-", "--json-lines"], input=header)
    assert out.returncode == 2 and "no data rows" in out.stderr
    out = _cli([str(crack_file), "--json-lines", "--state", str(tmp_path / "x.txt")])
    assert out.returncode == 2 and ".npz" in out.stderr and out.stdout == ""  # said before reading the stream
    state = Monitor().save(tmp_path / "s.npz")
    out = _cli([str(crack_file), "--resume", str(state), "--arl0", "1000", "--model", "unbalance"])
    assert out.returncode == 2 and "--model, --arl0" in out.stderr


def test_cli_bad_line_in_the_first_block_gives_an_error_event_and_a_summary(tmp_path, crack_file):
    lines = crack_file.read_text().splitlines(keepends=True)[:200]
    cells = lines[1].split(",")
    cells[4] = "nan"  # theta_x of the first row: a validation error in the first read block
    lines[1] = ",".join(cells)
    path = tmp_path / "bad.csv"
    path.write_text("".join(lines))
    out = _cli([str(path), "--json-lines"])
    assert out.returncode == 2 and "line 2, column 'theta_x'" in out.stderr
    ev = [json.loads(x) for x in out.stdout.splitlines()]
    assert ev[-2]["event"] == "error" and ev[-2]["line"] == 2
    assert ev[-1]["event"] == "summary" and ev[-1]["samples"] == 0


@pytest.fixture(scope="module")
def long_crack_file(tmp_path_factory):
    """The crack example sampled ten times finer (150 001 rows): a second or more of work
    (blocks of 200 samples span 0.4 time units here: no alarm)."""
    meas = with_crack(0.03, 0.04, rotor="table1", dt=0.002)
    path = tmp_path_factory.mktemp("mon_long") / "run.csv"
    type(meas)(meas.data, None).to_file(path)
    return path


_INTERRUPTIBLE = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
                  "from rotor_env.cli import main; sys.exit(main(sys.argv[1:]))")


@pytest.mark.parametrize("reader", ["drained", "blocked"])
def test_ctrl_c_on_a_busy_monitor_summarises_what_its_state_holds(tmp_path, long_crack_file, reader):
    """Item 4, end to end: Ctrl-C in the middle of the work ('drained': just after the first
    status line, mostly while the monitor processes a chunk; 'blocked': while its writes
    wait on a full pipe).  Every line is whole and the summary is on its own; the saved
    state holds exactly the samples the summary counts (processed up to its t, the rest
    waiting), and resuming it on the rows after them gives the uninterrupted run's result.
    Where the signal lands is up to the clock: the deterministic case is
    test_ctrl_c_inside_an_update_keeps_every_sample."""
    import fcntl
    import signal
    import termios
    import time

    from rotor_env.monitor import Monitor, StreamReader

    state = tmp_path / "state.npz"
    proc = subprocess.Popen([sys.executable, "-c", _INTERRUPTIBLE, "monitor", str(long_crack_file), "--json-lines",
                             "--state", str(state), "--status-every", "20" if reader == "drained" else "0.01"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        if reader == "drained":
            first = proc.stdout.readline()
            time.sleep(0.05)  # most of the time goes into the monitor's steps
        else:  # the pipe full (64 KiB): the monitor waits in a write
            # the writer is blocked once the pipe's content stops growing near its capacity: a
            # pipe fills by pages, so how full it stops depends on the lines' length (a fixed
            # 60000 bytes was never reached once the status lines grew: 56542, a 90 s wait)
            first = b""
            deadline = time.monotonic() + 90
            held, still = -1, 0
            while time.monotonic() < deadline and proc.poll() is None:
                n = int.from_bytes(fcntl.ioctl(proc.stdout.fileno(), termios.FIONREAD, b"\0\0\0\0"), sys.byteorder)
                still = still + 1 if n == held else 0
                held = n
                if n >= 32768 and still >= 10:
                    break
                time.sleep(0.02)
            assert proc.poll() is None and held >= 32768, "the monitor's writes never blocked on the full pipe"
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err[-2000:]
    lines = (first + out).decode().splitlines()
    events = [json.loads(x) for x in lines]  # a cut line would not parse
    summary = events[-1]
    assert summary["event"] == "summary" and all(e["event"] != "summary" for e in events[:-1])
    assert summary["samples"] < 150001  # it was interrupted

    saved = Monitor.load(state)
    assert (saved.samples, saved.t) == (summary["samples"], summary["t"])
    t_file = np.loadtxt(long_crack_file, delimiter=",", skiprows=1, usecols=0)
    processed = int(np.count_nonzero(t_file <= summary["t"] + 1e-9)) if summary["t"] > 0 else 0
    assert processed + summary["unprocessed_samples"] == summary["samples"]  # none lost
    assert summary["t_received"] == pytest.approx(t_file[summary["samples"] - 1])

    # resumed on the rows after the ones it holds, it ends where an uninterrupted run ends
    whole = Monitor(saved.config)
    for chunk in StreamReader(long_crack_file):
        whole.update(chunk)
    for chunk in StreamReader(long_crack_file):
        rest = chunk[chunk[:, 0] > summary["t_received"]]
        if rest.shape[0]:
            saved.update(rest)
    a, b = whole.summary(), saved.summary()
    assert (b["samples"], b["t"], b["alarms"], b["counted_blocks"]) == (a["samples"], a["t"], a["alarms"],
                                                                         a["counted_blocks"])
    assert b["events"] == a["events"]
    for name, coef in a["coefficients"].items():
        assert b["coefficients"][name] == pytest.approx(coef, rel=1e-9, abs=1e-15)


def test_ctrl_c_inside_an_update_keeps_every_sample(crack_file, monkeypatch):
    """Item 4, deterministic: SIGINT arrives while ``Monitor.update`` works through a chunk
    (after its third step).  It stops at the end of that step; every sample is processed or
    waits (main: the samples of the chunk were counted but neither processed nor kept, so a
    saved state dropped them), and going on gives the uninterrupted result."""
    import os
    import signal

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        data = np.concatenate(list(StreamReader(crack_file)))
        whole = Monitor(status_every=10.0)
        whole.update(data)

        mon = Monitor(status_every=10.0)
        original = Monitor._process
        calls = []

        def interrupted_in_third_step(self, rows):
            calls.append(rows.shape[0])
            out = original(self, rows)
            if len(calls) == 3:
                os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C now, in the middle of update
            return out

        monkeypatch.setattr(Monitor, "_process", interrupted_in_third_step)
        with pytest.raises(KeyboardInterrupt):
            mon.update(data)
        monkeypatch.setattr(Monitor, "_process", original)
    finally:
        signal.signal(signal.SIGINT, previous)
    summary = mon.summary()
    assert len(calls) == 3 and summary["samples"] == data.shape[0]
    processed = int(np.count_nonzero(data[:, 0] <= summary["t"]))
    assert processed == sum(calls) and processed + summary["unprocessed_samples"] == data.shape[0]
    mon.update(np.zeros((0, data.shape[1])))  # the waiting samples go on
    a, b = whole.summary(), mon.summary()
    assert (b["samples"], b["t"], b["alarms"], b["counted_blocks"]) == (a["samples"], a["t"], a["alarms"],
                                                                         a["counted_blocks"])
    assert a["alarms"] == 1 and b["events"] == a["events"]


@pytest.mark.parametrize("option", [["--model", "unbalance"], ["--ip", "0.2"], ["--forgetting", "0.999"],
                                    ["--window", "2000"], ["--arl0", "1000"], ["--block", "100"]])
def test_resume_refuses_each_option_it_would_ignore(tmp_path, crack_file, capsys, option):
    """Item 4: --resume ignored --model, --forgetting, --window, --arl0, --block silently."""
    from rotor_env.cli import main

    state = Monitor().save(tmp_path / "s.npz")
    assert main(["monitor", str(crack_file), "--json-lines", "--resume", str(state), *option]) == 2
    out = capsys.readouterr()
    assert f"{option[0]} cannot change them" in out.err and out.out == ""


def test_cli_bad_line_after_the_alarm_keeps_it_and_names_the_line(tmp_path, crack_file):
    """Item 4 through the command: the error event names the bad line (15004 for 14001
    before) and the summary keeps the alarm raised before it in the same read block."""
    lines = crack_file.read_text().splitlines(keepends=True)
    k = 14000  # t = 280: after the alarm (t 250-256)
    cells = lines[k].split(",")
    cells[0] = repr(float(cells[0]) - 1.0)  # a time going backwards
    lines[k] = ",".join(cells)
    path = tmp_path / "bad.csv"
    path.write_text("".join(lines))
    out = _cli([str(path), "--json-lines"])
    assert out.returncode == 2 and f"line {k + 1}," in out.stderr
    ev = [json.loads(x) for x in out.stdout.splitlines()]
    assert ev[-2]["event"] == "error" and ev[-2]["line"] == k + 1
    assert ev[-1]["event"] == "summary" and ev[-1]["alarms"] == 1 and ev[-1]["samples"] == k - 1
    assert [e["event"] for e in ev].count("changed") + [e["event"] for e in ev].count("appeared") == 1


def _peak_rss_mb(args) -> tuple[int, float]:
    """Exit code and peak resident memory (MB) of ``rotor-id ARGS`` in a child process."""
    code = ("import resource, sys\nfrom rotor_env.cli import main\ntry:\n    rc = main(sys.argv[1:])\nfinally:\n"
            "    print('RSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)\nsys.exit(rc)")
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=300)
    rss = [line for line in out.stderr.splitlines() if line.startswith("RSS ")]
    return out.returncode, int(rss[-1].split()[1]) / 1024.0  # Linux: kB


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="ru_maxrss in kB")
def test_a_100_mb_line_is_refused_without_reading_it_whole(tmp_path, crack_file):
    """Items 5 and 8: a 100 MB line gave a _csv.Error and no summary, after 950 MB of RSS.
    Now: an error event naming its line, a summary of the rows before, and the memory of
    a plain run within 100 MB."""
    head = "".join(crack_file.read_text().splitlines(keepends=True)[:2001])
    plain, long = tmp_path / "plain.csv", tmp_path / "long.csv"
    plain.write_text(head)
    with open(long, "w") as fh:
        fh.write(head)
        block = "1" * (1 << 20)
        for _ in range(100):
            fh.write(block)
        fh.write("\n")
    rc_plain, rss_plain = _peak_rss_mb(["monitor", str(plain), "--json-lines"])
    rc_long, rss_long = _peak_rss_mb(["monitor", str(long), "--json-lines"])
    assert (rc_plain, rc_long) == (0, 2)
    assert rss_long - rss_plain < 100, (rss_plain, rss_long)
    out = _cli([str(long), "--json-lines"])
    ev = [json.loads(x) for x in out.stdout.splitlines()]
    assert ev[-2]["event"] == "error" and ev[-2]["line"] == 2002 and "longer than" in ev[-2]["message"]
    assert ev[-1]["event"] == "summary" and ev[-1]["samples"] == 2000
