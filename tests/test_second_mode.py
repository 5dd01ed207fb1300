"""The waveforms' second mode (:mod:`rotor_env.diagnosis.second_mode`).

References: ``scipy.integrate.solve_ivp`` (DOP853, tight tolerances) of the mode's equation
written apart, central differences of the kernel's own prediction for its sensitivities,
and a simulated rig record of two modes with known truth (``benchmarks/foreign_rig.py``'s
two-disk rotor) for the fit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from rotor_env.diagnosis.second_mode import SecondMode, shoot_second_mode, substeps
from rotor_env.measurements.rig import SPEED_UNITS

SPEED_UNITS_RPM = SPEED_UNITS["rpm"]


def _run_up(n: int = 801, dt: float = 0.05, w0: float = 0.6, w1: float = 2.4):
    t = np.arange(n) * dt
    phid = w0 + (w1 - w0) * t / t[-1]
    phi = 0.3 + w0 * t + 0.5 * (w1 - w0) / t[-1] * t * t
    return t, phi, phid


def _shoot(t, phi, phid, seg, states, mode):
    pred = np.zeros((len(t), 2))
    jac = np.zeros((len(t), 2, 8))
    nsub = substeps(SecondMode.from_array(mode), float(np.max(np.diff(t))))
    shoot_second_mode(t, phi, phid, seg, states, mode, nsub, pred, jac, 0)
    return pred, jac


def test_the_second_modes_response_is_the_oscillators_solution():
    """Through its own resonance (``sqrt(k2)`` = 1.8, crossed at 1.8 rad per unit time) in
    two segments, each from its own start state: ``(th_x, th_y) = (Im z2, Re z2)`` of
    ``z2'' + c2 z2' + k2 z2 = u2 (W^2 - i W') e^{i phi}`` integrated by scipy, within 3e-5
    of the response's peak (RK4 at 0.09 rad a step over 20 time units: a phase error of
    ``w T (w h)^4 / 120 = 2e-5``)."""
    t, phi, phid = _run_up()
    a = (phid[-1] - phid[0]) / t[-1]
    mode = np.array([1.8 ** 2, 2 * 0.03 * 1.8, 0.02, -0.01])
    u = complex(mode[2], mode[3])
    seg = np.array([[0, 399], [400, 800]])
    states = np.array([[0.01, 0.0, 0.0, 0.02], [-0.005, 0.003, 0.01, 0.0]])
    pred, _ = _shoot(t, phi, phid, seg, states, mode)
    peak = np.abs(pred).max()
    assert peak > 0.05
    for s, (i0, i1) in enumerate(seg):
        def f(tt, y):
            z, v = y[0] + 1j * y[1], y[2] + 1j * y[3]
            w = phid[0] + a * tt
            p = phi[0] + phid[0] * tt + 0.5 * a * tt * tt
            acc = u * (w * w - 1j * a) * np.exp(1j * p) - mode[1] * v - mode[0] * z
            return [v.real, v.imag, acc.real, acc.imag]

        sol = solve_ivp(f, (t[i0], t[i1]), states[s], method="DOP853", t_eval=t[i0:i1 + 1], rtol=1e-11, atol=1e-13)
        ref = np.column_stack([sol.y[1], sol.y[0]])
        assert np.abs(pred[i0:i1 + 1] - ref).max() < 3e-5 * peak


def test_the_second_modes_sensitivities_are_its_predictions_derivatives():
    """Every Jacobian column (stiffness, damping, the modal unbalance's two parts, the start
    state's four) against central differences of the kernel's prediction, within 1e-5 of the
    column's size."""
    t, phi, phid = _run_up(401)
    seg = np.array([[0, 199], [200, 400]])
    mode = np.array([1.9 ** 2, 0.08, 0.02, 0.01])
    states = np.array([[0.01, -0.004, 0.002, 0.02], [0.003, 0.002, -0.01, 0.004]])
    _, jac = _shoot(t, phi, phid, seg, states, mode)
    for j in range(8):
        h = 1e-6 * max(1.0, abs(mode[j] if j < 4 else states[0, j - 4]))
        up_m, dn_m, up_s, dn_s = mode.copy(), mode.copy(), states.copy(), states.copy()
        if j < 4:
            up_m[j] += h
            dn_m[j] -= h
        else:
            up_s[:, j - 4] += h
            dn_s[:, j - 4] -= h
        num = (_shoot(t, phi, phid, seg, up_s, up_m)[0] - _shoot(t, phi, phid, seg, dn_s, dn_m)[0]) / (2 * h)
        col = jac[:, :, j]
        assert np.abs(col - num).max() < 1e-5 * np.abs(col).max(), j


def test_a_second_mode_that_is_not_one_is_refused():
    with pytest.raises(ValueError, match="stiffness"):
        SecondMode(0.0, 0.1)
    with pytest.raises(ValueError, match="damping"):
        SecondMode(2.0, -0.1)
    m = SecondMode.from_frequency(2.0, 0.02, 0.01 + 0.02j)
    assert m.frequency == pytest.approx(2.0) and m.damping_ratio == pytest.approx(0.02)
    assert SecondMode.from_array(m.as_array()) == m
    # the steady 1X state: z2 = u W^2 e^{i phi} / (k - W^2 + i c W), z2' = i W z2
    st = m.steady_states(np.array([0.7]), np.array([1.3]))[0]
    z = m.u * 1.3 ** 2 * np.exp(0.7j) / (m.k - 1.69 + 1j * m.c * 1.3)
    assert st == pytest.approx([z.real, z.imag, (1.3j * z).real, (1.3j * z).imag])
    assert math.isfinite(st[0])


# ------------------------------------------------------------------ on records
def _foreign(case: str, seed: int, tmp_path, fs: float = 2500.0):
    import sys
    from pathlib import Path

    from rotor_env.measurements.rig import load_rig
    from rotor_env.measurements.waveforms import load_waveforms

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import foreign_rig as fr

    _, _, out = fr.make_record(case, seed, 0.5, fs=fs)
    rig_path, data_path = fr.write_record(tmp_path, case, out["columns"])
    return load_waveforms(data_path, load_rig(rig_path)), out["truth"]


@pytest.fixture(scope="module")
def two_disks(tmp_path_factory):
    """The foreign simulator's two-disk rotor, seed 11: the second mode at 4473 rpm, 2.29 times
    the first and 27 % above the top speed of a coast-down from 3516 rpm; 0.5 um white noise."""
    return _foreign("two_modes", 11, tmp_path_factory.mktemp("two_disks"))


def test_a_second_mode_above_the_run_is_found_from_either_start(two_disks):
    """The one-mode model misses the record by more than twice its floor; with a second mode
    started at 1.25 or 2 times the top speed the fit finds its natural frequency within 1 %
    of the simulator's second mode (its ratio to the first) and stands at the floor."""
    from dataclasses import replace

    from rotor_env.diagnosis.from_rig import SECOND_MODE_STARTS, waveform_grid
    from rotor_env.diagnosis.from_vectors import diagnose_vectors
    from rotor_env.diagnosis.output_error import equation_error_start, fit_output_error

    record, truth = two_disks
    fit1 = diagnose_vectors(record.vectors((1,)), ip=record.rig.ip).after
    grid, _ = waveform_grid(record, fit1.w_ref)
    model = ["unbalance", "viscous_damping"]
    one = fit_output_error(grid, model, equation_error_start(grid, model))
    assert one.rms > 2.0 * grid.noise_std
    top = float(np.max(np.abs(grid.phid)))
    ratio = truth["second_critical_rpm"] / truth["critical_rpm"]
    for f in SECOND_MODE_STARTS:
        two = fit_output_error(replace(grid, second_mode=SecondMode.from_frequency(f * top, 0.02)), model,
                               previous=one)
        k1 = two.value("stiffness.k")
        assert two.second_mode.frequency / math.sqrt(k1) == pytest.approx(ratio, rel=0.01)
        assert two.rms < 1.03 * grid.noise_std
        assert two.x0.shape == (len(grid.segments), 8)


def test_a_two_disk_record_is_explained_by_one_rotor_with_two_modes(two_disks):
    """``diagnose_rig``: one rotor with two modes -- ``second_mode`` named, explained, nothing
    else named; the second mode's natural frequency within 1 % of the simulator's, its
    interval covering it; the summary says what the waveforms' model holds."""
    from rotor_env.diagnosis.from_rig import diagnose_rig

    record, truth = two_disks
    rd = diagnose_rig(record)
    d = rd.to_dict()
    assert d["verdict"] == "explained_after_adding" and d["missing"] == ["second_mode"], (d["verdict"], d["missing"])
    got = d["second_mode"]
    assert got["natural_frequency_rpm"] == pytest.approx(truth["second_critical_rpm"], rel=0.01)
    assert got["one_mode_residual_over_floor"] > 2.0 and 0.0 < got["damping_ratio"] < 0.1
    assert "the waveforms' model holds a second mode" in rd.summary()


def test_a_missing_crack_is_not_taken_for_a_second_mode(tmp_path):
    """The control: a one-mode rotor with an open crack (D = 0.03, 30 deg from the notch)
    diagnosed with no candidate to add -- the one-mode model misses it, the second mode is
    tried and not taken (a 1X-driven oscillator cannot hold a crack's 2X): the verdict stays
    not explained, nothing is named, and a note says what the second mode did."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.measurements.rig import load_rig
    from rotor_env.measurements.waveforms import load_waveforms
    from rotor_env.params import RotorParams
    from rotor_env.rig_simulation import simulate_rig

    (tmp_path / "rig.yaml").write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
    rig = load_rig(tmp_path / "rig.yaml")
    rotor = RotorParams(ip=0.0, values={"c": 0.04, "tau": 0.005, "beta": 0.4, "D": 0.03, "D_axis": math.radians(30)},
                        effects=("stiffness", "viscous_damping", "unbalance", "asymmetry"))
    run = simulate_rig(rig, rotor, natural_rpm=1650.0, rpm_from=300.0, rpm_to=3000.0, rpm_per_s=300.0,
                       sample_rate=2500.0, noise=0.5, seed=3)
    pq.write_table(pa.table(run.file_columns()), tmp_path / "run.parquet")
    d = diagnose_rig(load_waveforms(tmp_path / "run.parquet", rig), candidates=()).to_dict()
    assert d["verdict"] in ("unexplained", "partly_explained") and d["missing"] == [], (d["verdict"], d["missing"])
    assert d["second_mode"] is None
    assert any(n.startswith("a second mode in the waveforms' model") for n in d["notes"]), d["notes"]


@pytest.mark.parametrize(("frequency", "zeta", "reason"), [
    (1.1, 0.02, "split of one mode"),      # 1.1x the model's own: an asymmetry's two criticals
    (0.85, 0.02, "split of one mode"),
    (2.0, 1e-5, "rings undamped"),
    (2.5, 1e-5, ""),                       # above the run (top 1.8): its damping is not read
    (2.0, 0.26, "filter of the noise"),    # a 1/f record read as white fitted one so
    (0.3, 0.05, "below the run"),          # the run from 0.4: a mode's 1X there is a constant
    (2.0, 0.02, ""),                       # a second mode
    (0.6, 0.02, ""),                       # ... below the model's own, in the run
])
def test_what_is_not_a_second_mode(frequency, zeta, reason):
    """The rules a fitted second mode must pass (``from_rig._not_a_second_mode``), each with the
    record that taught it (PHYSICS.md section 9)."""
    from types import SimpleNamespace

    from rotor_env.diagnosis.from_rig import _not_a_second_mode

    fit = SimpleNamespace(second_mode=SecondMode.from_frequency(frequency, zeta), value=lambda name: 1.0,
                          grid=SimpleNamespace(phid=np.linspace(0.4, 1.8, 50)))
    why = _not_a_second_mode(fit)
    assert (reason in why) if reason else why == "", why


# ------------------------------------------------------------------ a mode above the run
@pytest.fixture(scope="module")
def mode_above(tmp_path_factory):
    """The foreign simulator's two-disk rotor, seed 26: a run-up to 2550 rpm, the second mode at
    3348 rpm (31 % above the top speed, 2.37 times the first); 0.5 um white noise, 2.5 kHz."""
    return _foreign("two_modes", 26, tmp_path_factory.mktemp("mode_above"))


def test_a_mode_above_the_run_is_not_read_as_a_bow(mode_above):
    """Below the critical a bow's 1X grows as W^2 from its slow-roll vector, as a higher mode's
    quasi-static response does.  The 1X vectors of a rotor whose second mode lies above the run
    named runout and a shaft bow before (1.27x their floor; the mode 0.85x, refused as outside
    the run): now the mode above the run is kept, no bow and no runout, and the record's one
    conclusion names no fault."""
    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.diagnosis.from_vectors import BOW, diagnose_vectors
    from rotor_env.diagnosis.synchronous import RUNOUT, SECOND_MODE

    record, truth = mode_above
    vd = diagnose_vectors(record.vectors((1,)), ip=record.rig.ip)
    assert vd.missing == [SECOND_MODE], vd.missing
    (w2, _), = vd.after.extra_modes
    top = float(record.vectors((1,)).speed.max())
    assert w2 > 1.2 * top
    assert w2 / SPEED_UNITS_RPM == pytest.approx(truth["second_critical_rpm"], rel=0.1)
    assert vd.after.rms < 1.5 * vd.noise_floor
    assert BOW not in vd.missing and RUNOUT not in vd.missing
    rd = diagnose_rig(record)
    assert BOW not in rd.missing and rd.verdict.startswith("explained"), (rd.verdict, rd.missing)


def test_a_bow_is_still_named_beside_a_mode_above_the_run(tmp_path):
    """The control: the foreign simulator's bowed one-disk rotor (seed 26, 9 um bow): past the
    critical a bow's 1X falls as 1/W^2 and a mode above the run's keeps growing, so the mode's
    fit is far from the bow's and the bow is named by the vectors and by the record (20 kHz, as drawn)."""
    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.diagnosis.from_vectors import BOW, diagnose_vectors

    record, truth = _foreign("shaft_bow", 26, tmp_path, fs=20000.0)
    vd = diagnose_vectors(record.vectors((1,)), ip=record.rig.ip)
    assert BOW in vd.missing and BOW not in vd.undecidable, (vd.missing, vd.undecidable)
    assert BOW in diagnose_rig(record).missing


def test_the_closest_two_mode_reading_is_taken_even_in_two_parts():
    """``from_rig.closest_reading``: a foreign two-disk crack with both criticals in the run
    (seed 28 at 10 kHz, 100 s: not run here) read with the roles as found named a rub at 1.98x
    the floor as one rotor, with them exchanged a hinge crack at 1.14x whose two sides of a
    break differ (each explained).  The nearer reading is the record's -- the crack, not the
    false rub; before, only the one-rotor readings were compared."""
    from types import SimpleNamespace

    from rotor_env.diagnosis.from_rig import closest_reading

    rub = SimpleNamespace(rms_ratio_after=1.98, missing=["rub"], parts=None)
    crack = SimpleNamespace(rms_ratio_after=1.14, missing=["hinge_crack"],
                            parts=SimpleNamespace(changed=True, explained=True))
    assert closest_reading([(199.3, rub), (320.2, crack)])[1] is crack
    assert closest_reading([(320.2, crack), (199.3, rub)])[0] == 320.2
    assert closest_reading([]) is None
