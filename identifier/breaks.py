"""Did a fitted model's parameters stay the same over the record?  A sup-LM break test that
stays valid where the information arrives unevenly and the errors are dependent.

A least-squares fit (linear, or the Gauss-Newton linearisation of a non-linear one) with
Jacobian rows ``J_i`` (one or more rows per sample ``i``), residual ``e_i`` and scores
``s_i = J_i' e_i`` has score partial sums ``S_k = sum_{i <= k} s_i`` that end at zero (the
normal equations).  If every parameter may change at sample ``k``, ``S_k`` is the score of
that change, and the Lagrange-multiplier statistic is ``LM_k = S_k' W_k^-1 S_k`` with ``W_k``
the variance of ``S_k`` under constant parameters.  The test is ``sup_k LM_k`` over the middle
of the record (Andrews 1993); the break's place is estimated by least squares (Bai 1997):
the ``k`` where letting every parameter change lowers the sum of squares most,
``S_k' (H_k - H_k H^-1 H_k)^-1 S_k`` in the notation below.

Why not the textbook form.  Andrews' statistic takes ``W_k = lambda (1 - lambda) n V`` with
``lambda = k / n`` and ``V`` the per-sample long-run covariance of the scores, and its null is
the supremum of a squared Brownian bridge.  That holds when the information accumulates
evenly in time.  A run-up through a critical speed gathers most of its information in the
few seconds at the resonance: then ``W_k`` is not proportional to ``lambda (1 - lambda)``, and
the bridge's critical values are wrong in either direction (Hansen 2000 shows the same for
regressors whose distribution changes).  Here, under constant parameters and to first order,

    S_k = U_k - H_k H^-1 U_n,      U_k = sum_{i <= k} J_i' u_i,   H_k = sum_{i <= k} J_i' J_i,

with ``u`` the errors, so

    W_k = O_k - H_k H^-1 O_k - O_k H^-1 H_k + H_k H^-1 O_n H^-1 H_k,

``O_k`` the variance of ``U_k``, estimated by batch means: ``O_k = sum_{blocks <= k} b_j b_j'``
with ``b_j`` the scores summed over block ``j`` -- consistent for heteroskedastic and
dependent errors whose correlation is shorter than a block, whatever the information's
path.  Each ``LM_k`` is then about chi-square with ``p`` degrees of freedom; the null of their
supremum is drawn by the dependent wild (multiplier) bootstrap with the Jacobian held --
Hansen's (2000) fixed-regressor bootstrap with Shao's (2010) blocks:
``U*_k = sum_{blocks <= k} eta_j b_j``, ``eta_j`` standard normal, ``S*_k = U*_k - H_k H^-1 U*_n``
and the same ``W_k``; no refit, a few hundred draws in a fraction of a second.  The record's
``W_k`` is estimated from the very scores it normalises, which narrows its ``LM_k`` where few
blocks per parameter lie behind a boundary, and the draws are not narrowed alike: the test is
conservative there (on 20 constant rig records, `benchmarks/change_size.py`, none below 5 %, one below 10 %).  Drawing
``W*_k`` from each draw's own blocks would mend that at ten times the cost per draw, a few
seconds a record; not done.  With evenly
arriving information and white errors it reproduces Andrews' table (the tests check 8.68 at
5 % for ``p = 1``).

The blocks (``boundaries``: where each ends, and where a break may be) must be long against
the errors' correlation, and there must be many of them: ``W_k`` is a sum of ``k`` block
outer products, so at least ``MIN_BLOCKS_PER_PARAMETER`` blocks per parameter are required.
A fit whose residuals are projected in segments (multiple shooting, each segment's start
state estimated) has its block scores exact only over whole segments: its blocks are
made of whole segments.  The errors' correlation is best taken from the sensor's noise
measured apart from the fit: read off the scores, a misfit's slow structure counts as
noise, and under a break that hides the very change the scores show.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .hac import andrews_bandwidth

__all__ = ["SupLMTest", "sup_lm_test"]

#: most blocks (the longer blocks of a long record: the bootstrap's cost and the break's
#: resolution, a thousandth of the record)
MAX_BLOCKS = 1000
#: blocks per tested parameter at least (``W_k`` sums ``k`` outer products of block scores)
MIN_BLOCKS_PER_PARAMETER = 8


@dataclass(frozen=True)
class SupLMTest:
    """The sup-LM break test of :func:`sup_lm_test` (module docstring)."""

    statistic: float  #: sup_k LM_k
    p_value: float  #: from the bootstrap draws (at least 1 / (draws + 1))
    dof: int  #: parameters tested (their change; the others held)
    index: int  #: the break's estimate: the last sample of its block (the least-squares date)
    fraction: float  #: its place in the record (share of the samples, 0..1)
    partial_sum: np.ndarray  #: S_k there, every parameter (p,)
    covariance: np.ndarray  #: W_k there, every parameter (p, p)
    null: np.ndarray  #: the bootstrap's draws of the supremum under constant parameters (sorted)

    def group_statistic(self, idx) -> float:
        """The same statistic at the break for a subset of the parameters (what moved)."""
        idx = np.asarray(idx, dtype=int)
        S = self.partial_sum[idx]
        return float(S @ np.linalg.pinv(self.covariance[np.ix_(idx, idx)], rcond=1e-10) @ S)

    def critical_value(self, alpha: float = 0.05) -> float:
        """The supremum's ``1 - alpha`` quantile under constant parameters (bootstrap)."""
        return float(np.quantile(self.null, 1.0 - alpha))


