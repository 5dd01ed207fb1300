"""A drawn rotor whose own simulation diverges is said apart, not counted as the product's error.

A rub's dry friction can drive a backward whirl that grows without bound (a contact model with
no stator to stop it): the rig suite's seed-6 record #14 at 0.5 um (a two-plane rig) does so in
the package's simulator, and the foreign simulator's seed-11 rub does so in its own
(``tests/test_foreign_rig.py``).  No record exists to diagnose, so neither a verdict nor an
error of the diagnosis is reported; the tables say "not made".
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import rig_suite as rs


def _spec(index: int) -> rs.RecordSpec:
    return next(s for s in rs.build_specs((0.5,), rs.KINDS, 4, 6) if s.index == index)


def test_the_suites_diverging_rub_is_not_made_and_said_apart():
    spec = _spec(14)
    assert spec.fault == "rub"
    o = rs.run_record(spec)
    assert "unstable" in o and "error" not in o, o
    assert "diverged" in o["unstable"]
    row = rs.detection_table([o]).splitlines()[-1]
    assert row.endswith("| 0 (1 not made: the simulator diverged) |"), row
    assert "0/0 (1 not made: the simulator diverged)" in rs.per_fault_table([o])
    (line,) = rs.failures([o])
    assert "not made, the simulator diverged" in line and "ERROR" not in line


def test_a_record_that_runs_is_counted_as_before():
    """Control: a healthy record of the same draw is made, diagnosed and counted."""
    o = rs.run_record(_spec(next(s.index for s in rs.build_specs((0.5,), rs.KINDS, 4, 6) if s.fault == "healthy")))
    assert "unstable" not in o and "error" not in o, o
    row = rs.detection_table([o]).splitlines()[-1]
    assert row.endswith("| 0 |"), row
    assert "| 0/1 |" in row  # its false-alarm column: healthy, nothing named
