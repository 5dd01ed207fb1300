"""Dimensionless angle records whose rates are estimated: decided on the output error
(rotor_env.diagnosis.from_angles), against simulations with known truth.

Issue 24's case: angles only, AR(1) noise and quantisation, the rates differentiated by
the loader -- a crack D = 0.03 must be named with its size and axis, a healthy rotor must
not be given an effect, and the floor must be the noise's own level although that noise
is coloured."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rotor_env.diagnosis import diagnose
from rotor_env.diagnosis.from_angles import AngleDiagnosis, needs_output_error
from rotor_env.diagnosis.output_error import ShootingGrid, noise_ar1_high_band
from rotor_env.measurements.files import load_measurements
from rotor_env.params import RotorParams
from rotor_env.simulator import RunUp, Simulator


def _ar1(rng: np.random.Generator, n: int, std: float, rho: float) -> np.ndarray:
    """Stationary AR(1) noise of marginal standard deviation ``std``."""
    from scipy.signal import lfilter

    e = rng.normal(0.0, std * math.sqrt(1 - rho * rho), n)
    e[0] = rng.normal(0.0, std)
    return lfilter([1.0], [1.0, -rho], e)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.8])
def test_ar1_noise_level_and_correlation_from_the_band_above_the_response(rho):
    rng = np.random.default_rng(11)
    n, dt = 40_000, 0.02
    t = np.arange(n) * dt
    signal = 0.05 * np.sin(0.9 * t) + 0.01 * np.sin(1.7 * t)
    noise = _ar1(rng, n, 5e-4, rho)
    std, rho_hat = noise_ar1_high_band(signal + noise, dt, 4 * 1.7 / (2 * math.pi))
    assert std == pytest.approx(float(np.std(noise)), rel=0.05)
    assert rho_hat == pytest.approx(rho, abs=0.03)


@pytest.mark.parametrize("rho", [0.0, 0.7])
def test_grid_noise_of_decimated_ar1_noise_is_its_measured_std(rho):
    """The grid's noise level (the FIR's gain for AR(1) noise) against the standard
    deviation of the same noise decimated by the same filter."""
    rng = np.random.default_rng(5)
    n, dt = 60_000, 0.02
    t = np.arange(n) * dt
    x = _ar1(rng, n, 1e-3, rho)
    y = _ar1(rng, n, 1e-3, rho)
    g = ShootingGrid.from_arrays(t, 1.5 * t, np.full(n, 1.5), x, y, 0.0, noise_std=1e-3, noise_rho=rho)
    assert g.decimation > 1
    assert g.noise_std == pytest.approx(float(np.std(g.y)), rel=0.03)


def _angle_file(path, extra: dict, effects: tuple[str, ...], *, ip: float, rho: float, seed: int):
    vals = {"tau": 0.005, "beta": 0.3, "c": 0.05, "k": 1.0, **extra}
    p = RotorParams(ip=ip, effects=("stiffness", "unbalance", "viscous_damping", *effects), values=vals)
    m = Simulator(p).run(t_end=1.3 / 0.004, dt=0.02, run_up=RunUp(rate=0.004, speed0=0.4))
    rng = np.random.default_rng(seed)
    q = 1e-4  # the angle sensor's resolution
    thx = np.round((m.theta_x + _ar1(rng, len(m.t), 5e-4, rho)) / q) * q
    thy = np.round((m.theta_y + _ar1(rng, len(m.t), 5e-4, rho)) / q) * q
    phi = np.round(m.phi / (2 * math.pi / 1024)) * (2 * math.pi / 1024)  # a 1024-line encoder
    np.savetxt(path, np.column_stack([m.t, phi, thx, thy]), delimiter=",", header="t,phi,theta_x,theta_y",
               comments="", fmt="%.10g")
    return path


@pytest.mark.parametrize(("ip", "rho"), [(0.0, 0.5), (0.4, 0.0)])
def test_a_crack_in_noisy_angles_is_named_with_size_and_axis(tmp_path, ip, rho):
    """D = 0.03 at 34.4 deg from the notch, rates estimated, ip not given: named by the output
    error with D within 5 % and the axis within 5 deg (ip read off the profile)."""
    f = _angle_file(tmp_path / "crack.csv", {"D": 0.03, "D_axis": 0.6}, ("asymmetry",), ip=ip, rho=rho, seed=2)
    meas = load_measurements(f)
    assert needs_output_error(meas)
    d = diagnose(meas)
    assert isinstance(d, AngleDiagnosis)
    assert d.missing == ["asymmetry"] and d.verdict == "explained_after_adding"
    p = d.diagnosis.after.parameters("asymmetry")
    D, axis = p["D"], p["D_axis"]
    if D < 0:
        D, axis = -D, (axis + math.pi / 2) % math.pi
    assert D == pytest.approx(0.03, rel=0.05)
    assert abs((math.degrees(axis) - math.degrees(0.6) + 90) % 180 - 90) < 5.0
    assert d.ip == pytest.approx(ip, abs=0.03)
    out = d.to_dict()
    assert out["kind"] == "angles" and 0.9 < out["rms_ratio_after"] < 1.1


def test_a_healthy_rotor_in_coloured_noise_is_explained_with_nothing_added(tmp_path):
    """AR(1) noise (rho 0.7) read as white would put the floor 3x too low and every
    candidate above it; the AR(1) floor keeps the healthy record explained."""
    f = _angle_file(tmp_path / "healthy.csv", {}, (), ip=0.0, rho=0.7, seed=3)
    d = diagnose(load_measurements(f))
    assert isinstance(d, AngleDiagnosis)
    assert d.missing == [] and d.verdict == "explained"
    assert d.diagnosis.rms_ratio_after < 1.1
    assert d.diagnosis.noise_floor * d.diagnosis.probe_factor == pytest.approx(5e-4, rel=0.1)


def test_noise_free_angles_keep_the_equation_error(tmp_path):
    """A simulation written without its rates: the equation error is exact there (no switch)."""
    vals = {"tau": 0.005, "beta": 0.3, "c": 0.05, "k": 1.0}
    p = RotorParams(ip=0.0, effects=("stiffness", "unbalance", "viscous_damping"), values=vals)
    m = Simulator(p).run(t_end=200.0, dt=0.02, run_up=RunUp(rate=0.006, speed0=0.4))
    path = tmp_path / "clean.csv"
    np.savetxt(path, np.column_stack([m.t, m.phi, m.theta_x, m.theta_y]), delimiter=",",
               header="t,phi,theta_x,theta_y", comments="", fmt="%.17g")
    assert not needs_output_error(load_measurements(path))
