"""The figures of a diagnosis: compare, where it fails, which effect is missing, before and after.

Each function draws numbers the diagnosis computed before (the mixin
:class:`~rotor_env.diagnosis.figures.DiagnosisFigures` computes them and hands them
over): plain arrays and numbers in, a matplotlib ``Figure`` out, ``ax=`` for the
caller's axes (a pair for the two-panel figures), units on every axis (``speed_unit``,
``time_unit``, ``amp_unit`` as in :mod:`.field`; ``"dimensionless"`` for the model's own).

:func:`plot_residual_by_speed` and :func:`plot_orbit_radius` draw the output-error
diagnosis's figures and the 1X-vector diagnosis's residual: one drawer for every residual
RMS against speed with the noise floor.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from .field import axis_label, by_speed, figure_axes

__all__ = [
    "LINE_COLOURS",
    "plot_autocorrelation",
    "plot_before_after",
    "plot_candidates",
    "plot_compare",
    "plot_orbit_radius",
    "plot_order_map",
    "plot_residual",
    "plot_residual_by_speed",
    "plot_residual_change",
    "speed_axis_functions",
]

#: colours of the expected order lines on the order map (visible on viridis)
LINE_COLOURS = ("#e41a1c", "#ff7f00", "#f781bf", "#000000", "#00e5ff", "#a65628")
#: the styles of the starting and the final model, in that order
MODEL_STYLES = ({"color": "C3", "ls": "--", "lw": 1.0}, {"color": "C0", "lw": 1.0})


def _given_axes(ax) -> tuple[object, list]:
    """``(figure, [axes])`` of the caller's ``ax``: one axes or a sequence of them."""
    axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
    return axes[0].figure, axes


# ------------------------------------------------------------------ a speed axis over time
def _interp_linear(x, xp: np.ndarray, fp_: np.ndarray):
    """``np.interp`` that extrapolates linearly past both ends (end slopes over up to 10
    samples) instead of clamping: a secondary axis built on it maps the whole axis range,
    margins included, one-to-one (a clamped map puts the ticks in the wrong place).
    ``xp`` must be increasing."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(np.interp(x, xp, fp_), dtype=float)
    k = min(len(xp) - 1, 10)
    if k < 1:
        return y
    lo, hi = x < xp[0], x > xp[-1]
    s_lo = (fp_[k] - fp_[0]) / (xp[k] - xp[0])
    s_hi = (fp_[-1] - fp_[-1 - k]) / (xp[-1] - xp[-1 - k])
    y = np.where(lo, fp_[0] + (x - xp[0]) * s_lo, y)
    return np.where(hi, fp_[-1] + (x - xp[-1]) * s_hi, y)


def speed_axis_functions(t: np.ndarray, speed: np.ndarray):
    """``(t -> speed, speed -> t)`` for ``secondary_xaxis`` where the speed is monotone in
    time (run-up or coast-down): piecewise linear through the samples, extrapolated
    linearly past the record's ends; ``None`` where the speed is not monotone."""
    t, speed = np.asarray(t, dtype=float), np.asarray(speed, dtype=float)
    d = np.diff(speed)
    if len(t) < 2 or not (np.all(d > 0) or np.all(d < 0)):
        return None
    if d[0] > 0:
        return (lambda x: _interp_linear(x, t, speed)), (lambda s: _interp_linear(s, speed, t))
    # a coast-down: the inverse interpolates on the speed reversed (np.interp needs it rising)
    return (lambda x: _interp_linear(x, t, speed)), (lambda s: _interp_linear(s, speed[::-1], t[::-1]))


