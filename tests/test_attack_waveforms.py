"""Issue 22, items 3 and 7 (raw waveforms with a rig file): implausible magnitudes and units
are refused with the file, line and column, not diagnosed into criticals at 1.65 rpm or
88 m orbits; a slow roll over the whole run is refused."""

from __future__ import annotations

import numpy as np
import pytest

from rotor_env.measurements.rig import load_rig
from rotor_env.measurements.waveforms import WaveformError, load_waveforms
from rotor_env.params import RotorParams
from rotor_env.rig_simulation import simulate_rig

ONE_PLANE = "keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A simulated run-up 600-2400 rpm through a 1650 rpm critical (um, s)."""
    folder = tmp_path_factory.mktemp("wave")
    (folder / "rig.yaml").write_text(ONE_PLANE)
    rig = load_rig(folder / "rig.yaml")
    params = RotorParams(ip=0.0, values={"c": 0.04, "tau": 0.005},
                         effects=("stiffness", "viscous_damping", "unbalance"))
    sim = simulate_rig(rig, params, natural_rpm=1650.0, rpm_from=600.0, rpm_to=2400.0, rpm_per_s=400.0,
                       noise=0.3, seed=2, sample_rate=1500.0)
    return folder, sim.file_columns()


def _write(folder, cols, name="run.csv", **change):
    cols = {k: change.get(k, v) for k, v in cols.items()}
    names = list(cols)
    path = folder / name
    np.savetxt(path, np.column_stack([cols[n] for n in names]), delimiter=",", header=",".join(names),
               comments="", fmt="%.10g")
    return path


def _rig(folder, text, name="r.yaml"):
    (folder / name).write_text(text)
    return load_rig(folder / name)


def test_the_plain_run_loads(run):
    folder, cols = run
    rec = load_waveforms(_write(folder, cols), _rig(folder, ONE_PLANE))
    assert 2300 < float(rec.rpm.max()) < 2500


@pytest.mark.parametrize(("case", "says"), [
    ("um_as_m", "beyond a displacement probe's range"),  # 88 m orbits before
    ("one_sample_1e200", "beyond a displacement probe's range"),  # a hang before
    ("all_probes_1e300", "beyond a displacement probe's range"),  # a hang before
    ("time_in_ms", "units.time"),  # criticals at 1.65 rpm before
    ("time_in_us", "units.time"),
    ("rig_ms_data_s", "units.time"),  # 1.65 M rpm before
    ("slow_roll_above_run", "slow_roll_rpm"),  # shaft_bow instead of the crack before
])
def test_implausible_waveforms_are_refused(run, case, says):
    folder, cols = run
    rig_text, change = ONE_PLANE, {}
    if case == "um_as_m":
        rig_text = ONE_PLANE.replace("um", "m")
    elif case == "one_sample_1e200":
        x = cols["x"].copy()
        x[1234] = 1e200
        change = {"x": x}
    elif case == "all_probes_1e300":
        change = {"x": cols["x"] * 1e300, "y": cols["y"] * 1e300}
    elif case in ("time_in_ms", "time_in_us"):
        change = {"t": cols["t"] * (1e3 if case == "time_in_ms" else 1e6)}
    elif case == "rig_ms_data_s":
        rig_text = ONE_PLANE.replace("{displacement: um}", "{displacement: um, time: ms}")
    else:
        rig_text = ONE_PLANE + "slow_roll_rpm: 5000\n"
    path = _write(folder, cols, name=f"{case}.csv", **change)
    with pytest.raises(WaveformError) as exc:
        load_waveforms(path, _rig(folder, rig_text, name=f"{case}.yaml"))
    assert str(path) in str(exc.value) and says in str(exc.value)
    if case == "one_sample_1e200":
        assert "line 1236" in str(exc.value)


