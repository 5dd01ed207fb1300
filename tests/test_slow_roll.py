"""Slow-roll compensation (``rotor_env.slow_roll``, ``diagnose(..., slow_roll=SPEED)``,
``rotor-id diagnose --slow-roll SPEED``): a probe runout is read below a speed,
extrapolated to zero speed, and subtracted with its rates and accelerations, so that it
biases neither the unbalance nor the damping.

Data: ``faults.probe_runout`` (r = 0.015 at 2 rad added to a clean run-up, then noise).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from functools import cache

import faults as F
import numpy as np
import pytest

from rotor_env.cli import main
from rotor_env.diagnosis import diagnose
from rotor_env.slow_roll import compensate_slow_roll, slow_roll_vector

SPEED = 0.6  # below the critical 1/sqrt(0.7) = 1.2: the unbalance response is still small


@cache
def _runout(seed: int):
    return F.probe_runout(seed, **F.FAST)


@pytest.mark.parametrize("seed", [1, 2])
def test_runout_is_read_at_slow_roll(seed):
    r = slow_roll_vector(_runout(seed), SPEED)
    # faults.probe_runout adds r e^{i(phi + gamma)}, r = 0.015, gamma = 2.0
    assert abs(r) == pytest.approx(0.015, rel=0.02)
    assert abs(math.remainder(math.atan2(r.imag, r.real) - 2.0, 2 * math.pi)) < 0.02


def test_compensated_record_equals_the_clean_one():
    """Noise-free: the runout is found to 2 % (measured 1 %: the unbalance response in the
    band is not exactly a polynomial in speed^2), and what is left in the compensated
    angles, rates and accelerations is that error's pattern, nothing else."""
    clean = F.healthy(None, 0.0, **F.FAST)
    measured = F.probe_runout(None, 0.0, **F.FAST)
    back, r = compensate_slow_roll(measured, SPEED)
    true = 0.015 * np.exp(2j)
    assert abs(r - true) < 0.02 * abs(true)
    left = (back.theta_y - clean.theta_y) + 1j * (back.theta_x - clean.theta_x)
    np.testing.assert_allclose(left, (true - r) * np.exp(1j * clean.phi), atol=1e-12)


@pytest.mark.parametrize("seed", [1, 2])
def test_runout_biases_nothing_once_compensated(seed):
    raw = diagnose(_runout(seed), model=F.BASE.model, ip=F.BASE.ip)
    comp = diagnose(_runout(seed), model=F.BASE.model, ip=F.BASE.ip, slow_roll=SPEED)
    # uncompensated, the runout reads as a bow and drags the unbalance far off
    assert raw.missing == ["shaft_bow"]
    assert abs(raw.after.physical["tau"] - F.BASE.tau) > 0.2 * F.BASE.tau
    # compensated: nothing missing, the unbalance and damping right
    assert comp.verdict == "explained" and comp.missing == [], (comp.verdict, comp.missing)
    assert comp.after.physical["tau"] == pytest.approx(F.BASE.tau, rel=0.05)
    assert abs(math.remainder(comp.after.physical["beta"] - F.BASE.beta, 2 * math.pi)) < 0.05
    assert comp.after.physical["c"] == pytest.approx(F.BASE.c, rel=0.05)
    assert any("slow-roll vector subtracted" in n for n in comp.notes)


def test_healthy_rotor_has_no_runout():
    meas = F.healthy(3, **F.FAST)
    r = slow_roll_vector(meas, SPEED)
    assert abs(r) < 0.05 * 0.015  # within the noise, far below any real runout
    d = diagnose(meas, model=F.BASE.model, ip=F.BASE.ip, slow_roll=SPEED)
    assert d.verdict == "explained" and d.missing == []


@pytest.mark.parametrize("speed, match", [(0.3, "revolutions"), (-1.0, "positive"), (float("nan"), "positive")])
def test_bad_slow_roll_band(speed, match):
    with pytest.raises(ValueError, match=match):
        slow_roll_vector(_runout(1), speed)


def test_cli_slow_roll(tmp_path):
    path = tmp_path / "runout.csv"
    _runout(1).to_file(path)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["diagnose", str(path), "--ip", "0.3", "--slow-roll", str(SPEED), "--json"]) == 0
    out = json.loads(buf.getvalue())
    assert out["missing"] == [] and out["verdict"] == "explained"
    assert any("slow-roll" in n for n in out["notes"])
