"""What the instruments add: lines at fixed frequencies (mains hum) and runout above 2X.

References: signals with known truth (synthetic sweeps, and the rig suite's simulated
records with the artefact added to the written file).  A healthy rig with 1 um of 50 Hz hum
was diagnosed with a ``second_mode`` (its order-tracked 1X turns once per revolution of
beat with the hum), and a crack with hum went unnamed; a scratch under the probes
(harmonics to 6X) left a healthy record ``unexplained``.
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from rotor_env.measurements.artefacts import find_lines, runout_harmonics

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

FS = 5000.0


def _sweep(seconds: float = 10.0, f0: float = 8.0, f1: float = 54.0):
    """A run-up's time, spin angle and speed (Hz), with a forward 1X resonance at 30 Hz."""
    t = np.arange(0.0, seconds, 1.0 / FS)
    speed = f0 + (f1 - f0) * t / seconds
    phi = 2 * math.pi * (f0 * t + 0.5 * (f1 - f0) / seconds * t * t)
    r = speed / 30.0
    h = r * r / (1 - r * r + 2j * 0.02 * r)  # unbalance response
    resp = 40.0 * h
    return t, phi, speed, resp


def _probes(resp, phi, rng, noise=0.5):
    x = np.real(resp * np.exp(1j * phi)) + rng.normal(0, noise, len(phi))
    y = np.real(resp * np.exp(1j * (phi - math.pi / 2))) + rng.normal(0, noise, len(phi))
    return x, y


@pytest.mark.parametrize("seed", [0, 1])
def test_a_mains_line_is_found_at_its_frequency_amplitude_and_phase(seed):
    rng = np.random.default_rng(seed)
    t, phi, speed, resp = _sweep()
    x, y = _probes(resp, phi, rng)
    hum = {"x": (1.0, 0.3), "y": (0.7, 1.2)}
    x = x + hum["x"][0] * np.cos(2 * math.pi * 50.0 * t + hum["x"][1]) + 0.3 * np.cos(2 * math.pi * 150.0 * t)
    y = y + hum["y"][0] * np.cos(2 * math.pi * 50.0 * t + hum["y"][1]) + 0.3 * np.cos(2 * math.pi * 150.0 * t)
    lines = find_lines(t, speed, {"x": x, "y": y})
    freqs = sorted(ln.frequency_hz for ln in lines)
    assert len(freqs) == 2, freqs
    assert abs(freqs[0] - 50.0) < 0.005 and abs(freqs[1] - 150.0) < 0.005
    line = min(lines, key=lambda ln: ln.frequency_hz)
    for nm, (amp, phase) in hum.items():
        assert abs(line.amplitude[nm] / amp - 1.0) < 0.03
        # the removed wave is the hum itself, to a few per cent of it at every sample
        truth = amp * np.cos(2 * math.pi * 50.0 * t + phase)
        assert np.sqrt(np.mean((line.wave(t, nm) - truth) ** 2)) < 0.05 * amp


def test_the_shafts_orders_and_a_random_resonance_are_not_lines():
    """A shaft at constant speed keeps its 1X, 2X and 3X at one frequency each: they are the
    rotor's, never a line.  A lightly damped mode rung by broadband forces is a narrow peak
    too, with a new phase in every stretch: not a deterministic line either."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(3)
    t = np.arange(0.0, 10.0, 1.0 / FS)
    speed = np.full(len(t), 30.0)
    phi = 2 * math.pi * 30.0 * t
    x = 80 * np.cos(phi) + 5 * np.cos(2 * phi + 1) + 1.0 * np.cos(3 * phi + 2) + rng.normal(0, 0.5, len(t))
    y = 80 * np.sin(phi) + 5 * np.sin(2 * phi + 1) + 1.0 * np.sin(3 * phi + 2) + rng.normal(0, 0.5, len(t))
    assert find_lines(t, speed, {"x": x, "y": y}) == []
    # a resonator at 75 Hz, damping ratio 0.3 %, driven by white noise (about 2 um rms)
    w0, zeta, dt = 2 * math.pi * 75.0, 0.003, 1.0 / FS
    a1, a2 = 2 * math.exp(-zeta * w0 * dt) * math.cos(w0 * dt), -math.exp(-2 * zeta * w0 * dt)
    ring = lfilter([1.0], [1.0, -a1, -a2], rng.normal(0, 1.0, len(t)))
    ring *= 2.0 / ring.std()
    assert find_lines(t, speed, {"x": x + ring, "y": y}) == []


def test_runout_above_2x_is_taken_only_where_it_is_the_same_at_every_speed():
    """A scratch under probe x (3X to 6X, the same at every speed) is taken, each order within
    3 %; probe y's 3X, large at slow roll and gone at speed (a breathing crack's slow-roll 3X
    under its static load), is the rotor's and stays."""
    rng = np.random.default_rng(5)
    t, phi, speed, resp = _sweep()
    x, y = _probes(resp, phi, rng)
    scratch = {n: 1.5 / n * np.exp(1j * 0.7 * n) for n in range(3, 7)}
    for n, v in scratch.items():
        x = x + np.real(v * np.exp(1j * n * phi))
    fade = np.clip(1.0 - (speed - 8.0) / 15.0, 0.0, 1.0)  # gone above 23 Hz
    y = y + 1.0 * fade * np.cos(3 * phi + 0.4)
    got = runout_harmonics(t, phi, speed, {"x": x, "y": y})
    assert {(h.probe, h.order) for h in got} == {("x", n) for n in scratch}
    for h in got:
        assert abs(h.vector - scratch[h.order]) < 0.03 * abs(scratch[h.order])


