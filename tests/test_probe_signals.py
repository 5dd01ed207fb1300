"""A probe that reads nothing, clips, or reads noise alone is refused by name (the file, the
column, the line); a healthy probe's signal -- quantised by a 12- or 16-bit converter, in volts
on a gap, with the probes' noise -- passes (``measurements.probes.check_probe_signals``)."""

from __future__ import annotations

import numpy as np
import pytest

from rotor_env.measurements.rig import load_rig
from rotor_env.measurements.waveforms import WaveformError, load_waveforms

VOLTS = "keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: V, sensitivity_mv_per_um: 7.87}\n"


@pytest.fixture(scope="module")
def record(tmp_path_factory, rig_records):
    """A cracked rotor's run-up through its critical (peak about 100 um), 0.3 um probe noise."""
    folder = tmp_path_factory.mktemp("probes")
    rig, cols, _ = rig_records.one_plane_run(folder, {"D": 0.03, "D_axis": 0.5}, rpm=(600.0, 2700.0),
                                             rpm_per_s=600.0, seed=5)
    return folder, rig, cols


def test_a_flat_channel_is_a_disconnected_probe(record, rig_records):
    folder, rig, cols = record
    path = rig_records.write_csv(folder / "dead.csv", {**cols, "y": np.zeros_like(cols["y"])})
    with pytest.raises(WaveformError, match=r"dead\.csv, column 'y': the reading is 0 um on every row: a "
                                            r"disconnected probe"):
        load_waveforms(path, rig)


def test_a_probe_reading_noise_alone_is_refused(record, rig_records):
    folder, rig, cols = record
    noise = np.random.default_rng(0).normal(0.0, 0.3, cols["y"].size)
    path = rig_records.write_csv(folder / "noise.csv", {**cols, "y": noise})
    with pytest.raises(WaveformError, match=r"noise\.csv, column 'y': its largest once-per-turn vibration is "
                                            r"[0-9.]+ um against [0-9.]+ um on 'x' of the same plane: it reads noise"):
        load_waveforms(path, rig)


@pytest.mark.parametrize(("share", "side"), [(0.6, "largest"), (0.8, "smallest")])
def test_a_clipped_orbit_is_refused_with_its_line(record, rig_records, share, side):
    folder, rig, cols = record
    peak = np.abs(cols["x"] - cols["x"].mean()).max()
    x = cols["x"].copy()
    if side == "largest":
        x = np.minimum(x, x.mean() + share * peak)
    else:
        x = np.maximum(x, x.mean() - share * peak)
    path = rig_records.write_csv(folder / f"clip_{side}.csv", {**cols, "x": x})
    with pytest.raises(WaveformError) as exc:
        load_waveforms(path, rig)
    msg = str(exc.value)
    assert "column 'x'" in msg and f"reading's {side} value" in msg and "clipped the orbit" in msg
    line = int(msg.split("line ")[1].split(",")[0])
    assert x[line - 2] == (x.max() if side == "largest" else x.min())  # the line named is a clipped sample


@pytest.mark.parametrize("bits", [12, 16])
def test_quantised_and_volt_records_pass(record, rig_records, tmp_path, bits):
    """A converter's steps (12 bits over +-10 V: 0.62 um a step at 7.87 mV/um) repeat the peak's
    value a few samples: no flat top; probes in volts on a -10 V gap read as before."""
    _, _, cols = record
    (tmp_path / "rig.yaml").write_text(VOLTS)
    rig = load_rig(tmp_path / "rig.yaml")
    step = 20.0 / 2**bits
    volts = {k: np.round((-10.0 + 7.87e-3 * cols[k]) / step) * step for k in ("x", "y")}
    path = rig_records.write_csv(tmp_path / "volts.csv", {**cols, **volts})
    rec = load_waveforms(path, rig)
    assert np.ptp(rec.u) > 0 and len(rec.t) > 1000