# ------------------------------------------------------------------ compare
def plot_compare(
    speed: np.ndarray,
    measured: np.ndarray,
    models: Mapping[str, tuple[np.ndarray, np.ndarray]],
    *,
    errors: Mapping[str, np.ndarray] | None = None,
    zoom: tuple[float, float] | None = None,
    speed_unit: str = "dimensionless",
    amp_unit: str = "rad",
    ax=None,
):
    """Measured and model amplitude against speed (top) and the output error (bottom).

    ``measured``: the measured amplitude ``|theta|`` at ``speed``; ``models``: legend label
    -> ``(speed, amplitude)`` of each model's free run (the first drawn as the starting
    model, red dashed; the second as the final, blue); ``errors``: label -> the output
    error ``|theta_measured - theta_model|`` at ``speed``, styled as the model of the same
    position (the bottom panel, drawn where there are two axes); ``zoom``: the speed range
    of an inset on the critical.  ``ax``: one axes (the top panel only) or a pair.
    """
    if ax is None:
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    else:
        fig, axes = _given_axes(ax)
    top = axes[0]
    speed = np.asarray(speed, dtype=float)
    curves = [(speed, np.asarray(measured, dtype=float), {"color": "k", "lw": 1.2}, "measured")]
    curves += [(np.asarray(x, dtype=float), np.asarray(y, dtype=float), MODEL_STYLES[i % 2], label)
               for i, (label, (x, y)) in enumerate(models.items())]
    for x, y, style, label in curves:
        top.plot(x, y, label=label, **style)
    top.set_ylabel(axis_label(r"amplitude $|\theta|$", amp_unit))
    # above the axes, between them and the title: never over a curve (nor the zoom)
    top.legend(fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.01), ncol=2, frameon=False, borderaxespad=0.0)
    top.set_title("measured vs model response (free run)", pad=8 + 11 * ((len(curves) + 1) // 2))
    if zoom is not None and zoom[1] > zoom[0]:
        lo, hi = zoom
        inset = top.inset_axes([0.62, 0.45, 0.36, 0.5])
        for x, y, style, _ in curves:
            sel = (x >= lo) & (x <= hi)
            inset.plot(x[sel], y[sel], **style)
        inset.set_title("zoom: the critical", fontsize=7)
        inset.tick_params(labelsize=6)
        top.indicate_inset_zoom(inset, edgecolor="0.5")
    if len(axes) > 1:
        bottom = axes[1]
        for i, (label, err) in enumerate((errors or {}).items()):
            err = np.asarray(err, dtype=float)
            bottom.plot(speed, err, label=f"{label} (RMS {np.sqrt(np.mean(err**2)):.3g})",
                        **{**MODEL_STYLES[i % 2], "lw": 0.8})
        bottom.set_ylabel(axis_label(r"output error $|\theta - \theta_{model}|$", amp_unit))
        bottom.legend(fontsize=7, loc="upper left")
        bottom.set_xlabel(axis_label("spin speed", speed_unit))
    else:
        top.set_xlabel(axis_label("spin speed", speed_unit))
    return fig


# ------------------------------------------------------------------ where it fails
def plot_residual(
    t: np.ndarray,
    residual: np.ndarray,
    noise_floor: float,
    *,
    windows: Sequence[tuple[float, float]] = (),
    speed_axis: tuple[np.ndarray, np.ndarray] | None = None,
    which: str = "before",
    model: Sequence[str] = (),
    rms: float = float("nan"),
    time_unit: str = "dimensionless",
    speed_unit: str = "dimensionless",
    ax=None,
):
    """Equation-error residual against time, shaded over ``windows`` (``(start, end)`` in
    ``t``'s unit: where its rolling RMS stands above 2x the noise floor), the floor's
    +-2x dotted; ``speed_axis``: ``(t, speed)`` of the record, a speed axis on top where
    the speed is monotone in time (exact: :func:`speed_axis_functions`).  ``which``,
    ``model`` and ``rms`` name the model in the title (``before``: red, else blue)."""
    fig, (ax,) = figure_axes(ax, 1)
    ax.plot(t, residual, lw=0.3, color="C3" if which == "before" else "C0")
    for start, end in windows:
        ax.axvspan(start, end, color="orange", alpha=0.2)
    ax.axhline(2 * noise_floor, color="k", lw=0.5, ls=":")
    ax.axhline(-2 * noise_floor, color="k", lw=0.5, ls=":")
    ax.set_xlabel(axis_label("t", time_unit))
    ax.set_ylabel("equation residual (dimensionless moment)")
    ax.set_title(f"residual of the {which} model ({', '.join(model)}); RMS {rms:.3g}; "
                 "shaded: above 2x the noise floor (dotted)", fontsize=9)
    funcs = speed_axis_functions(*speed_axis) if speed_axis is not None else None
    if funcs is not None:  # a speed axis only where speed maps one-to-one onto time
        top = ax.secondary_xaxis("top", functions=funcs)
        top.set_xlabel(axis_label("speed", speed_unit))
    return fig


def plot_order_map(
    speeds: np.ndarray,
    orders: np.ndarray,
    amp: np.ndarray,
    *,
    expected: Sequence[tuple[str, Sequence[float], str]] = (),
    mirrored: Sequence[tuple[str, int, np.ndarray, np.ndarray]] = (),
    which: str = "before",
    speed_unit: str = "dimensionless",
    ax=None,
):
    """Residual spectrum in rotation orders against speed (``amp``: one row per speed,
    :func:`~rotor_env.measurements.vectors.order_map`), 0x/1x/2x marked.

    ``expected``: ``(effect, signed orders, "added" | "lookalike")``: an added effect's
    orders solid, a lookalike's dashed, each named in the legend (an effect without an
    order line said so there); ``mirrored``: ``(effect, m, speed, order)``: where a
    rotating asymmetry puts the free whirl (``m x - w/Omega``), dash-dot.
    """
    fig, (ax,) = figure_axes(ax, 1)
    speeds, amp = by_speed(speeds, amp)  # pcolormesh wants monotonic rows (else a UserWarning)
    amp = np.asarray(amp)
    if amp.size:
        mesh = ax.pcolormesh(orders, speeds, np.log10(amp + 1e-12), shading="nearest", cmap="viridis")
        fig.colorbar(mesh, ax=ax, label="log10 amplitude (dimensionless moment)")
    for o in (-2, -1, 0, 1, 2):
        ax.axvline(o, color="w", lw=0.6, ls=":")
        ax.text(o, speeds.max() if amp.size else 1, f"{o}x", color="k", ha="center", va="bottom", fontsize=8)
    for i, (name, declared, kind) in enumerate(expected):
        colour = LINE_COLOURS[i % len(LINE_COLOURS)]
        style = ({"ls": "-", "lw": 1.6, "alpha": 0.95} if kind == "added"
                 else {"ls": "--", "lw": 1.1, "alpha": 0.85})
        label = name if kind == "added" else f"{name} (lookalike)"
        if not declared:  # no order line: said in the legend, nothing drawn on the map
            ax.plot([], [], color=colour, label=f"{label}: no order line", **style)
            continue
        for j, o in enumerate(declared):
            ax.axvline(o, color=colour, label=label if j == 0 else None, **style)
    for i, (name, m, speed, order) in enumerate(mirrored):
        ax.plot(order, speed, color=LINE_COLOURS[(len(expected) + i) % len(LINE_COLOURS)],
                ls="-.", lw=1.4, label=f"{name}: the free whirl ω mirrored to {m}x − ω/Ω")
    if expected or mirrored:
        # below the axes (and their order label), so the map stays unhidden
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16),
                  ncol=min(3, len(expected) + len(mirrored)),
                  title="expected order lines (solid: added, dashed: lookalike; dash-dot: a rotating "
                  "asymmetry turns the free whirl ω into 2Ω − ω, between 1x and 2x)", title_fontsize=7)
    ax.set_xlabel("rotation order (+ forward, - backward)")
    ax.set_ylabel(axis_label("speed", speed_unit))
    ax.set_title(f"order map of the {which}-model residual")
    return fig


