"""Statistics that stay valid when the residuals are autocorrelated (HAC / Newey–West).

The residual of a real fit is not white: a model that is nearly right leaves a slowly
varying misfit, measured rates are smoothed, and a prefilter colours the noise.  The
ordinary ``(X'X)^-1 s^2`` covariance and the partial F then count 58 000 correlated
rows as 58 000 independent ones and overstate the evidence by orders of magnitude.

We use the heteroskedasticity- and autocorrelation-consistent (HAC) long-run
covariance of the score ``u_t = x_t e_t`` with the Bartlett kernel (Newey & West,
1987)::

    S = sum_{|k| <= L} (1 - |k|/(L+1)) Gamma_k,     Gamma_k = sum_t u_t u_{t-k}'

so that ``Cov(theta_hat) = (X'X)^-1 S (X'X)^-1`` (the sandwich), and test a group of
coefficients by the Wald statistic ``theta_g' Cov_gg^-1 theta_g`` (chi-square with
``q`` degrees of freedom; reported as ``F = W/q``).  Adding candidate columns ``Z`` to
a fitted model is tested by the score (Lagrange multiplier) form of the same
statistic: with ``Z~`` the part of ``Z`` orthogonal to the model's columns and ``e``
the model's residual, ``s = Z~'e`` and ``LM = s' S_z^-1 s`` — it needs only the
fitted model, so ranking many candidates costs one projection each.

Why Bartlett/Newey–West rather than an effective sample size from the residual's
autocorrelation alone: the variance of ``sum x_t e_t`` depends on the
autocorrelation of the *product* (an oscillating regressor meets the residual's
spectrum at its own frequency), which a single inflation factor of the residual
cannot know.  Why not a block bootstrap: it costs hundreds of refits per test.

Bandwidth ``L``: Andrews' (1991) AR(1) plug-in rule for the Bartlett kernel,
``L = 1.1447 (alpha m)^(1/3)``, ``alpha = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2)``
averaged over the score's columns, clipped to ``[1, m/4]``.  ``statsmodels``'
``S_hac_simple`` computes the same sum with one matrix product per lag (O(m q^2 L));
slowly decaying residuals need ``L`` in the hundreds, so the lag sum is done here with
FFTs (O(q^2 m log m)); the tests check both agree.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal as sp_signal
from scipy import stats

__all__ = [
    "andrews_bandwidth",
    "chi2_log10_sf",
    "hac_covariance",
    "long_run_covariance",
    "score_test",
    "time_scores",
    "wald_group_test",
    "wald_test",
]


def andrews_bandwidth(u: np.ndarray) -> int:
    """Andrews' AR(1) plug-in bandwidth for the Bartlett kernel (rows of ``u`` = time)."""
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    m = u.shape[0]
    if m < 4:
        return 1
    num = den = 0.0
    for j in range(u.shape[1]):
        a, b = u[1:, j], u[:-1, j]
        bb = float(b @ b)
        if bb <= 0.0:
            continue
        rho = min(max(float(a @ b) / bb, -0.999), 0.999)
        resid = a - rho * b
        s2 = float(resid @ resid) / len(a)
        w = s2 * s2 / (1.0 - rho) ** 4  # Andrews' weights (the AR(1) long-run variance squared)
        num += w * 4.0 * rho * rho / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
        den += w
    alpha = num / den if den > 0 else 0.0
    L = 1.1447 * (alpha * m) ** (1.0 / 3.0)
    return int(min(max(1, math.ceil(L)), max(1, m // 4)))


def long_run_covariance(u: np.ndarray, bandwidth: int | None = None) -> np.ndarray:
    """Bartlett-weighted sum of the autocovariances of ``u`` (shape ``(m, q)``), lags ``<= L``.

    Equals ``statsmodels.stats.sandwich_covariance.S_hac_simple(u, nlags=L)`` (a sum, not
    a mean: it pairs with ``X'X``).
    """
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    m, q = u.shape
    L = andrews_bandwidth(u) if bandwidth is None else int(bandwidth)
    L = max(0, min(L, m - 1))
    # sum_{l=1..L} w_l Gamma_l = u' V with V[s] = sum_l w_l u[s - l] (u filtered by the
    # Bartlett weights: one FFT convolution per column), and Gamma_{-l} = Gamma_l', so
    # S = u'u + u'V + V'u: two products instead of q^2 cross-correlations
    S = u.T @ u
    if L > 0:
        w = 1.0 - np.arange(1, L + 1) / (L + 1.0)
        V = sp_signal.oaconvolve(u, np.concatenate([[0.0], w])[:, None], mode="full", axes=0)[:m]
        P = u.T @ V
        S = S + P + P.T
    return S


def time_scores(u: np.ndarray, rows_per_time: int = 1) -> np.ndarray:
    """Score rows summed per time step.

    A regression with several equations per sample (``rows_per_time`` consecutive
    rows) is a time series of *samples*, not of rows: interleaved, the rows of two
    nearly independent equations would look uncorrelated at lag 1 and the bandwidth
    rule would pick a tiny lag window, blind to the correlation over time.  The sum
    ``sum_t u_t`` is the same either way.
    """
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    g = int(rows_per_time)
    if g <= 1:
        return u
    if u.shape[0] % g:
        raise ValueError(f"{u.shape[0]} rows are not a whole number of {g}-row samples")
    return u.reshape(-1, g, u.shape[1]).sum(axis=1)


def hac_covariance(X: np.ndarray, resid: np.ndarray, bandwidth: int | None = None,
                   rows_per_time: int = 1) -> np.ndarray:
    """Sandwich covariance ``(X'X)^-1 S (X'X)^-1`` of least-squares coefficients
    (``rows_per_time``: equations per sample, see :func:`time_scores`)."""
    X = np.asarray(X, dtype=float)
    u = time_scores(X * np.asarray(resid, dtype=float)[:, None], rows_per_time)
    S = long_run_covariance(u, bandwidth)
    Xi = np.linalg.pinv(X.T @ X)
    return Xi @ S @ Xi


def chi2_log10_sf(stat: float, q: int) -> float:
    """log10 of the chi-square survival function, finite far into the tail."""
    if not math.isfinite(stat):
        return 0.0 if stat < 0 else -math.inf
    x = max(stat, 0.0)
    v = float(stats.chi2.logsf(x, q))
    if not math.isfinite(v):
        # the tail's leading term: Q(a, z) ~ z^(a-1) e^-z / Gamma(a), a = q/2, z = x/2
        a, z = 0.5 * q, 0.5 * x
        v = (a - 1.0) * math.log(z) - z - math.lgamma(a)
    return v / math.log(10.0)


def wald_test(theta: np.ndarray, cov: np.ndarray) -> tuple[float, float]:
    """``(F, log10 p)`` of ``theta = 0`` with covariance ``cov`` (``F = W/q``, chi-square p)."""
    theta = np.atleast_1d(np.asarray(theta, dtype=float))
    q = len(theta)
    W = float(theta @ np.linalg.pinv(np.atleast_2d(cov)) @ theta)
    return W / q, chi2_log10_sf(W, q)


def wald_group_test(X: np.ndarray, resid: np.ndarray, theta_group: np.ndarray, group,
                    bandwidth: int | None = None, rows_per_time: int = 1) -> tuple[float, float]:
    """HAC Wald test ``(F, log10 p)`` that the coefficients ``theta_group`` of columns
    ``group`` (indices) of the least-squares fit ``X`` with residual ``resid`` are zero.

    Only the group's block of the sandwich is needed: with ``A`` the group's rows of
    ``(X'X)^-1``, ``Cov_gg = A S A'`` is the long-run covariance of the ``q``-dimensional
    series ``(A x_t) e_t`` — ``q^2`` lag sums instead of ``n^2``.
    """
    X = np.asarray(X, dtype=float)
    A = np.linalg.pinv(X.T @ X)[list(group)]
    u = time_scores((X @ A.T) * np.asarray(resid, dtype=float)[:, None], rows_per_time)
    return wald_test(theta_group, long_run_covariance(u, bandwidth))


def score_test(X: np.ndarray, Z: np.ndarray, resid: np.ndarray, bandwidth: int | None = None,
               rows_per_time: int = 1) -> tuple[float, float]:
    """HAC score (LM) test of adding columns ``Z`` to the model ``X`` with residual ``resid``.

    Returns ``(F, log10 p)`` with ``F = LM/q``.  Columns of ``Z`` that lie in the span
    of ``X`` carry no test (their part is dropped through the pseudo-inverse).
    """
    X = np.asarray(X, dtype=float)
    Z = np.asarray(Z, dtype=float)
    if Z.ndim == 1:
        Z = Z[:, None]
    if X.shape[1]:
        coef, *_ = np.linalg.lstsq(X, Z, rcond=None)
        Zt = Z - X @ coef
    else:
        Zt = Z
    e = np.asarray(resid, dtype=float)
    s = Zt.T @ e
    S = long_run_covariance(time_scores(Zt * e[:, None], rows_per_time), bandwidth)
    # rank of the new directions: those not in X's span (relative to Z's own size)
    sv = np.linalg.svd(Zt, compute_uv=False)
    scale = np.linalg.norm(Z, axis=0).max() if Z.size else 0.0
    q = int(np.sum(sv > 1e-8 * max(scale, 1e-300)))
    if q == 0:
        return 0.0, 0.0
    LM = float(s @ np.linalg.pinv(S, rcond=1e-12) @ s)
    return LM / q, chi2_log10_sf(LM, q)
