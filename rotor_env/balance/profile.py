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

The minimiser
-------------
``R`` is minimised (the estimate, and every point of a profile) by Newton's method on the
exact Hessian of the variable-projection functional, damped Levenberg-Marquardt fashion (a
multiple of the identity added until the Hessian is positive definite and the step lowers
``R``).  Per cell ``n`` (weights ``s``, residual ``r_n``, ``M_n`` the inverse of the weighted
normal matrix, ``c_n = s^T r_n``, ``q_n = D_n^H s``, ``m_n = M_n q_n``,
``tau_n = |s|^2 - q_n^H m_n``) the gradient is ``g = \sum_n conj(c_n) H_n``
(``dR = -2 Re(g . dU)``) and

.. math::  dg = P\,dU + Q\,\overline{dU}, \quad P = -\sum_n \overline{c_n} (H_n m_n^T + m_n H_n^T),
           \quad Q = \sum_n (|c_n|^2 M_n - \tau_n H_n H_n^H)

(``H`` moves with ``U``).  The ``tau`` term alone is Kaufman's Gauss-Newton approximation; the
terms it drops vanish only with the residuals, which are noise here, not small, so
Gauss-Newton would converge linearly where Newton converges quadratically.  Why Newton: a
profile point starts from its neighbour's optimum, and Newton gets there in about three steps
(3.9 evaluations a point on average for two planes, 2.4 for one, coverage study seeds
100-139); BFGS took about 28, and scipy's line search around them dominated the intervals'
cost (``coverage_study(range(100, 140), planes=2)``: 46 s with BFGS, 5.2 s with Newton,
intervals equal to 2e-6 relative).  The
stopping test is BFGS's (the gradient's largest component), or the rounding floor: where two
planes act alike the normal equations are ill-conditioned and the gradient cannot get under
about 1e-5 (BFGS stopped there too, on a failed line search).  Far out on an unbounded profile
(an unbalance hundreds of times the trial weights) the planes' designs are so nearly collinear
that the Hessian's terms cancel to rounding noise: there, and where Newton does not converge,
BFGS takes over as before (its intervals there hang on rounding: a relative 1e-15 on ``R``
moves an angle bound between 137 degrees and unbounded, measured).

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


class _IllConditioned(Exception):
    """The normal equations too near singular for Newton's Hessian (:meth:`JointUnbalance._cells`)."""

