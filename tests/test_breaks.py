"""The sup-LM break test (identifier.breaks) by simulation with known truth: Andrews' (1993)
table where information arrives evenly, its size where it arrives at a resonance and the
errors are coloured, its power and the break's place."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from identifier.breaks import sup_lm_test

N = 6000


def _resonant_regressors(n=N):
    """A sweep through a resonance at mid-record: a 1X pair whose size peaks there (most of the
    information in a tenth of the record), plus an offset and a trend."""
    t = np.linspace(0.0, 1.0, n)
    phase = np.cumsum(2 * math.pi * (20 + 120 * t)) / n
    env = 1.0 / np.sqrt((1 - (t / 0.5) ** 2) ** 2 + (0.05 * t / 0.5) ** 2)
    return t, np.column_stack([env * np.cos(phase), env * np.sin(phase), np.ones(n), t])


def _test(X, y, **kw):
    theta = np.linalg.lstsq(X, y, rcond=None)[0]
    e = y - X @ theta
    return sup_lm_test(X * e[:, None], X, **kw)


def test_even_information_and_white_errors_reproduce_andrews_table():
    """A constant mean in white noise: the bootstrap's null is the squared Brownian bridge's,
    Andrews (1993) Table 1, pi_0 = 0.15, p = 1: 7.17 (10 %), 8.68 (5 %), 12.16 (1 %)."""
    rng = np.random.default_rng(0)
    X = np.ones((4000, 1))
    res = _test(X, rng.standard_normal(4000), draws=3999, boundaries=np.arange(3, 4000, 4))
    assert res.critical_value(0.10) == pytest.approx(7.17, abs=0.35)
    assert res.critical_value(0.05) == pytest.approx(8.68, abs=0.45)
    assert res.critical_value(0.01) == pytest.approx(12.16, abs=1.0)
    assert res.dof == 1 and 0 < res.p_value <= 1


@pytest.mark.parametrize("rho", [0.0, 0.8])
def test_size_at_a_resonance_with_white_and_coloured_errors(rho):
    """Constant parameters, information concentrated at a resonance, white or AR(1) errors:
    120 records at 5 %: between 1 and 13 rejections (binomial(120, 0.05): P(X = 0) = 0.002,
    P(X >= 14) = 0.002); the p-values spread over (0, 1) (their mean within 0.35-0.65)."""
    rng = np.random.default_rng(int(10 * rho) + 1)
    _, X = _resonant_regressors()
    p = []
    for r in range(120):
        e = lfilter([1.0], [1.0, -rho], rng.standard_normal(N))
        p.append(_test(X, X @ np.array([1.0, 0.5, 0.2, 0.1]) + e, draws=199, seed=r).p_value)
    p = np.array(p)
    assert 1 <= np.sum(p < 0.05) <= 13, np.sort(p)[:15]
    assert 0.35 < p.mean() < 0.65


def test_a_break_at_the_resonance_is_found_at_its_place():
    """The 1X coefficient steps by 5 % at 45 % of the record, before the resonance: significant, the break within 2 %
    of the record of its place, and the 1X pair is what moved (not the offset and trend)."""
    rng = np.random.default_rng(5)
    t, X = _resonant_regressors()
    theta = np.where(t[:, None] < 0.45, [1.0, 0.5, 0.2, 0.1], [1.05, 0.5, 0.2, 0.1])
    y = np.sum(X * theta, axis=1) + 0.2 * lfilter([1.0], [1.0, -0.5], rng.standard_normal(N))
    res = _test(X, y, draws=499)
    assert res.p_value < 0.01
    assert res.fraction == pytest.approx(0.45, abs=0.02)
    assert res.index == pytest.approx(0.45 * N, abs=0.02 * N)
    assert res.group_statistic([0, 1]) > 5 * res.group_statistic([2, 3])


def test_a_partial_change_is_tested_on_its_own_parameters():
    """The same break tested on the 1X pair alone (the offset and trend held the same on both
    sides, Andrews' partial structural change): significant with 2 degrees of freedom, dated
    alike; tested on the offset and trend alone: no change."""
    rng = np.random.default_rng(6)
    t, X = _resonant_regressors()
    theta = np.where(t[:, None] < 0.45, [1.0, 0.5, 0.2, 0.1], [1.05, 0.5, 0.2, 0.1])
    y = np.sum(X * theta, axis=1) + 0.2 * rng.standard_normal(N)
    pair = _test(X, y, draws=499, tested=[0, 1])
    assert pair.dof == 2 and pair.p_value < 0.01
    assert pair.fraction == pytest.approx(0.45, abs=0.02)
    assert _test(X, y, draws=499, tested=[2, 3]).p_value > 0.05


def test_bad_shapes_and_short_records_are_clear_errors():
    X = np.ones((100, 2))
    with pytest.raises(ValueError, match="do not match"):
        sup_lm_test(X, np.ones((100, 3)))
    with pytest.raises(ValueError, match="too few"):
        sup_lm_test(X[:30], X[:30], boundaries=np.arange(3, 30, 4))
    with pytest.raises(ValueError, match="too few"):  # 20 blocks, but 8 per parameter wanted
        sup_lm_test(np.ones((100, 3)), np.ones((100, 3)), boundaries=np.arange(4, 100, 5))
    with pytest.raises(ValueError, match="tested"):
        sup_lm_test(X, X, tested=[0, 0])
    with pytest.raises(ValueError, match="increase"):
        sup_lm_test(X, X, boundaries=np.array([5, 3, 50]))
    with pytest.raises(ValueError, match="trim"):
        sup_lm_test(X, X, trim=0.6)
