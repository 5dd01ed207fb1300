"""Keyphasor: once-per-revolution pulses -> spin angle, speed and acceleration.

A keyphasor probe sees a notch (or a projection) on the shaft once per turn.  Each
pulse's leading edge is found where the signal crosses a threshold (default halfway
between the signal's low and high levels, the 0.1th and 99.9th percentiles), the time
interpolated linearly between the two samples around the crossing.  A sampled edge is
only known to within a sample (a square pulse: +-dt/2, 0.1 rad at 3000 rpm and 5 kHz),
and that jitter would put a false wobble into the angle, the speed and every order-
tracked vector.  A real keyphasor's edge takes a few samples (a probe tip a few
millimetres wide crossing a notch), and the interpolated crossing is then far finer than
a sample; smoothing the pulse times would bias a fast start-up's angle more than it
removes (tried: a local cubic over 11 turns put 0.04 rad into the first turns), so the
angle is the cubic spline through ``(edge k, 2 pi k)`` (continuous speed and
acceleration).  Sample fast enough that ``speed * dt / 2`` is small where it matters.  The record is cut to the span between the first and the last pulse.
The leading edge is the transition into the pulse's short state: a notch gives a brief
dip, a projection a brief rise — the state the signal spends less time in.

Checks (a clear error naming the file, column, time and line): too few pulses; a
revolution twice as long as its neighbours say (a missed pulse) or half as long (a
double trigger, noise): its period times the speed its neighbours' line predicts,
over 2 pi, outside [0.6, 1.6] (a start from rest, whose periods shrink fast, passes).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import CubicSpline

__all__ = ["KeyphasorError", "pulse_edges", "spin_from_pulses"]

MIN_PULSES = 5
#: a revolution this much longer (shorter) than its neighbours is a missed (extra) pulse
PERIOD_RATIO = (0.6, 1.6)


class KeyphasorError(ValueError):
    """Keyphasor pulses that cannot give the spin angle."""


def pulse_edges(t: np.ndarray, signal: np.ndarray, threshold: float | None = None, *, where: str = "keyphasor",
                lines: np.ndarray | None = None) -> np.ndarray:
    """Times of the pulses' leading edges (see the module docstring)."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(signal, dtype=float)
    # 0.1 / 99.9 %: a narrow notch (1 % of a turn) still reaches its level
    lo, hi = np.percentile(x, [0.1, 99.9])
    if not hi > lo:
        raise KeyphasorError(f"{where}: the signal is constant ({lo:g}): no pulses")
    thr = 0.5 * (lo + hi) if threshold is None else float(threshold)
    if not lo < thr < hi:
        raise KeyphasorError(f"{where}: threshold {thr:g} is outside the signal's range [{lo:g}, {hi:g}]")
    high = x > thr
    # the pulse is the short state: a projection is high briefly, a notch low briefly
    pulse_high = high.mean() < 0.5
    state = high if pulse_high else ~high
    k = np.nonzero(~state[:-1] & state[1:])[0]  # last sample before the edge
    if len(k) < MIN_PULSES:
        raise KeyphasorError(f"{where}: only {len(k)} pulses found (threshold {thr:g}); at least {MIN_PULSES} "
                             "revolutions are needed")
    frac = (thr - x[k]) / (x[k + 1] - x[k])
    edges = t[k] + frac * (t[k + 1] - t[k])
    period = np.diff(edges)
    # each revolution's speed against the line through its neighbours' at its middle: a
    # start from rest (speed growing from zero) is smooth, a missed pulse halves the speed
    # of its revolution, a double trigger doubles it in the two halves it makes -- so the
    # neighbours are the 2nd and 3rd on each side, past a partner half
    speed = 2.0 * math.pi / period
    mid = 0.5 * (edges[1:] + edges[:-1])
    for i in range(len(period)):
        nb = [j for j in (i - 3, i - 2, i + 2, i + 3) if 0 <= j < len(period)]
        if len(nb) < 2:
            continue
        slope, icept = np.polyfit(mid[nb], speed[nb], 1)
        predicted = slope * mid[i] + icept
        ratio = period[i] * predicted / (2.0 * math.pi) if predicted > 0 else math.inf
        if not PERIOD_RATIO[0] <= ratio <= PERIOD_RATIO[1]:
            kind = "missing pulse" if ratio > 1 else "extra pulse (double trigger or noise)"
            line = f", line {lines[k[i] + 1]}" if lines is not None else ""
            raise KeyphasorError(
                f"{where}{line}: irregular pulses at t = {edges[i]:.6g}: a revolution of {period[i]:.4g} between "
                f"pulses {i + 1} and {i + 2}, {ratio:.2f}x its neighbours ({kind}); check the threshold "
                f"(now {thr:g}) or the keyphasor signal"
            )
    return edges


def spin_from_pulses(t: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(inside, phi, speed, acceleration)`` at the samples ``t[inside]`` between the first and last edge."""
    spline = CubicSpline(edges, 2.0 * math.pi * np.arange(len(edges)))
    inside = (t >= edges[0]) & (t <= edges[-1])
    ti = t[inside]
    return inside, spline(ti), spline(ti, 1), spline(ti, 2)
