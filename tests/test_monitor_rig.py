"""``rotor-id monitor --rig``: SI rig waveforms streamed into the monitor (issue 15).

References: the batch path ``load_waveforms(...).to_measurements(w_ref)`` on the same
file (the rows), the simulation's own truth (the crack's time in s, the sweep's rpm),
and the batch keyphasor check's own error message.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time

import numpy as np
import pytest

from rotor_env.measurements.files import MeasurementError
from rotor_env.measurements.rig import SPEED_UNITS, load_rig
from rotor_env.measurements.rig_stream import DC_GAP_REVOLUTIONS, RigStream
from rotor_env.measurements.waveforms import WaveformError, load_waveforms
from rotor_env.monitor import Monitor
from rotor_env.params import Crack, RotorParams
from rotor_env.rig_simulation import simulate_rig

NATURAL_RPM = 1650.0
W_REF = NATURAL_RPM * SPEED_UNITS["rpm"]
ONE_PLANE = "keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n"
SLOW_ROLL = ONE_PLANE + "slow_roll_rpm: 400\n"
SPEED_COLUMN = "speed: rpm\nprobes: {x: 45, y: -45}\nunits: {displacement: mil}\n"
TILT = json.dumps({
    "keyphasor": "kp", "units": {"displacement": "V", "sensitivity_mv_per_um": 7.87},
    "probes": [{"name": "xa", "angle_deg": 45, "plane": "A"}, {"name": "ya", "angle_deg": -45, "plane": "A"},
               {"name": "xb", "angle_deg": 45, "plane": "B"}, {"name": "yb", "angle_deg": -45, "plane": "B"}],
    "planes": {"A": {"axial_position_m": -0.1}, "B": {"axial_position_m": 0.15}},
    "disk": {"polar_inertia_kg_m2": 0.03, "diametral_inertia_kg_m2": 0.1}})


def _write_rig(folder, text: str, name: str = "rig.yaml"):
    path = folder / name
    path.write_text(text)
    return load_rig(path)


def _write_csv(path, columns: dict[str, np.ndarray]) -> None:
    names = list(columns)
    np.savetxt(path, np.column_stack([columns[n] for n in names]), delimiter=",", header=",".join(names),
               comments="", fmt="%.10g")


def _healthy(rig, **kw):
    params = RotorParams(ip=rig.ip, values={"c": 0.04, "tau": 0.005},
                         effects=("stiffness", "viscous_damping", "unbalance"))
    return simulate_rig(rig, params, natural_rpm=NATURAL_RPM, **kw)


# ----------------------------------------------------------------- (a) the batch path's rows
@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """Three rigs, each a run-up with noise written as CSV: a one-plane rig in um with
    probe-track runout and slow-roll compensation (12 kHz: decimated by 2), a two-plane
    tilt rig in volts (12 kHz), a one-plane rig in mil with a speed column (5 kHz)."""
    folder = tmp_path_factory.mktemp("rigs")
    out = {}
    for name, text, fname, kw in (
        ("translation", SLOW_ROLL, "rig.yaml", {"sample_rate": 12000.0, "runout": 3.0, "runout_phase_deg": 40.0}),
        ("tilt", TILT, "tilt.json", {"sample_rate": 12000.0}),
        ("speed column", SPEED_COLUMN, "speed.yaml", {"sample_rate": 5000.0}),
    ):
        rig = _write_rig(folder, text, fname)
        run = _healthy(rig, rpm_from=200.0, rpm_to=1500.0, rpm_per_s=300.0, noise=0.2, seed=1, **kw)
        path = folder / f"{fname}.csv"
        _write_csv(path, run.file_columns())
        out[name] = (rig, path)
    return out


@pytest.mark.parametrize("name, chunk_bytes", [("translation", 1500), ("translation", 1 << 20), ("tilt", 3000),
                                               ("tilt", 1 << 20), ("speed column", 3000)])
def test_streamed_rows_equal_the_batch_path(recordings, name, chunk_bytes):
    """Tolerances: the angle and speed differ only by the keyphasor's local spline (edges
    k-3..k+4) against the batch's spline through every edge, whose end conditions fade by
    0.27 a knot: 1e-4 rad and 1e-4 (dimensionless speed about 1; a speed column has no
    spline: 1e-7, the rounding of its integral).  The displacements are the same FIR on
    the same samples, so they agree to rounding (1e-9 of the orbit) once the origins are
    matched: the stream fixes the DC
    gap from the first revolutions, the batch path takes the record's mean; the
    difference is the batch's mean position over those revolutions, computed here."""
    rig, path = recordings[name]
    batch_rec = load_waveforms(path, rig)
    batch = batch_rec.to_measurements(W_REF).data
    stream = RigStream(path, rig, NATURAL_RPM, chunk_bytes=chunk_bytes)
    chunks = list(stream)
    if chunk_bytes < 5000:
        # tiny chunks (30-60 lines): edges, filters and buffers cross chunk boundaries
        assert len(chunks) > 40
    got = np.concatenate(chunks)
    assert got.shape == batch.shape
    inner = slice(20, -20)  # away from the ends (the Savitzky-Golay end fits)
    np.testing.assert_allclose(got[inner, 0], batch[inner, 0], rtol=0, atol=1e-9)
    spline_tol = 1e-7 if rig.keyphasor is None else 1e-4
    np.testing.assert_allclose(got[inner, 1], batch[inner, 1], rtol=0, atol=spline_tol)
    np.testing.assert_allclose(got[inner, 2], batch[inner, 2], rtol=0, atol=spline_tol)
    first = batch_rec.phi < 2 * math.pi * DC_GAP_REVOLUTIONS
    scale = 1e-3 if rig.model == "translation" else 1.0
    offset = {4: batch_rec.v[first].mean() / scale, 5: batch_rec.u[first].mean() / scale}
    amp = np.abs(batch[:, 4:6]).max()
    for j in (4, 5):
        np.testing.assert_allclose(got[inner, j], batch[inner, j] - offset[j], rtol=0, atol=1e-9 * amp)
    for j in (6, 7):  # rates: the same Savitzky-Golay filter of the same samples
        np.testing.assert_allclose(got[inner, j], batch[inner, j], rtol=0, atol=1e-6 * np.abs(batch[:, j]).max())
    assert stream.q == (2 if name != "speed column" else 1)
    # the clock: the first row is the batch's first kept sample, in the file's seconds
    kept = batch_rec.t[np.argmax(batch_rec.phi >= batch_rec.phi[0] + 2 * math.pi)]
    assert stream.clock.seconds(0.0) == pytest.approx(kept, abs=1e-9)
    if name == "translation":
        assert any("slow-roll runout" in n for n in stream.notes)


