"""Significance of regressors from residual energies: partial F, AIC, BIC, FPE.

Notation (Zhou & Shi 2004, Eq. 13): model I has ``q`` parameters and residual energy
``J_I``; it is nested in model II with ``p > q`` parameters and energy ``J_II``; ``m``
samples.  Then

    F = ((J_I - J_II) / (p - q)) / (J_II / (m - p)),    p-value = P[F(p-q, m-p) > F].

**Degrees of freedom under forgetting.**  With exponential forgetting ``lambda`` the
energies are weighted sums ``J = sum_k w_k e_k^2`` with ``w_k = lambda^(t-k)``.  Matching
the first two moments of ``J / sigma^2`` to a scaled chi-square (Satterthwaite) gives
``J ~ sigma^2 c chi2(m_eff - p)`` with ``c = sum w^2 / sum w`` and Kish's effective
sample size ``m_eff = (sum w)^2 / sum w^2``.  The scale ``c`` cancels in ``F``, so the
F-test keeps its form with ``m`` replaced by ``m_eff``.  For ``lambda = 1``,
``m_eff = m``; in steady state ``m_eff = (1 + lambda) / (1 - lambda)``, about twice the
"memory" ``1 / (1 - lambda)`` (= ``sum w``).  Using the memory instead would halve the
numerator's variance and make the test conservative by a factor of ~2 in F.

**Not testable.**  A test with no numerator degrees of freedom (the tested columns are
not identifiable) or no denominator degrees of freedom (``m_eff <= p``) is reported
with ``F = 0``, ``p = 1``, ``log10 p = 0`` and ``testable = False``: never NaN or inf.

**Underflow.**  ``log10 p`` is computed from the continued fraction of the regularised
incomplete beta function in log space whenever ``scipy.stats.f.sf`` would underflow, so
it stays finite (e.g. ``-4000``) where ``p`` itself is ``0.0``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import special

from .kernels import betainc_cf

__all__ = [
    "InformationCriteria",
    "SignificanceTable",
    "f_log10_sf",
    "information_criteria",
    "nested_f",
    "nested_tests",
    "partial_f",
]

_LN10 = np.log(10.0)
# Below this p, scipy's sf is replaced by the log-space continued fraction.
_SF_SWITCH = 1e-250


def _log_betainc_cf(a: np.ndarray, b: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``log I_x(a, b)`` in the lower tail (``x < (a+1)/(a+b+2)``), by continued fraction."""
    a, b, x = (np.ascontiguousarray(v, dtype=float).ravel() for v in np.broadcast_arrays(a, b, x))
    log_h = np.empty_like(x)
    betainc_cf(a, b, x, log_h)
    return a * np.log(x) + b * np.log1p(-x) - special.betaln(a, b) - np.log(a) + log_h


def f_log10_sf(F: np.ndarray | float, df_num, df_den) -> np.ndarray:
    """``log10 P[F(df_num, df_den) > F]`` without underflow (broadcasts)."""
    F, d1, d2 = np.broadcast_arrays(
        np.asarray(F, dtype=float), np.asarray(df_num, dtype=float), np.asarray(df_den, dtype=float)
    )
    with np.errstate(all="ignore"):
        # the ufunc behind stats.f.sf, without the distribution machinery (~50x faster)
        sf = special.fdtrc(d1, d2, F)
        out = np.array(np.log10(np.where(sf > 0, sf, 1.0)), dtype=float)  # 0-d stays an array
    small = ~(sf > _SF_SWITCH)
    if np.any(small):
        # sf(F) = I_x(d2/2, d1/2) with x = d2 / (d2 + d1 F); x is tiny exactly here.
        a, b = d2[small] / 2.0, d1[small] / 2.0
        x = d2[small] / (d2[small] + d1[small] * F[small])
        out[small] = _log_betainc_cf(a, b, x) / _LN10
    return out


