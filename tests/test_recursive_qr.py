"""RecursiveQR against independent references (numpy lstsq on the raw data).

Tolerance policy: the estimator is a backward-stable QR solver, so on well-conditioned
problems energies and coefficients agree with lstsq to ~1e-13; the tests demand 1e-9
relative.  On ill-conditioned problems (near-collinear columns, scales 1e-6..1e6) only the
fitted values ``X theta`` are determined to working precision, not each coefficient, so
coefficients are compared there in the fitted-value metric ``||X dtheta|| / ||y||``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from identifier import RecursiveQR
from identifier import kernels as K

RTOL = 1e-9


def _problem(rng, m, n, noise=0.5):
    """Well-conditioned regression: Gaussian columns of mixed (moderate) scale."""
    scales = np.linspace(0.5, 3.0, n)
    X = rng.standard_normal((m, n)) * scales
    theta = rng.uniform(0.5, 2.0, n) * rng.choice([-1.0, 1.0], n)
    y = X @ theta + noise * rng.standard_normal(m)
    return X, y


def _rel(a, b):
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b))


def _assert_nested_close(J, C, J_ref, C_ref, rtol=RTOL):
    np.testing.assert_allclose(J, J_ref, rtol=rtol, atol=0)
    n = C_ref.shape[0]
    for o in range(1, n + 1):
        assert _rel(C[o - 1, :o], C_ref[o - 1, :o]) <= rtol, o
        assert np.all(C[o - 1, o:] == 0.0)


def _state(est):
    return est.R.copy(), est._col_sq.copy(), est._sums.copy()


def _assert_state_equal(est, state):
    R, col_sq, sums = state
    assert np.array_equal(est.R, R)
    assert np.array_equal(est._col_sq, col_sq)
    assert np.array_equal(est._sums, sums)


def _all_outputs(est):
    """Every numeric output of the public API, flattened (for finiteness checks)."""
    out = [est.residual_energies(), est.all_coefficients().ravel()]
    for o in range(1, est.n + 1):
        out += [est.coefficients(o), est.standard_errors(o)]
    for tab in (est.nested_tests(), est.effect_tests()):
        out += [tab.F, tab.df_num, tab.df_den, tab.p_value, tab.log10_p]
    ic = est.information_criteria()
    out += [ic.aic, ic.bic, ic.fpe, np.array([est.effective_samples, est.weight_sum])]
    return np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in out])


def _assert_untestable(tab, mask):
    mask = np.asarray(mask, dtype=bool)
    assert not tab.testable[mask].any()
    assert np.all(tab.F[mask] == 0.0)
    assert np.all(tab.p_value[mask] == 1.0)
    assert np.all(tab.log10_p[mask] == 0.0)


# --------------------------------------------------------------------------- streaming
@pytest.mark.parametrize("forgetting", [1.0, 0.999, 0.99])
def test_streaming_nested_models_match_lstsq_at_checkpoints(ref, rng, forgetting):
    n, m = 6, 3000
    X, y = _problem(rng, m, n)
    est = RecursiveQR(n, forgetting=forgetting)
    cuts = np.sort(rng.choice(np.arange(20, m - 1), size=6, replace=False))
    bounds = [0, *cuts.tolist(), m]
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        hist = est.update_many(X[a:b], y[a:b], return_energies=True, return_coefficients="all")
        # random checkpoints inside the chunk, from the recorded histories
        for t in rng.choice(np.arange(max(a, 3 * n), b), size=2, replace=False):
            J_ref, C_ref = ref.nested(X[: t + 1], y[: t + 1], forgetting=forgetting)
            C = np.zeros((n, n))
            for o in range(1, n + 1):
                C[o - 1, :o] = hist.coefficients[o][t - a]
            _assert_nested_close(hist.energies[t - a], C, J_ref, C_ref)
        # chunk end, from the query methods
        J_ref, C_ref = ref.nested(X[:b], y[:b], forgetting=forgetting)
        _assert_nested_close(est.residual_energies(), est.all_coefficients(), J_ref, C_ref)
        for o in range(1, n + 1):
            assert _rel(est.coefficients(o), C_ref[o - 1, :o]) <= RTOL
    assert est.n_samples == m
    w = ref.forgetting_weights(m, forgetting)
    assert est.weight_sum == pytest.approx(w.sum(), rel=1e-12)
    assert est.effective_samples == pytest.approx(w.sum() ** 2 / (w @ w), rel=1e-12)


def test_one_million_samples_do_not_drift(ref):
    rng = np.random.default_rng(7)
    n, m = 7, 1_000_000
    X, y = _problem(rng, m, n, noise=1.0)
    est = RecursiveQR(n)
    est.update_many(X, y)
    J_ref, C_ref = ref.nested(X, y)
    _assert_nested_close(est.residual_energies(), est.all_coefficients(), J_ref, C_ref)


# ----------------------------------------------------------------------------- prior
@pytest.mark.parametrize("forgetting", [1.0, 0.98])
@pytest.mark.parametrize("prior", [0.01, 30.0])
def test_prior_is_least_squares_on_the_augmented_data(ref, rng, prior, forgetting):
    """R_0 = sqrt(delta) I of [X y] means the rows sqrt(delta_t) I_{n+1} are part of the
    data (delta_t = lambda^t delta): nested models are lstsq on X augmented by those rows
    (all of them, for every order), and J_i includes the y-row's delta_t."""
    n = 5
    est = RecursiveQR(n, forgetting=forgetting, prior=prior)
    # before any data: zero parameters, every J_i = delta, all columns identifiable
    # (sqrt(delta)**2 is delta up to one rounding)
    np.testing.assert_allclose(est.residual_energies(), np.full(n + 1, prior), rtol=4e-16)
    np.testing.assert_array_equal(est.all_coefficients(), np.zeros((n, n)))
    assert est.identifiable().all()
    X, y = _problem(rng, 40, n)
    for t in (3, 12, 40):  # t=3 < n: the prior alone makes every column identifiable
        est.reset().update_many(X[:t], y[:t])
        J, C = est.residual_energies(), est.all_coefficients()
        J_ref, C_ref = ref.nested(X[:t], y[:t], forgetting=forgetting, prior=prior)
        _assert_nested_close(J, C, J_ref, C_ref)
        # the same thing written as ridge regression, solved by the normal equations
        w = ref.forgetting_weights(t, forgetting)
        d_t = prior * forgetting**t
        for i in range(1, n + 1):
            Xi = X[:t, :i]
            theta = np.linalg.solve(Xi.T @ (w[:, None] * Xi) + d_t * np.eye(i), Xi.T @ (w * y[:t]))
            r = y[:t] - Xi @ theta
            J_ridge = w @ (r * r) + d_t * theta @ theta + d_t
            assert J[i] == pytest.approx(J_ridge, rel=RTOL)
            assert _rel(C[i - 1, :i], theta) <= RTOL