def plot_autocorrelation(lags: np.ndarray, ac: np.ndarray, bound: float, *, which: str = "before",
                         time_unit: str = "dimensionless", ax=None):
    """Residual autocorrelation against the lag with the white-noise band ``+-bound``
    (95 %: ``1.96 / sqrt(n)``)."""
    fig, (ax,) = figure_axes(ax, 1)
    ax.plot(lags, ac, lw=1)
    ax.axhspan(-bound, bound, color="grey", alpha=0.3, label="95 % bounds (white noise)")
    ax.set_xlabel(axis_label("lag", time_unit))
    ax.set_ylabel("autocorrelation (normalised)")
    ax.legend(fontsize=8)
    ax.set_title(f"residual autocorrelation ({which} model)")
    return fig


# ------------------------------------------------------------------ which effect is missing
def plot_candidates(names: Sequence[str], log10_p: Sequence[float], added: Sequence[bool], threshold: float,
                    *, ax=None):
    """The ranking: ``-log10 p`` of adding each candidate (red: added), the Bonferroni line
    at ``threshold`` (``-log10(alpha / n)``)."""
    fig, (ax,) = figure_axes(ax, 1)
    vals = [max(-float(p), 1e-3) for p in log10_p]  # a log axis: p = 1 still shows a stub
    ax.barh(list(names), vals, color=["C3" if a else "C7" for a in added])
    ax.set_xscale("log")
    ax.axvline(threshold, color="k", ls="--", lw=1, label="alpha / n")
    ax.invert_yaxis()
    ax.set_xlabel(r"$-\log_{10} p$ of adding the effect (dimensionless)")
    ax.legend(fontsize=8)
    ax.set_title("which effect is missing (red: added)")
    return fig


# ------------------------------------------------------------------ before and after
def plot_before_after(
    labels: Sequence[str],
    fit_percent: Sequence[float],
    rms: Sequence[float],
    *,
    residuals: Mapping | None = None,
    zoom: bool = True,
    ax=None,
):
    """Equation-error RMS and free-run fit % at each step of the forward selection
    (``labels``: ``start``, ``+ effect`` ...); with a second axes (a new figure has one)
    the residuals of :func:`plot_residual_change` (``residuals``: its keyword arguments)."""
    if ax is None:
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(2, 1, figsize=(8, 7.5), gridspec_kw={"height_ratios": [2, 3], "hspace": 0.35})
    else:
        fig, axes = _given_axes(ax)
    ax = axes[0]
    x = np.arange(len(labels))
    ax.bar(x - 0.2, list(fit_percent), 0.4, color="C0", label="free-run fit %")
    ax.set_ylabel("free-run fit (%)")
    ax2 = ax.twinx()
    ax2.bar(x + 0.2, list(rms), 0.4, color="C3", label="equation RMS")
    ax2.set_ylabel("equation error RMS (dimensionless)")
    ax.set_xticks(x, list(labels), rotation=15, fontsize=8)
    ax.set_title("before and after adding the missing effects")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax2.legend(h1 + h2, l1 + l2, fontsize=8, loc="lower right")  # on top of both bar sets
    if len(axes) > 1 and residuals is not None:
        plot_residual_change(ax=axes[1], zoom=zoom, **residuals)
    return fig