def partial_f(
    J_restricted, J_full, df_num, df_den
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Partial F-test of a restricted model inside a full one (Eq. 13), broadcasting.

    Returns ``(F, p_value, log10_p, testable)``; see the module docstring for the
    representation of tests that cannot be made.
    """
    Jr, Jf, d1, d2 = np.broadcast_arrays(
        np.asarray(J_restricted, dtype=float),
        np.asarray(J_full, dtype=float),
        np.asarray(df_num, dtype=float),
        np.asarray(df_den, dtype=float),
    )
    testable = (d1 > 0) & (d2 > 0) & np.isfinite(Jr) & np.isfinite(Jf)
    # A perfect fit (J_full = 0) would give F = inf: floor J_full at rounding level of J_r.
    floor = np.maximum(np.abs(Jr) * 1e-30, np.finfo(float).tiny)
    num = np.maximum(Jr - Jf, 0.0)
    with np.errstate(all="ignore"):
        F = np.where(
            testable,
            (num / np.where(d1 > 0, d1, 1.0)) / (np.maximum(Jf, floor) / np.where(d2 > 0, d2, 1.0)),
            0.0,
        )
    F = np.minimum(F, np.finfo(float).max)
    log10_p = np.where(testable, f_log10_sf(F, np.where(testable, d1, 1.0), np.where(testable, d2, 1.0)), 0.0)
    p = np.power(10.0, log10_p)
    return F, p, log10_p, testable


@dataclass(frozen=True)
class SignificanceTable:
    """Partial F-tests of named terms (one row per tested term or effect).

    ``kind`` is ``"nested"`` (term ``i`` added to the first ``i-1`` terms, the paper's
    sequence) or ``"last"`` (the effect removed from the full model).
    """

    names: tuple[str, ...]
    F: np.ndarray
    df_num: np.ndarray
    df_den: np.ndarray
    p_value: np.ndarray
    log10_p: np.ndarray
    testable: np.ndarray
    kind: str = "nested"
    alpha: float = field(default=0.05)

    def significant(self, alpha: float | None = None) -> np.ndarray:
        """``p < alpha`` (compared in log space, so it works where ``p`` underflows)."""
        a = self.alpha if alpha is None else alpha
        return self.testable & (self.log10_p < np.log10(a))

    def to_dict(self, alpha: float | None = None) -> dict[str, dict[str, float | bool]]:
        sig = self.significant(alpha)
        return {
            name: {
                "F": float(self.F[i]),
                "df_num": float(self.df_num[i]),
                "df_den": float(self.df_den[i]),
                "p_value": float(self.p_value[i]),
                "log10_p": float(self.log10_p[i]),
                "testable": bool(self.testable[i]),
                "significant": bool(sig[i]),
            }
            for i, name in enumerate(self.names)
        }

    def __str__(self) -> str:
        sig = self.significant()
        width = max([len(n) for n in self.names] + [6])
        head = f"{'term':<{width}}  {'F':>12}  {'df':>12}  {'log10 p':>10}  significant"
        lines = [f"partial F-tests ({self.kind}, alpha = {self.alpha:g})", head, "-" * len(head)]
        for i, name in enumerate(self.names):
            if not self.testable[i]:
                lines.append(f"{name:<{width}}  {'—':>12}  {'—':>12}  {'—':>10}  not testable")
                continue
            df = f"{self.df_num[i]:g}, {self.df_den[i]:.6g}"
            lines.append(
                f"{name:<{width}}  {self.F[i]:12.5g}  {df:>12}  {self.log10_p[i]:10.4g}  "
                f"{'yes' if sig[i] else 'no'}"
            )
        return "\n".join(lines)


def nested_tests(
    energies: np.ndarray,
    n_eff: float | np.ndarray,
    names: Sequence[str] | None = None,
    identifiable: np.ndarray | None = None,
    alpha: float = 0.05,
) -> SignificanceTable:
    """The paper's sequence: term ``i`` tested as the ``i``-th addition (``J_{i-1}`` vs ``J_i``).

    ``energies`` has shape ``(n+1,)`` (``J_0 .. J_n``).  Each test has ``(1, m_eff - i)``
    degrees of freedom.  For histories use :func:`nested_f` directly.
    """
    J = np.asarray(energies, dtype=float)
    n = J.shape[-1] - 1
    F, p, lp, ok, d1, d2 = nested_f(J, n_eff, identifiable)
    names = tuple(names) if names is not None else tuple(f"x{i + 1}" for i in range(n))
    return SignificanceTable(names, F, d1, d2, p, lp, ok, kind="nested", alpha=alpha)


def nested_f(energies: np.ndarray, n_eff, identifiable: np.ndarray | None = None):
    """Vectorised nested partial F over any leading axes (e.g. time).

    ``energies``: ``(..., n+1)``; ``n_eff``: scalar or ``(...)``.  Returns
    ``(F, p, log10_p, testable, df_num, df_den)`` each of shape ``(..., n)``.
    """
    J = np.asarray(energies, dtype=float)
    n = J.shape[-1] - 1
    order = np.arange(1, n + 1, dtype=float)
    d1 = np.ones_like(J[..., 1:])
    if identifiable is not None:
        d1 = d1 * np.asarray(identifiable, dtype=float)
    d2 = np.asarray(n_eff, dtype=float)[..., None] - order
    d2 = np.broadcast_to(d2, d1.shape)
    F, p, lp, ok = partial_f(J[..., :-1], J[..., 1:], d1, d2)
    return F, p, lp, ok, d1, d2


@dataclass(frozen=True)
class InformationCriteria:
    """AIC, BIC and FPE of the nested models of order ``0..n`` (lower is better)."""

    aic: np.ndarray
    bic: np.ndarray
    fpe: np.ndarray

    def best_order(self, criterion: str = "bic") -> int:
        return int(np.argmin(getattr(self, criterion)))


def information_criteria(energies: np.ndarray, n_eff: float, weight_sum: float | None = None):
    """AIC = m ln(V) + 2 d, BIC = m ln(V) + d ln(m), FPE = V (m + d) / (m - d).

    ``V = J_d / sum w`` is the (weighted) mean squared residual of the order-``d`` model
    and ``m`` the effective sample size (``sum w = m`` without forgetting).  Orders with
    ``d >= m`` get ``+inf``-free large values (``finfo.max``) so they are never chosen.
    """
    J = np.asarray(energies, dtype=float)
    d = np.arange(J.shape[-1], dtype=float)
    m = float(n_eff)
    wsum = m if weight_sum is None else float(weight_sum)
    big = np.finfo(float).max
    if m <= 0 or wsum <= 0:
        full = np.full_like(J, big)
        return InformationCriteria(full, full.copy(), full.copy())
    V = np.maximum(J / wsum, np.finfo(float).tiny)
    ln_v = np.log(V)
    aic = m * ln_v + 2.0 * d
    bic = m * ln_v + d * np.log(m)
    with np.errstate(all="ignore"):
        fpe = np.where(d < m, V * (m + d) / np.where(d < m, m - d, 1.0), big)
    aic = np.where(d < m, aic, big)
    bic = np.where(d < m, bic, big)
    return InformationCriteria(aic, bic, fpe)
