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
    ("time_in_ms", "units.time"),  # criticals at 1.65 rpm before
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
    elif case == "time_in_ms":
        change = {"t": cols["t"] * 1000.0}
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
