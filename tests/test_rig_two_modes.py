"""A rig record through two modes (rotor_env.diagnosis.from_rig): where the one-mode waveforms do
not explain the record, a second mode in the waveforms' model (rotor_env.diagnosis.second_mode);
where that is not taken and the 1X vectors add another mode, the waveforms are diagnosed without
that mode's fitted 1X response, on the first mode's band.  Known truth:
two modal responses simulated apart and added (a linear rotor with proportional damping is
the sum of its modes)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rotor_env.measurements.rig import SPEED_UNITS, load_rig
from rotor_env.measurements.waveforms import WaveformError, load_waveforms
from rotor_env.params import RotorParams
from rotor_env.rig_simulation import simulate_rig

MODES = ((1650.0, 0.04, 0.005, 0.6), (2700.0, 0.05, 0.004, 2.0))  # natural rpm, c = 2 zeta, tau, beta
NOISE_UM = 0.5


def _runs(rig):
    out = []
    for natural, c, tau, beta in MODES:
        p = RotorParams(ip=0.0, values={"c": c, "tau": tau, "beta": beta},
                        effects=("stiffness", "viscous_damping", "unbalance"))
        out.append(simulate_rig(rig, p, natural_rpm=natural, rpm_from=300.0, rpm_to=3600.0, rpm_per_s=400.0,
                                sample_rate=2500.0).file_columns())
    return out


@pytest.fixture(scope="module")
def two_modes(tmp_path_factory):
    import pyarrow as pa
    import pyarrow.parquet as pq

    folder = tmp_path_factory.mktemp("two_modes")
    (folder / "rig.yaml").write_text("keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n")
    rig = load_rig(folder / "rig.yaml")
    first, second = _runs(rig)
    rng = np.random.default_rng(0)
    cols = dict(first)
    for n in ("x", "y"):
        cols[n] = first[n] + second[n] + rng.normal(0.0, NOISE_UM, len(first[n]))
    pq.write_table(pa.table(cols), folder / "run.parquet")
    only_second = {**second, "kp": first["kp"]}
    pq.write_table(pa.table(only_second), folder / "second.parquet")
    pq.write_table(pa.table(first), folder / "first.parquet")
    return (load_waveforms(folder / "run.parquet", rig), load_waveforms(folder / "second.parquet", rig),
            load_waveforms(folder / "first.parquet", rig))


def test_the_second_modes_1x_is_what_the_vectors_fit_of_it(two_modes):
    """extra_mode_vectors: the 1X vectors' added mode at every revolution, against the second
    mode simulated alone and order-tracked the same way (within 2 % of its peak)."""
    from rotor_env.diagnosis.from_vectors import diagnose_vectors
    from rotor_env.diagnosis.synchronous import SECOND_MODE, extra_mode_vectors

    record, second, _ = two_modes
    vd = diagnose_vectors(record.vectors((1,)), ip=0.0)
    assert SECOND_MODE in vd.missing
    extra = extra_mode_vectors(vd.after)
    truth = second.vectors((1,))
    assert np.allclose(truth.speed, vd.after.table.speed)
    peak = float(np.max(np.abs(truth.vectors[1])))
    assert float(np.max(np.abs(extra - truth.vectors[1]))) < 0.02 * peak
    assert extra_mode_vectors(diagnose_vectors(second.vectors((1,)), ip=0.0).after) is None


def test_the_two_modes_roles_exchanged_hold_the_other_mode(two_modes):
    """exchanged_modes: the same 1X fit with the rotor model on the other mode.  Its own
    critical is the vectors' added one and the other way round (each within 0.5 %), it fits
    the vectors as well (within 1 %), and the mode it now adds is the one the first fit held,
    simulated alone and order-tracked the same way (within 2 % of its peak at every
    revolution)."""
    from rotor_env.diagnosis.from_rig import exchanged_modes, one_mode_band
    from rotor_env.diagnosis.from_vectors import diagnose_vectors
    from rotor_env.diagnosis.synchronous import extra_mode_vectors

    record, second, first = two_modes
    fit = diagnose_vectors(record.vectors((1,)), ip=0.0).after
    swapped = exchanged_modes(fit)
    assert swapped is not None
    own, extra = fit.rotor_criticals[0]["rpm"], fit.extra_criticals[0]["rpm"]
    assert swapped.rotor_criticals[0]["rpm"] == pytest.approx(extra, rel=5e-3)
    assert swapped.extra_criticals[0]["rpm"] == pytest.approx(own, rel=5e-3)
    assert swapped.rms <= 1.01 * fit.rms
    # exchanged, the mode taken away is the one the vectors' model held: the lower one
    # (simulated alone as ``first``) where it held the lower, else the higher
    lower_is_own = own < extra
    truth = (first if lower_is_own else second).vectors((1,))
    peak = float(np.max(np.abs(truth.vectors[1])))
    assert float(np.max(np.abs(extra_mode_vectors(swapped) - truth.vectors[1]))) < 0.02 * peak
    # the band reaches from the model's own critical to the geometric mean with the other
    # mode's natural frequency, on the side where that mode is
    lo, hi = one_mode_band(swapped)
    mean = math.sqrt(swapped.rotor_criticals[0]["rpm"] * swapped.extra_modes[0][0] / SPEED_UNITS["rpm"])
    assert (lo, hi) == pytest.approx((mean, math.inf) if lower_is_own else (0.0, mean), rel=1e-9)
    # a fit without an added mode has nothing to exchange
    assert exchanged_modes(diagnose_vectors(first.vectors((1,)), ip=0.0).after) is None


def test_a_1x_taken_away_leaves_no_1x(two_modes):
    """RigRecord.minus_1x: a mode's record less its own 1X vectors (``lead``, cubic between the
    revolutions) keeps under 0.2 % of the peak 1X away from its resonance (0.14 % measured,
    where the ring-down after the peak ends), and under 2 % through it (3 half-power widths
    either side, 1.3 % measured: the vector turns within a revolution, and the mode rings at
    its own frequency -- why the diagnosis leaves that band out); a straight line between
    the revolutions left 2 % of a 46 um mode at 0.5 um noise.  A plain sign or convention
    error would leave twice the 1X."""
    _, second, _ = two_modes
    tab = second.vectors((1,))
    less = second.minus_1x(tab.t, {n: tab.vectors[1][:, j] for j, n in enumerate(tab.probes)}, "1X taken away")
    left = np.abs(less.vectors((1,)).vectors[1])
    peak = float(np.max(np.abs(tab.vectors[1])))
    natural, c = MODES[1][0], MODES[1][1]
    near = np.abs(tab.speed / SPEED_UNITS["rpm"] - natural) < 3 * c * natural
    assert near.sum() > 10 and (~near).sum() > 100
    assert np.max(left[~near]) < 0.002 * peak
    assert np.max(left[near]) < 0.02 * peak
    assert less.notes[-1] == "1X taken away"


def test_a_speed_band_is_one_stretch_of_the_record(two_modes):
    record, _, _ = two_modes
    part = record.between_rpm(1000.0, 2000.0)
    assert 1000.0 <= part.rpm.min() and part.rpm.max() <= 2000.0
    assert np.all(np.diff(part.t) > 0) and len(part.t) > 0.25 * len(record.t)
    assert record.between_rpm(0.0, 1e6) is record
    with pytest.raises(WaveformError, match="no sample between 5000 and 6000 rpm"):
        record.between_rpm(5000.0, 6000.0)


def test_a_record_through_two_modes_is_one_rotor_with_two_modes(two_modes):
    """The one-mode waveform model cannot hold the record; with a second mode in the waveforms'
    model (:mod:`rotor_env.diagnosis.second_mode`: the record is two independent modes, that
    model exactly) the whole record is at the floor, the verdict names the second mode and no
    fault, and the second mode's natural frequency (within 1 %) and damping ratio (within 10 %)
    are the simulated one's, each inside its 95 % interval's reach; nothing is subtracted and
    the whole run is fitted.  A small library (two candidates) keeps the first, failing search
    short."""
    from rotor_env.diagnosis.from_rig import diagnose_rig

    record, _, _ = two_modes
    d = diagnose_rig(record, candidates=("asymmetry", "shaft_bow"))
    out = d.to_dict()
    assert out["verdict"] == "explained_after_adding" and out["missing"] == ["second_mode"], out["missing"]
    assert out["rms_ratio_after"] < 1.1 and out["second_mode_subtracted"] is False
    assert out["waveform_band_rpm"] is None and d.fitted is None
    natural, c = MODES[1][0], MODES[1][1]
    got = out["second_mode"]
    assert got["natural_frequency_rpm"] == pytest.approx(natural, rel=0.01)
    assert abs(got["natural_frequency_rpm"] - natural) < 2.0 * got["natural_frequency_rpm_ci95"] + 1.0
    assert got["damping_ratio"] == pytest.approx(c / 2, rel=0.1)
    assert got["one_mode_residual_over_floor"] > 2.0
    assert "the waveforms' model holds a second mode of the rotor and its supports" in d.summary()


def _no_modelled_mode(monkeypatch):
    """The older reading, where the waveforms' second mode is not taken: without the vectors'
    second mode's 1X, on the first mode's band."""
    from rotor_env.diagnosis import from_rig

    monkeypatch.setattr(from_rig, "_second_mode", lambda *a, **k: (None, "a second mode in the waveforms' model: "
                                                                     "not tried (test)"))


def test_a_record_through_two_modes_is_explained_without_the_second(two_modes, monkeypatch):
    """Where the waveforms' own second mode is not taken: the vectors find the second mode
    (criticals within 1 %); without its 1X, on the first mode's band (up to the geometric mean
    of the criticals), the record is at the floor and the verdict names the second mode and no
    fault."""
    from rotor_env.diagnosis.from_rig import diagnose_rig

    _no_modelled_mode(monkeypatch)
    record, _, _ = two_modes
    d = diagnose_rig(record, candidates=("asymmetry", "shaft_bow"))
    out = d.to_dict()
    rpms = [c["rpm"] for c in out["criticals"]]
    assert len(rpms) == 2
    for got, (natural, c, _, _) in zip(rpms, MODES, strict=True):
        assert got == pytest.approx(natural * math.sqrt(1 - (c / 2) ** 2), rel=0.01)
    assert out["second_mode_subtracted"] is True
    assert out["verdict"] == "explained_after_adding" and out["missing"] == ["second_mode"], out["missing"]
    assert out["rms_ratio_after"] < 1.1
    lo, hi = out["waveform_band_rpm"]
    assert lo == 0.0 and hi == pytest.approx(math.sqrt(rpms[0] * rpms[1]), rel=0.01)
    assert d.fitted is not None and d.fitted.rpm.max() <= hi
    assert "another mode of the rotor and its supports (critical 2" in d.summary()
    # the change test's break is read on the part fitted, in the file's seconds
    assert out["change"]["t_s"] >= float(d.fitted.t[0]) and out["change"]["rpm"] <= hi


@pytest.mark.parametrize("modelled", [True, False])
def test_two_modes_are_preferred_to_two_rotors(two_modes, monkeypatch, modelled):
    """A record the one-mode model explains only as two rotors either side of a break (here
    the first diagnosis is made to say so: its parts explained) is diagnosed with a second mode
    in the waveforms' model -- or, where that is not taken, without the 1X vectors' other mode;
    one constant rotor with two modes explains it, and is taken, with a note saying what the
    first reading was."""
    from types import SimpleNamespace

    from rotor_env.diagnosis import from_rig

    if not modelled:
        _no_modelled_mode(monkeypatch)
    real = from_rig.RigDiagnosis.changed_parts

    def changed_parts(self):
        # the first, one-mode diagnosis: two rotors, each side explained
        two = self.second_mode or self.modelled_mode_from is not None
        return SimpleNamespace(explained=True, appeared=[]) if not two else real.fget(self)

    monkeypatch.setattr(from_rig.RigDiagnosis, "changed_parts", property(changed_parts))
    record, _, _ = two_modes
    d = from_rig.diagnose_rig(record, candidates=("asymmetry",))
    assert (d.modelled_mode is not None if modelled else d.second_mode) and d.missing == ["second_mode"], d.missing
    assert d.diagnosis.rms_ratio_after < 1.05
    assert any("only as two rotors" in n for n in d.record.notes)
