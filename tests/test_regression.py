"""The regression ``y = X theta + e`` built from the effect declarations: presets,
equations, the compiled builder against numpy, exact recovery of the true
coefficients on noise-free data, known effects, and the online estimator against
batch least squares."""

from __future__ import annotations

import numpy as np
import pytest

from rotor_env.effects import EFFECTS
from rotor_env.measurements import COLUMNS, Measurements
from rotor_env.paper import NOISE_STD, PRIOR, run_case
from rotor_env.params import RotorParams
from rotor_env.regression import (
    DEFAULT_EFFECTS,
    PAPER_EFFECTS,
    PRESETS,
    RegressionSpec,
    build_regression,
    build_rows,
    regression_arrays,
)
from rotor_env.simulator import simulate

ALL_EFFECTS = (
    "unbalance",
    "asymmetry",
    "viscous_damping",
    "nonlinear_stiffness",
    "structural_damping",
    "stiffness",
)
#: a rotor unlike Table 1 in every respect the regression must get right: unbalance out
#: of phase, k != 1, other ip, all quadratic terms distinct; no dry friction (h = 0), so
#: that the data follow the regression exactly (the switch model's stick phase and the
#: regressor's eps regularisation differ from the exact Coulomb column)
ODD = RotorParams(ip=0.25).replace(
    tau=0.03, beta=0.7, D=0.04, c=0.05, k30=0.06, k21=0.03, k12=0.02, k03=0.01, k=1.3, h=0.0
)


def true_coefficients(params: RotorParams, columns) -> np.ndarray:
    """RotorParams.coefficients of every effect, picked by the regression's column names."""
    truth = {
        name: value
        for e in params.effects
        for name, value in zip(EFFECTS[e].coefficients, params.coefficients(e), strict=True)
    }
    if params.values["beta"] == 0.0:  # the paper's in-phase column (unbalance_in_phase)
        truth["tau"] = params.values["tau"]
    return np.array([truth[c] for c in columns])


@pytest.fixture(scope="module")
def odd_run() -> Measurements:
    return simulate(ODD, t_end=400.0, dt=0.01)


@pytest.fixture(scope="module")
def table1_run() -> Measurements:
    return simulate(RotorParams(), t_end=400.0, dt=0.01)