# ----------------------------------------------------------------- sample by sample
def test_update_one_at_a_time_equals_update_many(rng):
    # update() rotates one row in; update_many() without histories reflects blocks of
    # rows (Householder): two exact algorithms, equal to rounding
    n = 5
    X, y = _problem(rng, 400, n)
    a = RecursiveQR(n, forgetting=0.99, prior=0.01)
    b = RecursiveQR(n, forgetting=0.99, prior=0.01)
    for k in range(X.shape[0]):
        a.update(X[k], y[k])
    b.update_many(X, y)
    np.testing.assert_allclose(a.R, b.R, rtol=0, atol=1e-13 * np.abs(b.R).max())
    assert np.array_equal(a._sums, b._sums)  # same recursion, same order
    np.testing.assert_allclose(a._col_sq, b._col_sq, rtol=1e-14)
    np.testing.assert_allclose(a.residual_energies(), b.residual_energies(), rtol=1e-12)
    np.testing.assert_allclose(a.all_coefficients(), b.all_coefficients(), rtol=1e-11, atol=1e-13)
    assert a.n_samples == b.n_samples == X.shape[0]


@pytest.mark.parametrize("forgetting", [1.0, 0.97])
def test_block_update_equals_row_rotations(rng, forgetting):
    # the block reflections against the per-row rotations (the path that records
    # histories), on a badly scaled problem with a zero column and a repeated one
    n, m = 7, 3 * K.BLOCK_ROWS + 5
    X, y = _problem(rng, m, n)
    X[:, 1] *= 1e-6
    X[:, 4] = 0.0
    X[:, 6] = X[:, 2]
    blocks = RecursiveQR(n, forgetting=forgetting)
    rows = RecursiveQR(n, forgetting=forgetting)
    blocks.update_many(X, y)
    rows.update_many(X, y, return_energies=True)
    assert np.all(np.diag(blocks.R) >= 0)
    # rows up to the repeated column are unique; below a zero pivot only the energy
    # R[6, y]^2 + R[y, y]^2 is (the split between the two depends on rounding)
    np.testing.assert_allclose(blocks.R[:6], rows.R[:6], rtol=0, atol=1e-12 * np.abs(rows.R).max())
    np.testing.assert_allclose(blocks.R[6:, 7] @ blocks.R[6:, 7], rows.R[6:, 7] @ rows.R[6:, 7], rtol=1e-10)
    np.testing.assert_array_equal(blocks.identifiable(), [True, True, True, True, False, True, False])
    np.testing.assert_array_equal(rows.identifiable(), blocks.identifiable())
    np.testing.assert_allclose(blocks.residual_energies(), rows.residual_energies(), rtol=1e-10)
    # and against batch least squares on the weighted data
    w = np.sqrt(forgetting ** np.arange(m - 1, -1, -1))
    keep = [0, 1, 2, 3, 5]
    ref, *_ = np.linalg.lstsq(w[:, None] * X[:, keep], w * y, rcond=None)
    np.testing.assert_allclose(blocks.coefficients()[keep], ref, rtol=1e-8)
    assert blocks.coefficients()[4] == blocks.coefficients()[6] == 0.0


