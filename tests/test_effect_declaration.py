"""The effect declaration is the only list (issue 23, item 5).

A brand-new effect, declared once with :func:`register_effect` and no other edit, is
ranked by the diagnosis, simulated, randomised by the environments, documented and
reported; and the package's own lists are exactly what the declarations say.
"""

from __future__ import annotations

import numpy as np
import pytest

from rotor_env.diagnosis import LIBRARY_CANDIDATES, diagnose
from rotor_env.diagnosis.field import whirl_frequencies
from rotor_env.diagnosis.synchronous import VECTOR_EFFECTS
from rotor_env.effects import EFFECTS, PHYSICAL_EFFECTS, Effect, Parameter, register_effect
from rotor_env.effects_doc import effects_markdown
from rotor_env.envs.randomization import FAULT_RANGES, ParamRange, check_faults, sample_params
from rotor_env.params import RotorParams
from rotor_env.simulator import simulate

# the effect registered here must not leak into other tests (conftest.py)
pytestmark = pytest.mark.usefixtures("restore_effect_registry")


def _hardening_columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    # a cubic (hardening) restoring moment -k3 |z|^2 z: numba-compilable plain arithmetic
    r2 = th_x * th_x + th_y * th_y
    return (-th_y * r2,), (-th_x * r2,)


HARDENING = Effect(
    name="hardening_test",
    parameters=(Parameter("k_hard", 0.0, "cubic stiffness of a hardening support", lower=0.0, upper=5.0,
                          bounds_reason="a support far harder than cubic 5 would not let the rotor whirl",
                          domain=(0.0, np.inf)),),
    coefficients=("k_hard",),
    columns=_hardening_columns,
    to_coefficients=lambda p: (float(p["k_hard"]),),
    from_coefficients=lambda c: {"k_hard": float(c[0])},
    moment="-k_hard |z|^2 th_y, -k_hard |z|^2 th_x",
    cause="a support that stiffens as it deflects",
    signature="a critical speed that rises with the amplitude (a jump on the run-up)",
    orders=(1,),
    candidate=True,
    fault_range=(("k_hard", 0.5, 1.5),),
)


def test_package_lists_are_the_declarations():
    # every list is read from the declared fields, in registration order
    assert tuple(LIBRARY_CANDIDATES) == tuple(n for n, e in EFFECTS.items() if e.candidate)
    assert "unbalance_in_phase" not in LIBRARY_CANDIDATES  # a preset view of unbalance, not a candidate
    assert list(FAULT_RANGES) == [n for n, e in EFFECTS.items() if e.fault_range]
    assert tuple(VECTOR_EFFECTS) == tuple(n for n, e in EFFECTS.items() if e.synchronous)
    assert FAULT_RANGES["support_anisotropy"] == (ParamRange("support_anisotropy", -0.08, 0.08, "support_anisotropy"),)


def test_the_crack_laws_are_the_declarations():
    from rotor_env.diagnosis.oe_diagnosis import CRACKS
    from rotor_env.effects import crack_effects

    assert tuple(CRACKS) == crack_effects() == tuple(n for n, e in EFFECTS.items() if e.crack)
    assert {"asymmetry", "breathing_crack", "hinge_crack"} <= set(CRACKS)