def test_a_table_whose_probe_reads_noise_alone_is_refused(record, rig_records, tmp_path):
    """The same rule on an order-tracked table of one plane (probe angles from the rig file)."""
    from rotor_env.measurements.vectors import VectorTableError, load_vector_table

    folder, rig, cols = record
    path = rig_records.write_csv(folder / "for_table.csv", cols)
    table = load_waveforms(path, rig).vectors((1,))
    table.to_csv(tmp_path / "table.csv")
    angles = {"x": 45.0, "y": -45.0}
    load_vector_table(tmp_path / "table.csv", angles=angles)  # healthy: read
    text = (tmp_path / "table.csv").read_text().splitlines()
    head = text[0].split(",")
    j = head.index("y_amp")
    rows = [r.split(",") for r in text[1:]]
    for r in rows:
        r[j] = repr(float(r[j]) * 1e-3)
    (tmp_path / "dead.csv").write_text("\n".join([text[0], *(",".join(r) for r in rows)]) + "\n")
    with pytest.raises(VectorTableError, match=r"dead\.csv, column 'y_amp': its largest 1X amplitude is .* it reads "
                                               r"noise alone"):
        load_vector_table(tmp_path / "dead.csv", angles=angles)


# ------------------------------------------------------------------ the monitor's stream
def _stream(path, rig, chunk_bytes=8192):
    from rotor_env.measurements.rig_stream import RigStream

    stream = RigStream(path, rig, 1650.0, chunk_bytes=chunk_bytes)
    rows = sum(len(out) for out in stream)
    return stream, rows


def test_the_stream_refuses_a_flat_channel_at_once(record, rig_records):
    """``RigStream`` (the monitor): the dead probe refused after ten revolutions, not at the
    end of the stream -- the batch reader's sentence, and the line the stream stopped at."""
    from rotor_env.measurements.files import MeasurementError
    from rotor_env.measurements.probes import FLAT_REVOLUTIONS

    folder, rig, cols = record
    path = rig_records.write_csv(folder / "dead_stream.csv", {**cols, "y": np.zeros_like(cols["y"])})
    with pytest.raises(MeasurementError, match=r"dead_stream\.csv, column 'y': the reading is 0 um on every row of "
                                               r"the first [0-9]+ revolutions: a disconnected probe") as exc:
        _stream(path, rig)
    turns = int(str(exc.value).split("the first ")[1].split(" ")[0])
    assert FLAT_REVOLUTIONS <= turns < 3 * FLAT_REVOLUTIONS


@pytest.mark.parametrize("chunk_bytes", [2048, 65536])
def test_the_stream_says_what_the_record_says(record, rig_records, chunk_bytes):
    """The clipped orbit and the probe reading noise alone: refused by the stream at its end with
    the batch reader's sentences (the same line for the clip), in small or large chunks; the
    clean record streams through."""
    from rotor_env.measurements.files import MeasurementError

    folder, rig, cols = record
    _, rows = _stream(rig_records.write_csv(folder / "clean_stream.csv", cols), rig, chunk_bytes)
    assert rows > 100
    peak = np.abs(cols["x"] - cols["x"].mean()).max()
    clipped = {**cols, "x": np.minimum(cols["x"], cols["x"].mean() + 0.6 * peak)}
    path = rig_records.write_csv(folder / "clip_stream.csv", clipped)
    with pytest.raises(WaveformError) as batch:
        load_waveforms(path, rig)
    with pytest.raises(MeasurementError) as streamed:
        _stream(path, rig, chunk_bytes)
    assert str(streamed.value) == str(batch.value)
    noise = {**cols, "y": np.random.default_rng(0).normal(0.0, 0.3, cols["y"].size)}
    path = rig_records.write_csv(folder / "noise_stream.csv", noise)
    with pytest.raises(MeasurementError, match=r"noise_stream\.csv, column 'y': its largest once-per-turn vibration "
                                               r"is [0-9.]+ um against [0-9.]+ um on 'x' of the same plane"):
        _stream(path, rig, chunk_bytes)


def test_the_stream_passes_quantised_volts(record, rig_records, tmp_path):
    """A 12-bit converter's steps, probes in volts on a -10 V gap: the stream reads them too."""
    _, _, cols = record
    (tmp_path / "rig.yaml").write_text(VOLTS)
    rig = load_rig(tmp_path / "rig.yaml")
    step = 20.0 / 2**12
    volts = {k: np.round((-10.0 + 7.87e-3 * cols[k]) / step) * step for k in ("x", "y")}
    _, rows = _stream(rig_records.write_csv(tmp_path / "volts_stream.csv", {**cols, **volts}), rig)
    assert rows > 100