def test_update_many_in_block_sized_calls_is_bit_identical(rng):
    n = 4
    X, y = _problem(rng, 4 * K.BLOCK_ROWS, n)
    a = RecursiveQR(n, forgetting=0.995)
    b = RecursiveQR(n, forgetting=0.995)
    a.update_many(X, y)
    for k in range(0, X.shape[0], K.BLOCK_ROWS):
        b.update_many(X[k : k + K.BLOCK_ROWS], y[k : k + K.BLOCK_ROWS])
    _assert_state_equal(a, _state(b))


@pytest.mark.parametrize("forgetting", [1.0, 0.995])
def test_histories_equal_the_queries_after_each_prefix(rng, forgetting):
    n, m0, m = 4, 50, 300
    X, y = _problem(rng, m0 + m, n)
    est = RecursiveQR(n, forgetting=forgetting, prior=0.1)
    est.update_many(X[:m0], y[:m0])  # histories must account for the samples before
    hist = est.update_many(X[m0:], y[m0:], return_energies=True, return_coefficients="all")
    assert hist.energies.shape == (m, n + 1)
    assert sorted(hist.coefficients) == list(range(1, n + 1))
    only = RecursiveQR(n, forgetting=forgetting, prior=0.1)
    only.update_many(X[:m0], y[:m0])
    h2 = only.update_many(X[m0:], y[m0:], return_coefficients=[2, n])
    assert sorted(h2.coefficients) == [2, n] and h2.energies is None
    h3 = RecursiveQR(n).update_many(X, y, return_coefficients=3)
    assert list(h3.coefficients) == [3] and h3.coefficients[3].shape == (m0 + m, 3)
    for t in (0, 1, 17, m - 1):
        ref_est = RecursiveQR(n, forgetting=forgetting, prior=0.1)
        ref_est.update_many(X[: m0 + t + 1], y[: m0 + t + 1])
        np.testing.assert_allclose(hist.energies[t], ref_est.residual_energies(), rtol=1e-14, atol=0)
        for o in range(1, n + 1):
            np.testing.assert_allclose(
                hist.coefficients[o][t], ref_est.coefficients(o), rtol=1e-14, atol=0
            )
        for o in (2, n):
            np.testing.assert_allclose(
                h2.coefficients[o][t], ref_est.coefficients(o), rtol=1e-14, atol=0
            )
        assert hist.effective_samples[t] == pytest.approx(ref_est.effective_samples, rel=1e-13)


