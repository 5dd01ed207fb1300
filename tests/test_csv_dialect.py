"""CSV files as acquisition and spreadsheet software write them: commas, semicolons or tabs
between the fields, and with semicolons or tabs a decimal comma (a European locale).  Each is
read as the plain comma file it stands for (:func:`rotor_env.measurements.files.csv_dialect`)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from rotor_env.balance import stack_tables
from rotor_env.measurements.files import CsvDialect, MeasurementError, csv_dialect, read_table
from rotor_env.measurements.rig import load_rig
from rotor_env.measurements.vectors import load_vector_table
from rotor_env.measurements.waveforms import load_waveforms
from rotor_env.params import RotorParams

#: (delimiter, decimal) of the exports tried
DIALECTS = [(",", "."), (";", "."), (";", ","), ("\t", "."), ("\t", ",")]


def _rewrite(src, dst, delimiter: str, decimal: str, *, bom: bool = False, blank_line: bool = False) -> None:
    """``src`` (a plain CSV) in another dialect; ``blank_line``: one empty line in the middle (the
    careful line-by-line reader then reads it, not the fast one)."""
    with open(src, newline="") as fh:
        rows = list(csv.reader(fh))
    with open(dst, "w", newline="", encoding="utf-8-sig" if bom else "utf-8") as fh:
        w = csv.writer(fh, delimiter=delimiter)
        for i, r in enumerate(rows):
            if blank_line and i == len(rows) // 2:
                fh.write("\r\n")
            w.writerow(r if i == 0 or decimal == "." else [c.replace(".", ",") for c in r])


@pytest.fixture(scope="module")
def record(tmp_path_factory, rig_records):
    """A short rig record (probes in um, keyphasor) and its 1X table, as plain CSV."""
    folder = tmp_path_factory.mktemp("dialect")
    rig, cols, run = rig_records.one_plane_run(folder, rpm=(600.0, 2400.0), rpm_per_s=600.0, seed=3,
                                               sample_rate=2500.0)
    rig_records.write_csv(folder / "run.csv", cols)
    run.vectors(rig, (1,)).to_csv(folder / "table.csv")
    return folder, rig


@pytest.mark.parametrize(("delimiter", "decimal"), DIALECTS)
def test_the_dialect_is_read_off_the_first_lines(record, delimiter, decimal):
    folder, _ = record
    path = folder / f"d{ord(delimiter)}{ord(decimal)}.csv"
    _rewrite(folder / "run.csv", path, delimiter, decimal, bom=True)
    assert csv_dialect(path) == CsvDialect(delimiter, decimal)


@pytest.mark.parametrize(("delimiter", "decimal"), DIALECTS)
@pytest.mark.parametrize("blank_line", [False, True])
def test_every_dialect_reads_the_same_numbers(record, delimiter, decimal, blank_line):
    folder, rig = record
    head0, data0, _ = read_table(folder / "run.csv")
    path = folder / f"r{ord(delimiter)}{ord(decimal)}{int(blank_line)}.csv"
    _rewrite(folder / "run.csv", path, delimiter, decimal, blank_line=blank_line)
    head, data, lines = read_table(path)
    assert head == head0
    np.testing.assert_array_equal(data, data0)  # the same text, the same doubles
    # file lines as errors name them: the header is line 1, a blank line counts
    assert lines[-1] == len(data) + 1 + int(blank_line)
    rec0, rec = load_waveforms(folder / "run.csv", rig), load_waveforms(path, rig)
    np.testing.assert_array_equal(rec.u, rec0.u)
    np.testing.assert_array_equal(rec.phi, rec0.phi)


@pytest.mark.parametrize(("delimiter", "decimal"), [(";", ","), ("\t", ".")])
def test_tables_and_balancing_stacks_read_every_dialect(record, tmp_path, delimiter, decimal):
    folder, _ = record
    path = tmp_path / "table.csv"
    _rewrite(folder / "table.csv", path, delimiter, decimal)
    t0 = load_vector_table(folder / "table.csv", angles={"x": 45.0, "y": -45.0})
    t1 = load_vector_table(path, angles={"x": 45.0, "y": -45.0})
    np.testing.assert_array_equal(t1.vectors[1], t0.vectors[1])
    np.testing.assert_array_equal(t1.speed, t0.speed)
    # a campaign joined from one plain and one European file: plain CSV out, every number read
    out = stack_tables(tmp_path / "stacked.csv", {"ref": folder / "table.csv", "T1": path})
    runs = load_vector_table(out, run_column="run")
    n = len(t0.speed)
    np.testing.assert_array_equal(runs.vectors[1][n:], runs.vectors[1][:n])
    assert runs.runs == ("ref",) * n + ("T1",) * n


def test_a_decimal_comma_the_first_lines_do_not_show_is_named(tmp_path):
    path = tmp_path / "late.csv"
    rows = [f"{i};0;0;0" for i in range(40)] + ["40;0;4,5;2"]
    path.write_text("t;kp;x;y\n" + "\n".join(rows) + "\n")
    with pytest.raises(MeasurementError, match=r"late.csv, line 42, column 'x': '4,5' is not a number \(a decimal "
                                                r"comma where the file's first lines write none"):
        read_table(path)
    # a comma file keeps its commas as separators: a point-decimal file is untouched
    plain = tmp_path / "plain.csv"
    plain.write_text("t,x\n0,1.5\n1,2.5\n")
    assert csv_dialect(plain) == CsvDialect(",", ".")
    assert read_table(plain)[1].tolist() == [[0.0, 1.5], [1.0, 2.5]]


@pytest.mark.parametrize(("delimiter", "decimal"), [(";", ","), ("\t", ".")])
def test_the_stream_reader_reads_every_dialect(tmp_path, delimiter, decimal):
    """The monitor's reader (blocks of bytes, a file being appended) gives the same samples."""
    from rotor_env.measurements.stream import StreamReader
    from rotor_env.simulator import simulate

    run = simulate(RotorParams(), t_end=30.0, dt=0.01)
    plain = tmp_path / "plain.csv"
    data = np.column_stack([run[c] for c in ("t", "phi", "theta_x", "theta_y")])
    np.savetxt(plain, data, delimiter=",", header="t,phi,theta_x,theta_y", comments="", fmt="%.12g")
    other = tmp_path / "other.csv"
    _rewrite(plain, other, delimiter, decimal)
    a = np.concatenate(list(StreamReader(plain, chunk_bytes=4096)))
    b = np.concatenate(list(StreamReader(other, chunk_bytes=4096)))
    np.testing.assert_array_equal(a, b)
    assert a.shape == (len(data), 10)


