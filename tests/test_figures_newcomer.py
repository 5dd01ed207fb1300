"""Figures that do not mislead (issue 25, item 4): the tests read the data the figures draw
(the plotted arrays, the legend's box against the curves), not pixels."""

from __future__ import annotations

import math
import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pytest

from rotor_env import plots as fp  # the drawing
from rotor_env.diagnosis import field  # what it draws, computed


def _circling(n=300):
    """1X vectors through a resonance (lag 0 -> 180 deg), then circling (the free whirl
    beating against 1X after a fast passage): the lag grows on to ~900 deg."""
    speed = np.linspace(0.3, 3.0, n)
    h = 1.0 / (1.0 - speed**2 + 2j * 0.05 * speed)  # lead convention: angle -> -180 deg
    extra = np.where(speed > 1.6, np.radians(400.0) * (speed - 1.6), 0.0)
    return speed, speed**2 * h * np.exp(-1j * extra)


def test_bode_phase_is_continuous_and_model_lies_on_measured():
    speed, X = _circling()
    # the measured lag starts at 359.5 deg, the model's at 2 deg: folded separately, 360 apart
    i0 = int(np.flatnonzero(np.abs(X) > 0.02 * np.abs(X).max())[0])
    meas = X * np.exp(-1j * np.angle(X[i0])) * np.exp(1j * np.radians(0.5))
    model = meas * np.exp(-1j * np.radians(2.5))
    fig = fp.plot_bode(speed, {"x": meas}, {"final model": {"x": model}}, speed_unit="dimensionless")
    try:
        a_ph = fig.axes[1]
        m_ph, mod_ph = (np.asarray(line.get_ydata(), float) for line in a_ph.lines[:2])
        ok = np.isfinite(m_ph) & np.isfinite(mod_ph)
        assert np.nanmax(np.abs(np.diff(m_ph[np.isfinite(m_ph)]))) < 30.0, "the measured phase zig-zags"
        assert np.nanmax(m_ph) > 540.0  # unwrapped on, not folded back into [0, 360)
        np.testing.assert_allclose(mod_ph[ok] - m_ph[ok], 2.5, atol=1e-6)  # lag of the model - measured
        # the lag convention: lag = -angle(X), the first point in [0, 360)
        first = m_ph[np.isfinite(m_ph)][0]
        assert math.isclose(first, 359.5, abs_tol=1e-6)  # -angle(X) of the first point, in [0, 360)
        assert mod_ph[np.isfinite(mod_ph)][0] == pytest.approx(362.0)  # on the measured curve, not at 2
    finally:
        plt.close(fig)


def test_parameter_tracks_marks_from_the_monitors_test_and_truth_dashed():
    """On-line flags marked the crack long before it opened; the monitor's calibrated
    alarms mark it from its onset, and the truth (a step at the crack) is drawn dashed."""
    from rotor_env import Crack, RotorParams, simulate
    from rotor_env.walkthrough import true_coefficients

    params = RotorParams().replace(crack=Crack(250.0, 0.04))
    meas = simulate(params, t_end=300.0, dt=0.01)
    model = ("unbalance", "asymmetry", "viscous_damping", "nonlinear_stiffness", "structural_damping")
    alarms = field.monitor_alarms(meas, model, params.ip)
    assert [a["effect"] for a in alarms] == ["asymmetry"]
    assert 245.0 <= alarms[0]["t_onset"] <= 256.0
    tracks = field.parameter_tracks(meas, model, params.ip, 0.9995, checkpoints=50)
    truth = true_coefficients(params, model, tracks.t)
    fig = fp.plot_parameter_tracks(tracks.t, tracks.coefficients, alarms=alarms, truth=truth, groups=tracks.groups)
    try:
        a_tr, a_sig = fig.axes[:2]
        # the bottom panel: one bar, asymmetry's, from the onset to the end
        names = [tl.get_text() for tl in a_sig.get_yticklabels()]
        bars = [(c.get_paths()[0].vertices[:, 0].min(), c.get_paths()[0].vertices[:, 0].max(),
                 c.get_paths()[0].vertices[:, 1].mean()) for c in a_sig.collections if c.get_paths()]
        assert len(bars) == 1
        x0, x1, y = bars[0]
        assert names[round(y)] == "asymmetry"
        assert x0 == pytest.approx(alarms[0]["t_onset"], abs=0.02) and x1 >= tracks.t[-1] - 0.02
        # the truth: dashed, D a step at t = 250 from 0.03 to 0.04
        dashed = [ln for ln in a_tr.lines if ln.get_linestyle() == "--"]
        steps = [ln for ln in dashed if np.ptp(np.asarray(ln.get_ydata(), float)) > 0]
        assert len(steps) == 1
        x, ytrue = np.asarray(steps[0].get_xdata(), float), np.asarray(steps[0].get_ydata(), float)
        np.testing.assert_allclose(ytrue[x < 250.0], 0.03)
        np.testing.assert_allclose(ytrue[x >= 250.0], 0.04)
        assert len(dashed) == len(tracks.coefficients)  # every coefficient has its truth
    finally:
        plt.close(fig)