@pytest.mark.parametrize("forgetting", [1.0, 0.99, 0.9])
def test_effective_samples_closed_form(forgetting):
    est = RecursiveQR(2, forgetting=forgetting)
    rng = np.random.default_rng(3)
    X = rng.standard_normal((1500, 2))
    hist = est.update_many(X, X[:, 0], return_energies=True)
    t = np.arange(1, X.shape[0] + 1, dtype=float)
    if forgetting < 1:
        lam = forgetting
        s1 = (1 - lam**t) / (1 - lam)
        s2 = (1 - lam ** (2 * t)) / (1 - lam**2)
    else:
        s1 = s2 = t
    np.testing.assert_allclose(hist.effective_samples, s1 * s1 / s2, rtol=1e-12)
    assert est.effective_samples == pytest.approx(s1[-1] ** 2 / s2[-1], rel=1e-12)
    assert est.weight_sum == pytest.approx(s1[-1], rel=1e-12)
    if forgetting < 1:  # steady state (1 + lambda) / (1 - lambda)
        assert est.effective_samples == pytest.approx((1 + lam) / (1 - lam), rel=1e-6)


# ---------------------------------------------------------------------- save / load
def test_save_load_continue_is_bit_identical(rng, tmp_path):
    n = 4
    cols = ["a", "b", "c", "d"]
    groups = {"first": ["a"], "pair": ["b", "c"], "last": ["d"]}
    X, y = _problem(rng, 1200, n)
    kw = {"forgetting": 0.999, "prior": 0.05, "columns": cols, "groups": groups, "rtol": 1e-9}
    never = RecursiveQR(**kw)  # the same calls without the save / load in between
    never.update_many(X[:500], y[:500])
    for k in range(500, 700):
        never.update(X[k], y[k])
    never.update_many(X[700:], y[700:])
    first = RecursiveQR(**kw)
    first.update_many(X[:500], y[:500])
    path = first.save(tmp_path / "state.npz")
    assert path.exists()
    loaded = RecursiveQR.load(path)
    assert loaded.columns == tuple(cols)
    assert loaded.groups == {k: tuple(v) for k, v in groups.items()}
    assert (loaded.forgetting, loaded.prior, loaded.rtol) == (0.999, 0.05, 1e-9)
    assert loaded.n_samples == 500
    for k in range(500, 700):  # continue both ways: one at a time and in bulk
        loaded.update(X[k], y[k])
    loaded.update_many(X[700:], y[700:])
    _assert_state_equal(loaded, _state(never))
    assert np.array_equal(loaded.residual_energies(), never.residual_energies())
    assert np.array_equal(loaded.all_coefficients(), never.all_coefficients())


def test_save_refuses_to_overwrite(tmp_path, rng):
    est = RecursiveQR(2)
    est.update_many(*_problem(rng, 10, 2))
    path = tmp_path / "s.npz"
    est.save(path)
    before = path.read_bytes()
    with pytest.raises(FileExistsError, match="overwrite=True"):
        est.save(path)
    assert path.read_bytes() == before
    est.update_many(*_problem(rng, 10, 2))
    est.save(path, overwrite=True)
    assert RecursiveQR.load(path).n_samples == 20
    with pytest.raises(ValueError, match=r"\.npz"):
        est.save(tmp_path / "s.txt")


