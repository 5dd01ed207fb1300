"""The figures of a balancing: every run's 1X vectors and the correction's predicted effect.

These are not the Bode and polar plots of a run-up (:mod:`.field`): they set the runs of
a campaign (reference, trial weights) side by side, the effect of each plane's trial
weight as an arrow, and the vibration predicted after the correction with its 95 %
interval.  The balancing result computes every vector and hands them over (complex, lead
convention ``x = Re(X e^{i phi})``); the angles are drawn in the campaign's phase
convention (:func:`~rotor_env.measurements.vectors.to_phase`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..measurements.vectors import to_phase

__all__ = ["plot_correction_bode", "plot_correction_polar"]


def plot_correction_polar(
    probes: Sequence[str],
    runs: Mapping[str, np.ndarray],
    after: np.ndarray,
    arrows: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
    *,
    arrow_rpm: float | None = None,
    phase: str = "lag",
    amp_unit: str = "µm",
    ax=None,
):
    """One polar panel per probe: each run's 1X vectors over its speeds (``runs``: run ->
    ``(speeds, probes)`` complex), the predicted vibration after the correction (``after``:
    ``(speeds, probes)``, black stars) and, per plane, an arrow from the reference vector to
    the reference plus the trial weight's effect ``H W`` (``arrows``: plane -> ``(from, to)``,
    one complex per probe, at ``arrow_rpm``).  Zero at the top; the angle runs clockwise
    for the ``lag`` convention.  ``ax``: one polar axes per probe."""
    P = len(probes)
    if ax is None:
        import matplotlib.pyplot as plt

        fig, axs = plt.subplots(1, P, subplot_kw={"projection": "polar"}, figsize=(4.2 * P, 4.4), squeeze=False)
        axes = list(axs[0])
    else:
        axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
        if len(axes) != P:
            raise ValueError(f"this plot draws one polar axes per probe ({P}); got {len(axes)}")
        fig = axes[0].figure
    after = np.asarray(after)
    for p, a in enumerate(axes):
        a.set_theta_zero_location("N")
        a.set_theta_direction(-1 if phase == "lag" else 1)
        for run, Y in runs.items():
            amp, ang = to_phase(np.asarray(Y)[:, p], phase)
            a.plot(np.radians(ang), amp, "o-", ms=4, lw=0.8, label=run)
        for plane, (start, tip) in (arrows or {}).items():
            a0, g0 = to_phase(np.array([start[p], tip[p]]), phase)
            a.annotate("", xy=(np.radians(g0[1]), a0[1]), xytext=(np.radians(g0[0]), a0[0]),
                       arrowprops={"arrowstyle": "->", "lw": 1.4})
            a.text(np.radians(g0[1]), a0[1], f" H·W {plane}", fontsize=8)
        ar, gr = to_phase(after[:, p], phase)
        a.plot(np.radians(gr), ar, "k*", ms=8, label="after correction (predicted)")
        a.set_title(f"{probes[p]}: 1X [{amp_unit}], phase {phase} [deg]", fontsize=9)
    axes[0].legend(fontsize=7, loc="lower left", bbox_to_anchor=(-0.25, -0.2))
    where = f" at {arrow_rpm:.0f} rpm" if arrow_rpm is not None else ""
    fig.suptitle(f"1X vectors per run; arrows: each plane's trial-weight effect{where}", y=1.04)
    return fig


def plot_correction_bode(
    rpm: np.ndarray,
    probes: Sequence[str],
    before: np.ndarray,
    after: np.ndarray,
    after_halfwidth: np.ndarray | None = None,
    *,
    phase: str = "lag",
    amp_unit: str = "µm",
    ax=None,
):
    """1X amplitude (top) and phase (bottom) against speed per probe: the reference run
    (``before``: ``(speeds, probes)`` complex, circles) and the vibration predicted after
    the correction (``after``, squares, dashed) with its 95 % half-widths of amplitude
    (``after_halfwidth``, error bars).  ``ax``: a pair of axes."""
    if ax is None:
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5.5))
    else:
        axes = list(ax)
        if len(axes) != 2:
            raise ValueError(f"this plot draws on 2 axes; got {len(axes)}")
        fig = axes[0].figure
    rpm = np.asarray(rpm, dtype=float)
    before, after = np.asarray(before), np.asarray(after)
    for p, probe in enumerate(probes):
        a0, g0 = to_phase(before[:, p], phase)
        a1, g1 = to_phase(after[:, p], phase)
        line, = axes[0].plot(rpm, a0, "o-", label=f"{probe} before (reference)")
        axes[0].errorbar(rpm, a1, yerr=None if after_halfwidth is None else np.asarray(after_halfwidth)[:, p],
                         fmt="s--", color=line.get_color(), label=f"{probe} predicted after")
        axes[1].plot(rpm, g0, "o-", color=line.get_color())
        axes[1].plot(rpm, g1, "s--", color=line.get_color())
    axes[0].set_ylabel(f"1X amplitude [{amp_unit}]")
    axes[1].set_ylabel(f"phase {phase} [deg]")
    axes[1].set_xlabel("speed [rpm]")
    axes[1].set_ylim(0, 360) if phase == "lag" else axes[1].set_ylim(-180, 180)
    axes[0].legend(fontsize=8)
    axes[0].set_title("before and predicted after the correction (bars: 95 % intervals)")
    return fig
