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