def _write_bad_files(d):
    (d / "text.npz").write_text("not a state file")
    np.savez(d / "other.npz", x=np.ones(3))
    np.save(d / "array.npy", np.ones(3))
    good = {"R": np.eye(3), "col_sq": np.ones(2), "sums": np.ones(3)}
    np.savez(d / "nometa.npz", **good)
    np.savez(d / "badversion.npz", meta=np.array(json.dumps({"version": 99})), **good)
    np.savez(d / "partialmeta.npz", meta=np.array(json.dumps({"version": 1})), **good)
    np.savez(d / "listmeta.npz", meta=np.array(json.dumps([1, 2])), **good)
    meta = {"version": 1, "forgetting": 1.0, "prior": 0.0, "rtol": 1e-10,
            "columns": ["a", "b", "c"], "groups": {"a": ["a"], "b": ["b"], "c": ["c"]}}
    np.savez(d / "shapes.npz", meta=np.array(json.dumps(meta)), **good)  # 3 columns, R for 2
    return [
        "text.npz", "other.npz", "array.npy", "nometa.npz", "badversion.npz",
        "partialmeta.npz", "listmeta.npz", "shapes.npz", "missing.npz",
    ]


def test_load_rejects_non_state_files(tmp_path):
    for name in _write_bad_files(tmp_path):
        with pytest.raises(ValueError):
            RecursiveQR.load(tmp_path / name)


# ------------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    ("where", "value"),
    [((3, 1), np.nan), ((0, 2), np.inf), ((7, 0), -np.inf), (("y", 5), np.nan), (("y", 0), np.inf)],
)
def test_non_finite_input_names_sample_and_column_and_changes_nothing(rng, where, value):
    n, m0 = 3, 25
    est = RecursiveQR(columns=["u", "v", "w"], forgetting=0.99)
    est.update_many(*_problem(rng, m0, n))
    state = _state(est)
    X, y = _problem(rng, 10, n)

    def pattern(first):  # sample indices count from the last reset
        if where[0] == "y":
            return rf"non-finite y at sample {first + where[1]}\b"
        name = est.columns[where[1]]
        return rf"non-finite regressor at sample {first + where[0]}, column {where[1]} \('{name}'\)"

    if where[0] == "y":
        y[where[1]] = value
    else:
        X[where] = value
    with pytest.raises(ValueError, match=pattern(m0)):
        est.update_many(X, y, return_energies=True, return_coefficients="all")
    _assert_state_equal(est, state)
    # the same sample fed alone through update()
    k = where[1] if where[0] == "y" else where[0]
    for j in range(k):
        est.update(X[j], y[j])
    state = _state(est)
    with pytest.raises(ValueError, match=pattern(m0)):
        est.update(X[k], y[k])
    _assert_state_equal(est, state)
    with pytest.raises(ValueError, match=pattern(0)):
        est.fit(X, y)  # fit validates before it resets
    _assert_state_equal(est, state)


@pytest.mark.parametrize(
    ("call", "pattern"),
    [
        (lambda e, X, y: e.update_many(X[:, :2], y), r"shape \(m, 3\).*got shape \(10, 2\)"),
        (lambda e, X, y: e.update_many(np.c_[X, X[:, 0]], y), r"shape \(m, 3\).*\(10, 4\)"),
        (lambda e, X, y: e.update_many(X[0], y), r"shape \(m, 3\)"),
        (lambda e, X, y: e.update_many(X, y[:-1]), r"y must have shape \(10,\).*\(9,\)"),
        (lambda e, X, y: e.update_many(X, y[:, None]), r"y must have shape \(10,\)"),
        (lambda e, X, y: e.update(X[0, :2], y[0]), r"x must have shape \(3,\), got shape \(2,\)"),
        (lambda e, X, y: e.update(X[:2], y[0]), r"x must have shape \(3,\)"),
        (lambda e, X, y: e.update(X[0], y[:2]), r"y must be a scalar"),
        (lambda e, X, y: e.update_many(X, y, return_coefficients=4), r"orders must be in 1..3"),
        (lambda e, X, y: e.update_many(X, y, return_coefficients="some"), r"'all'"),
    ],
)
def test_wrong_shapes_are_rejected_and_change_nothing(rng, call, pattern):
    est = RecursiveQR(3, prior=0.5)
    est.update_many(*_problem(rng, 20, 3))
    state = _state(est)
    X, y = _problem(rng, 10, 3)
    with pytest.raises(ValueError, match=pattern):
        call(est, X, y)
    _assert_state_equal(est, state)


