"""One source for the candidate table and the turned-down list, the round named (issue 25,
item 5): no "fit % after -100.0", no rejection listed twice, the ip note only where the
record is not explained."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from rotor_env.diagnosis.report import fit_cell
from rotor_env.diagnosis.result import Diagnosis


def _cand(effect, fit=50.0, diverged=False):
    return SimpleNamespace(effect=effect, fit_percent_after=fit, comparison=SimpleNamespace(diverged=diverged))


def test_decisions_name_the_round_from_the_turned_down_list():
    stub = SimpleNamespace(
        rounds=[[_cand("asymmetry"), _cand("misalignment"), _cand("breathing_crack")],
                [_cand("misalignment"), _cand("breathing_crack")]],
        missing=["asymmetry"],
        rejected=[{"effect": "misalignment", "round": 2, "rule": "not significant: HAC Wald test log10 p = -1.02"},
                  {"effect": "breathing_crack", "round": 2, "rule": "confounded with ip: give --ip"}])
    d = Diagnosis.decisions(stub)
    assert d == {"asymmetry": "added in round 1", "misalignment": "turned down in round 2: not significant",
                 "breathing_crack": "turned down in round 2: confounded with ip"}


def test_a_diverged_free_run_has_no_fit_percent():
    assert fit_cell(_cand("x", fit=-100.0, diverged=True)) == "diverged"
    assert fit_cell(_cand("x", fit=-100.0)) == "diverged"
    assert fit_cell(_cand("x", fit=63.84)) == "63.8"


@pytest.fixture(scope="module")
def small_diagnosis():
    from rotor_env import RotorParams, diagnose, simulate

    meas = simulate(RotorParams(), t_end=150.0, dt=0.05, noise=5e-4, seed=1)
    return diagnose(meas, model=["unbalance", "viscous_damping"])


def test_summary_table_and_turned_down_list_agree(small_diagnosis):
    r = small_diagnosis
    text = r.summary()
    assert len(r.rounds) >= 2, "the test needs a diagnosis of several rounds"
    names = [x["effect"] for x in r.rejected]
    assert len(names) == len(set(names)), f"a rejection listed twice: {names}"
    table = text[text.index("candidates, round 1"):text.index("\n\n", text.index("candidates, round 1"))]
    for x in r.rejected:
        assert x["round"] >= 1
        row = next(ln for ln in table.splitlines() if ln.strip().startswith(x["effect"] + " "))
        assert row.endswith(f"turned down in round {x['round']}: {x['rule'].split(':')[0]}"), (row, x)
        assert f"  - {x['effect']} (round {x['round']}): {x['rule']}" in text
    for k, e in enumerate(r.missing, start=1):
        row = next(ln for ln in table.splitlines() if ln.strip().startswith(e + " "))
        assert row.endswith(f"added in round {k}")
    assert "-100.0" not in table
    if r.verdict in ("explained", "explained_after_adding"):
        assert not any("outside the library biases" in n for n in r.notes), r.notes
