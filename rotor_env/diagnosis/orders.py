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
