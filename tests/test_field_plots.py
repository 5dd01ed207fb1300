"""The plots engineers read (issue 14 item 4), checked against independent truths.

Synthetic signals with known 1X/2X vectors on an accelerating shaft, the closed-form
whirl frequencies of the isotropic rotor (and the roots of its complex characteristic
polynomial), least squares by numpy for the identifier's tracks, and the speed axis of the
residual figure whose ticks must sit where the run-up reaches those speeds.
"""

from __future__ import annotations

import copy
import functools
import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.collections import QuadMesh
from matplotlib.figure import Figure

from rotor_env import plots as fp  # the drawing
from rotor_env.diagnosis import diagnose, field  # field: what the plots draw, computed
from rotor_env.diagnosis.report import speed_axis_functions
from rotor_env.params import Crack, RotorParams
from rotor_env.regression import RegressionSpec, regression_arrays
from rotor_env.simulator import simulate

RUN_UP = 0.02  # phi_dot = RUN_UP * t in the simulated run-up
CRACK = Crack(100.0, 0.05)


@functools.cache
def _diagnosis():
    """A short run-up whose shaft cracks at t = 100 (the walkthrough's story, small)."""
    params = RotorParams().replace(D=0.0, k30=0.0, k21=0.0, k12=0.0, k03=0.0, crack=CRACK)
    meas = simulate(params, t_end=160.0, dt=0.04, run_up=RUN_UP, noise=5e-4, seed=1)
    res = diagnose(meas, ("unbalance", "viscous_damping", "structural_damping"), ip=0.3)
    assert res.missing == ["asymmetry"]
    return res


def _shaft(n: int = 6001):
    """An accelerating shaft: phi = 0.5 a t^2 + w0 t (t in s), speed w0 + a t rad/s."""
    t = np.linspace(0.0, 12.0, n)
    a, w0 = 3.0, 20.0
    return t, 0.5 * a * t**2 + w0 * t, a, w0


# ------------------------------------------------------------------ order tracking
def test_order_vectors_recover_known_vectors_and_speeds():
    t, phi, a, w0 = _shaft()
    amp, lag = 35.0, math.radians(70.0)
    x = amp * np.cos(phi - lag) + 8.0 * np.cos(2 * phi + 0.4) + 3.0  # 1X, 2X and a DC offset
    t_mid, speed, vec = field.order_vectors(t, x, phi, orders=(1, 2))
    np.testing.assert_allclose(vec[1], amp * np.exp(-1j * lag), atol=1e-9)  # lead: x = Re(X e^{i phi})
    np.testing.assert_allclose(vec[2], 8.0 * np.exp(0.4j), atol=1e-9)
    # the keyphasor marks: phi = 2 pi k exactly, t from the quadratic
    k = np.arange(math.ceil(phi[0] / (2 * math.pi)), math.floor(phi[-1] / (2 * math.pi)) + 1)
    tk = (-w0 + np.sqrt(w0**2 + 2 * a * 2 * math.pi * k)) / a
    np.testing.assert_allclose(speed, 2 * math.pi / np.diff(tk), rtol=1e-6)
    np.testing.assert_allclose(t_mid, 0.5 * (tk[1:] + tk[:-1]), atol=1e-6)
    # lag convention: the instrument's phase comes back
    np.testing.assert_allclose(fp.phase_deg(vec[1], "lag"), 70.0, atol=1e-6)
    np.testing.assert_allclose(fp.phase_deg(vec[1], "lead", unwrap=False), 290.0, atol=1e-6)


def test_order_vectors_of_a_complex_orbit_give_signed_orders():
    t, phi, *_ = _shaft()
    z = 2.0 * np.exp(1j * (phi + 0.3)) + 0.5 * np.exp(-1j * (phi - 1.0))  # forward + backward 1X
    _, _, vec = field.order_vectors(t, z, phi, orders=(1, -1))
    np.testing.assert_allclose(vec[1], 2.0 * np.exp(0.3j), atol=1e-9)
    np.testing.assert_allclose(vec[-1], 0.5 * np.exp(1.0j), atol=1e-9)