def random_data(m: int = 400, seed: int = 7) -> np.ndarray:
    """Random-ish measurements: large spin angles, signed rates, some exact zeros."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(m, len(COLUMNS)))
    d[:, 0] = np.arange(m) * 0.01
    d[:, 1] = rng.uniform(-800.0, 800.0, m)
    d[:, 2] = rng.uniform(0.0, 4.0, m)
    d[:10, 4:] = 0.0  # a rotor at rest: friction column 0/eps
    d[10:20, 6:8] = 1e-9  # relative speed near the friction's regularisation
    return d


# ------------------------------------------------------------------ presets
def test_paper_preset_is_eq10():
    spec = RegressionSpec("paper")
    assert spec.effects == PAPER_EFFECTS == PRESETS["paper"]
    assert spec.columns == ("tau", "D", "c", "k21", "k12", "k03", "h")
    assert spec.n_columns == 7 and spec.rows_per_sample == 1
    assert spec.known == {"stiffness": {"k": 1.0}}


def test_default_preset_has_two_unbalance_columns():
    spec = RegressionSpec("default")
    assert spec.effects == DEFAULT_EFFECTS == PRESETS["default"]
    assert spec.columns == ("tau_cos_beta", "tau_sin_beta", "D", "c", "k21", "k12", "k03", "h")
    assert spec.groups["unbalance"] == ("tau_cos_beta", "tau_sin_beta")
    assert spec.groups["nonlinear_stiffness"] == ("k21", "k12", "k03")
    assert RegressionSpec() == spec  # the default spec is the default preset


def test_preset_by_name_in_build_regression(table1_run):
    a = build_regression(table1_run, "paper", ip=0.3)
    b = build_regression(table1_run, list(PAPER_EFFECTS), ip=0.3)
    assert a.columns == b.columns
    np.testing.assert_array_equal(a.X, b.X)
    np.testing.assert_array_equal(a.y, b.y)


# ------------------------------------------------------------------ equations
@pytest.mark.parametrize(
    ("equation", "rows", "k30", "k03"),
    [("first", 1, False, True), ("second", 1, True, False), ("both", 2, True, True)],
)
def test_equations_shapes_and_k30(table1_run, equation, rows, k30, k03):
    reg = build_regression(table1_run, "default", ip=0.3, equation=equation)
    m = len(table1_run)
    n = 8 + (equation == "both")
    assert reg.X.shape == (rows * m, n)
    assert reg.y.shape == reg.t.shape == reg.equation.shape == (rows * m,)
    assert ("k30" in reg.columns) is k30
    assert ("k03" in reg.columns) is k03
    nl = reg.groups["nonlinear_stiffness"]
    assert nl == tuple(c for c in ("k30", "k21", "k12", "k03") if c in reg.columns)
    if equation == "both":
        np.testing.assert_array_equal(reg.equation[:4], [1, 2, 1, 2])
        np.testing.assert_array_equal(reg.t[0::2], table1_run.t)
        np.testing.assert_array_equal(reg.t[1::2], table1_run.t)
    else:
        assert set(reg.equation.tolist()) == {1 if equation == "first" else 2}
        np.testing.assert_array_equal(reg.t, table1_run.t)


def test_both_stacks_first_and_second(table1_run):
    first = build_regression(table1_run, ALL_EFFECTS, ip=0.3, equation="first")
    second = build_regression(table1_run, ALL_EFFECTS, ip=0.3, equation="second")
    both = build_regression(table1_run, ALL_EFFECTS, ip=0.3, equation="both")
    j1 = [both.columns.index(c) for c in first.columns]
    j2 = [both.columns.index(c) for c in second.columns]
    np.testing.assert_array_equal(both.X[0::2][:, j1], first.X)
    np.testing.assert_array_equal(both.X[1::2][:, j2], second.X)
    np.testing.assert_array_equal(both.y[0::2], first.y)
    np.testing.assert_array_equal(both.y[1::2], second.y)
    # k30 is zero in every first-equation row, k03 in every second-equation row
    assert not both.X[0::2, both.columns.index("k30")].any()
    assert not both.X[1::2, both.columns.index("k03")].any()
    assert both.X[1::2, both.columns.index("k30")].any()


def test_only_k30_has_no_column_in_the_first_equation():
    assert RegressionSpec(("nonlinear_stiffness",), equation="first").columns == ("k21", "k12", "k03")
    assert RegressionSpec(("nonlinear_stiffness",), equation="second").columns == ("k30", "k21", "k12")
    assert RegressionSpec(("nonlinear_stiffness",), equation="both").columns == ("k30", "k21", "k12", "k03")
    for e in ALL_EFFECTS:  # every other effect has all its columns in both equations
        if e != "nonlinear_stiffness":
            cols = EFFECTS[e].coefficients
            assert RegressionSpec((e,), equation="first").columns == cols
            assert RegressionSpec((e,), equation="second").columns == cols


# ------------------------------------------------------------------ numba == numpy
@pytest.mark.parametrize("equation", ["first", "second", "both"])
@pytest.mark.parametrize(
    "effects",
    ["paper", "default", ALL_EFFECTS, ("structural_damping", "unbalance_in_phase")],
    ids=["paper", "default", "all", "reordered"],
)
def test_build_rows_equals_numpy(equation, effects):
    data = random_data()
    spec = RegressionSpec(effects=effects, equation=equation)
    X1, y1 = regression_arrays(spec, data, 0.3)
    X2, y2 = build_rows(spec, data, 0.3)
    np.testing.assert_array_equal(X2, X1)
    np.testing.assert_array_equal(y2, y1)
    assert X1.shape == (len(data) * spec.rows_per_sample, spec.n_columns)


@pytest.mark.parametrize("equation", ["first", "second", "both"])
def test_build_rows_equals_numpy_with_known_effects_and_control(equation):
    data = random_data(seed=8)
    control = np.random.default_rng(3).normal(size=(len(data), 2))
    known = {"asymmetry": {"D": 0.03}, "stiffness": {"k": 1.2}, "unbalance": {"tau": 0.02, "beta": 0.4}}
    spec = RegressionSpec(effects=("viscous_damping", "nonlinear_stiffness"), equation=equation, known=known)
    X1, y1 = regression_arrays(spec, data, 0.2, control)
    X2, y2 = build_rows(spec, data, 0.2, control)
    np.testing.assert_array_equal(X2, X1)
    np.testing.assert_array_equal(y2, y1)
    # into preallocated arrays (the environment's path)
    out = (np.full_like(X1, np.nan), np.full_like(y1, np.nan))
    build_rows(spec, data, 0.2, control, out=out)
    np.testing.assert_array_equal(out[0], X1)
    np.testing.assert_array_equal(out[1], y1)


def test_build_regression_equals_build_rows_on_simulated_data(odd_run):
    for equation in ("first", "second", "both"):
        reg = build_regression(odd_run, ALL_EFFECTS, ip=ODD.ip, equation=equation)
        X, y = build_rows(reg.spec, odd_run.data, ODD.ip)
        np.testing.assert_array_equal(X, reg.X)
        np.testing.assert_array_equal(y, reg.y)


# ------------------------------------------------------------------ exact recovery
RECOVERY_RTOL = 1e-8  # measured ~1e-15 (the data follow the regression to rounding)


@pytest.mark.parametrize("equation", ["first", "second", "both"])
@pytest.mark.parametrize(
    ("params", "effects"),
    [
        (ODD, ALL_EFFECTS),  # k estimated
        (ODD.replace(k=1.0), DEFAULT_EFFECTS),  # k = 1 known (the default)
        (RotorParams().replace(h=0.0), DEFAULT_EFFECTS),  # Table 1 without friction
        (RotorParams().replace(h=0.0, beta=0.0), PAPER_EFFECTS),  # the paper's x1, beta = 0
    ],
    ids=["odd-k-estimated", "odd-k1", "table1-h0", "paper-beta0"],
)
def test_lstsq_recovers_true_coefficients(params, effects, equation):
    meas = simulate(params, t_end=400.0, dt=0.01)
    reg = build_regression(meas, effects, ip=params.ip, equation=equation)
    want = true_coefficients(params, reg.columns)
    theta, *_ = np.linalg.lstsq(reg.X, reg.y, rcond=None)
    scale = np.abs(want).max()
    err = np.abs(theta - want)
    assert err.max() < RECOVERY_RTOL * scale, dict(zip(reg.columns, err, strict=True))
    # and the physical parameters read back
    phys = reg.spec.physical(theta)
    for name, value in phys.items():
        if name in EFFECTS["nonlinear_stiffness"].coefficients and name not in reg.columns:
            continue  # k30 in the first equation, k03 in the second: not seen
        assert value == pytest.approx(params.values[name], rel=1e-7, abs=1e-9), name


def test_the_wrong_unbalance_column_leaves_a_residual():
    """PHYSICS.md: with beta != 0 the in-phase column alone cannot fit the unbalance."""
    params = RotorParams().replace(h=0.0, beta=0.7)
    meas = simulate(params, t_end=400.0, dt=0.01)
    for effects, exact in ((DEFAULT_EFFECTS, True), (PAPER_EFFECTS, False)):
        reg = build_regression(meas, effects, ip=0.3)
        theta, *_ = np.linalg.lstsq(reg.X, reg.y, rcond=None)
        rms = np.sqrt(np.mean((reg.y - reg.X @ theta) ** 2))
        assert bool(rms < 1e-12) is exact, (effects, rms)


# ------------------------------------------------------------------ names
def test_unknown_effect_lists_known_ones():
    with pytest.raises(ValueError, match="unknown effect 'crack'") as info:
        RegressionSpec(effects=("unbalance", "crack"))
    for name in EFFECTS:
        assert name in str(info.value)


def test_unknown_known_effect_lists_known_ones():
    with pytest.raises(ValueError, match="unknown effect 'gravity'") as info:
        RegressionSpec(effects=("unbalance",), known={"gravity": {"g": 1.0}})
    assert "asymmetry" in str(info.value)


def test_unknown_effect_in_build_regression(table1_run):
    with pytest.raises(ValueError, match=r"unknown effect 'damping'; known effects: .*viscous_damping"):
        build_regression(table1_run, ["unbalance", "damping"], ip=0.3)


def test_unknown_preset_lists_presets():
    with pytest.raises(ValueError, match="unknown preset 'papers'; presets: paper, default"):
        RegressionSpec("papers")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"effects": ()}, "at least one effect"),
        ({"effects": ("asymmetry", "asymmetry")}, "listed twice"),
        ({"equation": "third"}, "equation must be one of"),
        ({"effects": ("asymmetry",), "known": {"asymmetry": {"D": 0.1}}}, "both estimated and known"),
        ({"effects": ("unbalance",), "known": {"asymmetry": {}}}, r"lacks parameter\(s\) \['D'\]"),
    ],
)
def test_invalid_specs(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RegressionSpec(**kwargs)


@pytest.mark.parametrize("ip", [-0.1, 1.0, float("nan")])
def test_invalid_ip(table1_run, ip):
    with pytest.raises(ValueError, match="ip must be in"):
        build_regression(table1_run, "paper", ip=ip)


# ------------------------------------------------------------------ known effects
def test_known_effect_moves_to_y_exactly(odd_run):
    full = build_regression(odd_run, ALL_EFFECTS, ip=ODD.ip, equation="both")
    rest = tuple(e for e in ALL_EFFECTS if e != "asymmetry")
    known = build_regression(odd_run, rest, ip=ODD.ip, equation="both", known={"asymmetry": {"D": 0.04}})
    assert "D" not in known.columns
    jd = full.columns.index("D")
    keep = [full.columns.index(c) for c in known.columns]
    np.testing.assert_array_equal(known.X, full.X[:, keep])
    np.testing.assert_allclose(known.y, full.y - 0.04 * full.X[:, jd], rtol=0, atol=1e-15)


def test_known_effect_gives_the_same_fit_as_estimating_it(odd_run):
    """known={'asymmetry': {'D': D}} with the true D: the rest fit as when D is estimated."""
    rest = tuple(e for e in DEFAULT_EFFECTS if e != "asymmetry")
    est = build_regression(odd_run.data, (*rest, "asymmetry", "stiffness"), ip=ODD.ip)
    kn = build_regression(odd_run.data, (*rest, "stiffness"), ip=ODD.ip, known={"asymmetry": {"D": ODD.D}})
    th_est, *_ = np.linalg.lstsq(est.X, est.y, rcond=None)
    th_kn, *_ = np.linalg.lstsq(kn.X, kn.y, rcond=None)
    assert th_est[est.columns.index("D")] == pytest.approx(ODD.D, rel=1e-10)
    same = [est.columns.index(c) for c in kn.columns]
    np.testing.assert_allclose(th_kn, th_est[same], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(th_kn, true_coefficients(ODD, kn.columns), rtol=1e-9, atol=1e-12)


def test_stiffness_is_known_as_one_unless_estimated(odd_run):
    """Default: k = 1 known.  For the k = 1.3 rotor that leaves a residual; estimating k
    (or knowing the true k) removes it."""
    ip = ODD.ip
    fits = {}
    for label, effects, known in (
        ("k=1 known", DEFAULT_EFFECTS, None),
        ("k=1.3 known", DEFAULT_EFFECTS, {"stiffness": {"k": 1.3}}),
        ("k estimated", (*DEFAULT_EFFECTS, "stiffness"), None),
    ):
        reg = build_regression(odd_run, effects, ip=ip, known=known)
        theta, *_ = np.linalg.lstsq(reg.X, reg.y, rcond=None)
        fits[label] = float(np.sqrt(np.mean((reg.y - reg.X @ theta) ** 2)))
    assert fits["k=1.3 known"] < 1e-12 and fits["k estimated"] < 1e-12
    assert fits["k=1 known"] > 1e-4


def test_control_moments_are_subtracted(table1_run):
    M = np.random.default_rng(0).normal(size=(len(table1_run), 2))
    a = build_regression(table1_run, "default", ip=0.3, equation="both")
    b = build_regression(table1_run, "default", ip=0.3, equation="both", control=M)
    np.testing.assert_array_equal(a.X, b.X)
    np.testing.assert_allclose(b.y[0::2], a.y[0::2] - M[:, 1], atol=1e-15)
    np.testing.assert_allclose(b.y[1::2], a.y[1::2] - M[:, 0], atol=1e-15)


def test_select_and_physical(odd_run):
    reg = build_regression(odd_run, ALL_EFFECTS, ip=ODD.ip)
    late = reg.select(reg.t >= 300.0)
    assert late.t.min() >= 300.0 and late.X.shape[0] == late.y.shape[0] == late.t.shape[0]
    phys = reg.spec.physical(true_coefficients(ODD, reg.columns))
    assert phys["tau"] == pytest.approx(0.03) and phys["beta"] == pytest.approx(0.7)
    assert phys["k"] == 1.3 and phys["D"] == 0.04


# ------------------------------------------------------------------ online == batch
@pytest.fixture(scope="module")
def paper_regression(table1_run):
    reg = build_regression(table1_run, "paper", ip=0.3)
    y = reg.y + np.random.default_rng(11).normal(0.0, NOISE_STD, reg.y.shape)
    return reg, y


def augmented_lstsq(X: np.ndarray, y: np.ndarray, prior: float) -> tuple[np.ndarray, float]:
    """Least squares on ``[X y]`` with ``sqrt(prior) I`` rows appended (ridge for theta;
    the prior row of ``y`` adds ``prior`` to the residual energy)."""
    n = X.shape[1]
    A = np.column_stack([X, y])
    if prior > 0:
        A = np.vstack([A, np.sqrt(prior) * np.eye(n + 1)])
    theta, *_ = np.linalg.lstsq(A[:, :n], A[:, n], rcond=None)
    r = A[:, n] - A[:, :n] @ theta
    return theta, float(r @ r)


@pytest.mark.parametrize("prior", [0.0, PRIOR])
def test_online_estimator_at_t400_equals_batch(paper_regression, prior, ref):
    reg, y = paper_regression
    est = reg.estimator(prior=prior)
    # streamed in uneven chunks, as the paper's run does
    for lo, hi in ((0, 20001), (20001, 30001), (30001, len(y))):
        est.update_many(reg.X[lo:hi], y[lo:hi])
    assert est.n_samples == len(y) and reg.t[-1] == pytest.approx(400.0)
    theta, J = augmented_lstsq(reg.X, y, prior)
    np.testing.assert_allclose(est.coefficients(), theta, rtol=1e-10)
    assert est.residual_energies()[-1] == pytest.approx(J, rel=1e-11)
    if prior > 0:  # the augmented problem is ridge regression
        n = reg.X.shape[1]
        ridge = np.linalg.solve(reg.X.T @ reg.X + prior * np.eye(n), reg.X.T @ y)
        np.testing.assert_allclose(theta, ridge, rtol=1e-10)
    # every nested model (Fig. 2 of the paper), against the conftest reference
    J_ref, C_ref = ref.nested(reg.X, y, prior=prior)
    np.testing.assert_allclose(est.residual_energies(), J_ref, rtol=1e-11)
    np.testing.assert_allclose(est.all_coefficients(), C_ref, rtol=1e-10, atol=1e-13)


def test_paper_run_at_t400_equals_ridge(table1_run):
    """run_case's online estimate at t = 400 is the batch ridge solution on its data."""
    case = run_case("1", seed=4)
    reg = build_regression(table1_run, "paper", ip=0.3)
    y = reg.y + np.random.default_rng(4).normal(0.0, NOISE_STD, reg.y.shape)  # run_case's noise
    theta, _ = augmented_lstsq(reg.X, y, PRIOR)
    assert case.t[-1] == pytest.approx(400.0)
    np.testing.assert_allclose(case.coefficients[-1], theta, rtol=1e-10)