def _suite_record(tmp_path, fault: str, add):
    """A rig suite record (0.5 um) with ``add(columns)`` applied to the written file."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    import rig_suite as rs

    from rotor_env.measurements.rig import load_rig
    from rotor_env.measurements.waveforms import load_waveforms

    spec = rs.RecordSpec(index=0, seed=7, fault=fault, noise_um=0.5, rig="one-plane um", natural_rpm=1800.0,
                         zeta=0.02, sample_rate=5000.0, direction="run-up")
    rig_path, data_path, truth = rs.make_record(spec, tmp_path)
    tab = pq.read_table(data_path)
    cols = {k: tab[k].to_numpy().copy() for k in tab.column_names}
    add(cols)
    pq.write_table(pa.table(cols), data_path)
    return rs, load_waveforms(data_path, load_rig(rig_path)), truth


def _hum_and_scratch(cols):
    t = cols["t"]
    kp = cols["kp"]
    # the shaft angle from the notch's falling edges, for the scratch's pattern
    low = 0.5 * (kp.min() + kp.max())
    edges = np.flatnonzero((kp[1:] < low) & (kp[:-1] >= low)) + 1
    phi = np.interp(np.arange(len(t)), edges, 2 * math.pi * np.arange(len(edges)))
    for j, p in enumerate(("x", "y")):
        cols[p] = (cols[p] + 1.0 * np.sin(2 * math.pi * 50.0 * t + j) + 0.3 * np.sin(2 * math.pi * 150.0 * t)
                   + sum(1.5 / n * np.cos(n * (phi + j * math.pi / 2) + 0.7 * n) for n in range(3, 7)))


def test_a_healthy_rig_with_hum_and_a_scratch_is_healthy(tmp_path):
    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.diagnosis.from_vectors import diagnose_vectors

    _, record, _ = _suite_record(tmp_path, "healthy", _hum_and_scratch)
    # the artefacts matter: the raw record's 1X vectors read the hum as another mode
    assert "second_mode" in diagnose_vectors(record.vectors((1,)), ip=record.rig.ip).missing
    d = diagnose_rig(record)
    out = d.to_dict()
    assert out["missing"] == [] and out["verdict"] == "explained", (out["verdict"], out["missing"])
    notes = " ".join(d.record.notes)

    found = sorted(float(f) for f in re.findall(r"a line at ([0-9.]+) Hz", notes))
    assert len(found) == 2 and abs(found[0] - 50.0) < 0.005 and abs(found[1] - 150.0) < 0.005, found
    assert "runout above 2X" in notes
    assert 0.95 < out["rms_ratio_after"] < 1.05


def test_a_crack_under_hum_and_a_scratch_is_named_with_its_size_and_axis(tmp_path):
    from rotor_env.diagnosis.from_rig import diagnose_rig

    rs, record, truth = _suite_record(tmp_path, "asymmetry", _hum_and_scratch)
    out = diagnose_rig(record).to_dict()
    assert out["missing"] == ["asymmetry"], out["rejected"]
    err = rs.crack_errors("asymmetry", truth["fault"], out["parameters"])
    assert err["size_error"] < 0.05 and err["axis_error_deg"] < 5.0, err


def test_the_rig_simulators_artefacts_are_found_as_simulated(tmp_path):
    """``simulate_rig(lines=, scratch=)`` (the suite's ``--artefacts``) against the finder: the
    line's amplitude on every probe within 3 %, the scratch's orders 3-8 as its pattern
    (:data:`~rotor_env.rig_simulation.SCRATCH_ORDERS` times its height)."""
    import json

    from rotor_env.measurements.rig import load_rig
    from rotor_env.measurements.waveforms import load_waveforms
    from rotor_env.params import RotorParams
    from rotor_env.rig_simulation import SCRATCH_ORDERS, simulate_rig

    rig_path = tmp_path / "rig.json"
    rig_path.write_text(json.dumps({"keyphasor": "kp", "probes": {"x": 45, "y": -45}, "units": {"displacement": "um"}}))
    rig = load_rig(rig_path)
    params = RotorParams(ip=0.0, values={"k": 1.0, "c": 0.04, "tau": 0.005, "beta": 0.7},
                         effects=("stiffness", "viscous_damping", "unbalance"))
    run = simulate_rig(rig, params, natural_rpm=1650.0, rpm_from=400.0, rpm_to=3000.0, rpm_per_s=300.0,
                       sample_rate=5000.0, noise=0.5, lines=((60.0, 0.8),), scratch=2.0, seed=11)
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.table(run.file_columns()), tmp_path / "run.parquet")
    record = load_waveforms(tmp_path / "run.parquet", rig)
    lines = find_lines(record.t, record.speed / (2 * math.pi), record.readings)
    assert len(lines) == 1 and abs(lines[0].frequency_hz - 60.0) < 0.005
    for amp in lines[0].amplitude.values():
        assert abs(amp / 0.8 - 1.0) < 0.03
    # the scratch: each order's size against its pattern, within four of the median's standard
    # errors (0.5 um of noise on a 0.16 um order: about 2 % each)
    got = {(h.probe, h.order): h for h in runout_harmonics(record.t, record.phi, record.speed, record.readings)}
    for probe in ("x", "y"):
        for n in range(3, 9):
            h = got[probe, n]
            assert abs(abs(h.vector) - 2.0 * SCRATCH_ORDERS[n]) < 4.0 * h.std_error + 0.01 * abs(h.vector), (probe, n)