@pytest.fixture(scope="module")
def crack_diagnosis():
    from rotor_env import Crack, RotorParams, diagnose, simulate
    from rotor_env.walkthrough import true_coefficients

    params = RotorParams().replace(D=0.0, crack=Crack(250.0, 0.05))
    meas = simulate(params, t_end=300.0, dt=0.02, noise=5e-4, seed=1)
    res = diagnose(meas, ["unbalance", "viscous_damping"], ip=params.ip)
    res.truth = true_coefficients(params, res.model, res.data.meas.t)
    return res


def test_diagnosis_figures_raise_no_user_warnings_and_keep_legends_off_the_curves(crack_diagnosis):
    res = crack_diagnosis
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        figs = res.figures()
    try:
        top = figs["compare"].axes[0]
        figs["compare"].canvas.draw()
        box = top.get_legend().get_window_extent()
        for line in top.lines:
            xy = top.transData.transform(np.column_stack([line.get_xdata(), line.get_ydata()]))
            inside = (xy[:, 0] > box.x0) & (xy[:, 0] < box.x1) & (xy[:, 1] > box.y0) & (xy[:, 1] < box.y1)
            assert not inside.any(), f"the legend covers {line.get_label()!r}"
        # the noise floor band says what it is and its unit
        labels = [t.get_text() for ax in figs["before_after"].axes if ax.get_legend() for t in ax.get_legend().texts]
        band = [lb for lb in labels if "noise floor" in lb]
        assert band and "white-noise RMS" in band[0] and "dimensionless" in band[0]
        # the parameter tracks: the monitor's alarm on asymmetry, none before the crack
        a_sig = figs["parameter_tracks"].axes[1]
        starts = [c.get_paths()[0].vertices[:, 0].min() for c in a_sig.collections if c.get_paths()]
        assert starts and min(starts) >= 240.0, starts
        assert "monitor's calibrated" in a_sig.get_title()
        # the order map: the added asymmetry's mirror of the free whirl, 2 - w_f/Omega, drawn
        # where the residual sits (between 1x and 2x), and said in the legend
        omap = figs["order_map"].axes[0]
        mirror = [ln for ln in omap.lines if "mirrored" in str(ln.get_label())]
        assert "asymmetry" in res.missing and len(mirror) == 1
        speed, branches = res.whirl_model()
        (e, m, s, order), = res._mirrored_whirl()
        w_f = min((np.asarray(w) for w in branches.values() if np.nanmedian(w) > 0), key=np.nanmedian)
        np.testing.assert_allclose(np.asarray(mirror[0].get_xdata(), float),
                                   2 - np.interp(s, speed, w_f) / s, rtol=1e-9)
        assert 1.0 < float(np.median(mirror[0].get_xdata())) < 2.0
        assert "2Ω − ω" in omap.get_legend().get_title().get_text()
    finally:
        for f in figs.values():
            plt.close(f)


def test_waterfall_of_a_speed_that_dips_warns_nothing_and_draws_rows_by_speed():
    """A rig's measured speed is not monotonic block by block: pcolormesh warned (a
    UserWarning with a source path reached the user) and misplaced the cells."""
    t = np.linspace(0.0, 400.0, 40001)
    speed = 0.5 + 0.005 * t + 0.4 * np.sin(t / 15.0)  # rises with dips
    phi = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))])
    z = 0.01 * np.exp(1j * phi) + 0.002 * np.exp(2j * phi)
    for x_axis in ("order", "frequency"):
        with warnings.catch_warnings():
            warnings.simplefilter("error", UserWarning)
            fig = fp.plot_waterfall(t, z, phi, x_axis=x_axis, speed_unit="dimensionless", amp_unit="rad")
        try:
            mesh = fig.axes[0].collections[0]
            ys = mesh.get_coordinates()[:, 0, 1]  # the cell rows' speeds (edges), bottom to top
            assert np.all(np.diff(ys) >= 0), "rows not in speed order"
        finally:
            plt.close(fig)
