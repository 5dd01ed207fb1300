"""The search's note on a candidate beside the one named (rotor_env.diagnosis.oe_diagnosis):
a tie is said as a tie (the data cannot tell them apart), a much better fit that a rule turned
down is said with that rule -- never as "fits as well" (stop 31's gravity-sag crack: 1.003x
the floor against 11.16x was called a tie).  Stand-in fits with known residual energies; the
tie's level is scipy's chi-square 99 % point."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from rotor_env.diagnosis.oe_diagnosis import Candidate, _comparison_note


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