#: a magnitude interval is called unbounded beyond this many times the estimate
_UNBOUNDED = 1e3
#: an angle profile's optimum below this log of the radius (over the estimate's) has collapsed
#: towards zero and does not start the next point
_COLLAPSED_LOG_RADIUS = -5.0


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
        self._s2 = self._sw ** 2
        self._sy = self._sw * self._yw
        self._ss = self._s2.sum(axis=1)  # (N,)
        self._scale = 1.0

    # -------------------------------------------------------------- the profiled likelihood
    def rss(self, U: np.ndarray) -> float:
        """``R(U)``: the weighted residual sum of squares with every cell's ``H`` fitted."""
        return self.rss_grad(U)[0]

    def _cells(self, U: np.ndarray, second: bool = False):
        """``R(U)``, ``g`` and (``second``) the Hessian's ``P``, ``Q`` with ``dg = P dU + Q conj(dU)``.

        The minimiser's terms (module docstring); ``None`` where a normal matrix is singular;
        :class:`_IllConditioned` for the Hessian where one is nearly so (its determinant under
        1e-5 of its diagonal's product: the planes' designs within 0.3 % of collinear, an
        unbalance hundreds of times the trial weights, where the Hessian's terms cancel to noise).
        Every cell's weighted design is ``s_k (U + W_k)``, so its sums are the weights'
        matrix products with ``D = U + W`` (no (N, K, J) array: this runs thousands of times).
        """
        D = U[None, :] + self.W  # (K, J)
        Dc = D.conj()
        J = D.shape[1]
        b = self._sy @ Dc  # (N, J): Dw^H yw
        e = self._s2 @ D  # (N, J): Dw^T s
        if J == 1:
            a = self._s2 @ (D.real[:, 0] ** 2 + D.imag[:, 0] ** 2)
            if not a.min() > 1e-300:
                return None
            M = (1.0 / a)[:, None, None]
            H = b / a[:, None]
            hadamard = 1.0
        elif J == 2:  # the 2 x 2 normal equations in closed form
            a11 = self._s2 @ (D.real[:, 0] ** 2 + D.imag[:, 0] ** 2)
            a22 = self._s2 @ (D.real[:, 1] ** 2 + D.imag[:, 1] ** 2)
            a12 = self._s2 @ (Dc[:, 0] * D[:, 1])
            det = a11 * a22 - (a12.real ** 2 + a12.imag ** 2)
            if not det.min() > 1e-300:
                return None
            M = np.empty((len(det), 2, 2), dtype=complex)
            M[:, 0, 0], M[:, 0, 1], M[:, 1, 0], M[:, 1, 1] = a22, -a12, -a12.conj(), a11
            M /= det[:, None, None]
            H = (M @ b[:, :, None])[:, :, 0]
            hadamard = float((det / (a11 * a22)).min())
        else:
            A = (self._s2 @ (Dc[:, :, None] * D[:, None, :]).reshape(len(D), J * J)).reshape(-1, J, J)
            try:
                M = np.linalg.inv(A)
            except np.linalg.LinAlgError:
                return None
            H = (M @ b[:, :, None])[:, :, 0]
            hadamard = float((np.linalg.det(A).real / np.prod(np.diagonal(A, axis1=1, axis2=2).real, axis=1)).min())
        r = self._yw - self._sw * (H @ D.T)  # (N, K)
        c = (self._sw * r).sum(axis=1)  # (N,): s^T r
        cc = c.conj()
        g = cc @ H
        val = float((r.real ** 2 + r.imag ** 2).sum())
        if not second:
            return val, g
        m = (M @ e.conj()[:, :, None])[:, :, 0]  # M q, q = Dw^H s
        tau = self._ss - (e * m).sum(axis=1).real  # s^T (I - projection) s
        P = H.T @ (cc[:, None] * m)
        P = -(P + P.T)
        Q = ((c.real ** 2 + c.imag ** 2) @ M.reshape(len(c), J * J)).reshape(J, J) - (H.T * tau) @ H.conj()
        if hadamard < 1e-5:
            raise _IllConditioned
        return val, g, P, Q

    def rss_grad(self, U: np.ndarray) -> tuple[float, np.ndarray]:
        """``R(U)`` and ``g`` with ``dR = -2 Re(g . dU)`` (variable projection: ``H`` held at its optimum)."""
        out = self._cells(U)
        return (math.inf, np.zeros_like(U)) if out is None else out

    def _objective(self, build):
        """``R`` and its gradient in the real parameters ``x`` of ``U, dU/dx, _ = build(x)`` (for BFGS)."""
        def f(x: np.ndarray) -> tuple[float, np.ndarray]:
            U, T, _ = build(x)
            val, g = self.rss_grad(U)
            if not math.isfinite(val):
                return 1e300, np.zeros_like(x)
            return val, -2.0 * np.real(T @ g)
        return f

    def _minimise(self, build, x0: np.ndarray, gtol: float) -> tuple[float, np.ndarray]:
        """``min R`` over the real parameters ``x`` of ``U, T, U2 = build(x)`` from ``x0``: damped Newton.

        ``T`` (p, J): ``dU/dx``; ``U2`` (J,): ``d^2U/dx_0^2`` (the only non-linear parameter).
        Stops where the gradient's largest component is under ``gtol`` (BFGS's test) or, the
        rounding floor, where it is under ``1e3 gtol`` and the step fails to lower ``R`` while
        the iteration's first (least damped) step promised less than ``1e-10 (1 + R)``.  BFGS
        (as before the Newton steps), from the last accepted point, where Newton does not get
        there or the normal equations are nearly singular (:class:`_IllConditioned`).
        """
        def evaluate(x):
            try:
                U, T, U2 = build(x)
            except OverflowError:  # a step to a radius beyond floating point: rejected, damped
                return math.inf, None, None
            if not float(np.max(np.abs(U))) < 1e100:  # as would be its squares
                return math.inf, None, None
            out = self._cells(U, second=True)
            if out is None or not math.isfinite(out[0]):
                return math.inf, None, None
            val, g, P, Q = out
            grad = -2.0 * np.real(T @ g)
            hess = -2.0 * np.real(T @ P @ T.T + T @ Q @ T.conj().T)
            hess[0, 0] -= 2.0 * float(np.real(U2 @ g))
            return val, grad, hess

        x = np.asarray(x0, dtype=float)
        try:
            f, grad, hess = evaluate(x)
            if not math.isfinite(f):  # as BFGS: a singular start has no gradient to follow
                return 1e300, x
            eye = np.eye(len(x))
            lam = 0.0
            for _ in range(60):
                if float(np.max(np.abs(grad))) <= gtol:
                    return f, x
                promise = None  # the decrease the first step of this iteration's model promised
                while True:  # Levenberg-Marquardt: raise the damping until the step lowers R
                    try:
                        L = np.linalg.cholesky(hess + lam * eye)
                    except np.linalg.LinAlgError:
                        if lam > 1e20:
                            return self._bfgs(build, x, gtol)
                        lam = max(4.0 * lam, 1e-6 * float(np.max(np.abs(np.diag(hess)))), 1e-12)
                        continue
                    step = -np.linalg.solve(L.T, np.linalg.solve(L, grad))
                    if promise is None:
                        promise = -float(grad @ step)
                    f_new, grad_new, hess_new = evaluate(x + step)
                    if f_new <= f:
                        break
                    if promise <= 1e-10 * (1.0 + abs(f)):
                        if float(np.max(np.abs(grad))) <= 1e3 * gtol:
                            # the rounding floor (BFGS stops there too, on a failed line search): where
                            # two planes act alike the normal equations put ~1e-5 of noise on the gradient
                            return f, x
                        return self._bfgs(build, x, gtol)
                    if lam > 1e20:
                        return self._bfgs(build, x, gtol)
                    lam = max(4.0 * lam, 1e-6 * float(np.max(np.abs(np.diag(hess)))), 1e-12)
                x, f, grad, hess = x + step, f_new, grad_new, hess_new
                lam = 0.0 if lam < 1e-6 else lam / 16.0
        except _IllConditioned:
            pass
        return self._bfgs(build, x, gtol)

    def _bfgs(self, build, x0: np.ndarray, gtol: float) -> tuple[float, np.ndarray]:
        best = optimize.minimize(self._objective(build), x0, jac=True, method="BFGS", options={"gtol": gtol})
        return float(best.fun), best.x

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
        flat = np.zeros(J, dtype=complex)

        def build(x: np.ndarray):
            return self._unpack(x), dU, flat

        for x0 in (self._pack(start), self._pack(np.zeros_like(start))):
            cand = self._minimise(build, x0, 1e-8)
            if best is None or cand[0] < best[0]:
                best = cand
        self.U = self._unpack(best[1])
        self.rss_min = float(best[0])
        return self

    # -------------------------------------------------------------- profiles
    def _profile(self, j: int, shift: complex, *, radius: float | None = None,
                 angle: float | None = None, warm: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """``min R`` with ``U_j + shift`` held at ``radius`` (free angle) or at ``angle`` (free radius).

        Free parameters: the held quantity's partner (the angle, or the log of the radius over
        the estimate's) and the other planes' unbalance; warm start ``warm`` (their previous
        optimum).
        """
        J = self.W.shape[1]
        others = [i for i in range(J) if i != j]
        assert self.U is not None
        z_hat = self.U[j] + shift
        p = 1 + 2 * len(others)
        T = np.zeros((p, J), dtype=complex)  # dU/dx: constant but for the held plane's column
        for n, i in enumerate(others):
            T[1 + 2 * n, i] = self._scale
            T[2 + 2 * n, i] = 1j * self._scale
        ray = abs(z_hat) * np.exp(1j * angle) if radius is None else 0.0

        def build(x: np.ndarray):
            U = np.empty(J, dtype=complex)
            U2 = np.zeros(J, dtype=complex)
            if radius is not None:
                e = radius * np.exp(1j * x[0])
                T[0, j], U2[j] = 1j * e, -e
            else:
                e = math.exp(x[0]) * ray
                T[0, j], U2[j] = e, e
            U[j] = e - shift
            for n, i in enumerate(others):
                U[i] = (x[1 + 2 * n] + 1j * x[2 + 2 * n]) * self._scale
            return U, T, U2

        default = np.concatenate([[float(np.angle(z_hat)) if radius is not None else 0.0],
                                  *[[self.U[i].real / self._scale, self.U[i].imag / self._scale] for i in others]])
        # warm start: the neighbouring point's optimum (the profile is traced outward from the estimate)
        return self._minimise(build, default if warm is None else warm, 1e-6)

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
                # a point whose optimum collapsed towards zero radius (log-radius -20) is no
                # start for the next: there the gradient is ~e^(log-radius), under the
                # tolerance, and every later point stayed on that plateau (a low-SNR seed's
                # angle bound read 49.88 deg where the profile crosses at 51.27)
                warm[0] = x if x[0] > _COLLAPSED_LOG_RADIUS else None
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
