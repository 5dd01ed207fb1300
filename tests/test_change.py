"""Did the rotor change during the record? (rotor_env.diagnosis.change): the sup-LM test's
null distribution against Andrews' table, its size on constant rotors and its power and
break time on a crack that appears mid-record, by simulation with known truth."""

from __future__ import annotations

import numpy as np
import pytest

from rotor_env.diagnosis.change import parameter_constancy, sup_lm_distribution
from rotor_env.diagnosis.output_error import ShootingGrid, equation_error_start, fit_output_error
from rotor_env.params import Crack, RotorParams
from rotor_env.simulator import RunUp, Simulator

MODEL = ("unbalance", "viscous_damping")
NOISE = 5e-4
T_END = 300.0


def _grid(crack=None, seed=0):
    p = RotorParams(ip=0.0, effects=("stiffness", "unbalance", "viscous_damping", "asymmetry"),
                    values={"tau": 0.005, "beta": 0.3, "c": 0.05, "D": 0.0}, crack=crack)
    m = Simulator(p).run(t_end=T_END, dt=0.04, run_up=RunUp(rate=0.005, speed0=0.4))
    rng = np.random.default_rng(seed)
    return ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, m.theta_x + rng.normal(0, NOISE, len(m.t)),
                                    m.theta_y + rng.normal(0, NOISE, len(m.t)), 0.0, noise_std=NOISE)


def _fit(grid):
    return fit_output_error(grid, MODEL, equation_error_start(grid, MODEL))


def test_null_distribution_matches_andrews_table():
    """Andrews (1993), Table 1, pi_0 = 0.15, one parameter: 7.17 (10 %), 8.68 (5 %), 12.16 (1 %)."""
    d = sup_lm_distribution(1)
    q = lambda a: d[int((1 - a) * len(d))]  # noqa: E731
    assert q(0.10) == pytest.approx(7.17, abs=0.35)
    assert q(0.05) == pytest.approx(8.68, abs=0.45)
    assert q(0.01) == pytest.approx(12.16, abs=1.0)
    # more parameters, a larger supremum
    assert sup_lm_distribution(4)[int(0.95 * len(d))] > q(0.05) + 4


def test_constant_rotors_are_said_constant():
    """Size: 12 noise draws of a constant rotor, the test at 5 %: at most 3 rejections
    (binomial(12, 0.05): P(X >= 4) = 0.002)."""
    rejections = []
    for seed in range(12):
        c = parameter_constancy(_fit(_grid(seed=seed)))
        assert 0 < c.p_value <= 1 and c.dof >= 5
        assert c.method == "bridge"  # 25 shooting segments: too few blocks for 12 parameters
        rejections.append(c.significant)
    assert sum(rejections) <= 3, rejections


def test_a_crack_appearing_mid_record_is_a_change_at_its_time():
    """A crack D = 0.03 appearing at 45 % of the record (just past the critical): a change, found
    within 5 % of the record of its time, and the diagnosis says so."""
    from rotor_env.diagnosis.oe_diagnosis import diagnose_output_error

    T = 0.45 * T_END  # just above the critical (speed 1.08), where the response is large
    grid = _grid(Crack(T, 0.03), seed=7)
    c = parameter_constancy(_fit(grid))
    assert c.significant, c
    assert c.t_break == pytest.approx(T, abs=0.05 * T_END)
    assert c.fraction == pytest.approx(T / grid.t[-1], abs=0.05)
    diag = diagnose_output_error(grid, MODEL, ("asymmetry", "shaft_bow"))
    assert diag.change is not None and diag.change.significant
    if diag.change.explained:
        assert diag.change.changed
        assert "not the same over the record" in diag.summary()
    assert diag.to_dict()["change"]["significant"] is True


def _change_at(grid, t_break):
    """A break at model time ``t_break`` as the change test reports one (significant)."""
    from rotor_env.diagnosis.change import ParameterChange

    return ParameterChange(99.0, 1e-4, 6, t_break, t_break / grid.t[-1], {}, 0.05, True)


