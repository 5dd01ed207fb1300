"""The search's note on a candidate beside the one named (rotor_env.diagnosis.oe_diagnosis):
a tie is said as a tie (the data cannot tell them apart), a much better fit that a rule turned
down is said with that rule -- never as "fits as well" (stop 31's gravity-sag crack: 1.003x
the floor against 11.16x was called a tie); and the same tie deciding between crack laws (a
hinge named only where it beats an open crack).  Stand-in fits with known residual energies;
the tie's level is scipy's chi-square 99 % point."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from rotor_env.diagnosis.oe_diagnosis import Candidate, _comparison_note, _simpler_crack_law_first


@dataclass
class Fit:
    rss: float
    n_rows: int = 10_000
    n_values: int = 3

    @property
    def values(self) -> np.ndarray:
        return np.zeros(self.n_values)

    @property
    def rms(self) -> float:
        return math.sqrt(self.rss / self.n_rows)


def _row(effect: str, reason: str) -> Candidate:
    return Candidate(1, effect, 0.0, -50.0, 1.0, {}, {}, False, reason)


FLOOR = 1.0
CHOSEN = Fit(rss=10_000 * 1.2**2)


def test_a_tie_is_said_as_a_tie():
    level = chi2.ppf(0.99, 3)
    for gap in (-0.5 * level, 0.0, 0.9 * level):
        note = _comparison_note(1, _row("breathing_crack", "a better candidate in this round: asymmetry"),
                                Fit(rss=CHOSEN.rss + gap, n_values=3), "asymmetry", Fit(CHOSEN.rss, n_values=1),
                                FLOOR)
        assert "fits these data as well as asymmetry" in note and "as the simpler" in note


def test_a_much_better_fit_turned_down_names_the_rule():
    reason = "rule crack_amplitude_independence: its stiffness asymmetry is 0.0242 on the low half"
    better = Fit(rss=10_000 * 1.003**2)
    note = _comparison_note(1, _row("breathing_crack", reason), better, "asymmetry", CHOSEN, FLOOR)
    assert "as well as" not in note
    assert note.startswith("round 1: breathing_crack fits these data better than asymmetry")
    assert note.endswith(reason)


def test_a_much_worse_fit_gets_no_note():
    worse = Fit(rss=CHOSEN.rss + 10 * chi2.ppf(0.99, 3))
    assert _comparison_note(1, _row("rub", "significant, not relevant"), worse, "asymmetry", CHOSEN, FLOOR) == ""


# ------------------------------------------------------------------ the simpler crack law
def _accepted(effect: str) -> Candidate:
    return Candidate(1, effect, 0.0, -50.0, 1.0, {}, {}, True, "")


def test_a_hinge_that_ties_with_an_open_crack_gives_way_to_it():
    """Gasch's hinge and the open crack have as many parameters: where they tie (within the
    chi-square 99 % point of the gap), the open crack -- the law that assumes less -- is named;
    where the hinge fits better beyond it, the hinge stays first."""
    level = chi2.ppf(0.99, 3)
    rows = [_accepted("hinge_crack"), _accepted("misalignment"), _accepted("asymmetry")]
    hinge = Fit(rss=CHOSEN.rss, n_values=3)
    for gap in (-level, 0.0, 0.9 * level):
        fits = {"hinge_crack": hinge, "misalignment": Fit(rss=CHOSEN.rss), "asymmetry": Fit(CHOSEN.rss + gap)}
        out = _simpler_crack_law_first(rows, fits, FLOOR)
        assert [r.effect for r in out] == ["asymmetry", "hinge_crack", "misalignment"]
    fits = {"hinge_crack": hinge, "misalignment": Fit(rss=CHOSEN.rss), "asymmetry": Fit(CHOSEN.rss + 1.1 * level)}
    assert _simpler_crack_law_first(rows, fits, FLOOR) == rows


def test_a_simpler_law_with_more_parameters_is_left_to_the_criterion():
    """A breathing crack (more parameters than the hinge) that ties is not moved ahead: the
    information criterion, which charges its parameters, already ranked them; nor is anything
    moved ahead of a first candidate that is not a crack."""
    rows = [_accepted("hinge_crack"), _accepted("breathing_crack")]
    fits = {"hinge_crack": Fit(CHOSEN.rss, n_values=3), "breathing_crack": Fit(CHOSEN.rss, n_values=5)}
    assert _simpler_crack_law_first(rows, fits, FLOOR) == rows
    rows = [_accepted("misalignment"), _accepted("asymmetry")]
    fits = {"misalignment": Fit(CHOSEN.rss), "asymmetry": Fit(CHOSEN.rss - 5.0)}
    assert _simpler_crack_law_first(rows, fits, FLOOR) == rows
