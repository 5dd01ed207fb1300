r"""Influence coefficients by weighted least squares, the unbalance of every run, and
first-order uncertainties.

The influence model
-------------------
At speed ``s`` probe ``p`` reads the 1X vector (lead convention, the table's unit)

.. math::  X_{k,sp} = X_{0,sp} + \sum_j H_{sp,j} W_{kj} + n_{k,sp}

for run ``k`` with trial unbalances ``W_kj`` (g·mm, complex, :meth:`Campaign.trial_matrix`;
``W_0 = 0`` for the reference), influence coefficients ``H`` (table unit per g·mm) and
circular noise ``n`` of variance ``v_{k,sp} = E|n|^2`` (the repeats' pooled scatter
divided by their number).  Per speed and probe this is a complex linear regression of
the ``K`` runs on the design ``A = [1, W]`` (``K x (J+1)``); its weighted least squares
(weights ``1/v``) is

.. math::  \hat\theta_{sp} = (A^H V^{-1} A)^{-1} A^H V^{-1} y_{sp} = L_{sp}\, y_{sp},
   \qquad \mathrm{Cov}\,\hat\theta_{sp} = (A^H V^{-1} A)^{-1}

(exact: ``A`` holds the weights, known).  ``K > J + 1`` leaves ``2(K - J - 1)`` real
degrees of freedom per speed and probe for the misfit (:mod:`.misfit`).

The unbalance
-------------
A run's total unbalance ``U_k`` (g·mm per plane) is what makes its vibration,
``X_k ≈ H U_k`` at every speed and probe at once (``N = S P`` complex equations, ``J``
unknowns), solved by weighted least squares with the weights ``w_sp = mean_k n_{k,sp} / sigma_p^2``
(``sigma_p^2``: probe ``p``'s scatter of one acquisition pooled over all speeds — weights
from a dozen degrees of freedom per cell would bias the intervals low):
``U_k = G X_k``, ``G = (H^H W H)^{-1} H^H W``.  The reference's unbalance ``U_0 = G X_0``
uses the fitted reference response; the correction is ``-U_0`` and the predicted residual
vibration ``(I - H G) X_0``.  ``cond(W^{1/2} H)`` (columns scaled to unit norm) is the
condition number: large means two planes act alike at the probes and speeds measured.

What the intervals cover
------------------------
Every estimate is a function of the mean vectors ``y``.  To first order (the terms with
the model's residual, of the noise's size, dropped),

.. math::  dU_k = \sum_{sp} G_{:,sp}\; a_{sp}^T dy_{sp},\qquad a_{sp} = c_k - L_{sp,1:}^T U_k

(``c_k`` picks the run's response from ``y``: ``e_k`` for a measured run, ``L_{sp,0}`` for
the fitted reference) — complex-linear in the independent circular ``dy``, so
``Cov U_k = G\,\mathrm{diag}(q)\,G^H`` with ``q_{sp} = \sum_k |a_{sp,k}|^2 v_{k,sp}``; the
residual vibration's is ``|I - H G|^2 q``.  The 95 % intervals are ``t_{0.975,\nu}`` times
the standard error of the magnitude (radial) and of the angle (tangential over the
magnitude), ``nu`` the Welch-Satterthwaite degrees of freedom of the estimate's variance
(each cell's pooled scatter has ``2 sum (n - 1)``: circular noise).  They cover the
measurement noise as the repeats show it; not a model that does not hold (see the
misfit), not the placement of the weights, not a drift between runs the repeats do not
see.  Coverage is checked by simulation (tests/test_balance.py,
benchmarks/balance_coverage.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from .runs import BalanceData, BalanceError, Campaign

__all__ = ["InfluenceFit", "fit_influence", "t_quantile"]


def t_quantile(dof: float, level: float = 0.95) -> float:
    """Two-sided quantile: Student's t with the scatter's degrees of freedom, normal without."""
    q = 0.5 + level / 2
    return float(stats.t.ppf(q, dof)) if dof > 0 else float(stats.norm.ppf(q))


@dataclass(frozen=True)
class InfluenceFit:
    """The influence model fitted to a campaign (shapes: runs K, speeds S, probes P, planes J)."""

    data: BalanceData
    campaign: Campaign
    W: np.ndarray  #: (K, J) trial unbalance, g·mm, lead convention
    theta: np.ndarray  #: (S, P, J+1): X0 then H per plane
    cov_theta: np.ndarray  #: (S, P, J+1, J+1) complex covariance
    L: np.ndarray  #: (S, P, J+1, K): theta = L y
    v: np.ndarray  #: (K, S, P) variance of every mean vector used
    residual: np.ndarray  #: (K, S, P) y - A theta
    leverage: np.ndarray  #: (K, S, P)
    G: np.ndarray  #: (J, N) unbalance from a response
    condition_number: float
    calibration_condition_number: float
    variance_source: str  #: "repeats", "residuals" or "none"
    dof: int  #: smallest real degrees of freedom of a cell's variance (0: normal quantile, or none)
    phase: str = "lag"
    cell_dof: np.ndarray | None = None  #: (S, P) real degrees of freedom of each cell's variance
    w: np.ndarray | None = None  #: (N,) weights of the unbalance fit

    def satterthwaite(self, contrib: np.ndarray) -> np.ndarray:
        """Welch-Satterthwaite degrees of freedom of variances ``sum_sp contrib[..., sp]``.

        ``contrib[..., sp]``: the share of cell ``sp``'s (independent, estimated) variance;
        ``nu = (sum c)^2 / sum(c^2 / nu_sp)`` — an estimate resting on many cells has more
        degrees of freedom than any one of them.
        """
        if self.cell_dof is None or self.dof <= 0:
            return np.full(contrib.shape[:-1], float(self.dof))
        nu = self.cell_dof.reshape(-1).astype(float)
        c = np.asarray(contrib, dtype=float)
        den = np.sum(c ** 2 / nu, axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = np.sum(c, axis=-1) ** 2 / den
        return np.where(den > 0, out, float(self.dof))

    def unbalance_dof(self, c: np.ndarray, U: np.ndarray) -> np.ndarray:
        """Degrees of freedom (J,) of the unbalance's variance (:meth:`satterthwaite`)."""
        q = self._q(c, U)
        return self.satterthwaite(np.abs(self.G) ** 2 * q[None, :])

    def residual_dof(self, c: np.ndarray, U: np.ndarray) -> np.ndarray:
        """Degrees of freedom (S, P) of the residual vibration's variance."""
        S, P, _ = self.H.shape
        M = np.eye(S * P) - self.Hmat @ self.G
        return self.satterthwaite(np.abs(M) ** 2 * self._q(c, U)[None, :]).reshape(S, P)

    @property
    def X0(self) -> np.ndarray:
        return self.theta[..., 0]

    @property
    def H(self) -> np.ndarray:
        return self.theta[..., 1:]

    @property
    def Hmat(self) -> np.ndarray:
        """(N, J): H with speed and probe flattened (speed-major)."""
        S, P, J = self.H.shape
        return self.H.reshape(S * P, J)

    def unbalance(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unbalance (J,) and its complex covariance (J, J) of the response ``sum_k c[s,p,k] y_k``.

        ``c``: (S, P, K) combination of the runs (a measured run: one-hot; the fitted
        reference: ``L[..., 0, :]``).
        """
        S, P, J = self.H.shape
        X = np.einsum("spk,ksp->sp", c, self.data.Y).reshape(-1)
        U = self._corrected(c, X)
        q = self._q(c, U)
        cov = (self.G * q[None, :]) @ self.G.conj().T
        return U, cov

    def noise_terms(self, c: np.ndarray, U: np.ndarray) -> np.ndarray:
        """``q_sp`` (N,): each cell's share of the noise of an unbalance ``U`` of the response ``c``."""
        return self._q(c, U)

    def unbalance_covariance(self, c: np.ndarray, U: np.ndarray) -> np.ndarray:
        """First-order complex covariance (J, J) of an unbalance ``U`` of the response ``c``."""
        q = self._q(c, U)
        return (self.G * q[None, :]) @ self.G.conj().T

    def _corrected(self, c: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Least squares of ``X ≈ H U`` corrected for the noise of ``H`` (errors in variables).

        With noisy coefficients ``E[Ĥ^H W Ĥ] = H^H W H + sum_sp w_sp E[dH* dH^T]`` — the
        normal matrix grows by the coefficients' noise and the unbalance shrinks towards
        zero (regression dilution; tens of standard errors where a plane's influence on
        some probe is small against the noise) — and ``Ĥ^H W X̂`` gains
        ``sum_sp w_sp E[dH* dX]`` (both come from the same runs).  Both expectations are
        known from the influence regression (``Cov theta``, ``L``, ``v``) and subtracted
        (Fuller's corrected least squares); where the corrected normal matrix would lose
        more than half of any eigenvalue, the plain weighted least squares is kept.
        """
        if self.w is None or self.variance_source == "none":
            return self.G @ X
        S, P, J = self.H.shape
        w = self.w.reshape(S, P)
        H = self.Hmat
        A = (H.conj().T * self.w[None, :]) @ H
        b = (H.conj().T * self.w[None, :]) @ X
        # E[conj(dH_i) dH_j] = cov[j, i]; E[conj(dH_i) dX] = sum_k c_k conj(L[1+i, k]) v_k
        B = np.einsum("sp,spji->ij", w, self.cov_theta[:, :, 1:, 1:])
        d = np.einsum("sp,spk,spik,ksp->i", w, c, np.conj(self.L[:, :, 1:, :]), self.v)
        Ac = A - B
        ev_a = np.linalg.eigvalsh(A)
        ev_c = np.linalg.eigvalsh(0.5 * (Ac + Ac.conj().T))
        if ev_c.min() < 0.5 * ev_a.min():
            return self.G @ X
        return np.linalg.solve(Ac, b - d)

    def _q(self, c: np.ndarray, U: np.ndarray) -> np.ndarray:
        """``q_sp = sum_k |a_sp,k|^2 v_k,sp``, ``a_sp = c_sp - L_sp,1:^T U`` (module docstring)."""
        a = c - np.einsum("spjk,j->spk", self.L[:, :, 1:, :], U)
        return np.einsum("spk,ksp->sp", np.abs(a) ** 2, self.v).reshape(-1)

    def residual_vibration(self, c: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted vibration after removing ``U`` from the response ``c``: (S, P) and its variance."""
        S, P, J = self.H.shape
        X = np.einsum("spk,ksp->sp", c, self.data.Y).reshape(-1)
        M = np.eye(S * P) - self.Hmat @ self.G
        R = X - self.Hmat @ U
        var = (np.abs(M) ** 2) @ self._q(c, U)
        return R.reshape(S, P), var.reshape(S, P)

    def run_combination(self, k: int) -> np.ndarray:
        S, P = self.H.shape[:2]
        c = np.zeros((S, P, len(self.data.runs)))
        c[..., k] = 1.0
        return c

    def reference_combination(self) -> np.ndarray:
        return self.L[:, :, 0, :]


def fit_influence(data: BalanceData, campaign: Campaign, *, phase: str = "lag") -> InfluenceFit:
    """Weighted least squares of the influence model (module docstring) for every speed and probe."""
    W = campaign.trial_matrix(phase)
    K, J = W.shape
    names = campaign.plane_names
    for j, name in enumerate(names):
        if not np.any(W[:, j] != 0):
            raise BalanceError(f"{campaign.source}: plane {name!r}: no calibration run puts a trial weight on it, "
                               "so its influence cannot be measured (add a run with a weight on it under 'runs', "
                               "or remove the plane)")
    A = np.column_stack([np.ones(K), W])
    scaled = A / np.linalg.norm(A, axis=0)
    sv = np.linalg.svd(scaled, compute_uv=False)
    cal_cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    if K < J + 1 or cal_cond > 1e8:
        raise BalanceError(f"{campaign.source}: the calibration runs cannot separate the planes {list(names)} "
                           f"(condition number {cal_cond:.3g}): every plane needs a run whose weights are not "
                           "a combination of the other runs' (e.g. one trial weight per plane, one plane at a time)")
    Y = data.Y
    _, S, P = Y.shape
    if data.dof > 0:
        v = data.var.copy()
        source, dof = "repeats", data.dof
    else:
        v = np.ones_like(data.var)
        source, dof = ("residuals", 2 * (K - J - 1) * S * P) if K > J + 1 else ("none", 0)
    theta = np.zeros((S, P, J + 1), dtype=complex)
    cov = np.zeros((S, P, J + 1, J + 1), dtype=complex)
    L = np.zeros((S, P, J + 1, K), dtype=complex)
    lev = np.zeros((K, S, P))
    for s in range(S):
        for p in range(P):
            w = 1.0 / v[:, s, p]
            AhW = A.conj().T * w[None, :]
            C = np.linalg.inv(AhW @ A)
            L[s, p] = C @ AhW
            theta[s, p] = L[s, p] @ Y[:, s, p]
            cov[s, p] = C
            lev[:, s, p] = np.real(np.einsum("kj,jk->k", A, L[s, p]))
    resid = Y - np.einsum("kj,spj->ksp", A, theta)
    if source == "residuals":
        # no repeats: the scale of the noise from the influence residuals (one level for all)
        s2 = float(np.sum(np.abs(resid) ** 2) / max(1, (K - J - 1) * S * P))
        v = v * s2
        cov = cov * s2
    H = theta[..., 1:].reshape(S * P, J)
    # the weights of the unbalance fit: the noise level per probe, pooled over its speeds, over
    # the repeats averaged.  Per-cell variances (a dozen degrees of freedom) as weights would
    # favour the cells whose scatter happens to be low *and* claim their low variance: the
    # intervals would cover 90 % instead of 95 % (measured); the per-cell variances still
    # give the intervals (the sandwich G diag(q) G^H holds for any fixed weights)
    if source == "repeats" and data.cell_dof is not None:
        pooled = (data.var * data.n)[0]  # (S, P): one acquisition's variance per cell
        level = np.sum(pooled * data.cell_dof, axis=0) / np.sum(data.cell_dof, axis=0)  # (P,)
        wsp = (np.mean(data.n, axis=0) / level[None, :]).reshape(-1)
    else:
        wsp = 1.0 / v.mean(axis=0).reshape(-1)
    Hw = H * np.sqrt(wsp)[:, None]
    colnorm = np.linalg.norm(Hw, axis=0)
    for j, name in enumerate(names):
        if colnorm[j] == 0 or not np.isfinite(colnorm[j]):
            raise BalanceError(f"{campaign.source}: plane {name!r}: its trial weights changed no probe's vibration "
                               f"in {data.source}")
    svh = np.linalg.svd(Hw / colnorm, compute_uv=False)
    cond = float(svh[0] / svh[-1]) if svh[-1] > 0 else math.inf
    G = np.linalg.pinv(Hw) * np.sqrt(wsp)[None, :]
    cell_dof = data.cell_dof if source == "repeats" else None
    return InfluenceFit(data, campaign, W, theta, cov, L, v, resid, lev, G, cond, cal_cond, source, dof, phase,
                        cell_dof, wsp)


def visibility(fit: InfluenceFit) -> list[dict]:
    """Per plane: the Wald test that its influence is zero at every speed and probe.

    ``chi2 = sum_sp |H_sp,j|^2 / Var H_sp,j`` (each term ``chi2_2 / 2`` under the null):
    a plane whose trial weights moved no probe beyond the scatter is not seen by the
    calibration (its correction would be noise).
    """
    out = []
    S, P, J = fit.H.shape
    for j, name in enumerate(fit.campaign.plane_names):
        var = np.real(fit.cov_theta[:, :, 1 + j, 1 + j])
        z2 = np.abs(fit.H[:, :, j]) ** 2 / var
        stat = float(2 * z2.sum())
        dfn = 2 * S * P
        if fit.dof > 0 and fit.variance_source == "repeats":
            p = float(stats.f.sf(stat / dfn, dfn, float(fit.satterthwaite(var.reshape(-1)))))
        else:
            p = float(stats.chi2.sf(stat, dfn))
        out.append({"plane": name, "chi2": stat, "dof": dfn, "p_value": p,
                    "snr": float(math.sqrt(z2.max())), "rms_snr": float(math.sqrt(z2.mean()))})
    return out