def test_the_hinge_is_gasch_s_body_frame_stiffness():
    """``hinge_crack``'s moment against the hinge written in the shaft's body axes: the crack's
    mouth xi at the fixed-frame angle phi + axis (z = th_y + i th_x: y is the real axis), the
    stiffness across it k - dk while the deflection stretches it (xi > 0), k otherwise --
    ``-R diag(k - dk H(xi), k) R' q`` minus the healthy ``-k q``; continuous where it switches."""
    rng = np.random.default_rng(7)
    eff = EFFECTS["hinge_crack"]
    dk = 0.07
    for _ in range(200):
        phi, axis = rng.uniform(0, 4 * np.pi), rng.uniform(0, 2 * np.pi)
        q = rng.normal(size=2)  # (th_y, th_x)
        a = phi + axis
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        xi = (R.T @ q)[0]
        K = np.diag([1.0 - dk * (xi > 0), 1.0])
        expected = -R @ K @ R.T @ q + q
        cy, cx = eff.columns(phi, 0.0, 0.0, q[1], q[0], 0.0, 0.0, 0.3, axis)
        assert np.allclose([dk * cy[0], dk * cx[0]], expected, atol=1e-12)
    # at the switch the moment is zero from both sides (no jump: the simulator integrates it)
    phi, axis = 0.3, 1.1
    n = np.array([np.cos(phi + axis), np.sin(phi + axis)])
    t = np.array([-n[1], n[0]])  # across the mouth: xi = 0
    for eps in (1e-9, -1e-9):
        q = t + eps * n
        cy, cx = eff.columns(phi, 0.0, 0.0, q[1], q[0], 0.0, 0.0, 0.3, axis)
        assert abs(cy[0]) < 1e-8 and abs(cx[0]) < 1e-8


def test_a_bad_fault_range_is_refused():
    with pytest.raises(ValueError, match="fault_range entry"):
        register_effect(Effect(**{**HARDENING.__dict__, "name": "bad_range", "fault_range": (("nope", 0.0, 1.0),)}))
    with pytest.raises(ValueError, match="fault_range entry"):
        register_effect(Effect(**{**HARDENING.__dict__, "name": "bad_range", "fault_range": (("k_hard", 2.0, 1.0),)}))


def test_one_declaration_is_enough(tmp_path):
    register_effect(HARDENING)
    name = HARDENING.name
    # randomised: the environments draw it as a field fault, reproducibly, within its range
    assert FAULT_RANGES[name] == (ParamRange("k_hard", 0.5, 1.5, name),)
    assert check_faults({name: 1.0}) == {name: 1.0}
    drawn = sample_params(np.random.default_rng(3), faults={name: 1.0})
    assert name in drawn.effects and 0.5 <= drawn.values["k_hard"] <= 1.5
    again = sample_params(np.random.default_rng(3), faults={name: 1.0})
    assert again.values["k_hard"] == drawn.values["k_hard"]
    # documented: its catalogue entry, with where the declaration puts it
    doc = effects_markdown({name: HARDENING})
    assert f"## `{name}`" in doc and "the diagnosis (a default candidate)" in doc
    assert "`k_hard` U(0.5, 1.5)" in doc
    # simulated: a rotor with the effect (the Jeffcott rotor of Table 1 without its other
    # non-linearities), noise as a probe would add
    params = RotorParams(effects=(*PHYSICAL_EFFECTS, name),
                         values={"D": 0.0, "k30": 0.0, "k21": 0.0, "k12": 0.0, "k03": 0.0, "h": 0.0, "k_hard": 1.0})
    meas = simulate(params, t_end=300.0, noise=5e-4, seed=2)
    # ranked: the diagnosis's default candidates include it, it is found and identified
    res = diagnose(meas, ip=0.3)
    assert name in {c.effect for c in res.candidates}
    assert name in res.missing, res.summary()
    assert res.after.physical["k_hard"] == pytest.approx(1.0, rel=0.1)
    # reported: the summary, the JSON and the HTML report name it
    assert name in res.summary() and name in res.to_json()
    report = tmp_path / "report.html"
    res.report(report)
    assert name in report.read_text()


def test_whirl_model_takes_declared_effects():
    # the Campbell model is built from the effects declared whirl=True; a value for each of
    # the four the package declares gives the textbook isotropic rotor at standstill
    out = whirl_frequencies(np.array([0.0]), 1.0, 0.0, 0.3)
    assert out["forward"][0] == pytest.approx(1.0) and out["backward"][0] == pytest.approx(-1.0)
