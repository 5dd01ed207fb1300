"""The probes' slowly moving mean: the shaft's centreline on its bearings, thermal drift.

References: signals with known truth (a sweep's 1X with a drift added), ``numpy.linalg.lstsq``
for the spline projection, and simulated rig records (``simulate_rig(drift=...)``) diagnosed
with the baseline and, as the control that shows the check can fail, without it.  Before the
baseline, a ±2 um linear drift made a healthy rig ``unexplained`` (2.5x its floor) and a
1 um random walk had a ``nonlinear_stiffness`` named; taken out of the data alone (not
fitted with the model), a cracked shaft's own mean deflection under its load went with it
and the load came out 30 % off.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from rotor_env.measurements.drift import drift_knot_spacing, probe_drift, turn_means

FS = 2500.0


def _sweep(seconds: float = 10.0, f0: float = 5.0, f1: float = 50.0, coast: bool = False):
    t = np.arange(0.0, seconds, 1.0 / FS)
    speed = f0 + (f1 - f0) * t / seconds
    if coast:
        speed = speed[::-1]
    phi = 2 * math.pi * np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) / FS)])
    return t, phi, speed


@pytest.mark.parametrize("coast", [False, True])
def test_the_mean_over_two_turns_takes_every_order_and_half_order_of_the_shaft(coast):
    t, phi, speed = _sweep(coast=coast)
    x = 3.0 + sum(50.0 / k * np.cos(k * phi + k) for k in (1, 2, 3, 5)) + 20.0 * np.sin(0.5 * phi + 0.3)
    m = turn_means(phi, x)
    # trapezoidal integration of orders of a few samples per turn: exact to the step's error
    assert np.max(np.abs(m - 3.0)) < 0.02
    # against the mean of the samples themselves over two whole turns, at constant speed
    phi_c = 2 * math.pi * 20.0 * t
    xc = 1.0 + np.cos(phi_c) + np.sin(3 * phi_c)
    i = len(t) // 2
    per = int(FS / 20.0)
    ref = np.mean(xc[i - per:i + per])
    assert turn_means(phi_c, xc)[i] == pytest.approx(ref, abs=1e-3)
    assert turn_means(phi[:10], x[:10]) is None  # fewer than two turns


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_slow_drift_under_a_large_1x_is_recovered(seed):
    rng = np.random.default_rng(seed)
    t, phi, speed = _sweep(coast=bool(seed % 2))
    r = speed / 25.0
    resp = 60.0 * r * r / (1 - r * r + 0.06j * r)
    drift = 4.0 * np.sin(2 * math.pi * t / 17.0 + seed) + 1.5 * (t / t[-1]) ** 2
    x = np.real(resp * np.exp(1j * phi)) + drift + rng.normal(0, 0.5, len(t))
    rec = SimpleNamespace(t=t, phi=phi, speed=2 * math.pi * speed, readings={"x": x})
    got = probe_drift(rec)
    truth = drift - drift.mean()
    assert np.sqrt(np.mean((got.baseline["x"] - truth) ** 2)) < 0.05
    assert got.peak_to_peak["x"] == pytest.approx(np.ptp(truth), rel=0.03)
    # four turns of the slowest speed (the 2 % quantile: 5.9 Hz) between knots
    assert got.knot_spacing_s == pytest.approx(4.0 / np.quantile(speed, 0.02), rel=1e-9)
    # and next to nothing of the 1X itself where there is no drift: a tenth of the probe
    # noise at most, at the slow end, where the speed changes by a third during two turns
    # (the turn means of a sweeping sinusoid are not quite zero); 0.02 of it on average
    quiet = probe_drift(SimpleNamespace(t=t, phi=phi, speed=2 * math.pi * speed,
                                        readings={"x": np.real(resp * np.exp(1j * phi))}))
    assert np.max(np.abs(quiet.baseline["x"])) < 0.05
    assert np.sqrt(np.mean(quiet.baseline["x"] ** 2)) < 0.01


def test_a_baseline_is_relevant_above_a_tenth_of_the_noise():
    from rotor_env.measurements.drift import DRIFT_RELEVANT, ProbeDrift

    t = np.linspace(0.0, 1.0, 1001)
    ramp = np.sqrt(3.0) * (2.0 * t - 1.0)  # unit RMS
    drift = ProbeDrift(t=t, baseline={"x": 0.05 * ramp, "y": 0.3 * ramp}, knot_spacing_s=0.1, slowest_rpm=600.0)
    assert drift.rms["y"] == pytest.approx(0.3, rel=1e-2)
    assert drift.relevant({"x": 1.0, "y": 0.3 / DRIFT_RELEVANT * 0.9})
    assert not drift.relevant({"x": 1.0, "y": 0.3 / DRIFT_RELEVANT * 1.1})
    assert not ProbeDrift(t=t, baseline={"x": ramp}, knot_spacing_s=0.0, slowest_rpm=0.0).relevant({"x": 0.01})


def test_the_knot_spacing_is_bounded_by_the_samples_and_the_record():
    t = np.arange(0.0, 2.0, 1e-3)
    assert drift_knot_spacing(t, np.full(len(t), 2 * math.pi * 100.0)) == pytest.approx(0.04)
    assert drift_knot_spacing(t, np.full(len(t), 2 * math.pi * 1e4)) == pytest.approx(32e-3)
    assert drift_knot_spacing(t, np.zeros(len(t))) == pytest.approx(t[-1])
    assert drift_knot_spacing(t[:1], np.ones(1)) == 0.0


def test_the_baseline_projection_is_least_squares_on_the_splines():
    """The fit's projection against ``numpy.linalg.lstsq`` on the dense spline design."""
    from rotor_env.diagnosis.output_error import ShootingGrid, _baseline_fit

    rng = np.random.default_rng(5)
    t = np.arange(0.0, 400.0, 0.1)
    phi = 0.5 * t + 0.001 * t * t
    th = rng.normal(0, 1.0, (len(t), 2))
    grid = ShootingGrid.from_arrays(t, phi, 0.5 + 0.002 * t, th[:, 0], th[:, 1], 0.0, noise_std=1.0,
                                    baseline_spacing=37.0)
    B, _ = grid.baseline_basis
    r = rng.normal(0, 1.0, (int(grid.inside.sum()), 3))
    ref = B.toarray() @ np.linalg.lstsq(B.toarray(), r, rcond=None)[0]
    np.testing.assert_allclose(_baseline_fit(grid, r), ref, atol=1e-9)
    assert B.shape[1] == 3 + int(math.floor((grid.t[grid.inside][-1] - grid.t[grid.inside][0]) / 37.0))
    with pytest.raises(ValueError, match="baseline_spacing"):
        ShootingGrid.from_arrays(t, phi, 0.5 + 0.002 * t, th[:, 0], th[:, 1], 0.0, baseline_spacing=-1.0)


