"""The spin angle's unwrapping, one rule for the batch reader and the stream (issue 23).

:class:`~rotor_env.measurements.files.PhiUnwrapper`: a sampled spin angle never moves more
than pi between samples, so jumps beyond pi within one turn's span are wraps (undone as
:func:`numpy.unwrap` does, whatever the chunks), beyond a turn's span they are refused
(degrees, or an aliased angle) with the line and the column named.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rotor_env.measurements.files import MeasurementError, PhiUnwrapper, load_measurements
from rotor_env.measurements.stream import StreamReader

TWO_PI = 2 * math.pi


def _ramp(n: int = 5000, seed: int = 0) -> np.ndarray:
    """A spin angle over many turns, every step below pi (speeding up and slowing down)."""
    rng = np.random.default_rng(seed)
    return 0.4 + np.concatenate([[0.0], np.cumsum(rng.uniform(0.0, 3.0, n - 1))])


def _cuts(n: int, rng) -> list[slice]:
    edges = np.unique(np.concatenate([[0, n], rng.integers(1, n, size=rng.integers(1, 40))]))
    return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


@pytest.mark.parametrize("wrap", ["[0, 2pi)", "(-pi, pi]"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_chunks_unwrap_as_numpy_does(wrap, seed):
    true = _ramp(seed=seed)
    wrapped = np.mod(true, TWO_PI) if wrap == "[0, 2pi)" else np.angle(np.exp(1j * true))
    lines = np.arange(2, len(true) + 2)
    one = PhiUnwrapper("ramp.csv")
    whole = one.push(wrapped, lines)
    assert one.unwrapped
    np.testing.assert_allclose(whole, np.unwrap(wrapped), rtol=0, atol=1e-9)
    offset = whole - true
    np.testing.assert_allclose(offset, offset[0], rtol=0, atol=1e-9)
    assert abs(math.remainder(offset[0], TWO_PI)) < 1e-9
    rng = np.random.default_rng(100 + seed)
    for _ in range(5):
        chunked = PhiUnwrapper("ramp.csv")
        got = np.concatenate([chunked.push(wrapped[s], lines[s]) for s in _cuts(len(true), rng)])
        np.testing.assert_array_equal(got, whole)  # whole turns added: the cut does not matter


def test_an_unwrapped_angle_is_left_as_it_is():
    true = _ramp()
    unwrapper = PhiUnwrapper("ok.csv")
    np.testing.assert_array_equal(np.concatenate([unwrapper.push(true[:100]), unwrapper.push(true[100:100]),
                                                  unwrapper.push(true[100:])]), true)
    assert not unwrapper.unwrapped


def test_degrees_are_refused_with_line_and_column():
    deg = np.mod(np.degrees(0.3 + 0.02 * np.arange(2000)), 360.0)
    lines = np.arange(2, len(deg) + 2)
    first = int(np.argmax(np.abs(np.diff(deg)) > math.pi)) + 1
    with pytest.raises(MeasurementError, match=rf"^deg\.csv, line {first + 2}, column 'phi': wrapped to 360 ") as err:
        PhiUnwrapper("deg.csv").push(deg, lines)
    assert err.value.row == first
    # in chunks: refused in the chunk that holds the first jump, with the row in that chunk,
    # and the rows before it are good: pushed again, they pass
    unwrapper = PhiUnwrapper("deg.csv")
    unwrapper.push(deg[:first - 3], lines[:first - 3])
    with pytest.raises(MeasurementError, match=rf"line {first + 2}, column 'phi': wrapped to 360") as err:
        unwrapper.push(deg[first - 3:], lines[first - 3:])
    assert err.value.row == 3
    np.testing.assert_array_equal(unwrapper.push(deg[first - 3:first], lines[first - 3:first]), deg[first - 3:first])


def test_an_aliased_jump_is_refused():
    phi = _ramp()
    phi[3000:] += 2.5  # a step of up to 5.5 rad between two samples, far beyond one turn's span
    lines = np.arange(2, len(phi) + 2)
    with pytest.raises(MeasurementError, match=r"^alias\.csv, line 3002, column 'phi': jumps from \S+ to \S+ between "
                                               r"two samples \(more than half a turn: the angle is aliased") as err:
        PhiUnwrapper("alias.csv").push(phi, lines)
    assert err.value.row == 3000


def _write(path, t, phi):
    theta = 1e-3 * np.column_stack([np.cos(phi), np.sin(phi)])
    np.savetxt(path, np.column_stack([t, phi, theta]), delimiter=",", header="t,phi,theta_x,theta_y", comments="",
               fmt="%.17g")
    return path


@pytest.mark.parametrize("wrap", ["[0, 2pi)", "(-pi, pi]"])
def test_batch_and_stream_unwrap_a_file_alike(tmp_path, wrap):
    t = np.arange(4000) * 0.01
    true = 0.3 + 20.0 * t + 2.0 * t * t  # up to 1.8 rad a sample
    phi = np.mod(true, TWO_PI) if wrap == "[0, 2pi)" else np.angle(np.exp(1j * true))
    path = _write(tmp_path / "encoder.csv", t, phi)
    batch = load_measurements(path)
    assert "phi unwrapped (it was wrapped to one turn)" in batch.source
    chunks = list(StreamReader(path, chunk_bytes=4096))
    assert len(chunks) > 10
    stream = np.concatenate(chunks)
    np.testing.assert_array_equal(stream[:, 1], batch.phi)
    np.testing.assert_allclose(batch.phi, np.unwrap(phi), rtol=0, atol=1e-9)


def test_batch_and_stream_refuse_a_degrees_file_alike(tmp_path):
    t = np.arange(4000) * 0.01
    path = _write(tmp_path / "deg.csv", t, np.mod(np.degrees(0.3 + 5.0 * t), 360.0))
    with pytest.raises(MeasurementError, match=r"deg\.csv, line \d+, column 'phi': wrapped to 360") as batch:
        load_measurements(path)
    reader = StreamReader(path, chunk_bytes=4096)
    with pytest.raises(MeasurementError) as stream:
        for _ in reader:
            pass
    assert str(stream.value) == str(batch.value)
    assert reader.error_line == int(str(batch.value).split(", line ")[1].split(",")[0])
