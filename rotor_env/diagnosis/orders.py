"""Where a model fails: the residual over time, in rotation orders, and its noise floor."""

from __future__ import annotations

import math

import numpy as np


# ------------------------------------------------------------------ where it fails
def complex_rows(values: np.ndarray, equation: str) -> np.ndarray:
    """Per-sample complex signal ``eq1 + i eq2`` (``theta_y + i theta_x`` convention).

    In this coordinate the unbalance is ``e^{+i phi}``: positive rotation orders are
    forward whirl.  With one equation only, the real signal is returned.
    """
    if equation == "both":
        return values[0::2] + 1j * values[1::2]
    return values.astype(complex)


def order_map(
    t: np.ndarray, phi: np.ndarray, speed: np.ndarray, signal: np.ndarray,
    revolutions: int = 8, max_order: float = 4.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Amplitude spectrum in rotation orders over windows of ``revolutions`` turns.

    Returns ``(speeds, orders, amplitude)`` with ``amplitude[window, order]``.  The
    signal is resampled on a uniform spin-angle grid (order tracking), so a component
    at ``k`` times the spin frequency stays in bin ``k`` while the speed changes.

    Orders count with the direction of rotation: for a rotor turning backwards
    (``phi`` decreasing) the angle is ``-phi`` and the signal is conjugated, so the
    unbalance is order +1 either way.  The angle must progress overall; brief
    reversals (encoder noise, a stall) are held at the angle already reached, because
    the resampling needs a monotone angle.
    """
    phi = np.asarray(phi, dtype=float)
    signal = np.asarray(signal)
    if phi.size and phi[-1] < phi[0]:  # turning backwards: count angle and orders with the rotation
        phi, signal = -phi, np.conj(signal)
    phi = np.maximum.accumulate(phi) if phi.size else phi
    span = 2 * np.pi * revolutions
    n_per = 64 * revolutions
    starts = np.arange(phi[0], phi[-1] - span, span / 2) if phi.size else np.empty(0)
    speeds, rows = [], []
    freqs = np.fft.fftfreq(n_per, d=1.0 / (64))  # cycles per revolution
    keep = np.abs(freqs) <= max_order
    order = np.argsort(freqs[keep])
    for s in starts:
        grid = s + np.arange(n_per) * (span / n_per)
        re = np.interp(grid, phi, signal.real)
        im = np.interp(grid, phi, signal.imag)
        z = (re + 1j * im) * np.hanning(n_per)
        spec = np.abs(np.fft.fft(z)) / (n_per / 2)
        rows.append(spec[keep][order])
        speeds.append(float(np.interp(s + span / 2, phi, speed)))
    if not rows:
        return np.empty(0), freqs[keep][order], np.empty((0, int(keep.sum())))
    return np.array(speeds), freqs[keep][order], np.array(rows)


def autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    x = x - x.mean()
    n = len(x)
    f = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[: max_lag + 1]
    return ac / ac[0] if ac[0] > 0 else ac


def noise_floor(r: np.ndarray) -> float:
    """Robust white-noise level of a residual: from the MAD of its first differences."""
    d = np.diff(r)
    return float(np.median(np.abs(d - np.median(d))) / 0.6745 / math.sqrt(2.0))


def failing_windows(t: np.ndarray, r: np.ndarray, width: float = 2.0, factor: float = 2.0,
                    floor: float | None = None, speed: np.ndarray | None = None) -> tuple[list[dict], float]:
    """Time windows where the rolling RMS of ``r`` exceeds ``factor`` x the noise floor.

    ``floor`` defaults to :func:`noise_floor` of ``r``; ``width`` is the rolling window in
    time units (at most the record).  With ``speed`` each window also gives its speed range.
    """
    floor = noise_floor(r) if floor is None else float(floor)
    if len(r) < 2:
        return [], floor
    dt = float(np.median(np.diff(t)))
    n = int(min(max(3, round(width / dt)) if dt > 0 else 3, len(r)))
    kernel = np.ones(n) / n
    rms = np.sqrt(np.convolve(r * r, kernel, mode="same"))
    above = rms > factor * max(floor, 1e-300)
    # runs of samples above the threshold; runs closer than the rolling window are one
    # episode (the rolling RMS dips between them by chance, not because the misfit stops)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], above.astype(np.int8), [0]])))
    runs = [[int(a), int(b) - 1] for a, b in zip(edges[0::2], edges[1::2], strict=True)]
    merged: list[list[int]] = []
    for a, b in runs:
        if merged and a - merged[-1][1] <= n:
            merged[-1][1] = b
        else:
            merged.append([a, b])
    out = []
    for k, j in merged:
        w = {"t_start": float(t[k]), "t_end": float(t[j]),
             "peak_rms_over_floor": float(rms[k : j + 1].max() / max(floor, 1e-300))}
        if speed is not None:
            w["speed_min"] = float(np.min(speed[k : j + 1]))
            w["speed_max"] = float(np.max(speed[k : j + 1]))
        out.append(w)
    return out, floor


def first_rows(values: np.ndarray, equation: str) -> np.ndarray:
    return values[0::2] if equation == "both" else values