def _inverse_root(W: np.ndarray) -> np.ndarray:
    """``R`` with ``R R' = pinv(W)`` for a stack of symmetric matrices (directions with no
    variance carry no test)."""
    W = 0.5 * (W + np.swapaxes(W, -1, -2))
    ev, vec = np.linalg.eigh(W)
    tol = 1e-10 * np.maximum(ev[..., -1:], 1e-300)
    inv = np.where(ev > tol, 1.0 / np.where(ev > tol, ev, 1.0), 0.0)
    return vec * np.sqrt(inv)[..., None, :]


def sup_lm_test(scores: np.ndarray, jacobian: np.ndarray, *, boundaries: np.ndarray | None = None,
                tested=None, trim: float = 0.15, draws: int = 499, seed: int = 0) -> SupLMTest:
    """The sup-LM test of constant parameters (module docstring).

    ``scores``: ``(n, p)``, the per-sample scores ``J_i' e_i`` of a converged fit (they sum to
    about zero); ``jacobian``: ``(n, p)`` or ``(n, r, p)``, the Jacobian rows behind them;
    ``boundaries``: increasing sample indices where a block ends (default: blocks of Andrews'
    Bartlett bandwidth of the scores, at least ``n / MAX_BLOCKS`` samples); ``tested``: the
    indices of the parameters whose change is tested (default: all; the others are estimated
    but held the same on both sides: Andrews' partial structural change); ``trim``: the share
    of the record at each end where no break is looked for; ``seed``: the bootstrap's (the
    same answer every run)."""
    sc = np.asarray(scores, dtype=float)
    J = np.asarray(jacobian, dtype=float)
    if J.ndim == 2:
        J = J[:, None, :]
    n, p = sc.shape
    if J.shape[0] != n or J.shape[2] != p:
        raise ValueError(f"scores {sc.shape} and jacobian {J.shape} do not match")
    if not (0.0 < trim < 0.5):
        raise ValueError(f"trim must lie in (0, 0.5), got {trim!r}")
    if boundaries is None:
        step = max(andrews_bandwidth(sc), int(math.ceil(n / MAX_BLOCKS)))
        ends = np.arange(step, n + 1, step)
    else:
        ends = np.asarray(boundaries, dtype=int) + 1
        if ends.ndim != 1 or len(ends) == 0 or np.any(np.diff(ends) <= 0) or ends[0] < 1 or ends[-1] > n:
            raise ValueError(f"boundaries must increase within [0, {n - 1}]")
    ends = ends.copy()
    ends[-1] = n  # what follows the last boundary joins the last block
    idx = np.arange(p) if tested is None else np.asarray(tested, dtype=int)
    if idx.ndim != 1 or len(idx) == 0 or np.any((idx < 0) | (idx >= p)) or len(set(idx.tolist())) != len(idx):
        raise ValueError(f"tested must name distinct parameters among 0..{p - 1}")
    q = len(idx)
    nb = len(ends)
    if nb < max(20, MIN_BLOCKS_PER_PARAMETER * q):
        raise ValueError(f"{n} samples in {nb} blocks: too few for a break test of {q} parameters "
                         f"(at least {max(20, MIN_BLOCKS_PER_PARAMETER * q)})")
    starts = np.concatenate([[0], ends[:-1]])
    b = np.add.reduceat(sc, starts, axis=0)
    Hb = np.stack([np.einsum("krp,krq->pq", J[i0:i1], J[i0:i1]) for i0, i1 in zip(starts, ends, strict=True)])
    H = np.cumsum(Hb, axis=0)
    Ob = np.cumsum(b[:, :, None] * b[:, None, :], axis=0)
    Hi = np.linalg.pinv(H[-1], rcond=1e-12)
    lam = ends / n
    sel = np.nonzero((lam >= trim) & (lam <= 1.0 - trim))[0]
    if len(sel) == 0:
        raise ValueError(f"no block boundary between {trim} and {1 - trim} of the record")
    A = H[sel] @ Hi
    Ok = Ob[sel]
    W = Ok - A @ Ok - np.swapaxes(A @ Ok, 1, 2) + A @ Ob[-1] @ np.swapaxes(A, 1, 2)
    Wt = W[:, idx][:, :, idx]
    R = _inverse_root(Wt)
    S = np.cumsum(b, axis=0)
    lm = np.sum((S[sel][:, idx][:, None, :] @ R)[:, 0, :] ** 2, axis=1)
    # the break's place: the least-squares date (Bai 1997), where splitting every parameter
    # lowers the sum of squares most -- not the argmax of LM, which its weighting pulls towards
    # where the information is
    G = (H[sel] - A @ H[sel])[:, idx][:, :, idx]
    dssr = np.sum((S[sel][:, idx][:, None, :] @ _inverse_root(G))[:, 0, :] ** 2, axis=1)
    j = int(np.argmax(dssr))
    rng = np.random.default_rng(seed)
    sup = np.empty(draws)
    chunk = max(1, int(2e7 // max(1, nb * p)))
    for c0 in range(0, draws, chunk):
        eta = rng.standard_normal((nb, min(chunk, draws - c0), 1))
        U = np.cumsum(eta * b[:, None, :], axis=0)  # (block, draw, p)
        Ss = (U[sel] - np.swapaxes(A @ U[-1].T, 1, 2))[:, :, idx]
        sup[c0:c0 + eta.shape[1]] = np.max(np.sum((Ss @ R) ** 2, axis=2), axis=0)
    stat = float(np.max(lm))
    pval = (np.sum(sup >= stat) + 1) / (draws + 1)
    k = sel[j]
    return SupLMTest(stat, float(pval), q, int(ends[k] - 1), float(lam[k]), S[k].copy(),
                     0.5 * (W[j] + W[j].T), np.sort(sup))