def _drop_pulses(kp: np.ndarray, which: slice) -> np.ndarray:
    """The keyphasor signal with the pulses ``which`` (of all its pulses) taken out."""
    kp = kp.copy()
    pulse = kp < 0.5 * (kp.min() + kp.max())  # the simulated rig's notch: a brief dip
    if pulse.mean() > 0.5:
        pulse = ~pulse
    starts = np.flatnonzero(~pulse[:-1] & pulse[1:]) + 1
    ends = np.flatnonzero(pulse[:-1] & ~pulse[1:]) + 1
    base = float(np.median(kp[~pulse]))
    for s in starts[which]:
        later = ends[ends > s]
        kp[s : later[0] if later.size else len(kp)] = base
    return kp


@pytest.mark.parametrize(("which", "says"), [
    (slice(1, None, 2), "vibrate at twice the keyphasor's rate"),  # 1214 rpm top, criticals halved before
    (slice(56, None, 2), "every other pulse missing"),  # from pulse 56 on: a step the neighbours half saw
])
def test_every_other_keyphasor_pulse_missing_is_refused(run, which, says):
    """Item 7: a regular train at half the shaft's rate was read as a rotor at half the speed."""
    folder, cols = run
    path = _write(folder, cols, name="half_pulses.csv", kp=_drop_pulses(cols["kp"], which))
    with pytest.raises(WaveformError) as exc:
        load_waveforms(path, _rig(folder, ONE_PLANE))
    message = str(exc.value)
    assert str(path) in message and "column 'kp'" in message and says in message and "line" in message


def test_the_streaming_tracker_refuses_a_step_to_half_the_pulse_rate(run):
    """The monitor's keyphasor (chunk by chunk) runs the same check: the samples before the
    step go out, the error names the line where the rate halves."""
    from rotor_env.measurements.keyphasor import KeyphasorError, KeyphasorTracker

    _, cols = run
    kp = _drop_pulses(cols["kp"], slice(56, None, 2))
    tracker = KeyphasorTracker(where="kp")
    handed_out = 0
    lines = np.arange(len(kp)) + 2
    with pytest.raises(KeyphasorError, match="every other pulse missing") as exc:
        for lo in range(0, len(kp), 1000):
            sl = slice(lo, lo + 1000)
            handed_out += len(tracker.push(cols["t"][sl], kp[sl], cols["x"][sl], lines[sl])[0])
        handed_out += len(tracker.finish()[0])
    assert exc.value.line is not None and handed_out > 0
    t_line = cols["t"][exc.value.line - 2]  # the step is near pulse 56 of ~113 in a 4.5 s run
    assert 1.5 < t_line < 3.5


def test_a_duplicated_probe_column_is_refused(run):
    """Item 7: two columns named x: the last was read silently (the crack's probe missed)."""
    folder, cols = run
    path = _write(folder, cols, name="dup.csv")
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0] + ",x", *(f"{r},{r.split(',')[2]}" for r in lines[1:])]) + "\n")
    with pytest.raises(WaveformError, match=r"dup\.csv: column\(s\) \['x'\] appear more than once"):
        load_waveforms(path, _rig(folder, ONE_PLANE))


def test_the_monitor_refuses_a_keyphasor_at_half_the_shaft_rate(run):
    """The rig stream (``rotor-id monitor --rig``) runs the half-rate check on the revolutions
    its DC gap is learned from; the same run with all its pulses streams through."""
    from rotor_env.measurements.files import MeasurementError
    from rotor_env.measurements.rig_stream import RigStream

    folder, cols = run
    rig = _rig(folder, ONE_PLANE)
    good = _write(folder, cols, name="stream_good.csv")
    assert sum(chunk.shape[0] for chunk in RigStream(good, rig, 1650.0)) > 1000
    half = _write(folder, cols, name="stream_half.csv", kp=_drop_pulses(cols["kp"], slice(1, None, 2)))
    with pytest.raises(MeasurementError, match="vibrate at twice the keyphasor's rate") as exc:
        for _ in RigStream(half, rig, 1650.0):
            pass
    assert str(half) in str(exc.value) and exc.value.line is not None