# ----------------------------------------------------------------- (b) a crack, through the command
def _cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "rotor_env.cli", *args], capture_output=True, text=True,
                          timeout=300, **kw)


def test_crack_in_an_si_stream_alarms_on_asymmetry_at_its_time_in_seconds(tmp_path):
    """What ``rotor-id simulate run.csv --rig rig.yaml --set D=0 --crack 1200:0.1`` writes
    (its ``simulate_rig``, in process to spare a start-up): the crack's ``T`` is the model's
    time from the start of the sweep, ``T / w_ref`` s in the file; the sweep's speed is
    ``300 + 230 t`` rpm.  Noise-free: the Savitzky-Golay accelerations of probe noise
    would bury the crack's moment (see docs/MEASUREMENTS.md, on-line monitoring)."""
    rig = _write_rig(tmp_path, ONE_PLANE)
    crack_T = 1200.0
    params = RotorParams(ip=0.0, values={"c": 0.04, "tau": 0.005, "D": 0.0},
                         effects=("stiffness", "viscous_damping", "unbalance", "asymmetry"),
                         crack=Crack(crack_T, 0.1))
    _write_csv(tmp_path / "run.csv", simulate_rig(rig, params, natural_rpm=NATURAL_RPM).file_columns())
    crack_s = crack_T / W_REF
    text = (tmp_path / "run.csv").read_text()
    out = _cli("monitor", "-", "--rig", "rig.yaml", "--natural-rpm", f"{NATURAL_RPM:g}", "--json-lines",
               input=text, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    ev = [json.loads(x) for x in out.stdout.splitlines()]
    alarms = [e for e in ev if e["event"] in ("appeared", "changed", "disappeared")]
    assert [(e["event"], e["effect"]) for e in alarms] == [("appeared", "asymmetry")]
    a = alarms[0]
    assert crack_s - 0.05 <= a["t_onset_s"] <= crack_s <= a["t_alarm_s"] <= crack_s + 0.15
    assert a["rpm_alarm"] == pytest.approx(300.0 + 230.0 * a["t_alarm_s"], rel=0.01)
    assert a["value_after"]["D"] == pytest.approx(0.1, abs=0.06)
    status = [e for e in ev if e["event"] == "status"]
    assert len(status) >= 8  # every second (the default with --rig) of an 11.7 s run
    for s in status:
        assert s["rpm"] == pytest.approx(300.0 + 230.0 * s["t_s"], rel=0.01)
        assert s["t_s"] == pytest.approx(s["t"] / W_REF + ev[-1]["t_s"] - ev[-1]["t"] / W_REF, abs=1e-9)
    assert ev[-1]["event"] == "summary" and ev[-1]["events"][0]["t_alarm_s"] == a["t_alarm_s"]



@pytest.mark.parametrize("seed", [1, 2])
def test_crack_under_probe_noise_is_named_the_crack(tmp_path, seed):
    """The README's rig example with 0.001 um of probe noise (``--noise 0.001 --seed 1``).
    Until 2026-11-28 the monitor named ``changed unbalance`` at the crack's block (both
    seeds): on a synchronous orbit the crack's moment is a 1X forcing, the asymmetry blocks
    could not be sized, and the step reached the unbalance's score through the reference.
    The isolation (each effect's change alone fitted to the deciding block) names the crack,
    sized from that block (truth D = 0.1)."""
    rig = _write_rig(tmp_path, ONE_PLANE)
    params = RotorParams(ip=0.0, values={"c": 0.04, "tau": 0.005, "D": 0.0},
                         effects=("stiffness", "viscous_damping", "unbalance", "asymmetry"),
                         crack=Crack(1200.0, 0.1))
    run = simulate_rig(rig, params, natural_rpm=NATURAL_RPM, noise=0.001, seed=seed)
    _write_csv(tmp_path / "run.csv", run.file_columns())
    out = _cli("monitor", "-", "--rig", "rig.yaml", "--natural-rpm", f"{NATURAL_RPM:g}", "--json-lines",
               input=(tmp_path / "run.csv").read_text(), cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    ev = [json.loads(x) for x in out.stdout.splitlines()]
    alarms = [e for e in ev if e["event"] in ("appeared", "changed", "disappeared", "unattributed")]
    assert [(e["event"], e["effect"]) for e in alarms] == [("appeared", "asymmetry")]
    a = alarms[0]
    crack_s = 1200.0 / W_REF
    assert crack_s - 0.05 <= a["t_onset_s"] <= crack_s <= a["t_alarm_s"] <= crack_s + 0.15
    assert a["value_after"]["D"] == pytest.approx(0.1, abs=0.01)
    iso = a["evidence"]["isolation"]
    assert max(iso, key=iso.get) == "asymmetry" and a["evidence"]["detected_by"] == "unbalance"


# ----------------------------------------------------------------- (c) healthy streams
@pytest.fixture(scope="module")
def healthy_runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("healthy")
    rig = _write_rig(folder, ONE_PLANE)
    paths = []
    for seed in (11, 12, 13):
        run = _healthy(rig, rpm_from=300.0, rpm_to=2500.0, rpm_per_s=400.0, noise=0.001, seed=seed)
        paths.append(folder / f"healthy{seed}.csv")
        _write_csv(paths[-1], run.file_columns())
    return rig, folder, paths


def test_healthy_si_streams_raise_no_alarm(healthy_runs):
    rig, _, paths = healthy_runs
    for path in paths:
        mon = Monitor(ip=rig.ip)
        events = []
        for chunk in RigStream(path, rig, NATURAL_RPM):
            events += [e for e in mon.update(chunk) if e["event"] != "status"]
        assert events == [], (path.name, events)
        assert mon.counted_blocks["unbalance"] > 10  # the CUSUMs ran (identifiable blocks), they were not idle
        # and the streamed rows identify the simulated rotor (the truth: tau 0.005, c 0.04, no crack)
        coef = mon.coefficients()
        assert coef["unbalance"]["tau"] == pytest.approx(0.005, rel=0.02)
        assert coef["viscous_damping"]["c"] == pytest.approx(0.04, rel=0.05)
        assert abs(coef["asymmetry"]["D"]) < 2e-3


def test_live_view_and_report_show_seconds_and_rpm(healthy_runs, tmp_path):
    import io

    from rich.console import Console

    from rotor_env.monitor.live import LiveView
    from rotor_env.monitor.report import write_report

    rig, _, paths = healthy_runs
    stream = RigStream(paths[0], rig, NATURAL_RPM)
    mon = Monitor(ip=rig.ip, status_every=1.0 * W_REF)
    statuses = []
    for chunk in stream:
        statuses += [stream.clock.annotate(e) for e in mon.update(chunk) if e["event"] == "status"]
    last = statuses[-1]
    # the sweep's truth: 300 + 400 t rpm
    assert last["rpm"] == pytest.approx(300.0 + 400.0 * last["t_s"], rel=0.01)
    view = LiveView(str(paths[0]))
    view.monitor = mon
    view.show(last)
    buf = io.StringIO()
    Console(file=buf, width=200).print(view._render())
    assert f"t = {last['t_s']:.3f} s, {last['rpm']:.0f} rpm" in buf.getvalue()
    write_report(mon, tmp_path / "r.html", source=str(paths[0]), clock=stream.clock)
    text = (tmp_path / "r.html").read_text()
    end = mon.summary()
    assert f"{stream.clock.seconds(end['t']):.3f} s ({stream.clock.rpm(end['speed']):.0f} rpm" in text


# ----------------------------------------------------------------- (d) errors
def _lines(path):
    return path.read_text().splitlines(keepends=True)


def _consume(stream):
    rows = 0
    for chunk in stream:
        rows += len(chunk)
    return rows


def test_malformed_line_and_non_finite_value_name_file_line_and_column(healthy_runs, tmp_path):
    rig, folder, paths = healthy_runs
    lines = _lines(paths[0])
    bad = tmp_path / "bad.csv"
    lines_bad = list(lines)
    lines_bad[20000] = lines_bad[20000].replace(",", ",x", 1)  # line 20001 of the file
    bad.write_text("".join(lines_bad))
    stream = RigStream(bad, rig, NATURAL_RPM, chunk_bytes=8192)
    with pytest.raises(MeasurementError, match=rf"{bad}, line 20001, column 'kp': 'x"):
        _consume(stream)
    nan = tmp_path / "nan.csv"
    lines_nan = list(lines)
    cells = lines_nan[15000].rstrip("\n").split(",")
    cells[2] = "nan"  # column x
    lines_nan[15000] = ",".join(cells) + "\n"
    nan.write_text("".join(lines_nan))
    stream = RigStream(nan, rig, NATURAL_RPM)
    with pytest.raises(MeasurementError, match=rf"{nan}, line 15001, column 'x': value nan is not finite"):
        _consume(stream)
    assert stream.error_line == 15001 and stream.line == 15000  # the rows before it were read
    gap = tmp_path / "gap.csv"
    gap.write_text("".join(lines[:12000] + lines[12001:]))  # a sample missing after line 12000
    with pytest.raises(MeasurementError, match=rf"{gap}, line 12001, column 't': non-uniform sampling"):
        _consume(RigStream(gap, rig, NATURAL_RPM))
    # through the command: the error, and the monitor's state up to the bad line
    out = _cli("monitor", str(nan), "--rig", str(folder / "rig.yaml"), "--natural-rpm", "1650", "--json-lines")
    assert out.returncode == 2
    assert f"{nan}, line 15001, column 'x': value nan is not finite" in out.stderr
    ev = [json.loads(x) for x in out.stdout.splitlines()]
    assert ev[-2]["event"] == "error" and ev[-2]["line"] == 15001
    assert ev[-1]["event"] == "summary" and ev[-1]["samples"] > 0


def test_missing_keyphasor_pulse_is_the_batch_paths_error(healthy_runs, tmp_path):
    rig, _, paths = healthy_runs
    lines = _lines(paths[0])
    k = lines[0].strip().split(",").index("kp")
    low = [i for i, ln in enumerate(lines[1:], start=1) if float(ln.split(",")[k]) < -2.5]
    groups = np.split(np.array(low), np.nonzero(np.diff(low) > 1)[0] + 1)
    for i in groups[30]:  # the 31st pulse back to the baseline
        cells = lines[i].split(",")
        cells[k] = "0"
        lines[i] = ",".join(cells)
    path = tmp_path / "missing.csv"
    path.write_text("".join(lines))
    with pytest.raises(WaveformError) as batch:
        load_waveforms(path, rig)
    stream = RigStream(path, rig, NATURAL_RPM, chunk_bytes=4096)
    rows = 0
    with pytest.raises(MeasurementError) as streamed:
        for chunk in stream:
            rows += len(chunk)
    assert "missing pulse" in str(streamed.value) and f"{path}, column 'kp', line" in str(streamed.value)
    assert str(streamed.value) == str(batch.value)  # the same check, the same pulse, line and time
    assert f", line {stream.error_line}: irregular pulses" in str(streamed.value)
    assert rows > 0  # the revolutions before it went to the monitor


def test_missing_column_names_the_rig_description(healthy_runs, tmp_path):
    _, folder, paths = healthy_runs
    rig = _write_rig(tmp_path, "keyphasor: kp\nprobes: {x: 45, y2: -45}\n")
    with pytest.raises(MeasurementError, match=r"column\(s\) \['y2'\] named in the rig description .*rig.yaml"):
        _consume(RigStream(paths[0], rig, NATURAL_RPM))


# ----------------------------------------------------------------- (e) the time scale is required
def test_rig_without_natural_rpm_is_a_clear_error(healthy_runs):
    _, folder, paths = healthy_runs
    out = _cli("monitor", str(paths[0]), "--rig", str(folder / "rig.yaml"), "--json-lines")
    assert out.returncode == 2
    assert "--natural-rpm" in out.stderr and "rotor-id diagnose" in out.stderr and "Traceback" not in out.stderr
    assert out.stdout == ""


# ----------------------------------------------------------------- (f) --follow
def test_follow_picks_up_appended_si_rows(healthy_runs, tmp_path):
    rig, folder, paths = healthy_runs
    lines = _lines(paths[1])
    expected = len(load_waveforms(paths[1], rig).to_measurements(W_REF))
    live = tmp_path / "live.csv"
    live.write_text("".join(lines[:9001]))
    proc = subprocess.Popen([sys.executable, "-m", "rotor_env.cli", "monitor", str(live), "--rig",
                             str(folder / "rig.yaml"), "--natural-rpm", "1650", "--follow", "--idle-exit", "4",
                             "--json-lines", "--status-every", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.0)
    with open(live, "a") as fh:
        fh.write("".join(lines[9001:]))
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    summary = json.loads(stdout.splitlines()[-1])
    assert summary["event"] == "summary" and summary["samples"] == expected and summary["alarms"] == 0
    assert summary["rpm"] == pytest.approx(2500.0, rel=0.02)


def test_a_stream_whose_rates_are_noise_is_said_blind(healthy_runs, tmp_path):
    """At a rig's probe noise (0.5 um on a ~100 um orbit) the equation error's rates and
    accelerations are noise: no block carries evidence (the disk's speed relative to the
    shaft, nil on a synchronous whirl, never clears the rates' noise), nothing is identified
    and no alarm can be raised.  Until 2026-11-29 the monitor said so nowhere: every
    coefficient read 0 and "no alarm", as for a healthy rotor.  Now the status, the summary,
    the live view's last lines and the report say it is blind, with the counts; the nearly
    noise-free streams of the same rig (0.001 um) are not."""
    from rotor_env.monitor.core import BLIND_SHARE

    rig, _, paths = healthy_runs
    mon = Monitor(ip=rig.ip)
    for chunk in RigStream(paths[0], rig, NATURAL_RPM):
        mon.update(chunk)
    quiet = mon.summary()
    assert quiet["blind"] == "" and quiet["informative_blocks"] >= BLIND_SHARE * quiet["blocks"] > 0

    run = _healthy(rig, rpm_from=300.0, rpm_to=2500.0, rpm_per_s=400.0, noise=0.5, seed=11)
    _write_csv(tmp_path / "noisy.csv", run.file_columns())
    (tmp_path / "rig.yaml").write_text(ONE_PLANE)
    out = _cli("monitor", "noisy.csv", "--rig", "rig.yaml", "--natural-rpm", f"{NATURAL_RPM:g}", "--json-lines",
               "--status-every", "1", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    ev = [json.loads(x) for x in out.stdout.splitlines()]
    s = ev[-1]
    assert s["event"] == "summary" and s["alarms"] == 0
    assert s["informative_blocks"] < BLIND_SHARE * s["blocks"] and s["blocks"] >= 20
    assert s["blind"].startswith(f"blind: {s['informative_blocks']} of {s['blocks']} blocks carried evidence")
    assert "not a healthy verdict" in s["blind"] and "rotor-id diagnose" in s["blind"]
    # every coefficient stays at its start: nothing was identified
    assert all(v == 0.0 for c in s["coefficients"].values() for v in c.values())
    late = [e for e in ev if e["event"] == "status" and e["t_s"] > 2.0]
    assert late and all(e.get("blind") for e in late)
    # the human-readable end of the run says it too
    text = _cli("monitor", "noisy.csv", "--rig", "rig.yaml", "--natural-rpm", f"{NATURAL_RPM:g}", cwd=tmp_path)
    assert text.returncode == 0 and "not a healthy verdict" in " ".join(text.stdout.split())
