"""Significance tests and criteria against statsmodels, scipy, mpmath and the formulas."""

from __future__ import annotations

import mpmath
import numpy as np
import pytest
import statsmodels.api as sm
from scipy import stats

from identifier import (
    RecursiveQR,
    SignificanceTable,
    f_log10_sf,
    information_criteria,
    nested_f,
    nested_tests,
    partial_f,
)

RTOL = 1e-9


def _data(rng, m=400):
    """Five columns: strong, moderate, irrelevant, weak, irrelevant effects."""
    X = rng.standard_normal((m, 5)) * np.array([1.0, 2.0, 0.5, 1.5, 3.0])
    y = X @ np.array([1.0, 0.3, 0.0, 0.08, 0.0]) + rng.standard_normal(m)
    return X, y


def _scalar(v):
    return float(np.squeeze(v))


def _mp_log10_sf(F, d1, d2):
    """log10 P[F(d1, d2) > F] = log10 I_x(d2/2, d1/2), x = d2 / (d2 + d1 F), at 50 digits."""
    with mpmath.workdps(50):
        d1, d2, F = mpmath.mpf(d1), mpmath.mpf(d2), mpmath.mpf(F)
        x = d2 / (d2 + d1 * F)
        return float(mpmath.log10(mpmath.betainc(d2 / 2, d1 / 2, 0, x, regularized=True)))


# ------------------------------------------------------------------ vs statsmodels
def test_nested_tests_match_statsmodels(rng):
    X, y = _data(rng)
    m, n = X.shape
    est = RecursiveQR(n).fit(X, y)
    tab = est.nested_tests()
    assert tab.kind == "nested" and tab.names == est.columns
    for i in range(1, n + 1):
        full = sm.OLS(y, X[:, :i]).fit()
        if i == 1:  # restricted model is empty: the Wald F of theta_1 = 0 is the partial F
            res = full.f_test(np.eye(1))
            F, p, df_diff = _scalar(res.fvalue), _scalar(res.pvalue), 1.0
        else:
            F, p, df_diff = full.compare_f_test(sm.OLS(y, X[:, : i - 1]).fit())
        assert tab.F[i - 1] == pytest.approx(F, rel=RTOL)
        assert tab.p_value[i - 1] == pytest.approx(p, rel=RTOL)
        assert tab.log10_p[i - 1] == pytest.approx(np.log10(p), rel=RTOL)
        assert tab.df_num[i - 1] == df_diff and tab.df_den[i - 1] == full.df_resid
    assert tab.testable.all()
    # the strong column is significant, the irrelevant ones are not
    assert tab.significant()[0] and not tab.significant()[2]


@pytest.mark.parametrize(
    "groups",
    [
        {"A": ["a"], "BE": ["b", "e"], "C": ["c"], "D": ["d"]},
        {"ACE": ["a", "c", "e"], "BD": ["b", "d"]},  # scattered multi-column groups
    ],
)
def test_effect_tests_with_multi_column_groups_match_statsmodels(rng, groups):
    X, y = _data(rng)
    X[:, 4] += 0.9 * X[:, 0]  # correlated columns within a group
    m, n = X.shape
    cols = ["a", "b", "c", "d", "e"]
    est = RecursiveQR(columns=cols, groups=groups).fit(X, y)
    tab = est.effect_tests()
    assert tab.kind == "last" and tab.names == tuple(groups)
    full = sm.OLS(y, X).fit()
    for g, name in enumerate(tab.names):
        drop = [cols.index(c) for c in groups[name]]
        rest = [j for j in range(n) if j not in drop]
        F, p, df_diff = full.compare_f_test(sm.OLS(y, X[:, rest]).fit())
        assert tab.F[g] == pytest.approx(F, rel=RTOL)
        assert tab.p_value[g] == pytest.approx(p, rel=RTOL)
        assert tab.df_num[g] == df_diff == len(drop)
        assert tab.df_den[g] == full.df_resid == m - n
    d = tab.to_dict()
    assert set(d) == set(groups)
    assert all(d[name]["df_num"] == len(groups[name]) for name in groups)
    assert all(name in str(tab) for name in groups)