def test_phase_unwraps_through_a_resonance_and_folds_a_circling_vector():
    lead = np.radians(np.linspace(-10.0, -250.0, 60))  # lag rises from 10 to 250 deg through 180
    lag = fp.phase_deg(np.exp(1j * lead), "lag")
    np.testing.assert_allclose(lag, np.linspace(10.0, 250.0, 60), atol=1e-9)  # continuous, no jump at 180
    wrapped = fp.phase_deg(np.exp(1j * lead), "lag", unwrap=False)
    assert wrapped.min() >= 0 and wrapped.max() < 360
    # a vector circling many times (free whirl beating against 1X) is shown modulo 360
    circling = fp.phase_deg(np.exp(-1j * np.radians(np.linspace(0, 2000, 200))), "lag")
    assert np.nanmax(circling) <= 540 and np.nanmin(circling) >= -180
    # noise-level vectors carry no phase
    small = fp.phase_deg(np.array([1.0, 1e-4, 1.0j]), "lead")
    assert np.isnan(small[1]) and small[2] == pytest.approx(90.0)


# ------------------------------------------------------------------ whirl frequencies
@pytest.mark.parametrize("k", [1.0, 2.5])
def test_whirl_frequencies_match_the_isotropic_closed_form(k):
    speed = np.linspace(0.0, 4.0, 41)
    ip = 0.3
    w = field.whirl_frequencies(speed, k, 0.0, ip)
    root = np.sqrt(ip**2 * speed**2 + 4 * k)
    np.testing.assert_allclose(w["forward"], (ip * speed + root) / 2, rtol=1e-10)
    np.testing.assert_allclose(w["backward"], (ip * speed - root) / 2, rtol=1e-10)  # negative: backward


def test_whirl_frequencies_with_damping_and_cross_coupling_match_the_complex_roots():
    # z'' + (c - i ip W) z' + (k - i q) z = 0: z = e^{lambda t}, Im(lambda) the signed whirl
    speed = np.linspace(0.0, 3.0, 13)
    k, c, ip, q = 1.2, 0.08, 0.4, 0.03
    w = field.whirl_frequencies(speed, k, c, ip, cross_coupling=q)
    for j, s in enumerate(speed):
        roots = np.sort(np.roots([1.0, c - 1j * ip * s, k - 1j * q]).imag)[::-1]
        assert w["forward"][j] == pytest.approx(roots[0], rel=1e-9)
        assert w["backward"][j] == pytest.approx(roots[1], rel=1e-9)


def test_whirl_frequencies_of_anisotropic_supports_split_the_natural_frequency():
    # at rest, no damping: straight-line modes at sqrt(k +- delta)
    w = field.whirl_frequencies([0.0], 1.0, 0.0, 0.0, anisotropy=0.1)
    got = sorted(abs(float(w[b][0])) for b in ("forward", "backward"))
    assert got == pytest.approx([math.sqrt(0.9), math.sqrt(1.1)], rel=1e-10)
    # spinning with a gyroscopic rotor: the forward branch rises, the backward one falls
    w = field.whirl_frequencies([0.0, 2.0], 1.0, 0.01, 0.3, anisotropy=0.1)
    assert w["forward"][1] > abs(w["forward"][0]) and abs(w["backward"][1]) < abs(w["backward"][0])


