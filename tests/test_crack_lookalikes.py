"""A crack is named against every alternative at its optimum (``oe_diagnosis._crack_lookalikes``).

The screening's two Levenberg-Marquardt steps rank the candidates by where they stand early;
a shaft bow's 1X is a runout plus an unbalance but for the damping's share, so its fit moves
slowly there and it can be screened out beside a crack whose side load soaks up a few per cent
of the misfit.  Reference: simulated rig records with known truth (a bowed, unbalanced rotor,
no crack); the control (the lookalikes not fitted on) names a false crack on the same record.
"""

from __future__ import annotations

import math

import pytest


@pytest.fixture(scope="module")
def bowed_record(tmp_path_factory):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from rotor_env.measurements.rig import load_rig
    from rotor_env.params import RotorParams
    from rotor_env.rig_simulation import simulate_rig

    folder = tmp_path_factory.mktemp("bow")
    (folder / "rig.yaml").write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
    rig = load_rig(folder / "rig.yaml")
    # a foreign draw's rotor (seed 32): 10 um of bow, 11 um of unbalance 90 deg from it, 3.6 %
    # damping, 400 -> 2400 rpm through 1331 rpm; the peak is some 250 um
    params = RotorParams(ip=0.0, values={"c": 0.072, "tau": 0.0108, "beta": math.radians(90.0), "bow": 0.0104,
                                         "bow_phase": 0.0},
                         effects=("stiffness", "viscous_damping", "unbalance", "shaft_bow"))
    run = simulate_rig(rig, params, natural_rpm=1331.0, rpm_from=400.0, rpm_to=2396.0, rpm_per_s=238.0,
                       sample_rate=5000.0, noise=0.5, seed=3)
    path = folder / "run.parquet"
    pq.write_table(pa.table(run.file_columns()), path)
    return path, rig


def _diagnose(record):
    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.measurements.waveforms import load_waveforms

    path, rig = record
    return diagnose_rig(load_waveforms(path, rig)).to_dict()


def test_a_bow_screened_out_beside_a_crack_is_fitted_on_and_named(bowed_record, monkeypatch):
    from rotor_env.diagnosis import oe_diagnosis

    d = _diagnose(bowed_record)
    assert d["missing"] == ["shaft_bow"], (d["missing"], d["rejected"])
    assert d["verdict"] in ("explained", "explained_after_adding")
    got = d["parameters"]["shaft_bow"]["values"]
    assert got["bow"] == pytest.approx(0.0104, rel=0.1)
    # the control: without fitting the screened-out candidates on, a crack is named
    monkeypatch.setattr(oe_diagnosis, "LOOKALIKE_SCREEN", 0.0)
    control = _diagnose(bowed_record)
    assert set(control["missing"]) & set(oe_diagnosis.CRACKS), control["missing"]