def test_standard_errors_match_statsmodels_bse(rng):
    X, y = _data(rng)
    n = X.shape[1]
    est = RecursiveQR(n).fit(X, y)
    for o in range(1, n + 1):
        bse = sm.OLS(y, X[:, :o]).fit().bse
        np.testing.assert_allclose(est.standard_errors(o), bse, rtol=RTOL, atol=0)
    np.testing.assert_array_equal(est.standard_errors(), est.standard_errors(n))


def test_tests_with_a_non_identifiable_column_match_statsmodels_without_it(rng):
    X, y = _data(rng)
    X[:, 2] = 0.5 * X[:, 0] - X[:, 1]  # collinear: dropped
    est = RecursiveQR(5).fit(X, y)
    keep = [0, 1, 3, 4]
    full = sm.OLS(y, X[:, keep]).fit()
    np.testing.assert_allclose(est.standard_errors()[keep], full.bse, rtol=RTOL)
    assert est.standard_errors()[2] == 0.0
    tab = est.effect_tests()
    assert not tab.testable[2] and tab.p_value[2] == 1.0 and tab.F[2] == 0.0
    for g, j in enumerate(keep):
        F, p, _ = full.compare_f_test(sm.OLS(y, X[:, [k for k in keep if k != j]]).fit())
        assert tab.F[j] == pytest.approx(F, rel=RTOL), g
        assert tab.p_value[j] == pytest.approx(p, rel=RTOL)


def test_group_with_one_identifiable_column_has_one_degree_of_freedom(rng):
    X, y = _data(rng)
    X[:, 4] = 0.0
    est = RecursiveQR(columns="abcde", groups={"A": "a", "B": "b", "CE": ["c", "e"], "D": "d"})
    est.fit(X, y)
    tab = est.effect_tests()
    full = sm.OLS(y, X[:, :4]).fit()
    F, p, df = full.compare_f_test(sm.OLS(y, X[:, [0, 1, 3]]).fit())
    assert tab.df_num[2] == df == 1
    assert tab.df_den[2] == full.df_resid
    assert tab.F[2] == pytest.approx(F, rel=RTOL) and tab.p_value[2] == pytest.approx(p, rel=RTOL)


# ---------------------------------------------------------------- under forgetting
def test_tests_under_forgetting_use_kish_effective_samples(ref, rng):
    lam, m = 0.995, 3000
    X, y = _data(rng, m)
    n = X.shape[1]
    groups = {"x1": ["x1"], "x2x3": ["x2", "x3"], "x4": ["x4"], "x5": ["x5"]}
    est = RecursiveQR(n, forgetting=lam, groups=groups)
    est.update_many(X, y)
    w = ref.forgetting_weights(m, lam)
    m_eff = w.sum() ** 2 / (w @ w)
    J, _ = ref.nested(X, y, forgetting=lam)
    tab = est.nested_tests()
    for i in range(1, n + 1):
        d2 = m_eff - i
        F = (J[i - 1] - J[i]) / (J[i] / d2)
        assert tab.df_den[i - 1] == pytest.approx(d2, rel=1e-12)
        assert tab.F[i - 1] == pytest.approx(F, rel=RTOL)
        assert tab.p_value[i - 1] == pytest.approx(stats.f.sf(F, 1, d2), rel=1e-8)
    eff = est.effect_tests()
    for g, cols in enumerate(groups.values()):
        keep = np.ones(n, dtype=bool)
        keep[[est.columns.index(c) for c in cols]] = False
        Jr = ref.nested(X, y, forgetting=lam, keep=keep)[0][n]
        F = ((Jr - J[n]) / len(cols)) / (J[n] / (m_eff - n))
        assert eff.F[g] == pytest.approx(F, rel=RTOL)
        assert eff.p_value[g] == pytest.approx(stats.f.sf(F, len(cols), m_eff - n), rel=1e-8)


