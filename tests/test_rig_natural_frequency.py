"""The two parts of a rig diagnosis must agree on the natural frequency where the run does
not pass a critical speed (``RigDiagnosis.natural_frequency_disagreement``).  Known truth:
records simulated at 0.5 um probe noise from a 1650 rpm rotor -- one that barely changes
speed (1200-1210 rpm: one 1X vector, too few numbers for stiffness, damping and unbalance)
and one wholly above the critical (2200-3300 rpm: the response's fall with speed still
determines them)."""

from __future__ import annotations

import math

import pytest

from rotor_env.measurements.rig import load_rig
from rotor_env.measurements.waveforms import load_waveforms
from rotor_env.params import RotorParams
from rotor_env.rig_simulation import simulate_rig

NATURAL_RPM = 1650.0


def _diagnose(tmp_path, rpm_from: float, rpm_to: float, rpm_per_s: float, seed: int):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from rotor_env.diagnosis.from_rig import diagnose_rig

    (tmp_path / "rig.yaml").write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
    rig = load_rig(tmp_path / "rig.yaml")
    p = RotorParams(ip=0.0, values={"c": 0.04, "tau": 0.005, "beta": 0.3},
                    effects=("stiffness", "viscous_damping", "unbalance"))
    run = simulate_rig(rig, p, natural_rpm=NATURAL_RPM, rpm_from=rpm_from, rpm_to=rpm_to, rpm_per_s=rpm_per_s,
                       sample_rate=5000.0, noise=0.5, seed=seed)
    pq.write_table(pa.table(run.file_columns()), tmp_path / "run.parquet")
    return diagnose_rig(load_waveforms(tmp_path / "run.parquet", rig), candidates=("asymmetry",))


def test_a_run_at_one_speed_does_not_determine_the_natural_frequency(tmp_path):
    d = _diagnose(tmp_path, 1200.0, 1210.0, 2.0, seed=1)
    assert not d.vectors.after.rotor_criticals
    said = d.undecidable.get("natural_frequency", "")
    assert "disagree" in said and "does not determine" in said, d.undecidable
    assert d.to_dict()["undecidable"]["natural_frequency"] == said


@pytest.mark.parametrize("seed", [2, 3])
def test_a_run_above_the_critical_determines_it_and_the_parts_agree(tmp_path, seed):
    d = _diagnose(tmp_path, 2200.0, 3300.0, 180.0, seed=seed)
    assert not d.vectors.after.rotor_criticals
    assert d.natural_frequency_disagreement == ""
    assert "natural_frequency" not in d.undecidable
    # the waveforms' natural frequency within 2 % of the truth
    fit = d.diagnosis.after
    rpm = d.w_ref / (2 * math.pi / 60.0)
    assert rpm * math.sqrt(fit.value("stiffness.k")) == pytest.approx(NATURAL_RPM, rel=0.02)
