"""Critical speeds, damping ratios and the Campbell diagram of a synchronous model.

All from the eigenvalues of the model linearised at a speed (:func:`_eigen`): a critical is a
speed where the whirl frequency of a branch that whirls forward at least in part meets the speed
(:func:`critical_speeds`); :func:`whirl_branches` signs each branch by its whirl.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from ...measurements.vectors import SPEED_UNITS
from .model import SynchronousModel

__all__ = ["critical_speeds", "whirl_branches", "whirl_modes"]


def _eigen(model: SynchronousModel, coef: np.ndarray, W: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eigenvalues of the linearised state matrix at ``W`` and each eigenvector's forward
    and backward parts ``|v_u + i v_v|``, ``|v_u - i v_v|``."""
    A_q, A_w = model.linearised(coef, W)
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [A_q, A_w]])
    lam, vec = np.linalg.eig(A)
    return lam, np.abs(vec[0] + 1j * vec[1]), np.abs(vec[0] - 1j * vec[1])


def whirl_modes(model: SynchronousModel, coef: np.ndarray, W: float) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues with positive imaginary part and each one's forward share."""
    lam, fwd, bwd = _eigen(model, coef, W)
    keep = lam.imag > 1e-9
    lam, fwd, bwd = lam[keep], fwd[keep], bwd[keep]
    order = np.argsort(lam.imag)
    return lam[order], (fwd / np.maximum(fwd + bwd, 1e-300))[order]


def whirl_branches(model: SynchronousModel, coef: np.ndarray, speed: np.ndarray) -> dict[str, np.ndarray]:
    """The Campbell diagram's branches: the damped whirl frequencies ``Im lambda`` of the
    linearised model at each dimensionless ``speed``, signed by the whirl of each mode
    (forward where its forward part is at least its backward part; a double eigenvalue,
    the isotropic rotor at rest, is both circles).  ``{"forward": w_f, "backward": w_b}``
    (``w_b < 0`` for a backward whirl), NaN where a mode is over-critically damped;
    where both modes whirl the same way (strong anisotropy), the higher one is the
    ``forward`` branch, each keeping the sign of its own whirl."""
    speed = np.atleast_1d(np.asarray(speed, dtype=float))
    fwd, bwd = np.full(speed.shape, np.nan), np.full(speed.shape, np.nan)
    for j, w in enumerate(speed):
        lam, f, b = _eigen(model, coef, w)
        upper = np.flatnonzero(lam.imag > 1e-12 * max(1.0, float(np.max(np.abs(lam)))))
        if len(upper) == 2 and abs(lam[upper[0]] - lam[upper[1]]) <= 1e-9 * abs(lam[upper[0]]):
            # its eigenvectors are any mix of the forward and the backward circle
            modes = [lam[upper[0]].imag, -lam[upper[0]].imag]
        else:
            modes = [lam[i].imag if f[i] >= b[i] else -lam[i].imag for i in upper]
        modes.sort(reverse=True)
        if len(modes) == 2:
            fwd[j], bwd[j] = modes
        elif len(modes) == 1:  # one mode over-critically damped
            (fwd if modes[0] > 0 else bwd)[j] = modes[0]
    return {"forward": fwd, "backward": bwd}


def critical_speeds(model: SynchronousModel, coef: np.ndarray, w_ref: float, speed: np.ndarray,
                    min_forward_share: float = 0.1) -> list[dict[str, float]]:
    """Critical speeds (rpm) within the run's speed range and their damping ratios, lowest first."""
    W = np.asarray(speed, dtype=float) / w_ref
    lo, hi = float(W.min()), float(W.max())
    grid = np.linspace(0.5 * lo, hi, 400)
    out = []
    n_branch = None
    vals = []
    for w in grid:
        lam, _ = whirl_modes(model, coef, w)
        if n_branch is None:
            n_branch = len(lam)
        vals.append(lam.imag if len(lam) == n_branch else np.full(n_branch, np.nan))
    vals = np.array(vals) - grid[:, None]
    for b in range(n_branch or 0):
        f = vals[:, b]
        for k in np.nonzero(np.sign(f[:-1]) * np.sign(f[1:]) < 0)[0]:
            def g(w, b=b):
                lam, _ = whirl_modes(model, coef, w)
                return lam.imag[b] - w
            try:
                wc = brentq(g, grid[k], grid[k + 1], xtol=1e-12)
            except ValueError:
                continue
            lam, share = whirl_modes(model, coef, wc)
            if share[b] < min_forward_share or not (lo * 0.999 <= wc <= hi * 1.001):
                continue
            out.append({"rpm": wc * w_ref / SPEED_UNITS["rpm"],
                        "damping_ratio": float(-lam[b].real / abs(lam[b])),
                        "forward_share": float(share[b])})
    out = sorted(out, key=lambda d: d["rpm"])
    # a degenerate (isotropic) pair of branches crosses the 1x line once
    merged: list[dict[str, float]] = []
    for c in out:
        if merged and abs(c["rpm"] - merged[-1]["rpm"]) <= 1e-6 * c["rpm"]:
            merged[-1]["forward_share"] = max(merged[-1]["forward_share"], c["forward_share"])
            continue
        merged.append(c)
    return merged