def test_standard_errors_under_forgetting(ref, rng):
    lam, m = 0.99, 1500
    X, y = _data(rng, m)
    n = X.shape[1]
    est = RecursiveQR(n, forgetting=lam)
    est.update_many(X, y)
    w = ref.forgetting_weights(m, lam)
    m_eff = w.sum() ** 2 / (w @ w)
    J, _ = ref.nested(X, y, forgetting=lam)
    for o in (1, 3, n):
        Xo = X[:, :o]
        cov = np.linalg.inv(Xo.T @ (w[:, None] * Xo)) * J[o] / (m_eff - o)
        np.testing.assert_allclose(est.standard_errors(o), np.sqrt(np.diag(cov)), rtol=RTOL)


def _rejections(seed, forgetting, reps, m):
    """Under H0 (last column irrelevant, Gaussian noise): count p < 0.05 of the
    effect-last test as implemented (Kish m_eff) and with the naive memory sum(w)."""
    rng = np.random.default_rng(seed)
    kish = naive = 0
    for _ in range(reps):
        X = rng.standard_normal((m, 2))
        y = 0.8 * X[:, 0] + rng.standard_normal(m)
        est = RecursiveQR(columns=["x", "irrelevant"], forgetting=forgetting)
        est.update_many(X, y)
        kish += bool(est.effect_tests().p_value[1] < 0.05)
        J = est.residual_energies()
        d2 = est.weight_sum - 2  # naive: the memory sum(w) as sample size
        naive += bool(stats.f.sf((J[1] - J[2]) / (J[2] / d2), 1, d2) < 0.05)
    return kish, naive


def test_monte_carlo_size_under_forgetting():
    reps = 1000
    kish, naive = _rejections(seed=2024, forgetting=0.99, reps=reps, m=2000)
    lo, hi = stats.binomtest(kish, reps).proportion_ci(confidence_level=0.999)
    assert lo <= 0.05 <= hi, (kish, lo, hi)
    # the naive degrees of freedom halve F: clearly conservative
    _, hi_naive = stats.binomtest(naive, reps).proportion_ci(confidence_level=0.999)
    assert hi_naive < 0.05 / 2, naive


