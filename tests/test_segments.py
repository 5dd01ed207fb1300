"""identifier.segments: change-point energies against a refit by numpy.linalg.lstsq."""

import numpy as np
import pytest

from identifier.segments import SplitScan, split_energies


def _refit(lstsq, A, c, before, after):
    """The split model refitted: the columns zeroed where absent, then least squares
    (``ref.lstsq``: equilibrated, as the columns span twelve orders of magnitude)."""
    X = A[:, :-1].copy()
    X[:c, list(before)] = 0.0
    X[c:, list(after)] = 0.0
    r = A[:, -1] - X @ lstsq(X, A[:, -1])
    return float(r @ r)


def _data(seed, m=900, n=6):
    rng = np.random.default_rng(seed)
    # columns over twelve orders of magnitude, and a coefficient that changes at row 600
    X = rng.normal(size=(m, n)) * np.logspace(-6, 6, n)
    theta = rng.normal(size=n) / np.logspace(-6, 6, n)
    y = X @ theta + 0.1 * rng.normal(size=m)
    y[600:] += 0.5 * X[600:, 2] * theta[2]
    return np.column_stack([X, y])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(("before", "after"), [((2,), ()), ((), (1, 4)), ((0,), (5,))])
def test_energies_equal_a_refit_at_every_cut(ref, seed, before, after):
    A = _data(seed)
    cuts = np.array([0, 1, 7, 64, 65, 300, 599, 600, 601, 899, 900])
    J = split_energies(A, cuts, before, after)
    refits = np.array([_refit(ref.lstsq, A, c, before, after) for c in cuts])
    np.testing.assert_allclose(J, refits, rtol=1e-9)


def test_a_change_is_found_where_it_is():
    A = _data(3)
    # the changed coefficient: the column twice, its copy absent after the cut, itself before
    A2 = np.column_stack([A[:, :-1], A[:, 2], A[:, -1]])
    cuts = np.arange(50, 851, 50)
    J = split_energies(A2, cuts, before=[2], after=[6])
    assert cuts[np.argmin(J)] == 600


def test_refine_reuses_the_coarse_factors(ref):
    A = _data(4)
    scan = SplitScan(A, before=[2])
    coarse = np.arange(0, 901, 100)
    Jc = scan.energies(coarse)
    fine = np.arange(500, 701, 7)
    Jf = scan.refine(5, 7, fine)
    np.testing.assert_allclose(Jf, [_refit(ref.lstsq, A, c, [2], []) for c in fine], rtol=1e-9)
    np.testing.assert_allclose(Jc, [_refit(ref.lstsq, A, c, [2], []) for c in coarse], rtol=1e-9)
    with pytest.raises(ValueError, match="cuts must be ascending"):
        scan.refine(0, 1, [50, 20])  # the last scan's cuts are the fine ones now: rows 500..507


@pytest.mark.parametrize(
    ("A", "cuts", "kw", "match"),
    [
        (np.ones((5, 1)), [1], {}, "at least one regressor"),
        (np.ones((5, 3)), [3, 1], {}, "ascending"),
        (np.ones((5, 3)), [6], {}, "ascending"),
        (np.ones((5, 3)), [2], {"before": [2]}, "before: column 2"),
        (np.array([[1.0, 2.0], [np.nan, 1.0]]), [1], {}, "row 1, column 0"),
    ],
)
def test_bad_input_is_named(A, cuts, kw, match):
    with pytest.raises(ValueError, match=match):
        split_energies(A, cuts, **kw)


def test_a_duplicated_column_is_dropped_not_fitted_to_rounding(ref):
    A = _data(5)
    A2 = np.column_stack([A[:, :-1], 3.0 * A[:, 1], A[:, -1]])  # column 6 = 3 x column 1
    cuts = np.array([0, 100, 450, 900])
    J = split_energies(A2, cuts)
    np.testing.assert_allclose(J, [_refit(ref.lstsq, A, c, (), ()) for c in cuts], rtol=1e-9)
