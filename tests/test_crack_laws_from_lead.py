"""The other crack laws started from the best crack's side load and axis
(``oe_diagnosis._crack_laws_from_lead``): only from a lead that came near the round's best."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from rotor_env.diagnosis.oe_diagnosis import CONVERGE_ITERATIONS, CRAWL_SHARE, _crack_laws_from_lead


def _lead(gave_up: bool, significant: bool, iterations: int = 38):
    def wald(effect):
        if gave_up and iterations >= CRAWL_SHARE * CONVERGE_ITERATIONS:
            raise AssertionError("a crawled lead's side load is not read")
        return 0.0, 0.0, (-5.0 if significant else -0.5)

    return SimpleNamespace(effects=("stiffness", "unbalance", "viscous_damping", "static_load", "asymmetry"),
                           rss=1.0, gave_up=gave_up, wald=wald, iterations=iterations)


@pytest.mark.parametrize("significant", [True, False])
def test_no_law_is_started_from_a_crack_that_crawled_and_gave_up(significant, monkeypatch):
    """A misalignment record: the cracks' fits crawl along the crack-size x side-load valley for
    38 of their 40 steps and give up against the misalignment, which the round fits best; the
    other laws are not started from the best crack's load and axis (they were, and crawled and
    gave up too: 4.7 s of the record's 18.8 s)."""
    import rotor_env.diagnosis.oe_diagnosis as od

    def no_fit(*args, **kwargs):
        raise AssertionError("no crack law is fitted")

    monkeypatch.setattr(od, "fit_output_error", no_fit)
    fits = {"asymmetry": _lead(True, significant), "misalignment": SimpleNamespace(rss=0.5, gave_up=False)}
    out = _crack_laws_from_lead(None, None, None, ("unbalance", "viscous_damping"), (), fits,
                                ["asymmetry", "misalignment"], None, best_rss=0.5, floor=0.01)
    assert out == {}


def test_a_lead_without_a_significant_load_starts_nothing(monkeypatch):
    import rotor_env.diagnosis.oe_diagnosis as od

    monkeypatch.setattr(od, "start_from", lambda fit: (_ for _ in ()).throw(AssertionError("not read")))
    fits = {"asymmetry": _lead(False, False)}
    assert _crack_laws_from_lead(None, None, None, (), (), fits, ["asymmetry"], None) == {}


def test_a_lead_that_gave_up_early_still_starts_the_other_laws(monkeypatch):
    """A foreign breathing crack's record: the open crack (the lead) gave up after 10 steps
    against a misalignment; the breathing law started from its significant load is fitted (it
    beat the misalignment threefold there)."""
    import rotor_env.diagnosis.oe_diagnosis as od

    started = []

    def fit(grid, model, start, **kwargs):
        started.append(model[-1])
        raise FloatingPointError("stop here")

    monkeypatch.setattr(od, "fit_output_error", fit)
    monkeypatch.setattr(od, "start_from", lambda f: {"static_load": {"load_x": 0.1, "load_y": 0.0}})
    lead = _lead(True, True, iterations=10)
    lead.value = lambda name: 0.3
    fits = {"asymmetry": lead, "breathing_crack": SimpleNamespace(rss=2.0, gave_up=True),
            "misalignment": SimpleNamespace(rss=0.5, gave_up=False)}
    _crack_laws_from_lead(None, None, None, ("unbalance", "viscous_damping"), ("static_load",), fits,
                          ["asymmetry", "misalignment"], None, best_rss=0.5, floor=0.01)
    assert "breathing_crack" in started