def test_an_effect_named_for_a_change_is_absent_on_one_side_and_a_constant_one_is_not():
    """rule present_throughout (rotor_env.diagnosis.parts.absent_on_a_side), with known truth,
    three noise draws: one model of a record whose crack (D = 0.03) appears at 45 % (just past
    the critical) names an asymmetry of about half its size for the whole record; the side
    before the crack finds none and rejects that size -- flagged on at least two of the three
    (a side of 9 segments through the critical can find a crack it has not: seed 1's before
    side reads D = 0.016 at log10 p = -2.9, and then nothing is flagged).  The same crack
    present all through, cut at the same time, is on both sides: flagged on none."""
    from rotor_env.diagnosis.parts import absent_on_a_side

    T = 0.45 * T_END
    model = (*MODEL, "asymmetry")
    flagged_appearing, flagged_constant = 0, 0
    for seed in (1, 2, 3):
        appearing = _grid(Crack(T, 0.03), seed=seed)
        whole = fit_output_error(appearing, model, equation_error_start(appearing, model))
        assert whole.parameters("asymmetry")["D"] == pytest.approx(0.015, abs=0.005)  # half the crack
        flagged = absent_on_a_side(appearing, _change_at(appearing, T), whole, ["asymmetry"])
        if flagged:
            assert list(flagged) == ["asymmetry"], flagged
            assert flagged["asymmetry"].startswith("rule present_throughout: not there before the break")
            flagged_appearing += 1

        p = RotorParams(ip=0.0, effects=("stiffness", "unbalance", "viscous_damping", "asymmetry"),
                        values={"tau": 0.005, "beta": 0.3, "c": 0.05, "D": 0.03, "D_axis": 0.5})
        m = Simulator(p).run(t_end=T_END, dt=0.04, run_up=RunUp(rate=0.005, speed0=0.4))
        rng = np.random.default_rng(seed)
        constant = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, m.theta_x + rng.normal(0, NOISE, len(m.t)),
                                            m.theta_y + rng.normal(0, NOISE, len(m.t)), 0.0, noise_std=NOISE)
        whole = fit_output_error(constant, model, equation_error_start(constant, model))
        assert whole.wald("asymmetry")[2] < -10  # the crack is plainly in the record
        flagged_constant += bool(absent_on_a_side(constant, _change_at(constant, T), whole, ["asymmetry"]))
    assert flagged_appearing >= 2 and flagged_constant == 0, (flagged_appearing, flagged_constant)


def _rig_record(tmp_path, crack_at_rpm=None, seed=3, D=0.03, noise=0.5):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from rotor_env.measurements.rig import SPEED_UNITS, load_rig
    from rotor_env.measurements.waveforms import load_waveforms
    from rotor_env.rig_simulation import simulate_rig

    (tmp_path / "rig.yaml").write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
    rig = load_rig(tmp_path / "rig.yaml")
    w_ref = 1650.0 * SPEED_UNITS["rpm"]
    crack = None if crack_at_rpm is None else Crack((crack_at_rpm - 300.0) / 300.0 * w_ref, D)
    p = RotorParams(ip=0.0, values={"c": 0.04, "tau": 0.005, "D": 0.0, "D_axis": 0.5236},
                    effects=("stiffness", "viscous_damping", "unbalance", "asymmetry"), crack=crack)
    run = simulate_rig(rig, p, natural_rpm=1650.0, rpm_per_s=300.0, sample_rate=10000.0, noise=noise, seed=seed)
    pq.write_table(pa.table(run.file_columns()), tmp_path / "run.parquet")
    return load_waveforms(tmp_path / "run.parquet", rig)


def test_rig_crack_appearing_above_the_critical_is_a_change_in_seconds_and_rpm(tmp_path):
    """benchmarks/crack_onset.py's record: a crack appearing at 2400 rpm (7 s), after the
    critical, lifts the residual by 2 % only (the record is 'explained' by one model) -- the
    parameters are said not to be the same over the record, at the crack's time and speed;
    the same rig without the crack is constant."""
    from rotor_env.diagnosis.from_rig import diagnose_rig

    out = diagnose_rig(_rig_record(tmp_path, 2400.0)).to_dict()
    assert out["change"]["changed"], out["change"]
    assert "not the same over the record, most at" in out["change"]["sentence"]
    assert out["change"]["t_s"] == pytest.approx(7.0, abs=0.4)
    assert out["change"]["rpm"] == pytest.approx(2400.0, abs=120.0)
    # one model explains the record: it is not diagnosed apart (module docstring of .parts);
    # what its one model would name for the change (a shaft bow taking the 1X's move) is not
    # there before the break, so nothing is named: the change is said, the effect is not
    assert out["parts"] is None
    assert out["verdict"] == "explained" and out["missing"] == [], out["missing"]
    assert all("rule present_throughout" in r for e, r in out["rejected"].items() if e == "shaft_bow")
    (tmp_path / "healthy").mkdir()
    healthy = diagnose_rig(_rig_record(tmp_path / "healthy", None, seed=4)).to_dict()
    assert healthy["verdict"] == "explained" and not healthy["change"]["significant"], healthy["change"]