def test_bad_constructor_arguments():
    for kwargs in (
        {},
        {"n_regressors": 0},
        {"n_regressors": 2.5},
        {"n_regressors": 2, "forgetting": 0.0},
        {"n_regressors": 2, "forgetting": 1.01},
        {"n_regressors": 2, "prior": -1.0},
        {"n_regressors": 2, "prior": np.inf},
        {"n_regressors": 2, "rtol": -1.0},
        {"n_regressors": 3, "columns": ["a", "b"]},
        {"columns": ["a", "a"]},
    ):
        with pytest.raises(ValueError):
            RecursiveQR(**kwargs)


@pytest.mark.parametrize(
    ("groups", "pattern"),
    [
        ({"g": ["a", "zz"]}, r"unknown column 'zz'"),
        ({"g1": ["a", "b"], "g2": ["b", "c"]}, r"column 'b' is in groups 'g1' and 'g2'"),
        ({"g": []}, r"no columns"),
    ],
)
def test_bad_groups_are_rejected(groups, pattern):
    with pytest.raises(ValueError, match=pattern):
        RecursiveQR(columns=["a", "b", "c"], groups=groups)


def test_bad_orders_are_rejected(rng):
    est = RecursiveQR(3).fit(*_problem(rng, 20, 3))
    for order in (0, 4, 1.5, True):
        with pytest.raises(ValueError, match="order"):
            est.coefficients(order)
        with pytest.raises(ValueError, match="order"):
            est.standard_errors(order)


# ------------------------------------------------------------------------- hard data
def test_zero_column_is_dropped(ref, rng):
    n, m = 4, 200
    X, y = _problem(rng, m, n)
    X[:, 1] = 0.0
    est = RecursiveQR(n, forgetting=0.995).fit(X, y)
    keep = np.array([True, False, True, True])
    np.testing.assert_array_equal(est.identifiable(), keep)
    assert np.isfinite(_all_outputs(est)).all()
    J_ref, C_ref = ref.nested(X, y, forgetting=0.995, keep=keep)
    _assert_nested_close(est.residual_energies(), est.all_coefficients(), J_ref, C_ref)
    J = est.residual_energies()
    assert J[2] == J[1]  # no share of the energy
    assert all(est.standard_errors(o)[1] == 0.0 for o in range(2, n + 1))
    assert np.all(est.standard_errors()[keep] > 0)
    _assert_untestable(est.nested_tests(), ~keep)
    _assert_untestable(est.effect_tests(), ~keep)
    assert est.nested_tests().testable[keep].all() and est.effect_tests().testable[keep].all()


def test_exactly_collinear_column_is_dropped(ref, rng):
    n, m = 4, 150
    X, y = _problem(rng, m, n)
    X[:, 2] = 2.0 * X[:, 0] - 0.5 * X[:, 1]
    y = X @ np.array([1.0, -1.0, 0.5, 2.0]) + 0.3 * rng.standard_normal(m)
    est = RecursiveQR(n).fit(X, y)
    keep = np.array([True, True, False, True])
    np.testing.assert_array_equal(est.identifiable(), keep)
    assert np.isfinite(_all_outputs(est)).all()
    J_ref, C_ref = ref.nested(X, y, keep=keep)
    _assert_nested_close(est.residual_energies(), est.all_coefficients(), J_ref, C_ref)
    # the minimum-norm lstsq on all columns has other coefficients but the same fit
    theta_mn, *_ = np.linalg.lstsq(X, y, rcond=None)
    assert ref.fitted_error(X, est.coefficients(), theta_mn, y) <= RTOL
    _assert_untestable(est.nested_tests(), ~keep)
    _assert_untestable(est.effect_tests(), ~keep)


