"""The plots rotordynamics engineers read: Bode, polar, orbits, waterfall, Campbell, tracks.

These functions draw what was computed before (the diagnosis, a rig's vectors, the
on-line identifier's tracks: :mod:`rotor_env.diagnosis.field`); they compute only what
drawing needs (a phase unwrapped for its axis, an orbit's revolution, a waterfall's
spectra).  Every function takes plain arrays (dimensionless runs and rig data in
engineering units alike), returns a matplotlib ``Figure`` and accepts ``ax=`` (a pair of
axes for the two-panel plots).  Units are labels the caller states: ``speed_unit`` is
``"rpm"``, ``"Hz"``, ``"rad/s"`` or ``"dimensionless"`` (the model's time unit, radians
per time unit); where a speed is *computed* from ``t`` and ``phi`` (orbits, waterfall),
``t`` is in seconds for ``rpm``/``Hz``/``rad/s`` and in the model's unit for
``dimensionless``.

Conventions (docs/PHYSICS.md 1.2): ``z = th_y + i th_x``; a component ``e^{i n phi}`` is
at rotation order ``n`` (forward for ``n > 0``); the horizontal probe/angle is ``th_y``,
the vertical ``th_x``, so a forward whirl turns counter-clockwise in the orbit plot of a
shaft turning with ``phi`` increasing.

Vectors (1X, 2X ...) are complex numbers in the **lead** convention: a real channel
``x ≈ Re(X e^{i n phi})`` (``phi`` from the keyphasor; ``phi = 0`` at the mark).  The
**lag** convention of instruments, ``x = A cos(n phi - lag)``, has ``lag = -angle(X)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from ..measurements.vectors import fit_orders, keyphasor_times, order_map

__all__ = [
    "axis_label",
    "bode_phases",
    "by_speed",
    "figure_axes",
    "frequency_from_rad",
    "phase_deg",
    "plot_bode",
    "plot_campbell",
    "plot_centreline",
    "plot_orbit",
    "plot_parameter_tracks",
    "plot_polar",
    "plot_waterfall",
    "speed_from_rad",
]

#: speed unit -> factor from rad per time unit (t in s for the engineering units)
SPEED_FACTORS: dict[str, float] = {"rpm": 60.0 / (2 * math.pi), "Hz": 1.0 / (2 * math.pi), "rad/s": 1.0,
                                   "dimensionless": 1.0}
#: speed unit -> (frequency unit of its Campbell/waterfall axis, factor from rad per time unit)
FREQUENCY_UNITS: dict[str, tuple[str, float]] = {"rpm": ("Hz", 1.0 / (2 * math.pi)),
                                                 "Hz": ("Hz", 1.0 / (2 * math.pi)),
                                                 "rad/s": ("rad/s", 1.0),
                                                 "dimensionless": ("dimensionless", 1.0)}


def _unit(speed_unit: str) -> str:
    if speed_unit not in SPEED_FACTORS:
        raise ValueError(f"speed_unit must be one of {', '.join(SPEED_FACTORS)}, got {speed_unit!r}")
    return speed_unit


def speed_from_rad(omega: np.ndarray | float, speed_unit: str) -> np.ndarray:
    """A spin speed in rad per time unit (rad/s for the engineering units) in ``speed_unit``."""
    return np.asarray(omega, dtype=float) * SPEED_FACTORS[_unit(speed_unit)]


def frequency_from_rad(w: np.ndarray | float, speed_unit: str) -> np.ndarray:
    """A whirl frequency in rad per time unit in the frequency unit that goes with
    ``speed_unit`` (Hz for rpm and Hz, rad/s, dimensionless)."""
    return np.asarray(w, dtype=float) * FREQUENCY_UNITS[_unit(speed_unit)][1]


def _freq_per_speed(speed_unit: str) -> float:
    """Frequency (in the axis's frequency unit) of order 1 at speed 1 (in ``speed_unit``)."""
    return FREQUENCY_UNITS[_unit(speed_unit)][1] / SPEED_FACTORS[speed_unit]


def axis_label(quantity: str, unit: str | None) -> str:
    """``"quantity (unit)"``, ``"quantity (dimensionless)"`` where there is no unit."""
    if not unit or unit == "dimensionless":
        return f"{quantity} (dimensionless)"
    return f"{quantity} ({unit})"


def by_speed(speeds: np.ndarray, amp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows of a spectrum map sorted by speed: a run's blocks need not be monotonic in
    speed (a speed that dips, a rig's measured rpm), and matplotlib's ``pcolormesh``
    then places the cells wrongly and warns (a ``UserWarning`` that reached the user)."""
    order = np.argsort(np.asarray(speeds, dtype=float), kind="stable")
    return np.asarray(speeds)[order], np.asarray(amp)[order] if np.ndim(amp) else amp


def _alarm_spans(t: np.ndarray, alarms: Sequence[Mapping], groups) -> dict[str, np.ndarray]:
    """Effect -> bool over ``t``: from each "appeared"/"changed" alarm's onset to the
    effect's next alarm (a "disappeared" ends it) or the end of the record."""
    # an unattributed alarm names no effect: it spans none
    names = list(groups or {}) or sorted({a["effect"] for a in alarms if a.get("effect") is not None})
    out = {e: np.zeros(len(t), dtype=bool) for e in names}
    for e in names:
        mine = sorted((a for a in alarms if a["effect"] == e), key=lambda a: a["t_onset"])
        for i, a in enumerate(mine):
            if a["event"] == "disappeared":
                continue
            end = mine[i + 1]["t_onset"] if i + 1 < len(mine) else np.inf
            out[e] |= (t >= a["t_onset"]) & (t < end)
    return out


def figure_axes(ax, n: int, figsize=(8, 4), **kw):
    """``(figure, [axes])``: the caller's axes (one, or a sequence of ``n``) or a new figure
    with ``n`` rows."""
    if ax is None:
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(n, 1, figsize=figsize, squeeze=False, **kw)
        return fig, list(axes[:, 0])
    axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
    if len(axes) != n:
        raise ValueError(f"this plot draws on {n} axes; got {len(axes)}")
    return axes[0].figure, axes


# ------------------------------------------------------------------ order tracking
def phase_deg(X: np.ndarray, convention: str = "lag", *, unwrap: bool = True,
              min_relative_amplitude: float = 0.02, wrap_wild: bool = True) -> np.ndarray:
    """Phase of vectors ``X`` (lead convention, ``x = Re(X e^{i phi})``) in degrees.

    ``lead``: ``angle(X)``; ``lag``: the instrument convention ``x = A cos(phi - lag)``,
    ``lag = -angle(X)``.  With ``unwrap`` the phase runs on continuously through the run
    (a resonance turns it by 180 deg, two by 360), the first point in [0, 360), as long
    as it stays within [-180, 540]: beyond, the 1X vector is circling (the free whirl
    beating against 1X after a fast passage), not turning with a resonance, and those
    values are shown modulo 360 (``wrap_wild=False``: never; the Bode plot's choice, where
    a jump of 360 deg reads as a zig-zag).  Without ``unwrap`` every value is in [0, 360).  Vectors
    below ``min_relative_amplitude`` of the largest carry no phase (noise): NaN there.
    """
    if convention not in ("lag", "lead"):
        raise ValueError(f"phase convention must be 'lag' or 'lead', got {convention!r}")
    X = np.asarray(X, dtype=complex)
    amp = np.abs(X)
    ok = np.isfinite(X) & (amp > min_relative_amplitude * np.nanmax(amp)) if np.any(np.isfinite(X)) else \
        np.zeros(X.shape, bool)
    ang = np.angle(X)
    ang = -ang if convention == "lag" else ang
    out = np.full(X.shape, np.nan)
    if not ok.any():
        return out
    deg = np.degrees(np.unwrap(ang[ok]) if unwrap else ang[ok])
    if unwrap:
        deg = deg - 360.0 * math.floor(deg[0] / 360.0)
        if wrap_wild:
            wild = (deg < -180.0) | (deg > 540.0)
            deg[wild] = np.mod(deg[wild], 360.0)
    else:
        deg = np.mod(deg, 360.0)
    out[ok] = deg
    return out


# ------------------------------------------------------------------ Bode and polar
_SOURCE_STYLES = ({"ls": "--", "lw": 1.0}, {"ls": ":", "lw": 1.6}, {"ls": "-.", "lw": 1.0})


def _curves(measured: Mapping[str, np.ndarray], models: Mapping[str, Mapping[str, np.ndarray]] | None):
    """``(label, channel index, style, X)`` of every curve: colour per channel, line style
    per source (measured solid and thick)."""
    channels = list(measured)
    for m in (models or {}).values():
        channels += [c for c in m if c not in channels]
    out = [(f"{c}: measured", channels.index(c), {"ls": "-", "lw": 1.8}, np.asarray(X))
           for c, X in measured.items()]
    for k, (name, vecs) in enumerate((models or {}).items()):
        for c, X in vecs.items():
            out.append((f"{c}: {name}", channels.index(c), _SOURCE_STYLES[k % len(_SOURCE_STYLES)], np.asarray(X)))
    return out


def _vector_plot(ax, n: int, speed: np.ndarray, measured: Mapping[str, np.ndarray],
                 models: Mapping[str, Mapping[str, np.ndarray]] | None, **axes_kw):
    """The opening of the vector plots (Bode, polar): ``(figure, [axes], speed, curves)``,
    the caller's ``n`` axes or a new figure (``axes_kw``: its size, shared axes), the speeds
    as floats and every curve of :func:`_curves`."""
    fig, axes = figure_axes(ax, n, **axes_kw)
    return fig, axes, np.asarray(speed, dtype=float), _curves(measured, models)


def plot_bode(
    speed: np.ndarray,
    measured: Mapping[str, np.ndarray],
    models: Mapping[str, Mapping[str, np.ndarray]] | None = None,
    *,
    speed_unit: str = "rpm",
    amp_unit: str = "µm",
    phase: str = "lag",
    order: int = 1,
    ax=None,
):
    """Bode plot: amplitude ``|X|`` (top) and phase (bottom) against speed.

    ``measured``: channel -> complex vectors (lead convention) at ``speed``; ``models``:
    model name (``"starting model"``, ``"final model"``) -> channel -> vectors at the
    same speeds.  ``phase`` is ``lag`` (instrument, ``x = A cos(phi - lag)``, 0..360 deg
    unwrapped through the run) or ``lead`` (``angle(X)``).  ``ax``: a pair of axes.
    """
    fig, (a_amp, a_ph), speed, curves = _vector_plot(ax, 2, speed, measured, models, figsize=(8, 5.5), sharex=True)
    for (label, ch, style, X), ph in zip(curves, bode_phases(curves, phase), strict=True):
        colour = f"C{ch}"
        a_amp.plot(speed, np.abs(X), color=colour, label=label, **style)
        a_ph.plot(speed, ph, color=colour, **style)
    a_amp.set_ylabel(axis_label(f"{order}X amplitude", amp_unit))
    a_ph.set_ylabel(f"{order}X phase {phase} (deg)")
    a_ph.set_xlabel(axis_label("speed", speed_unit))
    a_amp.legend(fontsize=7, ncol=2)
    a_amp.set_title(f"Bode plot ({order}X, phase {phase}: "
                    + ("x = A cos(φ - lag))" if phase == "lag" else "x = Re(X e^{iφ}))"))
    a_ph.yaxis.set_major_locator(_degree_locator())
    return fig


def bode_phases(curves, convention: str = "lag") -> list[np.ndarray]:
    """The phase (deg) of every curve of :func:`_curves`, unwrapped consistently: each curve
    runs on continuously through the run (no jump back by 360 deg where a vector circles),
    a measured curve starts in [0, 360), and a model's curve is moved by the multiple of
    360 deg that lays it on the measured curve of its channel (the median difference within
    +-180 deg): measured and model never differ by a wrap."""
    out = [phase_deg(X, convention, wrap_wild=False) for _, _, _, X in curves]
    reference: dict[int, np.ndarray] = {}
    for (label, ch, _, _), ph in zip(curves, out, strict=True):
        if label.endswith(": measured") and ch not in reference:
            reference[ch] = ph
    for (_, ch, _, _), ph in zip(curves, out, strict=True):
        ref = reference.get(ch)
        if ref is None or ph is ref:
            continue
        both = np.isfinite(ph) & np.isfinite(ref)
        if both.any():
            ph -= 360.0 * np.round(np.median(ph[both] - ref[both]) / 360.0)
    return out


def _degree_locator():
    from matplotlib.ticker import MaxNLocator

    return MaxNLocator(nbins=8, steps=[1, 2, 4.5, 9, 10])  # multiples of 45/90 deg where it can


def plot_polar(
    speed: np.ndarray,
    measured: Mapping[str, np.ndarray],
    models: Mapping[str, Mapping[str, np.ndarray]] | None = None,
    *,
    speed_unit: str = "rpm",
    amp_unit: str = "µm",
    phase: str = "lag",
    n_labels: int = 5,
    order: int = 1,
    ax=None,
):
    """Polar (Nyquist) plot: the vectors ``X`` in the complex plane, speed along the curve.

    The point is ``X`` itself (``|X|`` at ``angle(X)``); the angle scale drawn around it
    reads in the chosen convention: ``lead`` counter-clockwise from the right, ``lag``
    clockwise (phase lag grows against the rotation, as instruments draw it).  Speeds are
    written at ``n_labels`` points of each measured curve.
    """
    fig, (ax,), speed, curves = _vector_plot(ax, 1, speed, measured, models, figsize=(6, 6))
    r_max = 0.0
    for label, ch, style, X in curves:
        ok = np.isfinite(X)
        ax.plot(X.real[ok], X.imag[ok], color=f"C{ch}", label=label, **style)
        r_max = max(r_max, float(np.nanmax(np.abs(X))) if ok.any() else 0.0)
    for X in measured.values():
        X = np.asarray(X)
        ok = np.flatnonzero(np.isfinite(X))
        if ok.size == 0:
            continue
        for j in ok[np.linspace(0, ok.size - 1, n_labels).round().astype(int)]:
            ax.plot(X[j].real, X[j].imag, "k.", ms=5)
            ax.annotate(f"{speed[j]:.4g}", (X[j].real, X[j].imag), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
    r_max = r_max or 1.0
    # the angle scale: circles and spokes, labelled in the chosen convention
    th = np.linspace(0, 2 * np.pi, 181)
    for f in (0.5, 1.0):
        ax.plot(f * r_max * np.cos(th), f * r_max * np.sin(th), color="0.8", lw=0.6, zorder=0)
    for deg in range(0, 360, 45):
        a = math.radians(deg)
        ax.plot([0, r_max * math.cos(a)], [0, r_max * math.sin(a)], color="0.85", lw=0.6, zorder=0)
        shown = deg if phase == "lead" else (-deg) % 360
        ax.text(1.08 * r_max * math.cos(a), 1.08 * r_max * math.sin(a), f"{shown}°", fontsize=7,
                ha="center", va="center", color="0.4")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(axis_label(f"{order}X in phase, Re X", amp_unit))
    ax.set_ylabel(axis_label(f"{order}X quadrature, Im X", amp_unit))
    ax.set_title(f"polar plot ({order}X; angles: phase {phase}; labels: speed in "
                 f"{speed_unit if speed_unit != 'dimensionless' else 'dimensionless units'})", fontsize=9)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    return fig


# ------------------------------------------------------------------ orbits
def _whirl(X: complex, Y: complex, turning: float) -> str:
    """``forward`` or ``backward``: the 1X orbit ``x + i y = F e^{i phi} + B e^{-i phi}`` with
    ``F = (X + iY)/2``, ``B = conj(X - iY)/2``, against the sense of rotation."""
    fwd, bwd = abs(X + 1j * Y), abs(X - 1j * Y)
    return "forward" if (fwd >= bwd) == (turning > 0) else "backward"


def plot_orbit(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    phi: np.ndarray,
    at_times: Sequence[float],
    *,
    filtered: bool = True,
    unfiltered: bool = True,
    unit: str = "rad",
    speed_unit: str = "dimensionless",
    time_unit: str = "dimensionless",
    labels: tuple[str, str] = ("x (horizontal)", "y (vertical)"),
    ax=None,
):
    """Orbits (``y`` against ``x``) over the revolution at each of ``at_times``.

    One panel per time (or the caller's axes: one, all orbits on it, or one per time).
    The unfiltered orbit has its mean over the revolution removed (as a probe's AC
    signal); the 1X-filtered orbit is ``(Re(X e^{i phi}), Re(Y e^{i phi}))`` with the
    revolution's 1X vectors (:func:`~rotor_env.diagnosis.field.order_vectors`).  The keyphasor dot marks where
    ``phi`` crosses a multiple of ``2 pi`` (on the 1X orbit: ``(Re X, Re Y)``); the arrow
    shows the direction of the whirl, named forward or backward against the rotation.
    Titles give the time and the speed.
    """
    t, x, y, phi = (np.asarray(v, dtype=float) for v in (t, x, y, phi))
    at_times = list(np.atleast_1d(np.asarray(at_times, dtype=float)))
    if ax is None:
        import matplotlib.pyplot as plt

        fig, axs = plt.subplots(1, len(at_times), figsize=(3.6 * len(at_times), 3.8), squeeze=False)
        axes = list(axs[0])
    else:
        axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
        if len(axes) not in (1, len(at_times)):
            raise ValueError(f"give one axes or one per time ({len(at_times)}), got {len(axes)}")
        fig = axes[0].figure
        axes = axes * len(at_times) if len(axes) == 1 else axes
    times, marks = keyphasor_times(t, phi)
    turning = 1.0 if phi[-1] >= phi[0] else -1.0
    for k, (tc, a) in enumerate(zip(at_times, axes, strict=True)):
        if len(times) < 2:
            raise ValueError("the record holds no whole revolution: no orbit")
        j = int(np.clip(np.searchsorted(times, tc, side="right") - 1, 0, len(times) - 2))
        ta, tb = times[j], times[j + 1]
        sel = (t >= ta) & (t <= tb)
        tt = np.concatenate([[ta], t[sel], [tb]])
        xx, yy = np.interp(tt, t, x), np.interp(tt, t, y)
        speed = float(speed_from_rad(abs(marks[j + 1] - marks[j]) / (tb - ta), speed_unit))
        # the 1X fit on the samples themselves (the interpolated ends only close the curve)
        ends = (marks[j], marks[j + 1])
        X, Y = fit_orders(phi[sel], x[sel], (1,), ends)[1], fit_orders(phi[sel], y[sel], (1,), ends)[1]
        colour = f"C{k}" if len(set(map(id, axes))) == 1 else "C0"
        when = f"t = {tc:.4g} {'' if time_unit == 'dimensionless' else time_unit}".rstrip()
        tag = f"{when}, {speed:.4g} {'(speed)' if speed_unit == 'dimensionless' else speed_unit}"
        if unfiltered:
            x0, y0 = xx - np.mean(xx), yy - np.mean(yy)
            a.plot(x0, y0, color=colour, lw=0.8, alpha=0.6, label="unfiltered (mean removed)")
            a.plot(x0[0], y0[0], "o", mfc="none", mec="k", ms=6)
        if filtered and np.isfinite(X) and np.isfinite(Y):
            ps = np.linspace(marks[j], marks[j + 1], 200)
            x1, y1 = (X * np.exp(1j * ps)).real, (Y * np.exp(1j * ps)).real
            whirl = _whirl(X, Y, turning)
            a.plot(x1, y1, color=colour, lw=1.6, label=f"1X filtered ({whirl} whirl)")
            a.plot(x1[0], y1[0], "ko", ms=6, label="keyphasor" if k == 0 or len(set(map(id, axes))) > 1 else None)
            q = 50  # a quarter turn after the mark: the arrow along the motion
            a.annotate("", xy=(x1[q + 3], y1[q + 3]), xytext=(x1[q], y1[q]),
                       arrowprops={"arrowstyle": "-|>", "color": colour, "lw": 1.5, "mutation_scale": 14})
        a.set_aspect("equal", adjustable="datalim")
        a.set_xlabel(axis_label(labels[0], unit))
        a.set_ylabel(axis_label(labels[1], unit))
        a.set_title(tag, fontsize=9)
        a.axhline(0, color="0.85", lw=0.5, zorder=0)
        a.axvline(0, color="0.85", lw=0.5, zorder=0)
        a.legend(fontsize=6, loc="upper center", bbox_to_anchor=(0.5, -0.2))
    return fig


# ------------------------------------------------------------------ centreline
def plot_centreline(
    speed: np.ndarray,
    positions: Mapping[str, np.ndarray],
    *,
    unit: str = "um",
    speed_unit: str = "rpm",
    labels: tuple[str, str] = ("u (0 deg)", "v (90 deg)"),
    points: int = 400,
    ax=None,
):
    """The shaft centreline plot: each plane's average position against the speed.

    ``positions``: plane -> ``(N, 2)`` average position (the probes' slowly moving mean, in
    the plane's axes) at the samples whose shaft speed is ``speed`` (in ``speed_unit``,
    already converted).  Each plane is a path from its first sample (open circle) to its
    last (filled), coloured by the speed; the origin is the record's mean position (the
    probes' gap at rest is not known from a run).  Up to ``points`` samples per path.
    """
    import matplotlib.pyplot as plt

    speed = np.asarray(speed, dtype=float)
    if ax is None:
        fig, ax = plt.subplots(figsize=(5.2, 4.4))
    else:
        fig = ax.figure
    sc = None
    markers = ("o", "s", "^", "D")
    for k, (plane, xy) in enumerate(positions.items()):
        xy = np.asarray(xy, dtype=float)
        if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) != len(speed):
            raise ValueError(f"plane {plane!r}: positions must be ({len(speed)}, 2), got {xy.shape}")
        step = max(1, len(xy) // points)
        sel = slice(None, None, step)
        ax.plot(xy[sel, 0], xy[sel, 1], color="0.7", lw=0.8, zorder=1)
        sc = ax.scatter(xy[sel, 0], xy[sel, 1], c=speed[sel], s=9, cmap="viridis", zorder=2,
                        marker=markers[k % len(markers)], label=f"plane {plane}")
        ax.plot(xy[0, 0], xy[0, 1], markers[k % len(markers)], mfc="none", mec="k", ms=9, zorder=3)
        ax.plot(xy[-1, 0], xy[-1, 1], markers[k % len(markers)], color="k", ms=6, zorder=3)
    if sc is not None:
        fig.colorbar(sc, ax=ax, label=axis_label("speed", speed_unit))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(axis_label(labels[0], unit))
    ax.set_ylabel(axis_label(labels[1], unit))
    ax.set_title("shaft centreline (open: first sample, filled: last)", fontsize=9)
    ax.axhline(0, color="0.85", lw=0.5, zorder=0)
    ax.axvline(0, color="0.85", lw=0.5, zorder=0)
    if len(positions) > 1:
        ax.legend(fontsize=7)
    return fig


# ------------------------------------------------------------------ waterfall
def plot_waterfall(
    t: np.ndarray,
    signal: np.ndarray,
    phi: np.ndarray,
    *,
    revolutions: int = 8,
    max_order: float = 4.0,
    x_axis: str = "order",
    speed_unit: str = "dimensionless",
    amp_unit: str = "rad",
    lines: Sequence[int] = (1, 2),
    ax=None,
):
    """Waterfall / order map: spectra of consecutive blocks of ``revolutions`` turns
    (order tracked: resampled uniformly in ``phi``, Hann window) against speed.

    A complex ``signal`` (``x + i y``, e.g. ``th_y + i th_x``) gives signed orders (``+``
    forward, ``-`` backward whirl); a real one positive orders (amplitudes of
    ``Re(X e^{i n phi})``).  ``x_axis="order"`` puts orders on x (``n x`` lines vertical);
    ``"frequency"`` puts the frequency on x (Hz for rpm; the ``n x`` lines are the rays
    ``f = n speed``), where a whirl at a fixed natural frequency stands upright.
    Colour: ``log10`` of the amplitude.
    """
    if x_axis not in ("order", "frequency"):
        raise ValueError(f"x_axis must be 'order' or 'frequency', got {x_axis!r}")
    fig, (ax,) = figure_axes(ax, 1, figsize=(8, 4.5))
    t, phi = np.asarray(t, dtype=float), np.asarray(phi, dtype=float)
    signal = np.asarray(signal)
    real = not np.iscomplexobj(signal)
    omega = np.abs(np.gradient(phi, t))
    speeds, orders, amp = order_map(t, phi, speed_from_rad(omega, speed_unit), signal,
                                    revolutions=revolutions, max_order=max_order)
    if real:  # a real channel: +n and -n carry half the amplitude each
        keep = orders >= 0
        amp = amp[:, keep] * np.where(orders[keep] > 0, 2.0, 1.0)
        orders = orders[keep]
    speeds, amp = by_speed(speeds, amp)
    fps = _freq_per_speed(speed_unit)
    freq_unit = FREQUENCY_UNITS[speed_unit][0]
    if amp.size:
        c = np.log10(amp + 1e-12 * max(float(amp.max()), 1e-300))
        if x_axis == "order":
            mesh = ax.pcolormesh(orders, speeds, c, shading="nearest", cmap="viridis")
        else:
            order_grid, speed_grid = np.meshgrid(orders, speeds)
            mesh = ax.pcolormesh(order_grid * speed_grid * fps, speed_grid, c, shading="nearest", cmap="viridis")
        fig.colorbar(mesh, ax=ax, label=f"log10 amplitude [{amp_unit}]")
    top = float(speeds.max()) if speeds.size else 1.0
    lo = float(speeds.min()) if speeds.size else 0.0
    signed = [n for n in lines] + ([] if real else [-n for n in lines])
    for n in signed:
        if x_axis == "order":
            ax.axvline(n, color="w", lw=0.8, ls=":")
            ax.text(n, top, f"{n}x", color="k", ha="center", va="bottom", fontsize=8)
        else:
            ax.plot([n * lo * fps, n * top * fps], [lo, top], color="w", lw=0.8, ls=":")
            ax.text(n * top * fps, top, f"{n}x", color="k", ha="center", va="bottom", fontsize=8)
    if x_axis == "order":
        ax.set_xlabel("rotation order" + (" (+ forward, - backward whirl)" if not real else ""))
    else:
        ax.set_xlabel(axis_label("frequency" + (" (+ forward, - backward whirl)" if not real else ""), freq_unit))
    ax.set_ylabel(axis_label("speed", speed_unit))
    ax.set_title(f"waterfall: spectra of {revolutions}-revolution blocks", fontsize=10)
    return fig


# ------------------------------------------------------------------ Campbell
def _crossings(speed: np.ndarray, f: np.ndarray, line: np.ndarray) -> list[tuple[float, float]]:
    """``(speed, frequency)`` where ``f`` crosses ``line`` (linear interpolation)."""
    d = f - line
    out = []
    for j in np.flatnonzero(np.isfinite(d[:-1]) & np.isfinite(d[1:]) & (np.sign(d[:-1]) != np.sign(d[1:]))):
        if d[j] == d[j + 1]:
            continue
        s = d[j] / (d[j] - d[j + 1])
        out.append((float(speed[j] + s * (speed[j + 1] - speed[j])), float(f[j] + s * (f[j + 1] - f[j]))))
    return out


def plot_campbell(
    speed: np.ndarray,
    whirl_frequencies: Mapping[str, np.ndarray],
    *,
    measured_peaks: tuple[np.ndarray, np.ndarray] | None = None,
    orders: Sequence[int] = (1, 2),
    critical_orders: Sequence[int] = (1,),
    speed_unit: str = "rpm",
    freq_unit: str | None = None,
    ax=None,
):
    """Campbell diagram: whirl frequencies against speed with the ``n x`` lines.

    ``whirl_frequencies``: branch label -> signed frequencies at ``speed`` (negative:
    backward whirl, drawn dashed as ``|w|``), in ``freq_unit`` (default: Hz for rpm and
    Hz, otherwise the speed's unit).  ``measured_peaks``: ``(speeds, frequencies)`` seen in
    the data (dots).  Critical speeds, where a line of ``critical_orders`` crosses a branch,
    are marked and written in the legend (forward: filled, backward: open; the unbalance
    excites the forward ones, a support anisotropy the backward ones too).
    """
    fig, (ax,) = figure_axes(ax, 1, figsize=(7, 4.5))
    speed = np.asarray(speed, dtype=float)
    fps = _freq_per_speed(speed_unit)
    freq_unit = freq_unit or FREQUENCY_UNITS[speed_unit][0]
    top = 0.0
    for i, (label, w) in enumerate(whirl_frequencies.items()):
        w = np.asarray(w, dtype=float)
        back = np.nanmedian(w) < 0 if np.any(np.isfinite(w)) else False
        whirl = "backward" if back else "forward"
        ax.plot(speed, np.abs(w), color=f"C{i}", ls="--" if back else "-", lw=1.5,
                label=label if whirl in label else f"{label} ({whirl} whirl)")
        top = max(top, float(np.nanmax(np.abs(w))) if np.any(np.isfinite(w)) else 0.0)
    if measured_peaks is not None:
        ps, pf = (np.asarray(v, dtype=float) for v in measured_peaks)
        top = max(top, float(np.nanmax(np.abs(pf))) if pf.size else 0.0)
    y_top = 1.15 * max(top, float(np.nanmax(speed)) * fps if speed.size else 1.0)
    for n in orders:
        line = n * speed * fps
        ax.plot(speed, line, color="0.3", lw=0.8, ls=":")
        inside = np.flatnonzero(line <= y_top)
        if inside.size:  # the label where the line leaves the plot, not beyond it
            j = inside[-1]
            ax.text(speed[j], line[j], f" {n}x", fontsize=8, va="top" if j < len(line) - 1 else "center")
        if n not in critical_orders:
            continue
        for i, w in enumerate(whirl_frequencies.values()):
            w = np.asarray(w, dtype=float)
            back = np.nanmedian(w) < 0 if np.any(np.isfinite(w)) else False
            for s, f in _crossings(speed, np.abs(w), line):
                ax.plot(s, f, "o", ms=8, color=f"C{i}", mfc="none" if back else f"C{i}", mec="k",
                        label=f"critical {n}x {'backward' if back else 'forward'}: {s:.4g} "
                              f"{'' if speed_unit == 'dimensionless' else speed_unit}".rstrip())
    if measured_peaks is not None:
        ax.plot(ps[pf >= 0], pf[pf >= 0], "k.", ms=5, label="measured peaks, forward")
        if np.any(pf < 0):
            ax.plot(ps[pf < 0], -pf[pf < 0], "kx", ms=4, label="measured peaks, backward")
    ax.set_ylim(0, y_top)
    ax.set_xlabel(axis_label("speed", speed_unit))
    ax.set_ylabel(axis_label("whirl frequency", freq_unit))
    ax.set_title("Campbell diagram (whirl frequencies and n x lines)", fontsize=10)
    ax.legend(fontsize=7, loc="upper left")
    return fig


def plot_parameter_tracks(
    t: np.ndarray,
    tracks: Mapping[str, np.ndarray],
    *,
    significance: Mapping[str, np.ndarray] | None = None,
    alarms: Sequence[Mapping] | None = None,
    truth: Mapping[str, float] | None = None,
    groups: Mapping[str, Sequence[str]] | None = None,
    final: Mapping[str, tuple[float, float]] | None = None,
    time_unit: str = "dimensionless",
    value_unit: str = "dimensionless",
    ax=None,
):
    """Parameter tracks of an online identification (top) and when each effect is
    significant (bottom: a bar where its test passes).

    ``tracks``: name -> value at each ``t``; ``significance``: name (a track, or an
    effect of ``groups``) -> bool at each ``t``: a track is drawn solid where its effect
    is significant, thin where not; ``alarms`` (instead of ``significance``): the
    monitor's calibrated alarms (:func:`~rotor_env.diagnosis.field.monitor_alarms`, times in ``t``'s unit): the
    bottom panel shows each effect from an alarm's onset to its next alarm or the end,
    the top one a dotted line at each onset, every track drawn plain; ``truth``: name ->
    the true value, a number or an array over ``t`` (a crack opening: a step) (dashed,
    for simulated data); ``final``: name -> ``(estimate, half-width)`` of a batch fit (a
    band at the right edge).  ``ax``: a pair of axes (the bottom one only with
    ``significance`` or ``alarms``).
    """
    t = np.asarray(t, dtype=float)
    if alarms is not None:
        significance = _alarm_spans(t, alarms, groups)
    n_ax = 2 if significance else 1
    if ax is None:
        import matplotlib.pyplot as plt

        fig, axs = plt.subplots(n_ax, 1, figsize=(8, 5.5 if n_ax == 2 else 4), sharex=True, squeeze=False,
                                gridspec_kw={"height_ratios": [3, 1][:n_ax]})
        axes = list(axs[:, 0])
    else:
        fig, axes = figure_axes(ax, n_ax)
    a_tr = axes[0]
    effect_of = {c: e for e, cols in (groups or {}).items() for c in cols}
    for i, (name, v) in enumerate(tracks.items()):
        colour = f"C{i % 10}"
        v = np.asarray(v, dtype=float)
        key = name if significance and name in significance else effect_of.get(name)
        if significance and key in significance and alarms is None:
            sig = np.asarray(significance[key], dtype=bool)
            a_tr.plot(t, v, color=colour, lw=0.6, alpha=0.45)
            a_tr.plot(t, np.where(sig, v, np.nan), color=colour, lw=1.6, label=name)
        else:
            a_tr.plot(t, v, color=colour, lw=1.2, label=name)
        if truth and name in truth:
            true = np.asarray(truth[name], dtype=float)
            if true.ndim == 0:
                a_tr.axhline(float(true), color=colour, ls="--", lw=0.9)
            else:
                a_tr.plot(t, true, color=colour, ls="--", lw=0.9)
        if final and name in final:
            est, half = final[name]
            a_tr.errorbar([t[-1]], [est], yerr=[[half], [half]], fmt="s", color=colour, ms=4, capsize=3)
    # the scale of the settled estimates: the first samples of a recursive fit swing wildly
    settled = [np.asarray(v, dtype=float)[len(t) // 5:] for v in tracks.values()]
    settled += [np.atleast_1d(np.asarray(x, dtype=float)) for x in (truth or {}).values()]
    settled += [np.array([e - h, e + h]) for e, h in (final or {}).values()]
    vals = np.concatenate([v[np.isfinite(v)] for v in settled]) if settled else np.empty(0)
    if vals.size:
        lo, hi = float(vals.min()), float(vals.max())
        pad = 0.1 * (hi - lo) if hi > lo else 0.1 * max(abs(hi), 1e-12)
        a_tr.set_ylim(lo - pad, hi + pad)
    for a in alarms or ():
        a_tr.axvline(a["t_onset"], color="0.3", ls=":", lw=0.9)
    a_tr.set_ylabel(axis_label("coefficient", value_unit))
    what = ("dotted: an alarm's onset" if alarms is not None else "bold: effect significant") if significance or \
        alarms is not None else ""
    what = ", ".join(x for x in (what, "dashed: truth" if truth else "") if x)
    a_tr.set_title("online identification: parameter tracks" + (f" ({what})" if what else ""), fontsize=10)
    a_tr.legend(fontsize=7, ncol=min(4, max(1, len(tracks))), loc="upper left")
    if n_ax == 2:
        a_sig = axes[1]
        names = list(significance)
        for i, name in enumerate(names):
            sig = np.asarray(significance[name], dtype=bool)
            edges = np.flatnonzero(np.diff(np.concatenate([[0], sig.astype(np.int8), [0]])))
            spans = [(t[a], t[min(b, len(t) - 1)] - t[a]) for a, b in zip(edges[0::2], edges[1::2], strict=True)]
            a_sig.broken_barh(spans, (i - 0.35, 0.7), color="C2")
        a_sig.set_yticks(range(len(names)), names, fontsize=7)
        a_sig.set_ylim(-0.6, len(names) - 0.4)
        a_sig.set_title("changed or appeared: the monitor's calibrated CUSUM test (rotor_env/monitor/detector.py)"
                        if alarms is not None else "significant (effect-last F test, alpha as given)", fontsize=8)
        a_sig.set_xlabel(axis_label("t", time_unit))
    else:
        a_tr.set_xlabel(axis_label("t", time_unit))
    return fig
