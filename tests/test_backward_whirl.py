"""A 1X whirl that turns backward: a crack under a large static load, or mirrored probe angles.

An unbalance drives a forward 1X whirl, and mirrored probe angles turn it backward at every
speed; so does a cracked horizontal shaft whose sag is many times its unbalance response (the
crack's stiffness turning against the fixed deflection drives a 1X both ways).  The record is
diagnosed where a crack under a side load explains it (its load started at the record's scale,
``oe_diagnosis.crack_fits_under_load``) and refused otherwise.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from rotor_env.diagnosis.from_rig import diagnose_rig
from rotor_env.diagnosis.from_vectors import BackwardWhirlError
from rotor_env.measurements.rig import load_rig
from rotor_env.measurements.waveforms import load_waveforms

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import foreign_rig as fr


def test_a_crack_under_a_large_sag_turning_the_1x_backward_is_diagnosed(tmp_path):
    """Foreign seed 45's breathing crack (Mayes, dk/k 0.043, its mouth 47.9 deg from the notch,
    sag 276 um against 3.4 um of unbalance; an up-down run, 5 kHz, 0.5 um): its 1X turns
    backward at 88 % of the speeds, and the file was refused as mirrored probe angles.  With
    the crack's side load started at the record's scale it is named, the record explained, the
    crack's axis within 5 deg (mod 180: the package's axis and breathing phase trade half
    turns), and the note says why the angles were taken as given."""
    _, _, out = fr.make_record("breathing_crack", 45, 0.5, profile="updown")
    truth = out["truth"]
    assert truth["static_deflection_um"] > 5 * truth["peak_um"]
    rig_path, data_path = fr.write_record(tmp_path, "breathing_crack", out["columns"])
    d = diagnose_rig(load_waveforms(data_path, load_rig(rig_path))).to_dict()
    assert d["verdict"] == "explained_after_adding" and d["missing"] == ["breathing_crack"], (d["verdict"],
                                                                                              d["missing"])
    got = math.degrees(d["parameters"]["breathing_crack"]["values"]["crack_axis"])
    assert abs((got - truth["axis_deg"] + 90.0) % 180.0 - 90.0) < 5.0, (got, truth["axis_deg"])
    assert any("1X whirl turns backward" in n and "taken as given" in n for n in d["notes"])


def test_mirrored_probe_angles_are_still_refused(tmp_path):
    """The control: a healthy rotor's record read with its probe angles mirrored (the rig file
    says x at -45, y at +45 deg) turns its 1X backward at every speed; no crack under a load
    explains it, and the file is refused as before."""
    _, _, out = fr.make_record("healthy", 45, 0.5, fs=2500.0)
    rig_path, data_path = fr.write_record(tmp_path, "healthy", out["columns"])
    mirrored = tmp_path / "mirrored_rig.json"
    mirrored.write_text(Path(rig_path).read_text().replace('"x": 45', '"x": -45').replace('"y": -45', '"y": 45'))
    assert '"x": -45' in mirrored.read_text()
    with pytest.raises(BackwardWhirlError) as refused:
        diagnose_rig(load_waveforms(data_path, load_rig(mirrored)))
    assert refused.value.share > 0.9 and "mirrored" in str(refused.value)
    # the same file with the right angles is diagnosed healthy
    d = diagnose_rig(load_waveforms(data_path, load_rig(rig_path))).to_dict()
    assert d["missing"] == [] and np.isfinite(d["rms_ratio_after"])