def test_fewer_samples_than_parameters(ref, rng):
    n = 5
    X, y = _problem(rng, 3, n)
    est = RecursiveQR(n)
    assert np.isfinite(_all_outputs(est)).all()  # no data at all
    assert not est.identifiable().any()
    _assert_untestable(est.nested_tests(), np.ones(n, bool))
    est.update_many(X, y)
    keep = np.array([True, True, True, False, False])
    np.testing.assert_array_equal(est.identifiable(), keep)
    assert np.isfinite(_all_outputs(est)).all()
    J, C = est.residual_energies(), est.all_coefficients()
    J_ref, C_ref = ref.nested(X, y, keep=keep)
    # 3 samples, 3 parameters: J_3 = J_4 = J_5 = 0 exactly in theory; a relative error of
    # (rounding-level) zero is meaningless, so these are compared on the scale of J_0.
    np.testing.assert_allclose(J[:3], J_ref[:3], rtol=RTOL)
    np.testing.assert_allclose(J[3:], J_ref[3:], rtol=0, atol=1e-12 * J_ref[0])
    for o in range(1, n + 1):
        assert _rel(C[o - 1], C_ref[o - 1]) <= RTOL
    # m_eff - p <= 0: the order-3 test and all standard errors of order >= 3 are void
    nt = est.nested_tests()
    _assert_untestable(nt, [False, False, True, True, True])
    assert np.all(est.standard_errors(5) == 0.0)
    ic = est.information_criteria()
    assert np.isfinite([ic.aic, ic.bic, ic.fpe]).all()
    assert ic.best_order("aic") < 3 and ic.best_order("bic") < 3 and ic.best_order("fpe") < 3


@pytest.mark.parametrize("forgetting", [1.0, 0.995])
def test_rotor_at_rest_then_excitation(ref, rng, forgetting):
    n, m_rest, m_run = 4, 600, 400
    X, y = _problem(rng, m_rest + m_run, n)
    X[:m_rest] = 0.0  # at rest: all regressors zero, y is noise
    est = RecursiveQR(n, forgetting=forgetting)
    hist = est.update_many(
        X[:m_rest], y[:m_rest], return_energies=True, return_coefficients="all"
    )
    w = ref.forgetting_weights(m_rest, forgetting)
    assert not est.identifiable().any()
    np.testing.assert_allclose(est.residual_energies(), np.full(n + 1, w @ y[:m_rest] ** 2), rtol=RTOL)
    assert np.all(est.all_coefficients() == 0.0)
    assert np.isfinite(_all_outputs(est)).all()
    _assert_untestable(est.nested_tests(), np.ones(n, bool))
    _assert_untestable(est.effect_tests(), np.ones(n, bool))
    assert np.all(hist.coefficients[n] == 0.0)
    assert np.all(hist.energies == hist.energies[:, :1])  # J_0 = ... = J_n at every sample
    hist = est.update_many(
        X[m_rest:], y[m_rest:], return_energies=True, return_coefficients="all"
    )
    assert all(np.isfinite(h).all() for h in (hist.energies, *hist.coefficients.values()))
    assert est.identifiable().all()
    assert np.isfinite(_all_outputs(est)).all()
    # zero rows contribute only to the y energy: lstsq on *all* rows is the reference
    J_ref, C_ref = ref.nested(X, y, forgetting=forgetting)
    _assert_nested_close(est.residual_energies(), est.all_coefficients(), J_ref, C_ref)
    t = 20  # soon after excitation, from the history
    J_ref, C_ref = ref.nested(X[: m_rest + t + 1], y[: m_rest + t + 1], forgetting=forgetting)
    C = np.array([np.r_[hist.coefficients[o][t], np.zeros(n - o)] for o in range(1, n + 1)])
    _assert_nested_close(hist.energies[t], C, J_ref, C_ref)


def test_identifiability_is_judged_on_the_weighted_column_norm(ref, rng):
    """A column that was huge long ago (forgotten) and is tiny but informative now is
    identifiable: the pivot is compared with the *weighted* column norm, the same weights
    as the data.  (Against the unweighted norm, 1e5**2 * 1000 samples, it would be lost.)"""
    lam, m_old, m_new = 0.98, 1000, 3000
    m = m_old + m_new
    X, y = _problem(rng, m, 3)
    X[:m_old, 2] *= 1e5
    X[m_old:, 2] *= 1e-5
    y = X[:, :2] @ np.array([1.0, -2.0]) + 3e4 * X[:, 2] + 0.1 * rng.standard_normal(m)
    est = RecursiveQR(3, forgetting=lam)
    est.update_many(X, y)
    assert est.identifiable().all()
    J_ref, C_ref = ref.nested(X, y, forgetting=lam)
    _assert_nested_close(est.residual_energies(), est.all_coefficients(), J_ref, C_ref)