def test_campbell_marks_the_critical_speed_where_1x_crosses_the_forward_branch():
    ip = 0.3
    speed = np.linspace(0.0, 3.0, 301)
    fig = fp.plot_campbell(speed, field.whirl_frequencies(speed, 1.0, 0.0, ip), speed_unit="dimensionless")
    try:
        labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
        crit = [s for s in labels if s.startswith("critical 1x forward")]
        assert len(crit) == 1
        assert float(crit[0].split(":")[1]) == pytest.approx(1 / math.sqrt(1 - ip), rel=1e-3)  # 1.195
        assert fig.axes[0].get_xlabel() == "speed (dimensionless)"
        assert "dimensionless" in fig.axes[0].get_ylabel()
    finally:
        plt.close(fig)
    # in rpm: the 1x line is speed/60 Hz, so a whirl branch at 50 Hz is crossed at 3000 rpm
    rpm = np.linspace(0.0, 6000.0, 61)
    fig = fp.plot_campbell(rpm, {"forward": np.full(rpm.shape, 50.0)}, speed_unit="rpm")
    try:
        labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
        assert any(s == "critical 1x forward: 3000 rpm" for s in labels), labels
        assert fig.axes[0].get_ylabel() == "whirl frequency (Hz)"
    finally:
        plt.close(fig)


# ------------------------------------------------------------------ Bode, polar, orbit, waterfall
def test_bode_draws_amplitude_and_lag_phase_on_the_callers_axes():
    t, phi, *_ = _shaft()
    _, speed, vx = field.order_vectors(t, 12.0 * np.cos(phi - math.radians(30.0)), phi)
    model = {"final model": {"probe": 0.5 * vx[1]}}
    fig, axes = plt.subplots(2, 1)
    try:
        out = fp.plot_bode(speed * 60 / (2 * math.pi), {"probe": vx[1]}, model, ax=axes)
        assert out is fig
        amp_line, ph_line = axes[0].lines[0], axes[1].lines[0]
        np.testing.assert_allclose(amp_line.get_ydata(), 12.0, atol=1e-9)
        np.testing.assert_allclose(ph_line.get_ydata(), 30.0, atol=1e-6)
        np.testing.assert_allclose(axes[0].lines[1].get_ydata(), 6.0, atol=1e-9)  # the model curve
        assert axes[0].get_ylabel() == "1X amplitude (µm)"
        assert axes[1].get_ylabel() == "1X phase lag (deg)" and axes[1].get_xlabel() == "speed (rpm)"
    finally:
        plt.close(fig)


def test_polar_plots_the_vector_itself_with_speed_labels():
    t, phi, *_ = _shaft()
    _, speed, vx = field.order_vectors(t, 5.0 * np.cos(phi + 1.0), phi)
    fig = fp.plot_polar(speed, {"probe": vx[1]}, n_labels=4, speed_unit="rad/s")
    try:
        line = fig.axes[0].lines[0]
        np.testing.assert_allclose(line.get_xdata() + 1j * line.get_ydata(), 5.0 * np.exp(1j), atol=1e-9)
        texts = [x.get_text() for x in fig.axes[0].texts]
        assert f"{speed[0]:.4g}" in texts and f"{speed[-1]:.4g}" in texts
        assert "µm" in fig.axes[0].get_xlabel() and "µm" in fig.axes[0].get_ylabel()
    finally:
        plt.close(fig)


@pytest.mark.parametrize("direction", ["forward", "backward"])
def test_orbit_keyphasor_dot_and_whirl_direction(direction):
    t, phi, *_ = _shaft()
    beta = 0.7
    x = 3.0 * np.cos(phi + beta)
    y = 3.0 * np.sin(phi + beta) * (1 if direction == "forward" else -1)
    fig = fp.plot_orbit(t, x, y, phi, [4.0, 8.0], unit="µm", speed_unit="rpm", time_unit="s")
    try:
        assert len(fig.axes) == 2
        ax = fig.axes[0]
        dots = [ln for ln in ax.lines if ln.get_marker() == "o" and ln.get_markerfacecolor() in ("k", (0, 0, 0, 1))]
        assert len(dots) == 1
        # the keyphasor: phi a multiple of 2 pi, so the 1X orbit is at (Re X, Re Y)
        expected_y = 3.0 * math.sin(beta) * (1 if direction == "forward" else -1)
        assert dots[0].get_xdata()[0] == pytest.approx(3.0 * math.cos(beta), abs=1e-9)
        assert dots[0].get_ydata()[0] == pytest.approx(expected_y, abs=1e-9)
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert f"1X filtered ({direction} whirl)" in labels
        assert ax.get_xlabel() == "x (horizontal) (µm)" and "rpm" in ax.get_title() and " s," in ax.get_title()
        assert any(a.arrow_patch is not None for a in ax.texts if hasattr(a, "arrow_patch"))
    finally:
        plt.close(fig)