@pytest.mark.parametrize(("fs", "decimals"), [(51200.0, 6), (25600.0, 6), (12800.0, 5)])
def test_times_written_with_too_few_decimals_are_the_grid_they_were_rounded_from(tmp_path, rig_records, fs,
                                                                                decimals):
    """Acquisition software and spreadsheets write the time column to a fixed number of
    decimals: at 51.2 kHz to the microsecond the steps read 19 and 20 us.  Read back as the
    uniform grid with a note; a missing sample is still refused."""
    from rotor_env.measurements.waveforms import WaveformError

    (tmp_path / "rig.yaml").write_text(rig_records.ONE_PLANE)
    rig = load_rig(tmp_path / "rig.yaml")
    n = 20000
    t = np.arange(n) / fs
    phi = 2 * np.pi * 25.0 * t + np.pi * 10.0 * t * t
    kp = np.where((phi / (2 * np.pi)) % 1.0 < 0.03, -5.0, 0.0)
    x, y = 50.0 * np.cos(phi), 50.0 * np.sin(phi)
    rows = [f"{ti:.{decimals}f},{k:g},{a:.6f},{b:.6f}" for ti, k, a, b in zip(t, kp, x, y, strict=True)]
    path = tmp_path / "run.csv"
    path.write_text("t,kp,x,y\n" + "\n".join(rows) + "\n")
    rec = load_waveforms(path, rig)
    first = int(np.searchsorted(t, rec.t[0] - 0.5 / fs))
    # the least-squares line through the rounded times: uniform, within a thousandth of the
    # resolution of the times they were rounded from
    np.testing.assert_allclose(rec.t, t[first:first + len(rec.t)], rtol=0, atol=1e-3 * 10.0 ** -decimals)
    assert np.ptp(np.diff(rec.t)) < 1e-9 / fs
    assert any(f"the times are written to {10.0 ** -decimals:g} s" in m for m in rec.notes), rec.notes
    # one sample missing: a gap the rounding cannot explain
    path.write_text("t,kp,x,y\n" + "\n".join(rows[:5000] + rows[5001:]) + "\n")
    with pytest.raises(WaveformError, match="non-uniform sampling"):
        load_waveforms(path, rig)


def test_columns_the_rig_does_not_name_may_hold_text(record, tmp_path):
    """An acquisition's export carries a timestamp, a note, a channel the rig file does not name:
    read as nothing (CSV, Parquet, the monitor's stream); a column the rig names must still hold
    numbers."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from rotor_env.measurements.rig_stream import RigStream
    from rotor_env.measurements.waveforms import WaveformError

    folder, rig = record
    head, data, _ = read_table(folder / "run.csv")
    stamp = [f"2026-11-29 10:00:{i / 2500:09.6f}" for i in range(len(data))]
    with open(tmp_path / "extra.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["timestamp", *head, "note", "temperature_C"])
        for i, row in enumerate(data):
            w.writerow([stamp[i], *(repr(float(v)) for v in row), "" if i % 50 else "marker", "25.5"])
    cols = {h: data[:, j] for j, h in enumerate(head)}
    pq.write_table(pa.table({"timestamp": stamp, **cols, "note": ["x"] * len(data)}), tmp_path / "extra.parquet")
    plain = load_waveforms(folder / "run.csv", rig)
    for path in (tmp_path / "extra.csv", tmp_path / "extra.parquet"):
        rec = load_waveforms(path, rig)
        np.testing.assert_array_equal(rec.u, plain.u)
        np.testing.assert_array_equal(rec.phi, plain.phi)
    streamed = sum(len(c) for c in RigStream(tmp_path / "extra.csv", rig, 1650.0, chunk_bytes=1 << 14))
    assert streamed == sum(len(c) for c in RigStream(folder / "run.csv", rig, 1650.0, chunk_bytes=1 << 14)) > 0
    text = (tmp_path / "extra.csv").read_text().splitlines()
    row = text[10].split(",")
    row[head.index("x") + 1] = "n/a"
    text[10] = ",".join(row)
    (tmp_path / "bad.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(WaveformError, match=r"bad\.csv, line 11, column 'x': 'n/a' is not a number"):
        load_waveforms(tmp_path / "bad.csv", rig)
    # the same for an order-tracked table
    t_head, t_data, _ = read_table(folder / "table.csv")
    with open(tmp_path / "table_extra.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["timestamp", *t_head, "note"])
        w.writerows([["2026-11-29 10:00", *(repr(float(v)) for v in r), "ok"] for r in t_data])
    angles = {"x": 45.0, "y": -45.0}
    np.testing.assert_array_equal(load_vector_table(tmp_path / "table_extra.csv", angles=angles).vectors[1],
                                  load_vector_table(folder / "table.csv", angles=angles).vectors[1])
