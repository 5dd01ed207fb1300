"""HAC statistics against statsmodels, and their calibration by simulation."""

from __future__ import annotations

import numpy as np
import pytest
import statsmodels.api as sm
from scipy import stats
from statsmodels.stats.sandwich_covariance import S_hac_simple

from identifier.hac import (
    andrews_bandwidth,
    hac_covariance,
    long_run_covariance,
    score_test,
    wald_group_test,
    wald_test,
)


def _ar1(rng, m, rho):
    e = np.empty(m)
    e[0] = rng.normal()
    eps = rng.normal(size=m)
    for i in range(1, m):
        e[i] = rho * e[i - 1] + eps[i]
    return e


@pytest.mark.parametrize("L", [0, 1, 7, 120])
def test_long_run_covariance_equals_statsmodels(L):
    rng = np.random.default_rng(L)
    u = rng.normal(size=(3000, 3))
    u[:, 1] += np.convolve(rng.normal(size=3000), np.ones(25) / 5, "same")
    np.testing.assert_allclose(long_run_covariance(u, L), S_hac_simple(u, nlags=L), rtol=1e-10)


def test_sandwich_equals_statsmodels_hac():
    rng = np.random.default_rng(1)
    m = 4000
    X = np.column_stack([np.ones(m), np.sin(np.arange(m) * 0.02), rng.normal(size=m)])
    y = X @ [1.0, 2.0, -0.5] + _ar1(rng, m, 0.9)
    res = sm.OLS(y, X).fit(cov_type="HAC", cov_kwds={"maxlags": 30, "use_correction": False})
    np.testing.assert_allclose(hac_covariance(X, res.resid, 30), res.cov_params(), rtol=1e-9)
    F, lp = wald_test(res.params[1:], res.cov_params()[1:, 1:])
    W = res.wald_test(np.eye(3)[1:], scalar=True, use_f=False).statistic
    assert F == pytest.approx(W / 2, rel=1e-9)
    assert lp == pytest.approx(np.log10(stats.chi2.sf(W, 2)), rel=1e-9)


def test_bandwidth_grows_with_autocorrelation():
    rng = np.random.default_rng(2)
    white = andrews_bandwidth(rng.normal(size=20000))
    red = andrews_bandwidth(_ar1(rng, 20000, 0.98))
    assert white <= 3 and red > 50


def test_score_test_size_under_autocorrelated_errors():
    """Rejection rate at alpha = 0.05 over 200 simulated nulls with AR(1) errors (rho 0.9):
    the HAC score test stays near 5 %, the classical F rejects far more often."""
    hac = classical = 0
    n = 200
    for s in range(n):
        rng = np.random.default_rng(100 + s)
        m = 4000
        t = np.arange(m)
        X = np.column_stack([np.ones(m), np.sin(t * 0.01)])
        Z = np.cos(t * 0.013)[:, None]
        y = X @ [1.0, 2.0] + _ar1(rng, m, 0.9)
        theta = np.linalg.lstsq(X, y, rcond=None)[0]
        r = y - X @ theta
        _, lp = score_test(X, Z, r)
        hac += lp < np.log10(0.05)
        full = np.column_stack([X, Z])
        r2 = y - full @ np.linalg.lstsq(full, y, rcond=None)[0]
        F = (r @ r - r2 @ r2) / (r2 @ r2 / (m - 3))
        classical += stats.f.sf(F, 1, m - 3) < 0.05
    assert hac / n <= 0.10
    assert classical / n >= 0.4
    # and the test has power when the column is there
    rng = np.random.default_rng(7)
    y = X @ [1.0, 2.0] + 2.0 * Z[:, 0] + _ar1(rng, m, 0.9)
    r = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    assert score_test(X, Z, r)[1] < np.log10(1e-3)


def test_score_test_ignores_columns_in_the_models_span():
    rng = np.random.default_rng(3)
    X = rng.normal(size=(500, 2))
    r = rng.normal(size=500)
    F, lp = score_test(X, X[:, :1] * 2.0, r)
    assert F == 0.0 and lp == 0.0


def test_wald_group_test_equals_the_full_sandwich():
    rng = np.random.default_rng(4)
    m = 3000
    X = np.column_stack([np.ones(m), np.sin(np.arange(m) * 0.02), rng.normal(size=m), np.cos(np.arange(m) * 0.05)])
    y = X @ [1.0, 0.5, 0.0, 0.2] + _ar1(rng, m, 0.8)
    theta = np.linalg.lstsq(X, y, rcond=None)[0]
    r = y - X @ theta
    cov = hac_covariance(X, r, 25)
    for group in ([1], [2, 3]):
        F, lp = wald_group_test(X, r, theta[group], group, 25)
        F_ref, lp_ref = wald_test(theta[group], cov[np.ix_(group, group)])
        assert F == pytest.approx(F_ref, rel=1e-8) and lp == pytest.approx(lp_ref, rel=1e-8)
