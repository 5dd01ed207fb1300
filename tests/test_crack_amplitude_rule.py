"""The rule that tells a crack from a rub by amplitude (``crack_amplitude_independence``).

A crack's stiffness asymmetry is the same at every amplitude; a rub's contact acts only above
its clearance.  The crack model is refitted on the low- and the high-amplitude half of the
record, free and held at the whole record's value; the halves disagree where holding it
costs more than ``CRACK_SPLIT_Z ** 2`` noise variances (a likelihood ratio).  References:
simulations with known truth (the package's and the rig suite's).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from rotor_env.diagnosis.oe_diagnosis import CRACK_SPLIT_Z, diagnose_output_error
from rotor_env.diagnosis.output_error import ShootingGrid

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


@pytest.mark.parametrize("seed", [3, 4])
def test_a_crack_model_on_a_rub_fails_the_halves(seed):
    """Without the rub among the candidates, the crack laws' fits of a rub record are turned
    down by the rule itself: the low-amplitude half (below the clearance) wants no asymmetry,
    the high one some, and holding the whole record's value costs far beyond the level."""
    from test_output_error import _record

    noise = 5e-4
    m, thx, thy = _record({"rub_stiffness": 0.5, "rub_friction": 0.2, "rub_clearance": 0.06}, ("rub",),
                          noise=noise, seed=seed)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, thx, thy, 0.0, noise_std=noise)
    d = diagnose_output_error(grid, ("unbalance", "viscous_damping"), ("asymmetry", "breathing_crack"))
    assert d.missing == []
    for crack in ("asymmetry", "breathing_crack"):
        reason = d.rejected[crack]
        assert "rule crack_amplitude_independence" in reason, reason
        cost = float(reason.split("residual rises by ")[1].split(" noise")[0])
        assert cost > 4 * CRACK_SPLIT_Z ** 2  # measured 110-122: far beyond the level, not at its edge


def test_a_crack_whose_low_half_hardly_determines_it_is_named(tmp_path):
    """Rig suite seed 1, record 36: an open crack D = 0.0396 at 3 um probe noise, 2.5 kHz.  Its
    low-amplitude half read 0.263 +- 0.039 (outside any crack's range) against 0.0397 on the
    high one, 5.5 standard errors apart by the Wald distance, and the crack was turned down;
    held at the whole record's value that half's fit rises by 12 noise variances only.  The
    crack is named with its size and axis."""
    import rig_suite as rs

    from rotor_env.diagnosis.from_rig import diagnose_rig
    from rotor_env.measurements.rig import load_rig
    from rotor_env.measurements.waveforms import load_waveforms

    spec = rs.RecordSpec(index=36, seed=100036, fault="asymmetry", noise_um=3.0, rig="one-plane um",
                         natural_rpm=1521.4, zeta=0.0219, sample_rate=2500.0, direction="run-up")
    rig_path, data_path, truth = rs.make_record(spec, tmp_path)
    out = diagnose_rig(load_waveforms(data_path, load_rig(rig_path))).to_dict()
    assert out["missing"] == ["asymmetry"], out["rejected"]
    got = out["parameters"]["asymmetry"]["values"]
    err = rs.crack_errors("asymmetry", truth["fault"], out["parameters"])
    assert err["size_error"] < 0.05 and err["axis_error_deg"] < 5.0, (got, truth["fault"])
    assert math.isfinite(got["D"]) and np.isfinite(out["rms_ratio_after"]) and out["rms_ratio_after"] < 1.05
