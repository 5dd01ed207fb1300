"""The keyphasor angle's error as what it is: one smooth curve, not white noise.

The spin spline through the pulses (:func:`~rotor_env.measurements.keyphasor.spin_fit`) averages
their timing jitter, and what is left of it is a curve in the spline's own space: neighbouring
rows of an order-tracked table carry nearly the same angle error, and every large vector moves
with it.  ``SpinFit.error_basis`` says that curve's covariance; the 1X vectors' comparisons of
two fits (:func:`~rotor_env.diagnosis.from_vectors._misfit`) read the residual against it.
References: a Monte Carlo of jittered pulses, the dense generalised-least-squares formula with
``numpy.linalg.solve``, and foreign records with known truth.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from rotor_env.measurements.keyphasor import spin_fit


def _jittered_run(rng, sigma_t: float, n_turns: int = 600, w0: float = 40.0, accel: float = 25.0):
    """A constant-acceleration spin (rad, s), its pulse times each off by white jitter, and the
    keyphasor angle interpolated between the jittered pulses (what a record carries)."""
    turns = np.arange(1, n_turns + 1)
    true_times = (-w0 + np.sqrt(w0 * w0 + 2 * accel * 2 * math.pi * turns)) / accel
    pulses = true_times + rng.normal(0.0, sigma_t, n_turns)
    t = np.linspace(0.0, true_times[-1] + 0.01, 40000)
    raw = np.interp(t, pulses, 2 * math.pi * turns, left=np.nan, right=np.nan)
    inside = np.isfinite(raw)
    return t[inside], raw[inside], lambda s: w0 * s + 0.5 * accel * s * s


def test_the_error_basis_is_the_smoothed_angles_covariance():
    """Over 300 draws of the pulses' jitter (0.1 ms: a 2.5 kHz keyphasor with a sharp edge; in
    angle 4 mrad at the run's start, 44 at its end), the smoothed angle's error at 40 rows: its
    RMS per row within 15 % of the basis's (read from one draw), and the correlation of rows a
    tenth of the run apart as the basis says (within 0.15); neighbouring rows' errors are far
    from independent (correlation above 0.8)."""
    rng = np.random.default_rng(11)
    t, raw, truth = _jittered_run(rng, 1e-4)
    rows = np.linspace(t[0] + 0.1 * (t[-1] - t[0]), t[-1] - 0.1 * (t[-1] - t[0]), 40)
    fit = spin_fit(t, raw)
    L = fit.error_basis(rows)
    cov = L @ L.T
    errors = []
    for _ in range(300):
        t, raw, truth = _jittered_run(rng, 1e-4)
        f = spin_fit(t, raw)
        e = f.spline(rows) - truth(rows)
        errors.append(e)
    errors = np.array(errors)
    emp = np.cov(errors.T, bias=True) + np.outer(errors.mean(0), errors.mean(0))
    sd, sd_emp = np.sqrt(np.diag(cov)), np.sqrt(np.diag(emp))
    assert np.allclose(sd_emp, sd, rtol=0.15), np.max(np.abs(sd_emp / sd - 1))
    k = 4  # a tenth of the run apart
    corr = np.array([cov[i, i + k] / (sd[i] * sd[i + k]) for i in range(40 - k)])
    corr_emp = np.array([emp[i, i + k] / (sd_emp[i] * sd_emp[i + k]) for i in range(40 - k)])
    assert np.max(np.abs(corr - corr_emp)) < 0.15
    # neighbouring rows (a fortieth of the run apart) carry nearly the same error: not white
    adjacent = np.array([emp[i, i + 1] / (sd_emp[i] * sd_emp[i + 1]) for i in range(39)])
    assert np.min(adjacent) > 0.8, np.min(adjacent)


def _fake_fit(rng, rows=30, probes=2, orders=(1,), p=4):
    pred = rng.normal(size=(rows, probes * len(orders))) + 1j * rng.normal(size=(rows, probes * len(orders)))
    resid = 0.1 * (rng.normal(size=pred.shape) + 1j * rng.normal(size=pred.shape))
    resid[3, 0] = np.nan  # a row the table lacks
    basis = 0.05 * rng.normal(size=(rows, p))
    table = SimpleNamespace(probes=tuple(f"p{i}" for i in range(probes)), phase_error_basis=basis)
    return SimpleNamespace(residual=resid, predicted=pred, table=table, orders=orders)


@pytest.mark.parametrize("orders", [(1,), (1, 2)])
def test_the_misfit_is_the_generalised_least_squares_energy(orders):
    """``_misfit`` against the dense formula ``r' (s^2 I + G G')^-1 r`` (real and imaginary
    parts stacked, ``G`` the vectors' response ``-i n X`` to the angle error along each basis
    column), and ``2 rss / floor^2`` where the table has no basis."""
    from rotor_env.diagnosis.from_vectors import _misfit

    rng = np.random.default_rng(3)
    fit = _fake_fit(rng, orders=orders)
    floor, probe_floor = 0.2, 0.15
    r, X = fit.residual, fit.predicted
    n = np.repeat(np.asarray(orders, float), 2)
    ok = np.isfinite(r)
    rv = np.concatenate([r[ok].real, r[ok].imag])
    G = []
    for L in fit.table.phase_error_basis.T:
        d = -1j * n[None, :] * X * L[:, None]
        G.append(np.concatenate([d[ok].real, d[ok].imag]))
    G = np.array(G).T
    s2 = probe_floor ** 2 / 2
    dense = rv @ np.linalg.solve(s2 * np.eye(len(rv)) + G @ G.T, rv)
    assert _misfit(fit, floor, probe_floor) == pytest.approx(dense, rel=1e-9)
    fit.table.phase_error_basis = None
    assert _misfit(fit, floor, probe_floor) == pytest.approx(2 * np.nansum(np.abs(r) ** 2) / floor ** 2, rel=1e-12)


def _foreign(case: str, seed: int, tmp_path, fs: float):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import foreign_rig as fr

    from rotor_env.measurements.rig import load_rig
    from rotor_env.measurements.waveforms import load_waveforms

    _, _, out = fr.make_record(case, seed, 0.5, fs=fs)
    rig_path, data_path = fr.write_record(tmp_path, case, out["columns"])
    return load_waveforms(data_path, load_rig(rig_path))


def test_a_bow_at_a_coarse_keyphasor_is_not_read_as_runout(tmp_path):
    """The foreign simulator's 9 um bow (seed 26) sampled at 2.5 kHz, its keyphasor a square
    notch (each pulse timed to 0.4 ms): the 1X vectors' angle error, 0.26 deg RMS, is one smooth
    curve.  Counted as white noise in the floor, runout fitted 21 noise variances better than
    the bow and was named; read as a curve, the bow fits better and is named (with a 20 kHz
    keyphasor's angle the same record names the bow either way)."""
    from rotor_env.diagnosis.from_vectors import BOW, diagnose_vectors

    record = _foreign("shaft_bow", 26, tmp_path, 2500.0)
    table = record.vectors((1,))
    assert table.phase_error_basis is not None and math.degrees(table.phase_error_rad) > 0.15
    vd = diagnose_vectors(table, ip=record.rig.ip)
    assert BOW in vd.missing, (vd.missing, vd.undecidable)


def test_runout_at_a_coarse_keyphasor_is_not_read_as_a_bow(tmp_path):
    """The control: the same simulator's probe runout (seed 26, no bow) at 2.5 kHz: no bow."""
    from rotor_env.diagnosis.from_vectors import BOW, diagnose_vectors

    record = _foreign("runout", 26, tmp_path, 2500.0)
    vd = diagnose_vectors(record.vectors((1,)), ip=record.rig.ip)
    assert BOW not in vd.missing, vd.missing
