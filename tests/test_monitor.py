"""The on-line monitor (issue 15): detection against simulated truths, false alarms, resume, streams."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from scipy import stats

from rotor_env.measurements.files import MeasurementError, load_measurements
from rotor_env.measurements.stream import read_ahead
from rotor_env.monitor import Monitor, StreamReader, cusum_threshold, simulate_arl
from rotor_env.monitor import kernel as K
from rotor_env.monitor.detector import chi2_sf, norm_ppf
from rotor_env.monitor.kernel import downdate_row
from rotor_env.monitor.scenarios import (
    HEALTHY_ROTORS,
    growing_crack,
    healthy,
    unbalance_step,
    with_crack,
)

NOISE = 5e-4


@pytest.fixture(scope="module")
def crack_04():
    return with_crack(0.0, 0.04)


def _events(meas, seed=1, **opts):
    mon = Monitor(**opts)
    return mon, [e for e in mon.update(meas.with_noise(NOISE, seed=seed).data) if e["event"] != "status"]


# ----------------------------------------------------------------- the test's design
def test_distributions_equal_scipy():
    for q in (1, 2, 3, 4, 7):
        for x in (0.01, 1.0, 9.0, 80.0, 700.0):
            assert chi2_sf(x, q) == pytest.approx(stats.chi2.sf(x, q), rel=1e-10, abs=1e-300)
    for p in (1e-300, 1e-12, 0.01, 0.3, 0.5, 0.97):
        assert norm_ppf(p) == pytest.approx(stats.norm.ppf(p), rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("arl, delta", [(300.0, 2.0), (1000.0, 1.0)])
def test_threshold_from_arl0_checked_by_simulation(arl, delta):
    # Siegmund's approximation against the CUSUM itself on i.i.d. N(0, 1) evidence
    h = cusum_threshold(arl, delta)
    mean, se = simulate_arl(h, delta, runs=3000, max_steps=int(20 * arl), seed=7)
    assert abs(mean - arl) < 0.12 * arl + 3 * se


# ----------------------------------------------------------------- detection
def test_crack_appearing_is_asymmetry_at_the_right_time(crack_04):
    for seed in (1, 2, 3):
        _, ev = _events(crack_04, seed)
        assert [(e["event"], e["effect"]) for e in ev] == [("appeared", "asymmetry")]
        assert 246.0 <= ev[0]["t_onset"] <= 250.0 <= ev[0]["t_alarm"] <= 256.0
        assert ev[0]["value_before"]["D"] == pytest.approx(0.0, abs=0.003)
        # the value after from the deciding block, wholly after the step (truth 0.04)
        assert ev[0]["value_after"]["D"] == pytest.approx(0.04, abs=0.003)
        assert ev[0]["evidence"]["detected_by"] == "asymmetry"


@pytest.mark.parametrize(("rotor", "dtau", "angle"), [("table1", 0.005, 0.0), ("light", 0.005, 0.7),
                                                      ("heavy", 0.01, -2.0)])
def test_a_lost_balance_weight_is_named_unbalance_with_its_new_value(rotor, dtau, angle):
    # a 1X forcing that steps at t = 250 (a test-only effect beside the rotor's unbalance):
    # on a synchronous orbit a crack's step is one too, and the isolation must tell them
    # apart where the data can; the truth is the sum of the two unbalances
    r = HEALTHY_ROTORS[rotor]
    before = r["tau"] * np.exp(1j * r["beta"])
    after = before + dtau * np.exp(1j * angle)
    mon = Monitor(ip=r["ip"])
    ev = [e for e in mon.update(unbalance_step(dtau, angle, rotor=rotor).with_noise(NOISE, seed=4).data)
          if e["event"] != "status"]
    assert [(e["event"], e["effect"]) for e in ev] == [("changed", "unbalance")]
    e = ev[0]
    assert 250.0 <= e["t_alarm"] <= 262.0
    assert e["value_before"]["tau"] == pytest.approx(abs(before), rel=0.02)
    assert e["value_after"]["tau"] == pytest.approx(abs(after), rel=0.03)
    assert abs(np.angle(np.exp(1j * (e["value_after"]["beta"] - np.angle(after))))) < 0.05
    iso = e["evidence"]["isolation"]
    assert max(iso, key=iso.get) == "unbalance"


def test_isolation_names_one_effect_only_beyond_the_margin():
    # the rule on a hand-made event row: each effect's explained energy (in the noise's
    # variance) less its parameter count is its score; candidates lie within the 99 % point
    # of chi2(q_best + q_h) of the best; a block whose best is below chi2(q_best)'s 99 %
    # point leaves the CUSUM's own attribution
    mon = Monitor()
    G, qm = mon._cols.shape
    q = dict(zip(mon.effects, mon._q, strict=True))
    width = K.N_EV_FIXED + 4 * qm + K.isolation_width(G, qm)

    def row(detected_by: str, scores: dict[str, float]) -> np.ndarray:
        r = np.zeros(width)
        r[K.V_G] = mon.effects.index(detected_by)
        r[K.V_LONG_RUN] = r[K.V_KAPPA] = 1.0
        r[K.V_CHI], r[K.V_DOF], r[K.V_BLOCKS] = 50.0, 4.0, 2.0  # the CUSUM's evidence (unused by the rule)
        for h, name in enumerate(mon.effects):
            o = K.N_EV_FIXED + 4 * qm + h * (1 + 4 * qm)
            r[o] = scores.get(name, 0.0) + q[name]
            r[o + 1 + qm : o + 1 + 2 * qm] = 1e-6  # the reference's errors
            r[o + 1 + 3 * qm : o + 1 + 4 * qm] = 1e-6
        return r

    margin = stats.chi2.ppf(0.99, q["unbalance"] + q["asymmetry"])
    near = mon._event(row("unbalance", {"unbalance": 1400.0, "asymmetry": 1400.0 - 0.9 * margin}))
    assert near["event"] == "unattributed" and near["effect"] is None
    assert near["candidates"] == ["unbalance", "asymmetry"]
    assert set(near["value_after"]) == {"unbalance", "asymmetry"}
    # in words (the command's lines and the live view): both, each with its values
    from rotor_env.monitor.core import alarm_words
    from rotor_env.monitor.live import _alarm_line

    assert alarm_words(near).startswith("unbalance or asymmetry")
    line = _alarm_line(near)
    assert "unbalance: tau = " in line and "asymmetry: D = " in line
    far = mon._event(row("unbalance", {"unbalance": 1400.0 - 1.1 * margin, "asymmetry": 1400.0}))
    assert (far["event"], far["effect"]) == ("appeared", "asymmetry")
    assert far["evidence"]["detected_by"] == "unbalance"
    weak = stats.chi2.ppf(0.99, q["asymmetry"])
    own = mon._event(row("unbalance", {"unbalance": 0.9 * weak, "asymmetry": 0.9 * weak}))
    assert own["effect"] == "unbalance" and "candidates" not in own


def test_crack_growing_is_followed():
    # D = 0.0008 (t - 250): first an appearance, then changes, each later value larger
    meas = growing_crack(0.04 / 50)
    _, ev = _events(meas, 2)
    assert {e["effect"] for e in ev} == {"asymmetry"}
    assert ev[0]["event"] == "appeared" and 250.0 <= ev[0]["t_alarm"] <= 262.0
    after = [e["value_after"]["D"] for e in ev]
    assert len(ev) >= 3 and np.all(np.diff(after) > 0)
    for e in ev:  # each value is the crack's size around its onset..alarm (truth 0.0008 (t - 250))
        assert e["value_after"]["D"] == pytest.approx(0.0008 * (0.5 * (e["t_onset"] + e["t_alarm"]) - 250.0), abs=4e-3)


def test_effect_disappearing():
    meas = with_crack(0.04, 0.0, t_c=248.0)  # on a block boundary (blocks of 4 time units)
    _, ev = _events(meas, 3)
    assert [(e["event"], e["effect"]) for e in ev] == [("disappeared", "asymmetry")]
    assert ev[0]["value_before"]["D"] == pytest.approx(0.04, abs=0.003)
    assert ev[0]["value_after"]["D"] == pytest.approx(0.0, abs=0.004)


def test_no_alarm_on_healthy_rotors_at_the_design_arl0():
    # 3 parameter sets x 17 noise seeds = 51 healthy streams of 15 000 samples
    counted = 0
    for name, rotor in HEALTHY_ROTORS.items():
        clean = healthy(name)
        for seed in range(17):
            mon = Monitor(ip=rotor["ip"])
            ev = [e for e in mon.update(clean.with_noise(NOISE, seed=100 + seed).data) if e["event"] != "status"]
            assert ev == [], (name, seed, ev)
            counted += sum(mon.counted_blocks.values())
    assert counted > 51 * 40  # the CUSUMs did run (identifiable blocks), they were not idle


# ----------------------------------------------------------------- state
def test_resume_after_restore_equals_uninterrupted_run(crack_04, tmp_path):
    data = crack_04.with_noise(NOISE, seed=4).data
    whole = Monitor(status_every=20.0)
    ev_whole = whole.update(data)
    first = Monitor(status_every=20.0)
    split = 6301  # not on a block boundary
    ev = first.update(data[:split])
    first.save(tmp_path / "state.npz")
    resumed = Monitor.load(tmp_path / "state.npz")
    for a in range(split, len(data), 977):  # other chunk sizes too
        ev += resumed.update(data[a : a + 977])
    assert json.dumps(ev) == json.dumps(ev_whole)
    for k, v in whole._arrays.items():
        np.testing.assert_array_equal(resumed._arrays[k], v, err_msg=k)
    assert any(e["event"] == "appeared" for e in ev)


def test_bad_chunk_leaves_the_state_unchanged(crack_04):
    data = crack_04.data[:5000].copy()
    mon = Monitor()
    mon.update(data[:3000])
    before = {k: v.copy() for k, v in mon._arrays.items()}
    bad = data[3000:].copy()
    bad[17, 5] = math.nan
    with pytest.raises(MeasurementError, match=r"row 17 .*theta_y"):
        mon.update(bad)
    gap = data[3000:].copy()
    gap[5:, 0] += 0.02
    with pytest.raises(MeasurementError, match=r"row 5 .*step"):
        mon.update(gap)
    for k, v in before.items():
        np.testing.assert_array_equal(mon._arrays[k], v, err_msg=k)


def test_sliding_window_downdate_equals_the_window_refit():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(60, 5))
    R = np.linalg.qr(A, mode="r")
    R = R * np.sign(np.diag(R))[:, None]
    for i in range(20):
        assert downdate_row(R, A[i, :4], A[i, 4])
    ref = np.linalg.qr(A[20:], mode="r")
    np.testing.assert_allclose(R.T @ R, ref.T @ ref, rtol=1e-10, atol=1e-10)
    assert (np.diag(R) >= 0).all()


def test_sliding_window_monitor_finds_the_crack(crack_04):
    _, ev = _events(crack_04, 1, window=2000)
    assert [(e["event"], e["effect"]) for e in ev] == [("appeared", "asymmetry")]
    assert 250.0 <= ev[0]["t_alarm"] <= 256.0


# ----------------------------------------------------------------- streams and the command
def test_stream_reader_equals_the_loader_and_names_a_bad_line(tmp_path, crack_04):
    path = tmp_path / "run.csv"
    crack_04.slice_time(0, 40).to_file(path)
    chunks = list(StreamReader(path, chunk_bytes=4096))
    assert len(chunks) > 3
    np.testing.assert_array_equal(np.concatenate(chunks), load_measurements(path).data)
    lines = path.read_text().splitlines()
    lines[1500] = lines[1500].replace(",", ",x", 1)
    path.write_text("\n".join(lines) + "\n")
    got = []
    with pytest.raises(MeasurementError, match=r"line 1501, column 'phi': 'x"):
        for c in StreamReader(path, chunk_bytes=4096):
            got.append(c)
    assert sum(len(c) for c in got) == 1499  # every row before the bad line was handed out


def test_read_ahead_keeps_order_then_the_error_and_lets_go_early(tmp_path, crack_04):
    path = tmp_path / "run.csv"
    crack_04.slice_time(0, 40).to_file(path)
    direct = list(StreamReader(path, chunk_bytes=4096))
    ahead = list(read_ahead(StreamReader(path, chunk_bytes=4096), depth=3))
    assert len(ahead) == len(direct)
    for a, b in zip(ahead, direct, strict=True):
        np.testing.assert_array_equal(a, b)
    # a bad line: every row before it first, then the reader's error, in the caller's thread
    lines = path.read_text().splitlines()
    lines[1500] = lines[1500].replace(",", ",x", 1)
    path.write_text("\n".join(lines) + "\n")
    got = []
    with pytest.raises(MeasurementError, match=r"line 1501, column 'phi': 'x"):
        for c in read_ahead(StreamReader(path, chunk_bytes=4096)):
            got.append(c)
    assert sum(len(c) for c in got) == 1499

    # a consumer that stops early releases the reader thread, even one that never ends
    def endless():
        k = 0
        while True:
            k += 1
            yield k

    gen = read_ahead(endless(), depth=2)
    assert [next(gen) for _ in range(5)] == [1, 2, 3, 4, 5]
    gen.close()
    time.sleep(0.5)
    assert not any(t.name == "rotor-id-reader" and t.is_alive() for t in threading.enumerate())


def test_angles_only_stream_estimates_the_rates_like_the_loader(tmp_path, crack_04):
    path = tmp_path / "angles.csv"
    d = crack_04.data[:3000]
    np.savetxt(path, d[:, [0, 1, 4, 5]], delimiter=",", header="t,phi,theta_x,theta_y", comments="", fmt="%.17g")
    chunks = list(StreamReader(path, chunk_bytes=8192))
    np.testing.assert_allclose(np.concatenate(chunks), load_measurements(path).data, rtol=0, atol=1e-12)


def _cli(args, **kw):
    return subprocess.run([sys.executable, "-m", "rotor_env.cli", "monitor", *args], capture_output=True,
                          text=True, timeout=120, **kw)


def test_cli_stdin_and_follow(tmp_path):
    # the example (Table-1 rotor, D 0.03 -> 0.04 at t = 250, noise-free), piped
    meas = with_crack(0.03, 0.04, rotor="table1")
    meas = type(meas)(meas.data, None)
    csv_text_path = tmp_path / "run.csv"
    meas.to_file(csv_text_path)
    text = csv_text_path.read_text()
    out = _cli(["-", "--json-lines"], input=text)
    assert out.returncode == 0, out.stderr
    ev = [json.loads(x) for x in out.stdout.splitlines()]
    alarms = [e for e in ev if e["event"] in ("appeared", "changed", "disappeared")]
    assert [(e["event"], e["effect"]) for e in alarms] == [("changed", "asymmetry")]
    assert 248.0 <= alarms[0]["t_onset"] <= 250.0 <= alarms[0]["t_alarm"] <= 256.0
    assert ev[-1]["event"] == "summary" and ev[-1]["samples"] == len(meas)
    assert any(e["event"] == "status" for e in ev)
    # --follow: start on the first rows, append the rest while it runs
    lines = text.splitlines(keepends=True)
    live = tmp_path / "live.csv"
    live.write_text("".join(lines[:5001]))
    proc = subprocess.Popen([sys.executable, "-m", "rotor_env.cli", "monitor", str(live), "--follow",
                             "--idle-exit", "4", "--json-lines", "--status-every", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.0)
    with open(live, "a") as fh:
        fh.write("".join(lines[5001:]))
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    summary = json.loads(stdout.splitlines()[-1])
    assert summary["samples"] == len(meas) and summary["alarms"] == 1


def test_cli_malformed_line_mid_stream(tmp_path, crack_04):
    path = tmp_path / "bad.csv"
    crack_04.slice_time(0, 100).to_file(path)
    lines = path.read_text().splitlines(keepends=True)
    lines[3000] = "1,2,3\n"
    path.write_text("".join(lines))
    out = _cli([str(path), "--json-lines"])
    assert out.returncode == 2
    assert f"{path}, line 3001: 3 fields, but the header has 10" in out.stderr
    ev = [json.loads(x) for x in out.stdout.splitlines()]
    assert ev[-2]["event"] == "error" and ev[-1]["event"] == "summary"
    assert ev[-1]["samples"] == 2999  # the state up to the bad line is kept
