"""The record in two parts (rotor_env.diagnosis.parts): when the two sides of a break tell a
change of the rotor, and when they do not -- on stand-in side diagnoses with known verdicts,
models and intervals (the whole chain on simulated rig records: tests/test_change.py)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from rotor_env.diagnosis.parts import RecordParts


@dataclass
class Side:
    verdict: str
    added: list
    model_after: tuple
    params: dict = field(default_factory=dict)
    rms_ratio_after: float = 1.0
    after: object = None
    change: object = None

    def parameters(self) -> dict:
        return self.params

    def to_dict(self) -> dict:
        return {"verdict": self.verdict, "missing": list(self.added), "rms_ratio_after": self.rms_ratio_after,
                "parameters": self.params, "rejected": {}, "undecidable": {}}


BASE = ("unbalance", "viscous_damping")


def _unbalance(tau, half, beta=0.0):
    return {"unbalance": {"values": {"tau": tau, "beta": beta}, "ci95": {"tau": half, "beta": 0.01}}}


def test_an_effect_named_after_the_break_only_appeared():
    before = Side("explained", [], BASE, _unbalance(0.005, 1e-5))
    after = Side("explained_after_adding", ["asymmetry"], (*BASE, "asymmetry"), _unbalance(0.005, 1e-5))
    parts = RecordParts(100.0, before, after)
    assert parts.explained and parts.changed
    assert parts.appeared == ["asymmetry"] and parts.gone == [] and parts.moved() == {}
    assert parts.sentence("at 3.0 s").startswith("the rotor changed at 3.0 s: asymmetry appeared")
    assert parts.to_dict()["appeared"] == ["asymmetry"]


def test_sides_not_both_explained_show_no_change_whatever_they_name():
    before = Side("unexplained", [], BASE, _unbalance(0.005, 1e-5), rms_ratio_after=1.65)
    after = Side("partly_explained", ["asymmetry", "cross_coupled_stiffness"],
                 (*BASE, "asymmetry", "cross_coupled_stiffness"), _unbalance(0.003, 1e-5), rms_ratio_after=4.3)
    parts = RecordParts(100.0, before, after)
    assert parts.appeared == ["asymmetry", "cross_coupled_stiffness"]
    assert not parts.explained and not parts.changed
    assert "not both explained" in parts.sentence()


def test_moved_means_the_intervals_do_not_overlap_and_angles_wrap():
    # tau: 0.0050 +- 0.0001 vs 0.0053 +- 0.0001 apart; beta: 359 deg vs 1 deg is 2 deg, within
    # the 0.05 rad (2.9 deg) the two half-widths add up to
    before = Side("explained", [], BASE, _unbalance(0.0050, 1e-4, math.radians(359.0)))
    after = Side("explained", [], BASE, _unbalance(0.0053, 1e-4, math.radians(1.0)))
    before.params["unbalance"]["ci95"]["beta"] = after.params["unbalance"]["ci95"]["beta"] = 0.025
    parts = RecordParts(100.0, before, after)
    assert parts.moved() == {"unbalance": {"tau": (0.0050, 0.0053)}}
    assert parts.changed and "parameters moved" in parts.sentence()
    # the same values with wider intervals: nothing moved, no change
    for side in (before, after):
        side.params["unbalance"]["ci95"]["tau"] = 2e-4
    assert parts.moved() == {} and not parts.changed
    assert parts.sentence().startswith("no change of the rotor")


def _with_stiffness(params: dict, k: float, half: float = 0.01) -> dict:
    return {**params, "stiffness": {"values": {"k": k}, "ci95": {"k": half}}}


def test_sides_whose_shafts_differ_beyond_any_fault_hold_two_modes_not_a_change():
    """A two-disk rotor's record, its second mode just above the run: before the break the
    one-mode model's stiffness 1.68 (a mode between the two), after it 1.04 with a crack and a
    bow "appeared" -- both sides explained, yet no fault moves the shaft's stiffness by 60 %:
    no change of the rotor, and the sentence says the model lacks a mode.  A crack's own 8 %
    (sqrt: 4 % in the natural frequency) is a change."""
    from rotor_env.diagnosis.parts import MAX_STIFFNESS_CHANGE

    before = Side("explained", [], BASE, _with_stiffness(_unbalance(0.0004, 7e-5), 1.68, 0.05))
    after = Side("explained_after_adding", ["hinge_crack", "shaft_bow"], (*BASE, "hinge_crack", "shaft_bow"),
                 _with_stiffness(_unbalance(0.015, 1e-4), 1.04))
    parts = RecordParts(100.0, before, after)
    assert parts.explained and parts.appeared == ["hinge_crack", "shaft_bow"]
    assert parts.other_mode == (1.68, 1.04) and not parts.changed
    assert "another mode of the rotor" in parts.sentence()
    # a crack that opened: the stiffness 8 % lower after, within what a fault does
    cracked = Side("explained_after_adding", ["asymmetry"], (*BASE, "asymmetry"),
                   _with_stiffness(_unbalance(0.0004, 7e-5), 1.68 * 0.92, 0.05))
    opened = RecordParts(100.0, before, cracked)
    assert opened.other_mode is None and opened.changed
    # the bound, either way
    for factor, two_modes in ((1.01, True), (0.99, False)):
        cracked.params["stiffness"]["values"]["k"] = 1.68 * (1 + MAX_STIFFNESS_CHANGE * factor)
        assert (RecordParts(100.0, before, cracked).other_mode is not None) == two_modes