@pytest.fixture(scope="module")
def one_plane(tmp_path_factory):
    from rotor_env.measurements.rig import load_rig

    path = tmp_path_factory.mktemp("rig") / "rig.yaml"
    path.write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
    return load_rig(path)


def _diagnose(rig, run, tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.measurements.waveforms import load_waveforms

    path = tmp_path / "run.parquet"
    pq.write_table(pa.table(run.file_columns()), path)
    return diagnose_rig(load_waveforms(path, rig), candidates=("asymmetry", "nonlinear_stiffness", "rub"))


def test_a_healthy_rig_whose_centreline_moves_is_explained(one_plane, tmp_path, monkeypatch):
    """The centreline lifting 6 um with the speed squared and each gap drifting by up to 3 um:
    with the baseline fitted, the healthy rotor is explained at its floor and nothing is
    named; without it (the control), the same record is not explained."""
    from rotor_env.diagnosis import from_rig
    from rotor_env.params import RotorParams
    from rotor_env.rig_simulation import simulate_rig

    p = RotorParams(ip=0.0, values={"c": 0.05, "tau": 0.005, "beta": 0.4},
                    effects=("stiffness", "viscous_damping", "unbalance"))
    run = simulate_rig(one_plane, p, natural_rpm=1800.0, rpm_from=600.0, rpm_to=3000.0, rpm_per_s=300.0,
                       sample_rate=2500.0, noise=0.5, drift=6.0, seed=3)
    result = _diagnose(one_plane, run, tmp_path)
    d = result.to_dict()
    assert d["verdict"] == "explained" and not d["missing"], (d["verdict"], d["missing"])
    assert d["rms_after"] / d["noise_floor"] < 1.05
    assert any("slowly moving mean" in n for n in d["notes"])
    # the centreline plot among the record's figures; its path moves by what was drawn: the
    # lift (5.8 um from 600 to 3000 rpm) and each gap's thermal drift (under 3 um)
    written = result.save_figures(tmp_path / "figs")
    assert (tmp_path / "figs" / "centreline.png") in written
    xy = probe_drift(result.record).centreline(one_plane)["A"]
    assert 5.8 - 3.0 < float(np.max(np.hypot(*(xy - xy[0]).T))) < 5.8 + 3.0
    # the same rotor without drift: the baseline is not fitted (under a tenth of the noise)
    still = simulate_rig(one_plane, p, natural_rpm=1800.0, rpm_from=600.0, rpm_to=3000.0, rpm_per_s=300.0,
                         sample_rate=2500.0, noise=0.5, seed=3)
    quiet = _diagnose(one_plane, still, tmp_path).to_dict()
    assert quiet["verdict"] == "explained" and not quiet["missing"]
    assert any("slowly moving mean" in n and "not fitted" in n for n in quiet["notes"])
    # the control: no baseline
    monkeypatch.setattr(from_rig, "drift_knot_spacing", lambda t, speed: 0.0)
    bare = _diagnose(one_plane, run, tmp_path).to_dict()
    assert bare["rms_after"] / bare["noise_floor"] > 1.5


def test_simulate_rig_refuses_a_drift_that_is_not_a_number(one_plane):
    from rotor_env.params import RotorParams
    from rotor_env.rig_simulation import simulate_rig

    p = RotorParams(ip=0.0, values={"c": 0.05, "tau": 0.005}, effects=("stiffness", "viscous_damping", "unbalance"))
    with pytest.raises(ValueError, match="drift"):
        simulate_rig(one_plane, p, rpm_from=600.0, rpm_to=900.0, rpm_per_s=300.0, sample_rate=1000.0,
                     drift=float("nan"))


def test_the_centreline_is_the_planes_mean_position_from_its_probes(one_plane):
    """Probes at +45 and -45 deg reading a shaft whose mean position moves along a known
    path (a lift with the speed squared, turning across the clearance) under a 1X: the
    centreline is that path (its mean removed), and its plot is labelled in the rig's units."""
    t, phi, speed = _sweep()
    lift = (speed / speed.max()) ** 2
    u_true, v_true = 12.0 * lift * np.cos(0.3 + lift), 12.0 * lift * np.sin(0.3 + lift)
    readings = {}
    for p in one_plane.probes:
        c, s = math.cos(p.angle), math.sin(p.angle)
        readings[p.name] = (u_true * c + v_true * s) + 80.0 * np.cos(phi - p.angle)
    drift = probe_drift(SimpleNamespace(t=t, phi=phi, speed=2 * math.pi * speed, readings=readings))
    xy = drift.centreline(one_plane)["A"]
    np.testing.assert_allclose(xy[:, 0], u_true - u_true.mean(), atol=0.05)
    np.testing.assert_allclose(xy[:, 1], v_true - v_true.mean(), atol=0.05)
    from rotor_env.plots import plot_centreline

    fig = plot_centreline(60.0 * speed, drift.centreline(one_plane), unit=one_plane.amp_unit)
    ax = fig.axes[0]
    assert "um" in ax.get_xlabel() and "um" in ax.get_ylabel()
    assert "rpm" in fig.axes[1].get_ylabel()  # the speed's colour bar
    import matplotlib.pyplot as plt

    plt.close(fig)