def test_history_uses_the_cleaned_factor_while_columns_are_missing(ref, rng):
    """Column 3 only switches on half-way: the per-sample histories (compiled path) drop it
    before and use it after, exactly like the query methods."""
    n, m = 3, 300
    X, y = _problem(rng, m, n)
    X[:150, 2] = 0.0
    est = RecursiveQR(n)
    hist = est.update_many(X, y, return_energies=True, return_coefficients="all")
    for t, keep in ((100, [True, True, False]), (260, [True, True, True])):
        J_ref, C_ref = ref.nested(X[: t + 1], y[: t + 1], keep=np.array(keep))
        C = np.array([np.r_[hist.coefficients[o][t], np.zeros(n - o)] for o in range(1, n + 1)])
        _assert_nested_close(hist.energies[t], C, J_ref, C_ref)


# ------------------------------------------------------------------- property tests
_EPS = {"free": None, "exact": 0.0, "tiny": 1e-13, "near": 1e-5}


@st.composite
def _hard_problems(draw):
    n = draw(st.integers(1, 12))
    m = draw(st.integers(2 * n + 3, 150))
    seed = draw(st.integers(0, 2**32 - 1))
    log_scales = draw(st.lists(st.floats(-6.0, 6.0), min_size=n, max_size=n))
    kinds = draw(st.lists(st.sampled_from(list(_EPS)), min_size=n, max_size=n))
    forgetting = draw(st.sampled_from([1.0, 0.995, 0.98]))
    rng = np.random.default_rng(seed)
    X = np.empty((m, n))
    free: list[int] = []
    expected = np.empty(n, dtype=bool)
    for j, kind in enumerate(kinds):
        if kind == "free" or not free:
            v = rng.standard_normal(m)
            free.append(j)
            expected[j] = True
        else:
            # a combination of earlier well-conditioned columns (no cancellation, so the
            # combination itself is exact to rounding) plus a relative perturbation eps
            v = X[:, free] @ rng.standard_normal(len(free))
            v /= np.linalg.norm(v)
            z = rng.standard_normal(m)
            v = v + _EPS[kind] * z / np.linalg.norm(z)
            expected[j] = kind == "near"  # 1e-5 >> rtol = 1e-10 >> 1e-13
        X[:, j] = 10.0 ** log_scales[j] * v / np.linalg.norm(v) * np.sqrt(m)
    theta = rng.standard_normal(n) / np.linalg.norm(X, axis=0) * np.sqrt(m)
    y = X @ theta + 0.3 * rng.standard_normal(m)
    return X, y, forgetting, expected


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(problem=_hard_problems())
def test_property_badly_scaled_and_near_collinear(ref, problem):
    X, y, forgetting, expected = problem
    m, n = X.shape
    est = RecursiveQR(n, forgetting=forgetting)
    hist = est.update_many(X, y, return_energies=True, return_coefficients="all")
    np.testing.assert_array_equal(est.identifiable(), expected)
    out = _all_outputs(est)
    assert np.isfinite(out).all()
    assert np.isfinite(hist.energies).all()
    assert all(np.isfinite(c).all() for c in hist.coefficients.values())
    J, C = est.residual_energies(), est.all_coefficients()
    assert np.all(np.diff(J) <= 0.0)  # J_0 >= J_1 >= ... >= J_n
    assert np.all(C[:, ~expected] == 0.0)
    J_ref, C_ref = ref.nested(X, y, forgetting=forgetting, keep=expected)
    np.testing.assert_allclose(J, J_ref, rtol=RTOL, atol=0)
    w = ref.forgetting_weights(m, forgetting)
    for o in range(1, n + 1):
        assert ref.fitted_error(X, C[o - 1, :o], C_ref[o - 1, :o], y, w) <= RTOL
    assert np.array_equal(hist.energies[-1], J)
