"""The probes' calibration: a difference of two probes' sensitivities or angles.

Two probes of a plane that read 2 % high and 2 % low (API 670 allows 5 % each) make a
circular orbit elliptical at every speed: ``z + eps conj(z)`` with ``eps = d e^{2 i a1}``
(``d`` half the difference, ``a1`` the first probe's angle); an angle error ``g`` on one probe
gives ``eps = i (g1 - g2) / 2 e^{2 i a1}``.  The 1X vectors' model read the ellipse as a
``support_anisotropy``; the waveforms' output-error fit carries ``eps`` with every model
(``OUTPUT_TERMS``), and an effect of the structure only the vectors name is tried in the
waveforms before it is named (``from_rig.check_by_waveforms``).  References: the rig
simulator with known probe errors, the formula above.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rotor_env.diagnosis.from_rig import diagnose_rig
from rotor_env.measurements.rig import load_rig
from rotor_env.measurements.waveforms import load_waveforms
from rotor_env.params import RotorParams
from rotor_env.rig_simulation import simulate_rig


def _record(tmp_path, effects=(), values=None, **probe_errors):
    import pyarrow as pa
    import pyarrow.parquet as pq

    rig_path = tmp_path / "rig.json"
    rig_path.write_text(json.dumps({"keyphasor": "kp", "probes": {"x": 45, "y": -45}, "units": {"displacement": "um"}}))
    rig = load_rig(rig_path)
    params = RotorParams(ip=0.0, values={"k": 1.0, "c": 0.04, "tau": 0.005, "beta": 0.7, **(values or {})},
                         effects=("stiffness", "viscous_damping", "unbalance", *effects))
    run = simulate_rig(rig, params, natural_rpm=1650.0, rpm_from=450.0, rpm_to=3000.0, rpm_per_s=300.0,
                       sample_rate=5000.0, noise=0.5, seed=5, **probe_errors)
    pq.write_table(pa.table(run.file_columns()), tmp_path / "run.parquet")
    return load_waveforms(tmp_path / "run.parquet", rig)


def _eps(d) -> complex:
    fit = d.diagnosis.after
    return complex(fit.value("output.calibration_re"), fit.value("output.calibration_im"))


@pytest.mark.parametrize("errors, expected", [
    ({"sensitivity": {"x": 1.02, "y": 0.98}}, 0.02j),  # d = 0.02, e^{2i 45deg} = i
    ({"angle_error_deg": {"y": 2.0}}, complex(math.radians(2.0) / 2, 0.0)),  # i (0 - g2)/2 * i = g2/2
])
def test_a_healthy_rotor_read_by_mismatched_probes_is_healthy(tmp_path, errors, expected):
    d = diagnose_rig(_record(tmp_path, **errors))
    out = d.to_dict()
    assert out["missing"] == [] and out["verdict"] == "explained", (out["missing"], out["notes"])
    assert abs(_eps(d) - expected) < 0.1 * abs(expected), _eps(d)
    assert out["rms_ratio_after"] < 1.02


def test_a_true_support_anisotropy_under_mismatched_probes_is_named_with_its_size(tmp_path):
    s = 0.06
    d = diagnose_rig(_record(tmp_path, ("support_anisotropy",), {"support_anisotropy": s, "support_axis": 0.4},
                             sensitivity={"x": 1.02, "y": 0.98}))
    out = d.to_dict()
    assert out["missing"] == ["support_anisotropy"], out["rejected"]
    got = out["parameters"]["support_anisotropy"]["values"]["support_anisotropy"]
    assert abs(abs(got) / s - 1.0) < 0.05, got
    assert abs(_eps(d) - 0.02j) < 0.004, _eps(d)
    assert np.isfinite(out["rms_ratio_after"]) and out["rms_ratio_after"] < 1.05
