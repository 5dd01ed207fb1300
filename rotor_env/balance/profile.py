r"""The unbalance by maximum likelihood over every run at once, with profile-likelihood intervals.

Why not first order
-------------------
The unbalance is a ratio: the reference's vibration divided by what a trial weight changed.
Where the trial weights move the vibration by a few standard errors only (small weights,
much noise, two planes that act alike), the ratio is far from its linearisation: the
first-order intervals of :mod:`.influence` covered 73 % (g·mm) and 81 % (angle) of the
seeds for two planes at 10 µm noise with two repeats — and as little with the *true*
noise variance in place of the repeats' estimate (measured), so neither the
t-quantile nor the variance's degrees of freedom was the cause: the linearisation was.

The joint model
---------------
If the influence model holds, every run ``k`` sees the same coefficients acting on its total
unbalance, ``y_{k,sp} = H_{sp}^T (U + W_k) + n`` (``U`` the reference's, ``W_k`` the trial
weights).  For a given ``U`` this is linear in each cell's ``H_sp`` (design rows ``U + W_k``,
known), so ``H`` is profiled out by weighted least squares and

.. math::  R(U) = \sum_{sp} \min_{H_{sp}} \sum_k |y_{k,sp} - H_{sp}^T (U + W_k)|^2 / v_{k,sp}

is a function of ``U`` alone (``J`` complex numbers).  Its minimum is the maximum-likelihood
unbalance (Gaussian circular noise, the repeats' variances).  It is consistent although every
cell has its own ``H``: ``E R(U) = |(I - P_U) D_{U_0} H|^2 + \sum_{sp} (K - J)`` is smallest at
the truth (the projection's rank does not depend on ``U``).  Every run's total unbalance is
``U + W_k``; whether the runs agree with that is the misfit check (:mod:`.misfit`).

The intervals
-------------
``2 (R(U) - R(\hat U))`` is the likelihood-ratio (deviance) statistic: for a magnitude
``|U_j + W_kj| = r`` (or an angle), minimised over the other parameters, it is ``chi^2_1``
for large samples and, with variances estimated on ``nu`` degrees of freedom, ``F(1, nu)``.
The 95 % interval is every ``r`` (angle) with ``R_profile - R_min <= t_{0.975,nu}^2 / 2`` —
Fieller's interval for a ratio in the one-cell case: asymmetric, unbounded when the trial
weights did not move the vibration (then said so).  Measured coverage:
benchmarks/balance_coverage.py, docs/BALANCING.md §4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

__all__ = ["JointUnbalance", "fit_joint", "joint_variances"]

#: a magnitude interval is called unbounded beyond this many times the estimate
_UNBOUNDED = 1e3


@dataclass
class JointUnbalance:
    """The joint model's likelihood (module docstring) for a campaign's mean vectors."""

    Y: np.ndarray  #: (K, S, P) mean vectors
    v: np.ndarray  #: (K, S, P) their variances
    W: np.ndarray  #: (K, J) trial unbalances, g·mm
    U: np.ndarray | None = None  #: (J,) the maximum-likelihood reference unbalance
    rss_min: float = math.nan
    probe_dof: np.ndarray | None = None  #: (P,) real degrees of freedom of each probe's noise level

    def __post_init__(self) -> None:
        K, S, P = self.Y.shape
        sw = 1.0 / np.sqrt(self.v)
        self._sw = sw.reshape(K, S * P).T  # (N, K)
        self._yw = (self.Y * sw).reshape(K, S * P).T  # (N, K)
        self._yy = float(np.sum(np.abs(self._yw) ** 2))
        self._scale = 1.0

    # -------------------------------------------------------------- the profiled likelihood
    def rss(self, U: np.ndarray) -> float:
        """``R(U)``: the weighted residual sum of squares with every cell's ``H`` fitted."""
        return self.rss_grad(U)[0]

    def rss_grad(self, U: np.ndarray) -> tuple[float, np.ndarray]:
        """``R(U)`` and ``g`` with ``dR = -2 Re(g . dU)`` (variable projection: ``H`` held at its optimum)."""
        D = U[None, :] + self.W  # (K, J)
        Dw = self._sw[:, :, None] * D[None, :, :]  # (N, K, J)
        Dc = Dw.conj()
        b = np.sum(Dc * self._yw[:, :, None], axis=1)  # (N, J)
        J = D.shape[1]
        if J == 1:
            a = np.sum(np.abs(Dw[:, :, 0]) ** 2, axis=1)
            H = (b[:, 0] / a)[:, None]
        elif J == 2:  # the 2 x 2 normal equations in closed form (this runs thousands of times)
            a11 = np.sum(np.abs(Dw[:, :, 0]) ** 2, axis=1)
            a22 = np.sum(np.abs(Dw[:, :, 1]) ** 2, axis=1)
            a12 = np.sum(Dc[:, :, 0] * Dw[:, :, 1], axis=1)
            det = a11 * a22 - np.abs(a12) ** 2
            if np.any(det <= 1e-300):
                return math.inf, np.zeros_like(U)
            H = np.stack([(a22 * b[:, 0] - a12 * b[:, 1]) / det, (a11 * b[:, 1] - a12.conj() * b[:, 0]) / det], axis=1)
        else:
            try:
                H = np.linalg.solve(np.einsum("nkj,nkl->njl", Dc, Dw), b[..., None])[..., 0]
            except np.linalg.LinAlgError:
                return math.inf, np.zeros_like(U)
        r = self._yw - np.sum(Dw * H[:, None, :], axis=2)
        g = np.sum((r.conj() * self._sw)[:, :, None] * H[:, None, :], axis=(0, 1))
        return float(np.sum(np.abs(r) ** 2)), g

    def _objective(self, build, jac):
        """``R`` and its gradient in the real parameters ``x`` of ``U = build(x)`` (``jac(x)``: dU/dx)."""
        def f(x: np.ndarray) -> tuple[float, np.ndarray]:
            val, g = self.rss_grad(build(x))
            if not math.isfinite(val):
                return 1e300, np.zeros_like(x)
            return val, -2.0 * np.real(jac(x) @ g)
        return f

    def _pack(self, U: np.ndarray) -> np.ndarray:
        return np.concatenate([U.real, U.imag]) / self._scale

    def _unpack(self, x: np.ndarray) -> np.ndarray:
        J = self.W.shape[1]
        return (x[:J] + 1j * x[J:]) * self._scale

    def fit(self, start: np.ndarray) -> JointUnbalance:
        """The maximum-likelihood ``U`` from a start (the two-stage estimate); returns ``self``."""
        start = np.asarray(start, dtype=complex)
        self._scale = max(float(np.max(np.abs(start))), float(np.max(np.abs(self.W))), 1e-12)
        best = None
        J = self.W.shape[1]
        dU = np.concatenate([np.eye(J), 1j * np.eye(J)]) * self._scale  # (2J, J)
        f = self._objective(self._unpack, lambda x: dU)
        for x0 in (self._pack(start), self._pack(np.zeros_like(start))):
            cand = optimize.minimize(f, x0, jac=True, method="BFGS", options={"gtol": 1e-8})
            if best is None or cand.fun < best.fun:
                best = cand
        self.U = self._unpack(best.x)
        self.rss_min = float(best.fun)
        return self

    # -------------------------------------------------------------- profiles
    def _profile(self, j: int, shift: complex, *, radius: float | None = None,
                 angle: float | None = None, warm: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """``min R`` with ``U_j + shift`` held at ``radius`` (free angle) or at ``angle`` (free radius).

        Free parameters: the held quantity's partner and the other planes' unbalance; warm
        start ``warm`` (their previous optimum).
        """
        J = self.W.shape[1]
        others = [i for i in range(J) if i != j]
        assert self.U is not None
        z_hat = self.U[j] + shift

        def build(x: np.ndarray) -> np.ndarray:
            U = np.empty(J, dtype=complex)
            if radius is not None:
                U[j] = radius * np.exp(1j * x[0]) - shift
            else:
                U[j] = math.exp(x[0]) * abs(z_hat) * np.exp(1j * angle) - shift
            for n, i in enumerate(others):
                U[i] = (x[1 + 2 * n] + 1j * x[2 + 2 * n]) * self._scale
            return U

        def jac(x: np.ndarray) -> np.ndarray:
            out = np.zeros((len(x), J), dtype=complex)
            out[0, j] = (1j * radius * np.exp(1j * x[0]) if radius is not None
                         else math.exp(x[0]) * abs(z_hat) * np.exp(1j * angle))
            for n, i in enumerate(others):
                out[1 + 2 * n, i] = self._scale
                out[2 + 2 * n, i] = 1j * self._scale
            return out

        f = self._objective(build, jac)
        default = np.concatenate([[float(np.angle(z_hat)) if radius is not None else 0.0],
                                  *[[self.U[i].real / self._scale, self.U[i].imag / self._scale] for i in others]])
        # warm start: the neighbouring point's optimum (the profile is traced outward from the estimate)
        best = optimize.minimize(f, default if warm is None else warm, jac=True, method="BFGS",
                                 options={"gtol": 1e-6})
        return float(best.fun), best.x

    def magnitude_interval(self, j: int, shift: complex, crit: float, guess: float | None = None) -> tuple[float, float]:
        """The 95 % profile interval of ``|U_j + shift|`` (``crit``: the allowed rise of ``R``).

        ``guess``: a half-width to start the search from (the first-order one).
        """
        assert self.U is not None
        z = abs(self.U[j] + shift)
        if z == 0:
            return 0.0, math.inf
        guess = guess if guess and math.isfinite(guess) and guess > 0 else 0.1 * z
        bounds = []
        for side in (-1.0, 1.0):
            warm: list[np.ndarray | None] = [None]

            def excess(d: float, side: float = side, warm: list = warm) -> float:
                val, x = self._profile(j, shift, radius=z + side * d, warm=warm[0])
                warm[0] = x
                return val - self.rss_min - crit

            limit = z * (1 - 1e-9) if side < 0 else (_UNBOUNDED - 1) * z
            bounds.append(_crossing(excess, guess, limit, crit))
        lo = 0.0 if bounds[0] is None else z - bounds[0]
        hi = math.inf if bounds[1] is None else z + bounds[1]
        return lo, hi

    def angle_interval(self, j: int, shift: complex, crit: float, guess: float | None = None) -> tuple[float, float]:
        """The 95 % profile interval of ``arg(U_j + shift)`` (radians, lead): offsets below and above.

        ``pi`` on a side where the angle is not bounded (the magnitude's interval reaches zero).
        """
        assert self.U is not None
        a = float(np.angle(self.U[j] + shift))
        guess = guess if guess and math.isfinite(guess) and guess > 0 else 0.1
        out = []
        for sign in (-1.0, 1.0):
            warm: list[np.ndarray | None] = [None]

            def excess(d: float, sign: float = sign, warm: list = warm) -> float:
                val, x = self._profile(j, shift, angle=a + sign * d, warm=warm[0])
                warm[0] = x
                return val - self.rss_min - crit

            found = _crossing(excess, min(guess, math.pi), math.pi, crit)
            out.append(math.pi if found is None else found)
        return out[0], out[1]


def _crossing(excess, guess: float, limit: float, crit: float) -> float | None:
    """The offset ``d`` in ``(0, limit]`` where ``excess`` (``-crit`` at 0) turns positive; ``None`` if never.

    Starts at ``guess`` (the first-order half-width) and steps by 1.6 inwards or outwards
    until the sign changes, then Brent's method to 0.1 % of the half-width.
    """
    memo: dict[float, float] = {}
    raw = excess

    def excess(d: float) -> float:
        if d not in memo:
            memo[d] = raw(d)
        return memo[d]

    d = min(guess, limit)
    val = excess(d)
    inside, outside = 0.0, None
    if val > 0:
        outside = d
        for _ in range(40):
            d /= 1.6
            if excess(d) <= 0:
                inside = d
                break
            outside = d
        else:
            return outside
    else:
        inside = d
        while outside is None:
            if d >= limit:
                return None
            d = min(d * 1.6, limit)
            if excess(d) > 0:
                outside = d
            else:
                inside = d
    memo.setdefault(0.0, -crit)
    return float(optimize.brentq(excess, inside, outside, xtol=1e-3 * guess))


def fit_joint(Y: np.ndarray, v: np.ndarray, W: np.ndarray, start: np.ndarray) -> JointUnbalance:
    """:class:`JointUnbalance` fitted from the two-stage estimate ``start``."""
    model = JointUnbalance(np.asarray(Y, dtype=complex), np.asarray(v, dtype=float), np.asarray(W, dtype=complex))
    model.fit(start)
    return model


def joint_variances(fit) -> JointUnbalance:
    """The joint model of an :class:`~.influence.InfluenceFit`'s campaign, with its noise levels.

    With repeats the variance of one acquisition is pooled per probe over every speed and run
    (the weights of the two-stage fit make the same assumption): per-cell variances with a
    dozen degrees of freedom as the likelihood's weights inflate its deviance by
    ``nu / (nu - 2)`` where they happen to be low — the profile intervals covered 88 % with
    them, 93 % pooled (two planes, 10 µm, two repeats; measured).  ``probe_dof``: each
    probe's pooled degrees of freedom.  Without repeats, the influence fit's own level.
    """
    data = fit.data
    if fit.variance_source == "repeats" and data.cell_dof is not None:
        one = (data.var * data.n)[0]  # (S, P): one acquisition's variance per cell
        probe_dof = np.sum(data.cell_dof, axis=0).astype(float)  # (P,)
        level = np.sum(one * data.cell_dof, axis=0) / probe_dof
        v = level[None, None, :] / data.n
    else:
        v = fit.v
        probe_dof = np.full(data.Y.shape[2], float(fit.dof))
    model = JointUnbalance(np.asarray(data.Y, dtype=complex), np.asarray(v, dtype=float),
                           np.asarray(fit.W, dtype=complex))
    model.probe_dof = probe_dof
    return model