def test_the_null_is_simulated_once_and_read_back(tmp_path, monkeypatch):
    """The simulated null is kept as a plain .npy in the kernel cache folder: read back, the
    same draws; a damaged file is simulated again, not trusted."""
    from rotor_env.diagnosis import change

    monkeypatch.setenv("ROTOR_ID_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(change, "_NULL", {})
    first = change.sup_lm_distribution(3)
    files = list((tmp_path / "null").glob("sup_lm_p3_*.npy"))
    assert len(files) == 1
    monkeypatch.setattr(change, "_NULL", {})
    assert np.array_equal(change.sup_lm_distribution(3), first)
    files[0].write_bytes(b"not an array")
    monkeypatch.setattr(change, "_NULL", {})
    assert np.array_equal(change.sup_lm_distribution(3), first)


def test_a_crack_opening_below_the_critical_is_named_and_dated(tmp_path):
    """A crack D = 0.03 (stiff axis 30 deg from the notch) opening at 1200 rpm (3.0 s), below the
    critical.  A crack held constant over the whole record explains it to 1.6 % above the floor,
    but it fails the crack-or-rub rule's halves: the low-amplitude half is mostly the record
    before the opening, where there is no crack (holding the whole record's value costs it 28
    noise variances; until 2026-11-28 the rule's Wald distance let the constant crack through).
    So the record is cut at its break and each side diagnosed: nothing before, the crack after,
    with its size, axis and time."""
    from rotor_env.diagnosis.from_rig import diagnose_rig

    out = diagnose_rig(_rig_record(tmp_path, 1200.0)).to_dict()
    assert out["verdict"] == "explained_after_adding" and out["missing"] == ["asymmetry"]
    assert "rule crack_amplitude_independence" in out["rejected"]["asymmetry"]
    parts = out["parts"]
    assert parts is not None and parts["changed"] and parts["appeared"] == ["asymmetry"], out["change"]
    assert parts["t_s"] == pytest.approx(3.0, abs=0.15)
    assert parts["before"]["verdict"] == "explained" and parts["before"]["missing"] == []
    crack = parts["after"]["parameters"]["asymmetry"]["values"]
    D, axis = crack["D"], crack["D_axis"]
    if D < 0:  # the same crack seen from its other axis
        D, axis = -D, axis + np.pi / 2
    assert D == pytest.approx(0.03, rel=0.05)
    assert abs((np.degrees(axis) - 30.0 + 90.0) % 180.0 - 90.0) <= 5.0
    assert out["change"]["significant"]  # the sup-LM test sees the drift; the parts tell the change


def test_a_crack_one_model_cannot_hold_is_named_after_its_time(tmp_path):
    """A crack D = 0.1 opening at 1890 rpm (5.3 s), just above the critical, 0.3 um probes: one
    model for the record cannot hold it (3.4x the floor); the change test dates a break, each
    side is diagnosed on its own, and the break is dated again by refits of the sides' joint
    model: before it, nothing; after it, the asymmetry with its size and axis; the record's
    verdict says so."""
    from rotor_env.diagnosis.from_rig import diagnose_rig

    out = diagnose_rig(_rig_record(tmp_path, 1890.0, D=0.1, noise=0.3)).to_dict()
    parts = out["parts"]
    assert parts is not None and parts["changed"], out["change"]
    assert parts["appeared"] == ["asymmetry"] and not parts["gone"]
    assert parts["t_s"] == pytest.approx(5.3, abs=0.15)
    assert parts["before"]["verdict"] == "explained" and parts["before"]["missing"] == []
    assert parts["after"]["verdict"] == "explained_after_adding"
    crack = parts["after"]["parameters"]["asymmetry"]["values"]
    D, axis = crack["D"], crack["D_axis"]
    if D < 0:  # the same crack seen from its other axis
        D, axis = -D, axis + np.pi / 2
    assert D == pytest.approx(0.1, rel=0.05)
    assert abs((np.degrees(axis) - 30.0 + 90.0) % 180.0 - 90.0) <= 5.0
    assert out["verdict"] == "explained_after_adding" and "asymmetry" in out["missing"]
    assert out["change"]["sentence"].startswith("the rotor changed at 5.3")
    assert "asymmetry appeared" in out["change"]["sentence"]


def test_a_crack_whose_1x_step_the_vectors_take_as_a_mode_stays_a_change(tmp_path):
    """The monitor example of the README diagnosed in batch (``rotor-id simulate rig_crack.csv
    --rig rig.yaml --set tau=0.005 --set c=0.04 --set D=0 --crack 1200:0.1 --noise 0.3 --seed 1``:
    a crack D = 0.1 opening at 1892 rpm, 300 + 230 t rpm).  The 1X vectors put a "second mode"
    at about 1850 rpm into the crack's 1X step without explaining the vectors; its band ended
    before the crack, and the record was read as one rotor with two modes (``second_mode``, the
    crack unseen).  It stays two rotors: the crack appears at its time."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.diagnosis.synchronous import SECOND_MODE
    from rotor_env.measurements.rig import SPEED_UNITS, load_rig
    from rotor_env.measurements.waveforms import load_waveforms
    from rotor_env.rig_simulation import simulate_rig

    (tmp_path / "rig.yaml").write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
    rig = load_rig(tmp_path / "rig.yaml")
    p = RotorParams(ip=0.0, values={"c": 0.04, "tau": 0.005, "D": 0.0},
                    effects=("stiffness", "viscous_damping", "unbalance", "asymmetry"), crack=Crack(1200.0, 0.1))
    run = simulate_rig(rig, p, natural_rpm=1650.0, noise=0.3, seed=1)
    pq.write_table(pa.table(run.file_columns()), tmp_path / "run.parquet")
    result = diagnose_rig(load_waveforms(tmp_path / "run.parquet", rig))
    assert SECOND_MODE in result.vectors.missing and result.vectors.verdict == "partly_explained"
    out = result.to_dict()
    assert SECOND_MODE not in out["missing"] and not out["second_mode_subtracted"]
    parts = out["parts"]
    assert parts is not None and parts["changed"] and parts["appeared"] == ["asymmetry"], out["change"]
    assert parts["t_s"] == pytest.approx(1200.0 / (1650.0 * SPEED_UNITS["rpm"]), abs=0.15)
    assert abs(parts["after"]["parameters"]["asymmetry"]["values"]["D"]) == pytest.approx(0.1, rel=0.05)
    assert out["verdict"] == "explained_after_adding" and "asymmetry" in out["missing"]


def test_a_bow_the_vectors_name_is_not_read_as_a_change(tmp_path):
    """A shaft bow (6 um, 0.5 um probe noise, 10 kHz): the 1X vectors name it, the waveforms'
    fit at its floor does not try it, and the record's one verdict names it.  The parameter-
    constancy test used to run on the waveforms' model without the bow, whose speed-dependent
    1X the runout term holds at one speed and not at another: "not the same over the record"
    (p = 0.0003 on seeds 1-3, the runout term "moved") for a rotor that never changed.  Run on
    the model the verdict stands on, the rotor is constant (p = 0.09, 0.83, 0.88)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.measurements.rig import load_rig
    from rotor_env.measurements.waveforms import load_waveforms
    from rotor_env.rig_simulation import simulate_rig

    (tmp_path / "rig.yaml").write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
    rig = load_rig(tmp_path / "rig.yaml")
    p = RotorParams(ip=0.0, values={"c": 0.034, "tau": 0.0048, "beta": -1.16, "bow": 0.006, "bow_phase": -1.4},
                    effects=("stiffness", "viscous_damping", "unbalance", "shaft_bow"))
    run = simulate_rig(rig, p, natural_rpm=1300.0, rpm_from=330.0, rpm_to=2350.0, rpm_per_s=220.0,
                       sample_rate=10000.0, noise=0.5, seed=2)
    pq.write_table(pa.table(run.file_columns()), tmp_path / "run.parquet")
    out = diagnose_rig(load_waveforms(tmp_path / "run.parquet", rig)).to_dict()
    assert out["missing"] == ["shaft_bow"] and out["vectors"]["missing"] == ["shaft_bow"], out["missing"]
    assert out["verdict"] == "explained_after_adding"
    assert not out["change"]["significant"], out["change"]
    assert "shaft_bow" in out["change"]["moved"]  # the test ran on the model with the bow
