"""Plausible but wrong input (issue 11, item 3): angles as encoders and other tools write them.

* ``phi`` wrapped to [0, 2 pi) or (-pi, pi] (encoder angle) is unwrapped on load — the
  rates estimated from it are then the true ones and the crack is found, not "+ stiffness";
* ``phi`` in degrees (its rate 57.3x ``phi_dot``, or wrapped to [0, 360)) and
  inclinations in degrees (beyond 1 rad) are refused with the file, column and line;
* a correct file is untouched.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rotor_env.measurements import COLUMNS
from rotor_env.measurements.files import MeasurementError, load_measurements
from rotor_env.params import RotorParams
from rotor_env.simulator import simulate

JEFFCOTT = RotorParams().replace(D=0.03, k30=0.0, k21=0.0, k12=0.0, k03=0.0, h=0.0)


@pytest.fixture(scope="module")
def run():
    return simulate(JEFFCOTT, t_end=250.0, dt=0.02, noise=5e-4, seed=4)


def _write(path, header, cols):
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(header), comments="", fmt="%.17g")
    return path


def _angles_only(run, phi):
    return ["t", "phi", "theta_x", "theta_y"], [run.t, phi, run.theta_x, run.theta_y]


@pytest.mark.parametrize("wrap", ["[0, 2pi)", "(-pi, pi]"])
def test_wrapped_phi_is_unwrapped(tmp_path, run, wrap):
    phi = np.mod(run.phi, 2 * math.pi) if wrap == "[0, 2pi)" else np.angle(np.exp(1j * run.phi))
    header, cols = _angles_only(run, phi)
    meas = load_measurements(_write(tmp_path / "wrapped.csv", header, cols))
    assert "phi unwrapped" in meas.source
    # the same angle up to a whole number of turns, continuous
    offset = meas.phi - run.phi
    np.testing.assert_allclose(offset, offset[0], atol=1e-9)
    assert abs(math.remainder(offset[0], 2 * math.pi)) < 1e-9
    assert np.max(np.abs(np.diff(meas.phi))) < math.pi


def test_wrapped_encoder_file_gives_the_crack(tmp_path, run):
    from rotor_env.diagnosis import diagnose

    header, cols = _angles_only(run, np.mod(run.phi, 2 * math.pi))
    meas = load_measurements(_write(tmp_path / "encoder.csv", header, cols))
    d = diagnose(meas, ip=0.3)
    assert "asymmetry" in d.missing and "stiffness" not in d.missing, (d.missing, d.rejected)


def test_phi_in_degrees_is_refused(tmp_path, run):
    cols = [run.data[:, j] for j in range(len(COLUMNS))]
    cols[1] = np.degrees(run.phi)
    with pytest.raises(MeasurementError, match=r"column 'phi': its rate is 57\.\d+x column 'phi_dot' \(degrees"):
        load_measurements(_write(tmp_path / "deg.csv", list(COLUMNS), cols))


def test_wrapped_degrees_are_refused(tmp_path, run):
    header, cols = _angles_only(run, np.mod(np.degrees(run.phi), 360.0))
    with pytest.raises(MeasurementError, match=r"deg_wrapped\.csv, line \d+, column 'phi': wrapped to 360"):
        load_measurements(_write(tmp_path / "deg_wrapped.csv", header, cols))


@pytest.mark.parametrize("column", ["theta_x", "theta_y"])
def test_inclination_in_degrees_is_refused(tmp_path, run, column):
    cols = [run.data[:, j] for j in range(len(COLUMNS))]
    j = COLUMNS.index(column)
    cols[j] = np.degrees(cols[j])
    with pytest.raises(MeasurementError, match=rf"line \d+, column '{column}': value .* beyond 1 rad .*degrees\?"):
        load_measurements(_write(tmp_path / "tilt_deg.csv", list(COLUMNS), cols))


def test_a_correct_file_is_untouched(tmp_path, run):
    path = tmp_path / "ok.csv"
    run.to_file(path)
    meas = load_measurements(path)
    np.testing.assert_array_equal(meas.data, run.data)
    assert "unwrapped" not in meas.source
