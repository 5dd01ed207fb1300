"""Output-error identification (rotor_env.diagnosis.output_error): simulations with known truth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from rotor_env.diagnosis.oe_diagnosis import diagnose_output_error
from rotor_env.diagnosis.output_error import ShootingGrid, fit_output_error, noise_std_high_band
from rotor_env.params import RotorParams
from rotor_env.simulator import RunUp, Simulator


def _record(extra: dict, effects: tuple[str, ...], *, noise: float, seed: int, rate=0.004, span=1.3, dt=0.02):
    vals = {"tau": 0.005, "beta": 0.3, "c": 0.05, "k": 1.0, **extra}
    p = RotorParams(ip=0.0, effects=("stiffness", "unbalance", "viscous_damping", *effects), values=vals)
    m = Simulator(p).run(t_end=span / rate, dt=dt, run_up=RunUp(rate=rate, speed0=0.4))
    rng = np.random.default_rng(seed)
    thx = m.theta_x + rng.normal(0.0, noise, len(m.t))
    thy = m.theta_y + rng.normal(0.0, noise, len(m.t))
    return m, thx, thy


@pytest.mark.parametrize("noise", [2e-4, 1e-3])
def test_noise_floor_from_the_band_above_the_response(noise):
    m, thx, _ = _record({}, (), noise=noise, seed=1)
    dt = float(m.t[1] - m.t[0])
    est = noise_std_high_band(thx, dt, 4 * float(m.phi_dot.max()) / (2 * math.pi))
    assert est == pytest.approx(noise, rel=0.1)


@pytest.mark.parametrize("axis_deg", [30.0, 117.0])
def test_crack_with_its_axis_anywhere_is_named_with_size_and_angle(axis_deg):
    """A crack whose stiff axis is not at the keyphasor notch: D and the axis within 5 % and
    5 deg, named by the output-error diagnosis from noisy displacements only."""
    axis = math.radians(axis_deg)
    noise = 5e-4
    m, thx, thy = _record({"D": 0.03, "D_axis": axis}, ("asymmetry",), noise=noise, seed=7)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    d = diagnose_output_error(grid, ("unbalance", "viscous_damping"),
                              ("asymmetry", "breathing_crack", "rub", "support_anisotropy", "misalignment",
                               "cross_coupled_stiffness"))
    assert d.missing == ["asymmetry"]
    p = d.after.parameters("asymmetry")
    D, ax = p["D"], p["D_axis"]
    if D < 0:  # the same crack seen from its other axis
        D, ax = -D, (ax + math.pi / 2) % math.pi
    assert D == pytest.approx(0.03, rel=0.05)
    err = (math.degrees(ax) - axis_deg + 90) % 180 - 90
    assert abs(err) < 5.0
    assert d.verdict == "explained_after_adding"
    assert d.rms_ratio_after < 1.1


def test_a_rub_is_not_called_a_crack():
    noise = 5e-4
    m, thx, thy = _record({"rub_stiffness": 0.5, "rub_friction": 0.2, "rub_clearance": 0.06}, ("rub",),
                          noise=noise, seed=3)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    d = diagnose_output_error(grid, ("unbalance", "viscous_damping"), ("asymmetry", "breathing_crack", "rub"))
    assert "asymmetry" not in d.missing and "breathing_crack" not in d.missing


def test_healthy_rotor_is_explained_with_nothing_added():
    noise = 5e-4
    m, thx, thy = _record({}, (), noise=noise, seed=11)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    d = diagnose_output_error(grid, ("unbalance", "viscous_damping"), ("asymmetry", "rub", "shaft_bow"))
    assert d.missing == [] and d.verdict == "explained"


def test_interval_coverage_on_noisy_displacements():
    """The 95 % intervals (HAC sandwich of the output-error Jacobian) cover the truth: a
    small honest version (24 seeds x 3 parameters), accepted within the binomial's 99.9 %
    range around 0.95; the larger study is benchmarks/output_error_coverage.py."""
    hits, n = 0, 0
    truth = {"unbalance.tau_cos_beta": 0.005 * math.cos(0.3), "unbalance.tau_sin_beta": 0.005 * math.sin(0.3),
             "viscous_damping.c": 0.05}
    for seed in range(24):
        noise = 1e-3
        m, thx, thy = _record({}, (), noise=noise, seed=100 + seed, rate=0.008, span=1.2, dt=0.04)
        grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
        f = fit_output_error(grid, ("unbalance", "viscous_damping"), {"unbalance": {"tau": 0.004, "beta": 0.0},
                                                                      "viscous_damping": {"c": 0.04}})
        for name, value in truth.items():
            i = f.names.index(name)
            hits += abs(f.values[i] - value) <= 1.96 * f.std_errors[i]
            n += 1
    lo = stats.binom.ppf(0.0005, n, 0.95)
    assert hits >= lo, f"coverage {hits}/{n}"
    assert hits / n <= 1.0


def test_sizes_are_read_against_the_fitted_shaft():
    """The fit frees the shaft stiffness k (the time unit of measured data is an estimate):
    a record whose true shaft has k = 1.06 in the time unit it is fitted in.  Every size is
    reported where the fitted shaft has k = 1 -- a crack's D and a side load relative to the
    shaft's stiffness, the damping as 2 zeta -- so each truth is the simulated value over k
    (c over sqrt k; the unbalance's eccentricity unchanged), within its 95 % interval
    (read in the time unit as fitted, D would be 6 % high: 0.030 against 0.0284, ten of its intervals
    away)."""
    k = 1.06
    noise = 5e-4
    m, thx, thy = _record({"D": 0.03, "D_axis": 0.6, "k": k}, ("asymmetry",), noise=noise, seed=11)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    d = diagnose_output_error(grid, ("unbalance", "viscous_damping"), ("asymmetry", "support_anisotropy"))
    assert d.missing == ["asymmetry"]
    p = d.parameters()
    assert p["stiffness"]["values"]["k"] == pytest.approx(k, rel=1e-3)
    for effect, name, truth in (("asymmetry", "D", 0.03 / k), ("viscous_damping", "c", 0.05 / math.sqrt(k)),
                                ("unbalance", "tau", 0.005)):
        got, half = p[effect]["values"][name], p[effect]["ci95"][name]
        assert abs(got - truth) < 2 * half, (effect, name, got, truth, half)
    assert abs(p["asymmetry"]["values"]["D"] - 0.03) > 5 * p["asymmetry"]["ci95"]["D"]


def test_a_held_effect_acts_and_is_not_fitted():
    """``held``: the effect's moment stays in the model at its start value, nothing of it is
    fitted (the crack's amplitude rule holds a side load this way).  Held at the truth the
    fit is as good as the free one; held at zero the side load's moment is missing."""
    noise = 5e-4
    extra = {"dk_crack": 0.06, "breathing_depth": 1.0, "breathing_phase": 0.3, "crack_axis": 0.4,
             "load_y": -0.05, "load_x": 0.0}
    m, thx, thy = _record(extra, ("breathing_crack", "static_load"), noise=noise, seed=5)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    model = ("unbalance", "viscous_damping", "breathing_crack", "static_load")
    start = {"unbalance": {"tau": 0.005, "beta": 0.3}, "viscous_damping": {"c": 0.05},
             "breathing_crack": {k: v for k, v in extra.items() if not k.startswith("load")}}
    free = fit_output_error(grid, model, {**start, "static_load": {"load_y": -0.05, "load_x": 0.0}})
    held = fit_output_error(grid, model, {**start, "static_load": {"load_y": -0.05, "load_x": 0.0}},
                            held=("static_load",))
    zero = fit_output_error(grid, model, {**start, "static_load": {"load_y": 0.0, "load_x": 0.0}},
                            held=("static_load",))
    assert not any(n.startswith("static_load.") for n in held.names)
    assert held.parameters("static_load")["load_y"] == pytest.approx(-0.05 / held.value("stiffness.k"))
    assert held.rms < 1.01 * free.rms
    assert zero.rms > 1.5 * free.rms
    with pytest.raises(ValueError, match="held"):
        fit_output_error(grid, ("unbalance",), held=("static_load",))


def test_an_argument_held_at_a_value_is_read_back_where_it_was_held():
    """``fixed_args``: an argument (the crack's axis) held in a refit is not a free parameter,
    and the fit's physical parameters report it at the value it was held at (a side's refit
    of ``parts.absent_on_a_side`` holds the whole record's axis)."""
    noise = 5e-4
    m, thx, thy = _record({"D": 0.03, "D_axis": 0.5}, ("asymmetry",), noise=noise, seed=2)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    model = ("unbalance", "viscous_damping", "asymmetry")
    start = {"unbalance": {"tau": 0.005, "beta": 0.3}, "viscous_damping": {"c": 0.05}, "asymmetry": {"D": 0.03}}
    held = fit_output_error(grid, model, start, fixed_args={"asymmetry": {"D_axis": 0.5}})
    assert "asymmetry.D_axis" not in held.names
    values = held.parameters("asymmetry")
    assert values["D_axis"] == pytest.approx(0.5, abs=1e-12)
    assert values["D"] == pytest.approx(0.03, rel=0.05)


def test_a_fit_that_cannot_reach_a_level_gives_up_and_says_how_low_it_could_go():
    """``give_up_above``: a model that misses an effect (no crack on a cracked record) cannot
    come down to the residual of the model that has it; its fit stops early, says so
    (``gave_up``, ``reachable`` above the level), and its residual is no lower than where the
    whole fit ends.  A level it can reach (its own optimum's) does not stop it."""
    noise = 5e-4
    m, thx, thy = _record({"D": 0.03, "D_axis": 0.5}, ("asymmetry",), noise=noise, seed=3)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    start = {"unbalance": {"tau": 0.004, "beta": 0.2}, "viscous_damping": {"c": 0.04}}
    right = fit_output_error(grid, ("unbalance", "viscous_damping", "asymmetry"), {**start, "asymmetry": {"D": 0.03}})
    wrong = fit_output_error(grid, ("unbalance", "viscous_damping"), start)
    assert wrong.rss > 4 * right.rss  # the crack is there
    stopped = fit_output_error(grid, ("unbalance", "viscous_damping"), start, give_up_above=right.rss)
    assert stopped.gave_up and not stopped.converged
    assert stopped.iterations < wrong.iterations
    assert stopped.reachable > right.rss
    assert stopped.rss >= wrong.rss * (1 - 1e-9)
    own = fit_output_error(grid, ("unbalance", "viscous_damping"), start, give_up_above=wrong.rss * 1.01)
    assert not own.gave_up and own.converged and own.rss == pytest.approx(wrong.rss, rel=1e-9)


def test_the_wald_test_against_a_value_is_the_test_against_zero_shifted():
    """``OutputErrorFit.wald(effect, null=...)``: the HAC Wald statistic of the effect's
    coefficients against given values; at the estimate itself it is zero, against zero it is
    the plain test, and against any value it is ``(b - b0)' V^-1 (b - b0)`` (numpy's solve)."""
    noise = 5e-4
    m, thx, thy = _record({"D": 0.03, "D_axis": 0.5}, ("asymmetry",), noise=noise, seed=4)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    f = fit_output_error(grid, ("unbalance", "viscous_damping", "asymmetry"),
                         {"unbalance": {"tau": 0.005, "beta": 0.3}, "asymmetry": {"D": 0.03}})
    idx = [i for i, (o, n) in enumerate(zip(f.owners, f.names, strict=True)) if o == "asymmetry" and n == "asymmetry.D"]
    at = {f.names[i]: float(f.values[i]) for i in idx}
    assert f.wald("asymmetry", null=at)[0] == pytest.approx(0.0, abs=1e-12)
    zero = {n: 0.0 for n in at}
    assert f.wald("asymmetry", null=zero) == pytest.approx(f.wald("asymmetry"))
    b0 = {n: v * 0.9 for n, v in at.items()}
    d = np.array([at[n] - b0[n] for n in at])
    cov = f.covariance[np.ix_(idx, idx)]
    w, q, lp = f.wald("asymmetry", null=b0)
    assert q == len(idx)
    assert w == pytest.approx(float(d @ np.linalg.solve(cov, d)), rel=1e-10)
    assert lp == pytest.approx(stats.chi2.logsf(w, q) / math.log(10), rel=1e-6)


def test_a_final_model_that_does_not_converge_is_run_on_and_said(monkeypatch):
    """``oe_diagnosis._run_on``: a final fit stopped at its step limit is fitted on; where it
    then converges it is taken (a lower residual) and nothing is said, where it still has
    not (a step limit of one), a note says its intervals do not hold."""
    from rotor_env.diagnosis import oe_diagnosis

    noise = 5e-4
    m, thx, thy = _record({}, (), noise=noise, seed=6)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    cut = fit_output_error(grid, ("unbalance", "viscous_damping"),
                           {"unbalance": {"tau": 0.003, "beta": 0.0}, "viscous_damping": {"c": 0.03}}, max_iter=1)
    assert not cut.converged
    notes: list[str] = []
    on = oe_diagnosis._run_on(cut, noise, notes)
    assert on.converged and on.rss < cut.rss and notes == []
    monkeypatch.setattr(oe_diagnosis, "CONVERGE_ITERATIONS", 1)
    worse = fit_output_error(grid, ("unbalance", "viscous_damping"),
                             {"unbalance": {"tau": 0.002, "beta": -0.5}, "viscous_damping": {"c": 0.02}}, max_iter=1)
    still = oe_diagnosis._run_on(worse, noise, notes)
    assert not still.converged and still.rss <= worse.rss
    assert len(notes) == 1 and "did not converge" in notes[0] and "do not hold" in notes[0]