def plot_residual_change(t: np.ndarray, before: np.ndarray, after: np.ndarray, *, rms_before: float,
                         rms_after: float, noise_floor: float, time_unit: str = "dimensionless",
                         zoom: bool = True, ax=None):
    """The starting and the final model's residual over time with the noise floor's
    +-2x band, and a zoom on the stretch (a tenth of the record) where the starting model
    fails most."""
    fig, (ax,) = figure_axes(ax, 1)
    t, r0, r1 = (np.asarray(v, dtype=float) for v in (t, before, after))
    ax.plot(t, r0, lw=0.3, color="C3", label=f"starting model (RMS {rms_before:.3g})")
    ax.plot(t, r1, lw=0.3, color="C0", label=f"final model (RMS {rms_after:.3g})")
    ax.axhspan(-2 * noise_floor, 2 * noise_floor, color="0.5", alpha=0.25,
               label=f"±2x the noise floor: the white-noise RMS of the residual, {noise_floor:.3g} "
               "(dimensionless moment)")
    ax.set_xlabel(axis_label("t", time_unit))
    ax.set_ylabel("equation residual (dimensionless)")
    ax.legend(fontsize=7, loc="upper left", markerscale=4)
    ax.set_title("residual before and after", fontsize=9)
    if zoom and len(t) > 50:
        n = max(10, len(t) // 10)
        energy = np.convolve(r0 * r0, np.ones(n), mode="valid")
        k = int(np.argmax(energy))
        inset = ax.inset_axes([0.58, 0.55, 0.4, 0.42])
        inset.plot(t[k:k + n], r0[k:k + n], lw=0.4, color="C3")
        inset.plot(t[k:k + n], r1[k:k + n], lw=0.4, color="C0")
        inset.tick_params(labelsize=6)
        inset.set_title("zoom: where the starting model fails most", fontsize=7)
        ax.indicate_inset_zoom(inset, edgecolor="0.5")
    return fig


# ------------------------------------------------------------------ residual RMS against speed
def plot_residual_by_speed(
    curves: Mapping[str, tuple[np.ndarray, np.ndarray]],
    noise_floor: float,
    *,
    quantity: str = "residual RMS",
    amp_unit: str = "model units",
    speed_label: str = "speed [rpm]",
    floor_label: str = "noise floor",
    floor_ratio: float | None = None,
    marks: Sequence[float] = (),
    log: bool = False,
    title: str = "where the model fails: residual against speed",
    ax=None,
):
    """A residual's RMS against speed per model (``curves``: legend label -> ``(speed,
    rms)``), the noise floor dashed (and ``floor_ratio`` times it dotted), grey vertical
    lines at ``marks`` (the criticals), a log scale with ``log``.  ``speed_label``: the
    whole x label with its unit (``"speed [rpm]"``); the y label is ``quantity [amp_unit]``."""
    fig, (ax,) = figure_axes(ax, 1, figsize=(8, 3.5))
    for label, (speed, rms) in curves.items():
        ax.plot(speed, rms, "-", lw=1, label=label)
    ax.axhline(noise_floor, color="k", ls="--", lw=0.8, label=floor_label)
    if floor_ratio is not None:
        ax.axhline(floor_ratio * noise_floor, color="k", ls=":", lw=0.8, label=f"{floor_ratio}x floor")
    for m in marks:
        ax.axvline(m, color="0.6", lw=0.8)
    ax.set_xlabel(speed_label)
    ax.set_ylabel(f"{quantity} [{amp_unit}]")
    if log:
        ax.set_yscale("log")
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title)
    return fig


def plot_orbit_radius(speed: np.ndarray, measured: np.ndarray, predicted: np.ndarray, *,
                      amp_unit: str = "model units", speed_label: str = "speed [rpm]", ax=None):
    """Measured (dots) and predicted (line) orbit radius against speed."""
    fig, (ax,) = figure_axes(ax, 1, figsize=(7.5, 3.6))
    ax.plot(speed, measured, ".", ms=1, alpha=0.4, label="measured")
    ax.plot(speed, predicted, "-", lw=0.8, label="final model")
    ax.set_xlabel(speed_label)
    ax.set_ylabel(f"orbit radius [{amp_unit}]")
    ax.legend(loc="upper left", fontsize=8)
    return fig