def _mesh(fig) -> tuple[np.ndarray, np.ndarray]:
    """``(cell centres (rows, cols, 2), colour values (rows, cols))`` of the map."""
    mesh = next(c for c in fig.axes[0].collections if isinstance(c, QuadMesh))
    corners = mesh.get_coordinates()  # cell edges with 'nearest' shading
    centres = 0.25 * (corners[:-1, :-1] + corners[1:, :-1] + corners[:-1, 1:] + corners[1:, 1:])
    return centres, np.asarray(mesh.get_array()).reshape(centres.shape[:2])


def test_waterfall_signed_orders_amplitudes_and_rpm():
    t, phi, a, w0 = _shaft(12001)
    z = 2.0 * np.exp(1j * phi) + 0.5 * np.exp(-2j * phi)
    fig = fp.plot_waterfall(t, z, phi, speed_unit="rpm", amp_unit="µm", max_order=3)
    try:
        _, c = _mesh(fig)
        orders = np.fft.fftshift(np.fft.fftfreq(8 * 64, d=1 / 64))
        orders = orders[np.abs(orders) <= 3]
        amp = 10 ** c
        # (order_map's symmetric Hann window sums to (n - 1)/2, not n/2: 0.2 % low)
        np.testing.assert_allclose(amp[:, np.argmin(abs(orders - 1))], 2.0, rtol=5e-3)
        np.testing.assert_allclose(amp[:, np.argmin(abs(orders + 2))], 0.5, rtol=5e-3)
        ax = fig.axes[0]
        assert ax.get_ylabel() == "speed (rpm)" and "backward" in ax.get_xlabel()
        lo, hi = ax.get_ylim()  # speeds in rpm: (w0 + a t) 60 / 2 pi within the record
        assert lo >= w0 * 60 / (2 * math.pi) - 60 and hi <= (w0 + a * t[-1]) * 60 / (2 * math.pi) + 60
        assert "µm" in fig.axes[1].get_ylabel()  # the colour bar
    finally:
        plt.close(fig)
    # a real channel: positive orders, the amplitude of Re(X e^{i phi})
    fig = fp.plot_waterfall(t, 4.0 * np.cos(phi + 0.2), phi, x_axis="frequency", speed_unit="rpm")
    try:
        coords, c = _mesh(fig)
        assert coords[..., 0].min() >= -1e-9  # orders >= 0 only
        row = 10 ** c[len(c) // 2]
        f_peak = coords[len(c) // 2, np.argmax(row), 0]
        s = coords[len(c) // 2, 0, 1]
        assert f_peak == pytest.approx(s / 60, rel=1e-6)  # 1x at speed/60 Hz
        assert row.max() == pytest.approx(4.0, rel=5e-3)
        assert fig.axes[0].get_xlabel() == "frequency (Hz)"
    finally:
        plt.close(fig)


# ------------------------------------------------------------------ parameter tracks
def test_parameter_tracks_end_at_the_batch_least_squares_and_follow_a_crack():
    res = _diagnosis()
    meas, model = res.data.meas, res.model
    full = field.parameter_tracks(meas, model, res.ip, forgetting=1.0)
    spec = RegressionSpec(effects=model, equation="both")
    X, y = regression_arrays(spec, np.ascontiguousarray(meas.data), res.ip)
    ref, *_ = np.linalg.lstsq(X, y, rcond=None)
    got = np.array([full.coefficients[c][-1] for c in spec.columns])
    np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-9)
    # halfway, the estimate is the least squares of the first half
    half = len(meas) // 2
    ref_half, *_ = np.linalg.lstsq(X[: 2 * (half + 1)], y[: 2 * (half + 1)], rcond=None)
    np.testing.assert_allclose([full.coefficients[c][half] for c in spec.columns], ref_half, rtol=1e-6, atol=1e-9)
    # with forgetting the crack shows: D about 0 before it opens, about its value after
    tr = field.parameter_tracks(meas, model, res.ip, forgetting=0.998)
    D, t = tr.coefficients["D"], tr.t
    assert abs(np.median(D[(t > 80) & (t < CRACK.time)])) < 0.01
    assert np.median(D[t > 140]) == pytest.approx(CRACK.D, abs=0.01)
    assert set(tr.significant) == set(model) and tr.significant["unbalance"][-1]
    assert not tr.significant["asymmetry"][0]  # causal: nothing is significant before the first test
    fig = fp.plot_parameter_tracks(t, tr.coefficients, significance=tr.significant, groups=tr.groups,
                                   truth={"D": CRACK.D})
    try:
        assert len(fig.axes) == 2 and [x.get_text() for x in fig.axes[1].get_yticklabels()] == list(tr.significant)
        assert any(ln.get_linestyle() == "--" and ln.get_ydata()[0] == CRACK.D for ln in fig.axes[0].lines)
    finally:
        plt.close(fig)


# ------------------------------------------------------------------ the report's figures
def _tick_offsets(ax, t_of_speed) -> list[float]:
    """For every visible tick of the top (speed) axis: its display x minus the display x of
    the time at which the run-up reaches that speed (0 where the axis is right)."""
    fig = ax.figure
    fig.canvas.draw()
    top = ax.child_axes[0]
    out = []
    lo, hi = top.get_xlim()
    for s in top.get_xticks():
        if not min(lo, hi) <= s <= max(lo, hi):
            continue
        x_tick = top.transData.transform((s, 0.0))[0]
        x_true = ax.transData.transform((t_of_speed(s), 0.0))[0]
        out.append(x_tick - x_true)
    return out


def test_residual_speed_axis_ticks_sit_where_the_speed_is_reached():
    res = _diagnosis()
    fig = res.plot_residual()
    try:
        off = _tick_offsets(fig.axes[0], lambda s: s / RUN_UP)
        assert len(off) >= 4
        assert np.max(np.abs(off)) < 0.5  # display pixels
        assert fig.axes[0].child_axes[0].get_xlabel() == "speed (dimensionless)"
    finally:
        plt.close(fig)
    # beyond the record (the axis margins) the map extrapolates instead of clamping
    t = np.linspace(10.0, 20.0, 11)
    fwd, inv = speed_axis_functions(t, 0.5 * t)
    np.testing.assert_allclose(fwd(np.array([0.0, 30.0])), [0.0, 15.0])
    np.testing.assert_allclose(inv(np.array([3.0, 12.0])), [6.0, 24.0])
    fwd, inv = speed_axis_functions(t, 20.0 - t)  # a coast-down
    np.testing.assert_allclose(inv(np.array([15.0, 5.0, 0.0])), [5.0, 15.0, 20.0])
    assert speed_axis_functions(t, np.sin(t)) is None


def test_report_units_in_seconds_and_rpm():
    res = copy.copy(_diagnosis())
    res.time_scale, res.time_unit = 50.0, "s"  # t_model = 50 t_s: natural frequency 50 rad/s
    fig = res.plot_residual()
    try:
        ax = fig.axes[0]
        assert ax.get_xlabel() == "t (s)" and ax.child_axes[0].get_xlabel() == "speed (rpm)"
        # speed (rpm) = RUN_UP t_model * 50 * 60 / 2 pi at t_s = t_model / 50
        off = _tick_offsets(ax, lambda rpm: rpm * 2 * math.pi / 60 / 50 / RUN_UP / 50)
        assert len(off) >= 3 and np.max(np.abs(off)) < 0.5
    finally:
        plt.close(fig)
    fig = res.plot_bode()
    try:
        assert fig.axes[1].get_xlabel() == "speed (rpm)"
    finally:
        plt.close(fig)


def test_report_figures_all_drawn_with_units_and_accept_ax(tmp_path):
    res = _diagnosis()
    figs = res.figures()
    try:
        assert tuple(figs) == res.FIGURES
        for name, fig in figs.items():
            assert isinstance(fig, Figure)
            drawn = [ax for ax in fig.axes if ax.has_data()]
            assert drawn, name
            for ax in drawn:
                if name == "candidates" or ax.get_label() == "<colorbar>":
                    continue  # -log10 p has no unit
                for label in (ax.get_xlabel(), ax.get_ylabel()):
                    if label:
                        assert "(" in label, f"{name}: no unit on {label!r}"
    finally:
        for fig in figs.values():
            plt.close(fig)
    # the measured 1X vectors and the final model's agree (the model explains the data)
    v = res._vectors()
    for ch, X in v["measured"].items():
        Xm = v["models"]["final model"][ch]
        ok = np.abs(X) > 0.2 * np.nanmax(np.abs(X))
        assert np.median(np.abs(Xm[ok] - X[ok]) / np.abs(X[ok])) < 0.05
    # orbits below, at and above the critical: the middle is the largest 1X
    times = res.orbit_times()
    assert len(times) == 3 and times[0] < times[1] < times[2]
    # each new plot on the caller's axes
    for method, n in (("plot_bode", 2), ("plot_polar", 1), ("plot_orbit", 1), ("plot_waterfall", 1),
                      ("plot_campbell", 1), ("plot_parameter_tracks", 2), ("plot_compare", 2),
                      ("plot_before_after", 2)):
        own, axes = plt.subplots(1, n + 1)
        try:
            target = list(axes[1:]) if n > 1 else axes[1]
            out = getattr(res, method)(ax=target)
            assert out is own
            assert all(a.has_data() for a in axes[1:]) and not axes[0].has_data(), method
        finally:
            plt.close(own)
    # the report holds every figure and the new sections
    text = res.report(tmp_path / "r.html").read_text()
    assert text.count("data:image/png;base64,") == len(res.FIGURES)
    for h in ("Bode and polar plots", "Orbits", "Waterfall", "Campbell diagram", "Parameter tracks"):
        assert f"<h2>{h}</h2>" in text
    assert 'alt="residual_after"' in text


def test_order_vectors_agree_with_the_measurements_order_track():
    """The lead's order tracker (trapezoid DFT against phi) and this least-squares one read
    the same 1X vectors and speeds from the same revolutions (to the trapezoid's accuracy)."""
    vectors = pytest.importorskip("rotor_env.measurements.vectors")
    t, phi, *_ = _shaft(20001)
    x = 7.0 * np.cos(phi - 0.9) + 1.5 * np.cos(2 * phi)
    t_mid, speed, mine = field.order_vectors(t, x, phi)
    theirs = vectors.order_track(t, x, phi)
    n = min(len(speed), len(theirs.speed))
    np.testing.assert_allclose(theirs.speed[:n], speed[:n], rtol=1e-6)
    np.testing.assert_allclose(theirs.vectors[1][:n], mine[1][:n], atol=1e-3 * 7.0)
    # fitting 1X alone, the 2X does not leak in (samples weighted by the angle they cover)
    np.testing.assert_allclose(mine[1], 7.0 * np.exp(-0.9j), atol=1e-3)