# ------------------------------------------------------------------- f_log10_sf
@pytest.mark.parametrize("d1", [1, 2, 5, 30])
@pytest.mark.parametrize("d2", [1, 4, 25, 300, 1e4])
def test_f_log10_sf_vs_scipy_and_mpmath_without_underflow(d1, d2):
    F = np.array([0.0, 1e-3, 0.3, 1.0, 2.5, 10.0, 1e2, 1e3])
    got = f_log10_sf(F, d1, d2)
    assert got.shape == F.shape
    sf = stats.f.sf(F, d1, d2)
    ok = sf > np.finfo(float).tiny  # scipy has not underflowed (not even to subnormal)
    assert ok.sum() >= 6
    np.testing.assert_allclose(got[ok], np.log10(sf[ok]), rtol=1e-12, atol=1e-14)
    mp = np.array([_mp_log10_sf(f, d1, d2) for f in F])
    np.testing.assert_allclose(got, mp, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(
    ("F", "d1", "d2"),
    [
        (1e5, 1, 30000),  # log10 p about -9555
        (1e5, 2, 30000),
        (1e5, 7, 30000),
        (1e8, 5, 2e5),
        (3.0, 1e4, 1e4),
        (2.0, 1e4, 1e4),  # sf ~ 2e-258: continued fraction with many terms
        (50.0, 100, 1e5),
        (1e4, 1, 2000),
        (1e300, 1, 5),
        (1e200, 1, 3),  # ~ -299.7, just below the switch to the continued fraction
        (1e150, 3, 3),  # ~ -224.8, just above it (scipy's sf)
    ],
)
def test_f_log10_sf_vs_mpmath_where_scipy_underflows(F, d1, d2):
    want = _mp_log10_sf(F, d1, d2)
    got = f_log10_sf(F, d1, d2)  # scalar in, 0-d array out
    assert np.ndim(got) == 0 and np.isfinite(got)
    assert float(got) == pytest.approx(want, rel=1e-12)
    if want < np.log10(np.finfo(float).tiny) - 20:
        assert stats.f.sf(F, d1, d2) == 0.0  # scipy really does underflow here


def test_f_log10_sf_broadcasts_and_mixes_regimes():
    F = np.array([[2.0], [1e5]])
    d1 = np.array([1.0, 3.0])
    got = f_log10_sf(F, d1, 30000)
    assert got.shape == (2, 2)
    for i in range(2):
        for j in range(2):
            assert got[i, j] == pytest.approx(_mp_log10_sf(F[i, 0], d1[j], 30000), rel=1e-10)


def test_huge_effect_has_finite_log10_p_in_the_estimator():
    rng = np.random.default_rng(1)
    m = 30000
    X = rng.standard_normal((m, 2))
    y = 50.0 * X[:, 0] + 0.01 * rng.standard_normal(m)
    est = RecursiveQR(2).fit(X, y)
    tab = est.nested_tests()
    J = est.residual_energies()
    F = (J[0] - J[1]) / (J[1] / (m - 1))
    assert tab.p_value[0] == 0.0  # underflows ...
    assert tab.log10_p[0] == pytest.approx(_mp_log10_sf(F, 1, m - 1), rel=1e-10)  # ... this not
    assert tab.significant(1e-300)[0]


# ------------------------------------------------------------------- partial_f
def test_partial_f_untestable_and_degenerate_cases():
    F, p, lp, ok = partial_f([10.0, 10.0, 10.0, 10.0], [5.0, 5.0, 0.0, 10.0 + 1e-12],
                             [0.0, 1.0, 1.0, 1.0], [20.0, 0.0, 20.0, 20.0])
    np.testing.assert_array_equal(ok, [False, False, True, True])
    np.testing.assert_array_equal(F[:2], 0.0)
    np.testing.assert_array_equal(p[:2], 1.0)
    np.testing.assert_array_equal(lp[:2], 0.0)
    assert np.isfinite(F).all() and np.isfinite(lp).all()
    assert F[2] > 1e20 and lp[2] < -100  # perfect fit: huge but finite
    assert F[3] == 0.0 and p[3] == 1.0  # J_full > J_restricted by rounding: no evidence
    Jr, Jf, d1, d2 = 12.0, 8.0, 2.0, 37.0
    F, p, lp, ok = partial_f(Jr, Jf, d1, d2)
    Fw = ((Jr - Jf) / d1) / (Jf / d2)
    assert F == pytest.approx(Fw, rel=1e-15)
    assert p == pytest.approx(stats.f.sf(Fw, d1, d2), rel=1e-12)


def test_nested_f_vectorised_over_history(rng):
    X, y = _data(rng, 300)
    n = X.shape[1]
    est = RecursiveQR(n, forgetting=0.98)
    hist = est.update_many(X, y, return_energies=True)
    F, p, lp, ok, d1, d2 = nested_f(hist.energies, hist.effective_samples)
    assert F.shape == (300, n)
    for t in (2, 40, 299):
        fresh = RecursiveQR(n, forgetting=0.98)
        fresh.update_many(X[: t + 1], y[: t + 1])
        tab = fresh.nested_tests()
        np.testing.assert_allclose(F[t], tab.F, rtol=1e-12)
        np.testing.assert_allclose(lp[t], tab.log10_p, rtol=1e-12, atol=1e-300)
        np.testing.assert_array_equal(ok[t], tab.testable)
        # m_eff - i may cancel to ~0 (absolute comparison on the scale of m_eff)
        np.testing.assert_allclose(d2[t], tab.df_den, rtol=0, atol=1e-12 * (t + 1))
    # t = 2: three samples, m_eff < 3 -> tests of orders >= m_eff are void, not NaN
    assert not ok[2, 2:].any() and np.isfinite(F).all() and np.isfinite(lp).all()


def test_nested_tests_function_names_and_mask():
    J = np.array([100.0, 50.0, 50.0, 20.0])
    tab = nested_tests(J, 40.0, identifiable=np.array([True, False, True]))
    assert isinstance(tab, SignificanceTable) and tab.names == ("x1", "x2", "x3")
    np.testing.assert_array_equal(tab.testable, [True, False, True])
    assert tab.F[0] == pytest.approx(50.0 / (50.0 / 39.0))
    assert tab.F[2] == pytest.approx(30.0 / (20.0 / 37.0))
    assert "not testable" in str(tab)


# ------------------------------------------------------------ information criteria
def test_information_criteria_match_formulas_and_statsmodels(ref, rng):
    X, y = _data(rng)
    m, n = X.shape
    est = RecursiveQR(n).fit(X, y)
    ic = est.information_criteria()
    J, _ = ref.nested(X, y)
    d = np.arange(n + 1)
    np.testing.assert_allclose(ic.aic, m * np.log(J / m) + 2 * d, rtol=RTOL)
    np.testing.assert_allclose(ic.bic, m * np.log(J / m) + d * np.log(m), rtol=RTOL)
    np.testing.assert_allclose(ic.fpe, (J / m) * (m + d) / (m - d), rtol=RTOL)
    # statsmodels' AIC/BIC (from the Gaussian log-likelihood) differ by m (1 + ln 2 pi)
    const = m * (1.0 + np.log(2 * np.pi))
    for o in range(1, n + 1):
        res = sm.OLS(y, X[:, :o]).fit()
        assert ic.aic[o] + const == pytest.approx(res.aic, rel=RTOL)
        assert ic.bic[o] + const == pytest.approx(res.bic, rel=RTOL)
    for name, crit in (("aic", ic.aic), ("bic", ic.bic), ("fpe", ic.fpe)):
        assert ic.best_order(name) == int(np.argmin(crit))
    assert ic.best_order("bic") >= 1  # the strong first term is always chosen


def test_information_criteria_under_forgetting(ref, rng):
    lam, m = 0.99, 800
    X, y = _data(rng, m)
    n = X.shape[1]
    est = RecursiveQR(n, forgetting=lam)
    est.update_many(X, y)
    w = ref.forgetting_weights(m, lam)
    m_eff, sw = w.sum() ** 2 / (w @ w), w.sum()
    J, _ = ref.nested(X, y, forgetting=lam)
    d = np.arange(n + 1)
    V = J / sw
    ic = est.information_criteria()
    np.testing.assert_allclose(ic.aic, m_eff * np.log(V) + 2 * d, rtol=RTOL)
    np.testing.assert_allclose(ic.bic, m_eff * np.log(V) + d * np.log(m_eff), rtol=RTOL)
    np.testing.assert_allclose(ic.fpe, V * (m_eff + d) / (m_eff - d), rtol=RTOL)


def test_information_criteria_without_enough_samples_are_finite():
    big = np.finfo(float).max
    ic = information_criteria(np.array([4.0, 1.0, 0.0, 0.0]), 2.0)
    for a in (ic.aic, ic.bic, ic.fpe):
        assert np.isfinite(a).all() and np.all(a[2:] == big)
    assert ic.best_order("aic") in (0, 1)
    ic = information_criteria(np.zeros(3), 0.0)
    assert np.all(ic.aic == big) and np.all(ic.fpe == big)
