"""The verdict's JSON contract, checked from outside: ``rotor-id diagnose FILE --json`` run
as a separate process on files written to disk, as a user runs it.

Files: a 3x forcing the library does not declare (``faults.forcing_3x``), a support
anisotropy it does (simulated by ``faults.anisotropy``'s own code), a
healthy rotor with ip = 0.2 (the default used to be 0.3), the same healthy rotor with
its time in seconds (natural frequency 40 Hz), and an all-zero record.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import faults as F
import pytest

from rotor_env.measurements import Measurements

#: keys the JSON had before the verdict (they stay)
OLD_KEYS = {"source", "ip", "alpha", "t_start", "start_model", "model", "missing", "onset", "candidates",
            "rounds", "rms_before", "rms_after", "r2_before", "r2_after", "fit_percent_before",
            "fit_percent_after", "coefficients", "standard_errors", "physical", "significance",
            "failing_windows", "noise_floor"}
NEW_KEYS = {"verdict", "noise_floor", "rms_ratio_after", "unexplained", "rejected", "ip", "ip_estimate"}


def _diagnose(path: Path, *args: str) -> tuple[dict, str]:
    proc = subprocess.run([sys.executable, "-m", "rotor_env.cli", "diagnose", str(path), "--json", *args],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().count("\n") == 0, "one JSON object on one line"
    return json.loads(proc.stdout), proc.stderr


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("verdict")
    out = {}
    out["3x"] = folder / "forcing_3x.csv"
    F.forcing_3x(1, **F.FAST).to_file(out["3x"])
    out["anisotropy"] = folder / "anisotropy.csv"
    F.anisotropy(1, **F.FAST).to_file(out["anisotropy"])
    healthy = F.healthy(5, rotor=F.with_rotor(F.BASE, ip=0.2), **F.FAST)
    out["ip 0.2"] = folder / "ip02.csv"
    healthy.to_file(out["ip 0.2"])
    # the same run with time in seconds: natural frequency w = 2 pi 40 rad/s
    w = 2 * math.pi * 40.0
    d = healthy.data.copy()
    d[:, 0] /= w
    d[:, 2] *= w
    d[:, 3] *= w * w
    d[:, 6:8] *= w
    d[:, 8:10] *= w * w
    out["seconds"] = folder / "seconds.csv"
    Measurements(d).to_file(out["seconds"])
    out["zeros"] = folder / "zeros.csv"
    F.zeros().to_file(out["zeros"])
    return out


def test_undeclared_fault_json(files):
    out, _ = _diagnose(files["3x"], "--model", "unbalance,viscous_damping", "--ip", "0.3")
    assert OLD_KEYS | NEW_KEYS <= set(out), sorted(OLD_KEYS | NEW_KEYS - set(out))
    assert out["verdict"] in ("partly_explained", "unexplained")
    assert out["missing"] == []  # nothing from the library stands for a 3x forcing
    assert out["rms_ratio_after"] == pytest.approx(out["rms_after"] / out["noise_floor"])
    assert out["rms_ratio_after"] > 1.5
    top = out["unexplained"]["orders"][0]
    assert set(top) == {"order", "direction", "share"}
    assert (top["order"], top["direction"]) == (3, "forward") and isinstance(top["order"], int)
    assert 0.3 < top["share"] <= 1.0
    assert out["unexplained"]["bands"] and all(
        {"t_start", "t_end"} <= set(b) for b in out["unexplained"]["bands"])
    assert all(set(r) == {"effect", "rule", "round"} and r["rule"] and r["round"] >= 1 for r in out["rejected"])
    assert out["ip"] == 0.3


def test_declared_fault_json(files):
    """The anisotropy is named, with ip estimated (the widest model holds it: unbiased)."""
    out, _ = _diagnose(files["anisotropy"], "--model", "unbalance,viscous_damping")
    assert out["verdict"] == "explained_after_adding" and out["missing"] == ["support_anisotropy"]
    assert out["unexplained"] is None and out["rms_ratio_after"] <= 1.5
    assert out["ip"] == pytest.approx(0.3, abs=0.01)
    assert out["physical"]["support_anisotropy"] == pytest.approx(0.08, rel=0.05)


def test_undeclared_fault_without_ip(files):
    """Without ``--ip`` the estimate is used; a fault outside the library may bias it, and
    the result says the estimate is uncertain — the verdict stays honest."""
    out, _ = _diagnose(files["3x"], "--model", "unbalance,viscous_damping")
    assert out["ip"] == pytest.approx(min(max(out["ip_estimate"], 0.0), 0.95))
    assert out["verdict"] in ("partly_explained", "unexplained") and out["missing"] == []
    assert any("uncertain" in n for n in out["notes"]), out["notes"]


def test_ip_is_estimated_and_a_wrong_one_is_flagged(files):
    est, _ = _diagnose(files["ip 0.2"])
    assert est["ip"] == pytest.approx(0.2, abs=0.01)
    assert est["verdict"] == "explained" and est["missing"] == []
    wrong, stderr = _diagnose(files["ip 0.2"], "--ip", "0.3")
    assert wrong["ip"] == 0.3
    assert wrong["ip_estimate"] == pytest.approx(0.2, abs=0.01)
    assert "contradict ip = 0.3" in stderr
    assert any("contradict" in n for n in wrong["notes"])


def test_time_in_seconds_is_rescaled(files):
    out, _ = _diagnose(files["seconds"])
    assert out["time_scale"] == pytest.approx(2 * math.pi * 40.0, rel=0.01)
    assert out["verdict"] == "explained" and out["missing"] == []
    assert out["ip"] == pytest.approx(0.2, abs=0.01)


def test_all_zero_file_is_not_identifiable(files):
    out, _ = _diagnose(files["zeros"])
    assert out["verdict"] == "not_identifiable"
    assert "no excitation" in out["reason"]
    assert NEW_KEYS <= set(out)
    assert out["missing"] == [] and out["unexplained"] is None


def test_verdict_words_are_the_documented_ones(files):
    """Every verdict above is one of the five the README documents."""
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    for word in ("explained", "explained_after_adding", "partly_explained", "unexplained", "not_identifiable"):
        assert f"`{word}`" in readme, word
