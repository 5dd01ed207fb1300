"""The rotor simulator: accuracy against the LSODA reference, the paper's response,
the declared regressors, rotation orders, noise, validation, divergence and the CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rotor_env import cli
from rotor_env.effects import EFFECTS, FRICTION_EPS
from rotor_env.measurements import COLUMNS, Measurements
from rotor_env.params import Crack, RotorParams
from rotor_env.reference import reference_solution
from rotor_env.simulator import SimulationError, Simulator, integrate, simulate

TABLE1 = RotorParams()
#: a linear rotor: no quadratic stiffness, no dry friction
LINEAR = {"k30": 0.0, "k21": 0.0, "k12": 0.0, "k03": 0.0, "h": 0.0}


@pytest.fixture(scope="module")
def table1_run() -> Measurements:
    return simulate(TABLE1)


def amplitude(meas: Measurements) -> np.ndarray:
    return np.hypot(meas.theta_x, meas.theta_y)


# ----------------------------------------------------------- accuracy vs reference
@pytest.mark.parametrize(
    "params",
    [
        TABLE1,
        TABLE1.replace(h=0.0),
        RotorParams(crack=Crack(250.0, 0.08)).replace(D=0.0),
        TABLE1.replace(beta=1.0),
    ],
    ids=["table1", "h=0", "crack@250", "beta=1"],
)
def test_matches_lsoda_reference(params):
    meas = simulate(params, t_end=400.0, dt=0.01)
    every = 10
    t = meas.t[::every]
    ref = reference_solution(params, t)
    peak = np.hypot(ref[:, 0], ref[:, 1]).max()
    assert peak > 0.1  # the run passes resonance: a meaningful comparison
    dev = max(
        np.abs(meas.theta_x[::every] - ref[:, 0]).max(),
        np.abs(meas.theta_y[::every] - ref[:, 1]).max(),
    )
    assert dev < 1e-3 * peak, f"max deviation {dev:.3g} vs peak {peak:.3g}"


def test_crack_changes_the_response_after_it_appears():
    """The crack parameter set above is only a test of the split if the jump matters."""
    intact = simulate(TABLE1.replace(D=0.0), t_end=400.0)
    cracked = simulate(RotorParams(crack=Crack(250.0, 0.08)).replace(D=0.0), t_end=400.0)
    before = intact.t <= 250.0
    np.testing.assert_array_equal(intact.data[before], cracked.data[before])
    assert np.abs(amplitude(intact)[~before] - amplitude(cracked)[~before]).max() > 1e-3


# ------------------------------------------------------------ the paper's response
def test_table1_response_matches_the_paper(table1_run):
    amp = amplitude(table1_run)
    i = int(np.argmax(amp))
    assert amp[i] == pytest.approx(0.307, abs=0.002)
    assert table1_run.t[i] == pytest.approx(145.0, abs=3.0)
    assert 0.21 <= amp[-1] <= 0.23
    assert table1_run.t[-1] == pytest.approx(400.0)
    # dry friction holds the disk (|theta| = 0, no creep) until the unbalance exceeds h
    assert np.all(amp[table1_run.t < 50.0] == 0.0)


def test_measurement_columns_are_consistent(table1_run):
    m = table1_run
    assert len(m) == 40001
    np.testing.assert_allclose(np.diff(m.t), 0.01, atol=1e-9)
    np.testing.assert_allclose(m.phi_dot, 0.01 * m.t, atol=1e-12)
    np.testing.assert_allclose(m.phi, 0.005 * m.t**2, rtol=1e-12, atol=1e-9)
    assert np.all(m.phi_ddot == 0.01)
    # rates are the derivatives of the angles (central differences, O(dt^2))
    dth = (m.theta_x[2:] - m.theta_x[:-2]) / 0.02
    assert np.abs(dth - m.theta_x_dot[1:-1]).max() < 1e-3 * np.abs(m.theta_x_dot).max()
    assert np.isfinite(m.data).all()


# ------------------------------------------------------ regressors reproduce y
def _regression(params: RotorParams, meas: Measurements):
    args = (
        meas.phi, meas.phi_dot, meas.phi_ddot, meas.theta_x, meas.theta_y,
        meas.theta_x_dot, meas.theta_y_dot, params.ip,
    )
    Xy, Xx, theta = [], [], []
    for name in params.effects:
        cy, cx = EFFECTS[name].regressors(*args)
        Xy.append(cy)
        Xx.append(cx)
        theta.extend(params.coefficients(name))
    # gyroscopic terms (known) moved to the left-hand side
    y = meas.theta_y_ddot + params.ip * meas.phi_dot * meas.theta_x_dot
    y_x = meas.theta_x_ddot - params.ip * meas.phi_dot * meas.theta_y_dot
    return (y, np.hstack(Xy)), (y_x, np.hstack(Xx)), np.array(theta)


@pytest.mark.parametrize(
    "params",
    [TABLE1, TABLE1.replace(beta=0.7, k=1.3), TABLE1.replace(h=0.0, beta=-2.0, k=0.8)],
    ids=["table1", "beta,k", "h=0"],
)
def test_declared_regressors_reproduce_both_equations(params):
    meas = simulate(params, t_end=400.0)
    (y, Xy), (y_x, Xx), theta = _regression(params, meas)
    assert theta.size == Xy.shape[1] == Xx.shape[1]
    S = np.hypot(
        meas.theta_y_dot + meas.phi_dot * meas.theta_x,
        meas.theta_x_dot - meas.phi_dot * meas.theta_y,
    )
    if params.h > 0:
        # The dry-friction column is the Coulomb (slipping) direction -v/|v|.  While the
        # disk sticks to the shaft (S ~ 0, t < ~90 for Table 1) the friction moment is
        # whatever holds the stick, smaller than h and not along that column, so the
        # equation only holds where the disk slips.  The column also regularises
        # S -> sqrt(S^2 + eps^2): that changes it by h (1 - S/sqrt(S^2+eps^2)) at most.
        slip = S > 1e-3
        assert 0.5 < slip.mean() < 0.95  # both phases are present
        model_error = params.h * (1.0 - S / np.sqrt(S**2 + FRICTION_EPS**2))
    else:
        slip = np.ones(len(meas), dtype=bool)  # no friction: every sample
        model_error = np.zeros(len(meas))
    for lhs, X in ((y, Xy), (y_x, Xx)):
        resid = lhs - X @ theta
        bound = model_error + 1e-12 * np.abs(lhs).max()
        assert np.all(np.abs(resid[slip]) <= bound[slip]), np.abs(resid[slip]).max()
        # and the check has teeth: coefficients 1% off break it by far
        assert np.abs((lhs - X @ (1.01 * theta))[slip]).max() > 1e3 * bound[slip].max()
    if params.h > 0:
        # while sticking, friction moments are below the Coulomb limit: the residual
        # there is the difference between the stick moment and the Coulomb column
        stick = S < 1e-9
        assert stick.sum() > 1000
        assert np.abs(y - Xy @ theta)[stick].max() <= 2 * params.h


# ----------------------------------------------------------------- rotation orders
def _order_amplitudes(meas: Measurements, orders, t_start=200.0, t_stop=400.0) -> dict:
    """|c_n| of ``z = theta_x + i theta_y`` on ``exp(i n phi)`` over a window in phi.

    ``c_n = int z e^{-i n phi} w dphi / int w dphi`` with a Hann window ``w`` in
    ``phi`` (resampling on the angle), so only components locked to the spin survive;
    in this sign convention the shaft turns as ``exp(-i phi)`` (the unbalance drives
    ``n = -1``, the forward whirl) and the rotating-frame response is
    ``z_r = z exp(i phi)``: a 2x component in rotating coordinates is ``n = +1`` or
    ``n = -3`` here, a 2x component in the fixed frame ``n = +-2``.
    """
    sel = (meas.t >= t_start) & (meas.t <= t_stop)
    z = meas.theta_x[sel] + 1j * meas.theta_y[sel]
    phi = meas.phi[sel]
    u = (phi - phi[0]) / (phi[-1] - phi[0])
    w = np.sin(np.pi * u) ** 2 * meas.phi_dot[sel]  # dphi = phi_dot dt
    return {n: float(abs(np.sum(z * np.exp(-1j * n * phi) * w)) / np.sum(w)) for n in orders}


def test_symmetric_linear_rotor_shows_no_2x():
    """D = 0, no quadratic stiffness, h = 0: the equations are rotationally symmetric,
    so the unbalance (1x) and a constant side load (0x, like gravity) produce nothing
    at 2x, in the rotating frame (n = +1, -3) or the fixed frame (n = +-2)."""
    params = TABLE1.replace(D=0.0, **LINEAR)
    load = (0.0, 0.01)  # (M_y, M_x)
    meas = Simulator(params).run(t_end=400.0, dt=0.01, control=load)
    c = _order_amplitudes(meas, (-3, -2, -1, 0, 1, 2))
    assert c[-1] > 0.01 and c[0] > 0.005  # the unbalance whirl and the static sag
    for n in (-3, -2, 1, 2):
        assert c[n] < 1e-5 * c[-1], (n, c)  # measured: <= 6e-7 (window leakage)
    # the measure sees a 2x where there is one: quadratic stiffness breaks the symmetry
    # (fixed-frame 2x from theta^2; rotating 2x from the sag times the whirl)
    quadratic = Simulator(TABLE1.replace(D=0.0, h=0.0)).run(t_end=400.0, dt=0.01, control=load)
    cq = _order_amplitudes(quadratic, (-2, -1, 1))
    assert cq[1] > 2e-5 * cq[-1] and cq[-2] > 1e-5 * cq[-1], cq


def test_asymmetric_rotor_shows_2x_linear_in_D():
    """With D != 0 the shaft's stiffness turns with it: a static load (0x, gravity-like)
    gets a 2x response in the fixed frame (the classic crack signature), of size ~ D."""
    load = (0.0, 0.01)
    c = {}
    for D in (0.0, 0.03, 0.1):
        meas = Simulator(TABLE1.replace(D=D, **LINEAR)).run(t_end=400.0, dt=0.01, control=load)
        amp = _order_amplitudes(meas, (-2, 0, 2))
        c[D] = max(amp[-2], amp[2]) / amp[0]
    assert c[0.0] < 1e-5 < 3e-4 < c[0.03]  # measured: 1.3e-6 and 1.0e-3
    assert c[0.1] / c[0.03] == pytest.approx(0.1 / 0.03, rel=0.05)


def test_asymmetry_alone_keeps_the_unbalance_response_at_1x():
    """Without a static load the asymmetric rotor is time-invariant in rotating
    coordinates (``D conj(z_r)``) and the unbalance is constant there, so even D != 0
    adds no other rotation order: a rotating-frame 2x needs another source (e.g. the
    quadratic stiffness).  This guards against an asymmetry implemented in the fixed
    frame (its unbalance response would have a backward 1x, n = +1)."""
    orders = (-3, -2, 0, 1, 2)
    sym = _order_amplitudes(simulate(TABLE1.replace(D=0.0, **LINEAR)), (-1, *orders))
    asym = _order_amplitudes(simulate(TABLE1.replace(D=0.1, **LINEAR)), (-1, *orders))
    for n in orders:
        assert sym[n] < 1e-5 * sym[-1], (n, sym)
        assert asym[n] < 1e-5 * asym[-1], (n, asym)


# ----------------------------------------------------------------------- noise
def test_noise_is_reproducible_and_has_the_right_std():
    clean = simulate(TABLE1, t_end=100.0)
    a = simulate(TABLE1, t_end=100.0, noise=0.01, seed=7)
    b = simulate(TABLE1, t_end=100.0, noise=0.01, seed=7)
    c = simulate(TABLE1, t_end=100.0, noise=0.01, seed=8)
    np.testing.assert_array_equal(a.data, b.data)
    assert not np.array_equal(a.data, c.data)
    # spin channels are exact encoder readings; t too
    np.testing.assert_array_equal(a.data[:, :4], clean.data[:, :4])
    e = a.data[:, 4:] - clean.data[:, 4:]
    assert e.shape[1] == 6
    std = e.std(axis=0)
    np.testing.assert_allclose(std, 0.01, rtol=0.03)  # 10001 samples: ~0.7% sampling error
    assert np.abs(e.mean(axis=0)).max() < 4 * 0.01 / math.sqrt(len(e))
    assert np.abs(np.corrcoef(e.T) - np.eye(6)).max() < 0.05  # independent channels


# ------------------------------------------------------------------ validation
@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: RotorParams(ip=1.0), r"'ip' must be in \[0, 1\)"),
        (lambda: RotorParams(ip=-0.1), r"'ip' must be in \[0, 1\)"),
        (lambda: RotorParams(ip=float("nan")), "'ip' must be finite"),
        (lambda: TABLE1.replace(c=float("nan")), "'c' must be finite"),
        (lambda: TABLE1.replace(D=float("inf")), "'D' must be finite"),
        (lambda: TABLE1.replace(tau="abc"), "'tau' must be a number"),
        (lambda: TABLE1.replace(c=-0.01), "'c' must be in"),
        (lambda: TABLE1.replace(h=-0.01), "'h' must be in"),
        (lambda: TABLE1.replace(tau=-0.02), "'tau' must be in"),
        (lambda: RotorParams(effects=("stiffness", "unbalance"), crack=Crack(1.0, 0.1)),
         "crack needs the 'asymmetry' effect"),
        (lambda: Crack(-1.0, 0.1), "crack time must be >= 0"),
        (lambda: Crack(float("nan"), 0.1), "must be finite"),
    ],
)
def test_invalid_parameters_are_rejected(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_unknown_parameter_lists_the_known_ones():
    with pytest.raises(ValueError, match="unknown parameter 'Dx'") as info:
        TABLE1.replace(Dx=0.1)
    for name in RotorParams.known_names():
        assert name in str(info.value)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"dt": 0.0}, "dt must be a positive number"),
        ({"dt": -0.01}, "dt must be a positive number"),
        ({"dt": float("nan")}, "dt must be a positive number"),
        ({"t_end": 0.0}, "t_end must be a positive number"),
        ({"t_end": float("inf")}, "t_end must be a positive number"),
        ({"t_end": 0.001, "dt": 0.01}, "shorter than one sample"),
        ({"run_up": float("nan")}, "run-up rate must be finite"),
        ({"max_substep": 0.0}, "max_substep must be > 0"),
        ({"noise": -1.0}, "must be a finite number >= 0"),
    ],
)
def test_invalid_run_settings_are_rejected(kwargs, match):
    with pytest.raises(ValueError, match=match):
        simulate(TABLE1, **{"t_end": 1.0, **kwargs})


# ------------------------------------------------------------------ divergence
@pytest.mark.parametrize("D", [0.5, 5.0], ids=["unstable band", "negative stiffness"])
def test_divergence_ends_with_simulation_error(D):
    params = TABLE1.replace(D=D)
    with pytest.raises(SimulationError, match=r"diverged at t = \d"):
        simulate(params)
    # the kernel stops at the first huge state and leaves no NaN in what it wrote
    sim = Simulator(params)
    coef, h = sim.coefficients(0.0)
    state = np.zeros(4)
    out = np.full((40000, len(COLUMNS)), -1.0)
    done = integrate(sim.accel, state, 0.0, 0.0, 0.0, 0.01, params.ip, coef, h, 0.0, 0.0,
                     40000, 1, 0.01, out)
    assert 0 < done < 40000
    assert np.isfinite(out[:done]).all() and np.isfinite(state).all()
    assert np.abs(out[:done, 4:6]).max() < 1e3
    assert np.all(out[done:] == -1.0)


def test_divergence_closes_the_progress_bar():
    tqdm = pytest.importorskip("tqdm").tqdm
    with pytest.raises(SimulationError):
        simulate(TABLE1.replace(D=0.5), progress=True)
    assert len(tqdm._instances) == 0


def test_progress_bar_run_equals_plain_run(table1_run):
    # the bar splits the run into chunks (each restarting the spin angle from t0):
    # rounding-level differences only (measured 9e-10)
    np.testing.assert_allclose(simulate(TABLE1, progress=True).data, table1_run.data, rtol=0, atol=1e-7)


# ------------------------------------------------------------------------- CLI
def _run_cli(capsys, *argv):
    code = cli.main(["simulate", *map(str, argv)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _read_csv(path) -> tuple[str, np.ndarray]:
    with open(path) as fh:
        header = fh.readline().strip()
    return header, np.loadtxt(path, delimiter=",", skiprows=1)


def test_cli_writes_csv(tmp_path, capsys):
    out = tmp_path / "run.csv"
    code, stdout, err = _run_cli(capsys, out, "--t-end", 150)
    assert code == 0, err
    header, data = _read_csv(out)
    assert header == "t,phi,phi_dot,phi_ddot,theta_x,theta_y,theta_x_dot,theta_y_dot,theta_x_ddot,theta_y_ddot"
    assert data.shape == (15001, 10)
    np.testing.assert_array_equal(data, simulate(TABLE1, t_end=150.0).data)  # %.17g: exact
    assert stdout.count("\n") == 1
    assert "15001 rows" in stdout and str(out) in stdout
    assert "peak |theta| = 0.307" in stdout and "t = 145.4" in stdout


def test_cli_parquet_round_trip(tmp_path, capsys):
    pq = pytest.importorskip("pyarrow.parquet")
    out = tmp_path / "run.parquet"
    code, _, err = _run_cli(capsys, out, "--t-end", 20, "--noise", 0.01, "--seed", 1)
    assert code == 0, err
    table = pq.read_table(out)
    assert tuple(table.column_names) == COLUMNS
    data = np.column_stack([table[c].to_numpy() for c in COLUMNS])
    np.testing.assert_array_equal(data, simulate(TABLE1, t_end=20.0, noise=0.01, seed=1).data)


def test_cli_refuses_to_overwrite_without_force(tmp_path, capsys):
    out = tmp_path / "run.csv"
    out.write_text("keep me\n")
    code, stdout, err = _run_cli(capsys, out, "--t-end", 1)
    assert code == 2
    assert str(out) in err and "--force" in err and "exists" in err
    assert err.count("\n") == 1 and stdout == ""
    assert out.read_text() == "keep me\n"
    code, _, err = _run_cli(capsys, out, "--t-end", 1, "--force")
    assert code == 0, err
    assert out.read_text().startswith("t,phi,")


def test_cli_set_params_crack_noise_seed(tmp_path, capsys):
    pfile = tmp_path / "p.json"
    pfile.write_text(json.dumps({"h": 0.0, "c": 0.05, "ip": 0.2, "crack": {"time": 5.0, "D": 0.2}}))
    out = tmp_path / "a.csv"
    common = ["--params", pfile, *"--set c=0.04 --set ip=0.25 --t-end 10 --dt 0.02".split()]
    common += [*"--run-up 0.05 --noise 0.001".split()]
    code, _, err = _run_cli(capsys, out, *common, "--seed", 3)
    assert code == 0, err
    expected = RotorParams(ip=0.25, values={"h": 0.0, "c": 0.04}, crack=Crack(5.0, 0.2))
    want = simulate(expected, t_end=10.0, dt=0.02, run_up=0.05, noise=0.001, seed=3)
    _, data = _read_csv(out)
    np.testing.assert_array_equal(data, want.data)
    # --crack overrides the file's crack; a different seed gives different noise
    out2 = tmp_path / "b.csv"
    code, _, err = _run_cli(capsys, out2, *common, "--crack", "2:0.3", "--seed", 4)
    assert code == 0, err
    want2 = simulate(expected.replace(crack=Crack(2.0, 0.3)), t_end=10.0, dt=0.02, run_up=0.05,
                     noise=0.001, seed=4)
    np.testing.assert_array_equal(_read_csv(out2)[1], want2.data)


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--set", "Dx=0.1"], "unknown parameter 'Dx'; known parameters: ip, k, tau, beta, c, D"),
        (["--set", "D"], "expected NAME=VALUE"),
        (["--set", "=0.1"], "expected NAME=VALUE"),
        (["--set", "D=abc"], "--set D: 'abc' is not a number"),
        (["--set", "ip=1.5"], "'ip' must be in [0, 1)"),
        (["--set", "c=nan"], "'c' must be finite"),
        (["--set", "crack=3"], "--crack"),
        (["--crack", "250"], "expected TIME:D"),
        (["--crack", "a:0.1"], "--crack TIME: 'a' is not a number"),
        (["--crack=-5:0.1"], "crack time must be >= 0"),
        (["--params", "MISSING"], "no such file"),
        (["--params", "BADJSON"], "invalid JSON"),
        (["--params", "LIST"], "expected a JSON object"),
        (["--params", "STRING"], "parameter 'c' must be a number"),
        (["--params", "BADCRACK"], '"crack" must be an object'),
        (["--params", "UNKNOWN"], "unknown parameter 'zeta'; known parameters: ip, k"),
        (["--dt", "0"], "dt must be a positive number"),
        (["--noise", "-1"], "--noise must be a finite number >= 0"),
    ],
)
def test_cli_rejects_bad_input_cleanly(tmp_path, capsys, argv, match):
    files = {
        "MISSING": tmp_path / "missing.json",
        "BADJSON": tmp_path / "bad.json",
        "LIST": tmp_path / "list.json",
        "STRING": tmp_path / "string.json",
        "BADCRACK": tmp_path / "crack.json",
        "UNKNOWN": tmp_path / "unknown.json",
    }
    files["BADJSON"].write_text("{'h': 0}")
    files["LIST"].write_text("[0.1, 0.2]")
    files["STRING"].write_text('{"c": "0.1x"}')
    files["BADCRACK"].write_text('{"crack": [250, 0.08]}')
    files["UNKNOWN"].write_text('{"zeta": 0.1}')
    argv = [str(files.get(a, a)) for a in argv]
    out = tmp_path / "out.csv"
    code, stdout, err = _run_cli(capsys, out, "--t-end", 1, *argv)
    assert code == 2
    assert match in err
    assert err.startswith("rotor-id simulate: error: ") and err.count("\n") == 1
    assert "Traceback" not in err and stdout == ""
    assert not out.exists()


def test_cli_reports_divergence(tmp_path, capsys):
    out = tmp_path / "out.csv"
    code, stdout, err = _run_cli(capsys, out, "--set", "D=0.5")
    assert code == 1
    assert "diverged" in err and err.count("\n") == 1 and stdout == ""
    assert not out.exists()


def test_cli_missing_directory(tmp_path, capsys):
    out = tmp_path / "nowhere" / "out.csv"
    code, _, err = _run_cli(capsys, out, "--t-end", 1)
    assert code == 2 and "does not exist" in err


# ----------------------------------------------------------- the rub (a scanned parameter)
#: a rotor with nothing but the rub: k = 0 and every other moment 0, so that the recorded
#: acceleration at rest (w = 0: no gyroscopic moment) is the rub's moment alone
_RUB_ONLY = {"k": 0.0, "tau": 0.0, "c": 0.0, "D": 0.0, "h": 0.0, "k30": 0.0, "k21": 0.0, "k12": 0.0,
             "k03": 0.0, "load_y": 0.0, "load_x": 0.0}


def _rub_by_hand(th_x, th_y, phid, k_c, mu, gap):
    """``M_y + i M_x = -k_c max(|z| - gap, 0) (1 + i mu sign(phid)) z/|z|``, ``z = th_y + i th_x``."""
    z = complex(th_y, th_x)
    pen = max(abs(z) - gap, 0.0)
    m = -k_c * pen * (1 + 1j * mu * math.copysign(1.0, phid)) * z / abs(z) if pen > 0 else 0j
    return m.real, m.imag


@pytest.mark.parametrize("compiled_for", [None, "library"])
def test_rub_moment_by_hand(compiled_for):
    """The simulator's rub moment (its own kernel and the whole library's, where the rub's
    clearance rides in the coefficient vector after other effects) equals a hand computation
    at states inside and beyond the clearance, forward and backward spin; none below it."""
    k_c, mu, gap = 0.7, 0.25, 0.05
    params = RotorParams(values={**_RUB_ONLY, "rub_stiffness": k_c, "rub_friction": mu, "rub_clearance": gap},
                         effects=(*TABLE1.effects, "rub"))
    sim = Simulator(params, compiled_for=tuple(EFFECTS) if compiled_for else None)
    states = [(0.0, 0.08, 1.2), (0.06, -0.03, 1.2), (-0.05, -0.05, -0.7), (0.03, 0.02, 1.5), (0.0, 0.0, 1.0),
              (0.0, 0.0499, 2.0)]
    for th_x, th_y, phid in states:
        row = sim._row(0.0, 0.3, phid, 0.0, np.array([th_x, th_y, 0.0, 0.0]), (0.0, 0.0))
        ax, ay = row[8], row[9]
        my, mx = _rub_by_hand(th_x, th_y, phid, k_c, mu, gap)
        assert ay == pytest.approx(my, abs=1e-14) and ax == pytest.approx(mx, abs=1e-14), (th_x, th_y, phid)
        if math.hypot(th_x, th_y) <= gap:
            assert ay == 0.0 and ax == 0.0
    # the friction of a forward-spinning shaft pushes the rotor backward along its orbit
    my, mx = _rub_by_hand(0.0, 0.08, 1.2, k_c, mu, gap)
    assert my < 0 and mx < 0  # at z = 0.08 (on the y axis) the forward tangent is +i: M_x < 0 is backward
    Xy, Xx = EFFECTS["rub"].regressors(0.3, 1.2, 0.0, np.array([0.0]), np.array([0.08]), np.array([0.0]),
                                       np.array([0.0]), 0.3, scanned={"rub_clearance": gap})
    coef = EFFECTS["rub"].to_coefficients({"rub_stiffness": k_c, "rub_friction": mu})
    assert (Xy @ coef)[0] == pytest.approx(my, abs=1e-14) and (Xx @ coef)[0] == pytest.approx(mx, abs=1e-14)


def test_rub_beyond_the_orbit_changes_nothing():
    """A clearance the orbit never reaches: the run is the rub-free one, sample for sample;
    a clearance it reaches: the peak is cut."""
    base = TABLE1.replace(**LINEAR)
    free = simulate(base, t_end=200.0)
    far = simulate(RotorParams(ip=base.ip, values={**base.values, "rub_stiffness": 0.5, "rub_clearance": 0.2 + 0.1},
                               effects=(*base.effects, "rub")), t_end=200.0)
    assert amplitude(free).max() < 0.3
    np.testing.assert_array_equal(far.data, free.data)
    near = simulate(RotorParams(ip=base.ip, values={**base.values, "rub_stiffness": 0.5, "rub_clearance": 0.05},
                                effects=(*base.effects, "rub")), t_end=200.0)
    assert amplitude(near).max() < 0.9 * amplitude(free).max()
