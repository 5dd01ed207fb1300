"""Issue 11, items 2, 5, 6, 8, 9: nothing hangs, nothing non-finite passes silently, odd inputs
and outputs are refused with a clear message (each test failed before its fix)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from identifier import RecursiveQR
from rotor_env import cli
from rotor_env.measurements import COLUMNS, Measurements
from rotor_env.measurements.files import (
    MeasurementError,
    _parse_csv,
    _read_csv_arrow,
    load_measurements,
    read_table,
)
from rotor_env.params import RotorParams
from rotor_env.simulator import SimulationTooLarge, free_run, simulate

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def run():
    return simulate(RotorParams(), t_end=200.0, dt=0.05, noise=5e-4, seed=3)


def _write_csv(path: Path, header, data, fmt="%.17g") -> Path:
    np.savetxt(path, data, delimiter=",", header=",".join(header), comments="", fmt=fmt)
    return path


def _error(path) -> str:
    with pytest.raises(MeasurementError) as exc:
        load_measurements(path)
    return str(exc.value)


# ------------------------------------------------------------------ item 2: hangs
def test_time_in_microseconds_beside_model_rates_is_refused(tmp_path, run):
    data = run.data.copy()
    data[:, 0] *= 1e6
    data[:, 2] *= 1e-6  # phi_dot and phi_ddot follow t: only the inclination rates are per model time
    data[:, 3] *= 1e-12
    msg = _error(_write_csv(tmp_path / "us.csv", COLUMNS, data))
    assert "column 'theta_x_dot': the rate of column 'theta_x' over 't' is " in msg and "time unit" in msg
    ratio = float(msg.split(" over 't' is ")[1].split("x")[0])
    assert ratio == pytest.approx(1e-6, rel=0.05)


def test_parquet_timestamp_time_column_is_refused(tmp_path, run):
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = {c: run.data[:, j] for j, c in enumerate(COLUMNS)}
    cols["t"] = pa.array((run.t * 1e9).astype("int64"), type=pa.timestamp("ns"))
    path = tmp_path / "ts.parquet"
    pq.write_table(pa.table(cols), path)
    msg = _error(path)
    assert str(path) in msg and "column 't'" in msg and "timestamp[ns]" in msg and "number" in msg


def test_fit_of_a_record_in_microseconds_is_refused_not_run_for_hours(tmp_path, run, capsys):
    data = run.data[:, [0, 1, 4, 5]].copy()
    data[:, 0] *= 1e6  # angles only: the rates come out per microsecond, consistently
    path = _write_csv(tmp_path / "us.csv", ["t", "phi", "theta_x", "theta_y"], data)
    start = time.perf_counter()
    code = cli.main(["fit", str(path), "--model", "unbalance,viscous_damping"])
    err = capsys.readouterr().err
    assert code == 2 and time.perf_counter() - start < 60
    assert "integration steps" in err and "microseconds" in err and "Traceback" not in err


def test_free_run_bound(run):
    t = run.t * 1e4  # 1e6 sub-steps a sample
    with pytest.raises(SimulationTooLarge, match=r"more than the 1e\+08 allowed"):
        free_run(RotorParams(), t, run.phi, run.phi_dot / 1e4, (0.0, 0.0, 0.0, 0.0))


def test_free_run_in_chunks_equals_one_call(run, monkeypatch):
    import rotor_env.simulator as sim

    ref = free_run(RotorParams(), run.t, run.phi, run.phi_dot, (0.0, 0.0, 0.0, 0.0)).data
    monkeypatch.setattr(sim, "CHUNK_STEPS", 37 * 5)  # 37 samples (5 sub-steps each) a chunk
    chunked = free_run(RotorParams(), run.t, run.phi, run.phi_dot, (0.0, 0.0, 0.0, 0.0), max_substep=0.01).data
    np.testing.assert_array_equal(chunked, ref)


def test_long_free_run_hears_ctrl_c():
    """SIGINT in the middle of a long compiled free run ends it within a few seconds."""
    code = textwrap.dedent("""
        import signal, sys, time
        # a process started in the background by a non-interactive shell inherits SIGINT
        # ignored; the test is about the loop hearing Ctrl-C, so give it Python's handler
        signal.signal(signal.SIGINT, signal.default_int_handler)
        import numpy as np
        from rotor_env.params import RotorParams
        from rotor_env.simulator import free_run
        n = 30_000
        t = np.arange(n) * 20.0                 # 2000 sub-steps a sample: 6e7 steps, ~20 s
        phid = 1e-4 * t
        phi = 0.5e-4 * t * t
        free_run(RotorParams(), t[:3], phi[:3], phid[:3], (0.0, 0.0, 0.0, 0.0))  # compile first
        print("started", flush=True)
        t0 = time.perf_counter()
        try:
            free_run(RotorParams(), t, phi, phid, (0.0, 0.0, 0.0, 0.0))
            print("finished", time.perf_counter() - t0, flush=True)
        except KeyboardInterrupt:
            print("interrupted", time.perf_counter() - t0, flush=True)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "started"
        time.sleep(1.0)
        sent = time.perf_counter()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
        waited = time.perf_counter() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
    assert out.startswith("interrupted"), (out, err)
    assert waited < 5.0


# ------------------------------------------------------------------ item 5: non-finite
@pytest.mark.parametrize("column", ["theta_y_ddot", "phi_dot", "theta_x_dot"])
def test_a_huge_cell_is_refused_naming_line_and_column(tmp_path, run, column):
    data = run.data.copy()
    data[2000, COLUMNS.index(column)] = 1e300
    msg = _error(_write_csv(tmp_path / "big.csv", COLUMNS, data))
    assert f"line 2002, column '{column}'" in msg and "1e+300" in msg and "np.float64" not in msg


def test_fit_of_overflowing_measurements_is_an_error_not_inf(run):
    from rotor_env.diagnosis import fit

    data = run.data.copy()
    data[2000, COLUMNS.index("theta_y_ddot")] = 1e200  # Python users bypass the loader
    with pytest.raises(ValueError, match=r"not finite at t = .*\(from sample 2000 of the record, t = 100: "
                       r"theta_y_ddot = 1e\+200\)"):
        fit(Measurements(data, "big"), ["unbalance", "viscous_damping"])


def _lstsq_problem(rng):
    X = rng.standard_normal((300, 3))
    y = X @ np.array([1.0, -2.0, 3.0]) + 0.01 * rng.standard_normal(300)
    return X, y


@pytest.mark.parametrize("scale", [1e102, 1e150, 1e-110, 1e-150])
@pytest.mark.parametrize("forgetting", [1.0, 0.999])
def test_estimator_is_right_far_from_one(scale, forgetting):
    X, y = _lstsq_problem(np.random.default_rng(4))
    ref = RecursiveQR(3, forgetting=forgetting).fit(X, y)
    est = RecursiveQR(3, forgetting=forgetting).fit(X * scale, y * scale)
    theta = np.linalg.lstsq(X, y, rcond=None)[0]
    assert est.identifiable().all()
    if forgetting == 1.0:
        np.testing.assert_allclose(est.coefficients(), theta, rtol=1e-12)
    np.testing.assert_allclose(est.coefficients(), ref.coefficients(), rtol=1e-13)
    np.testing.assert_allclose(est.standard_errors(), ref.standard_errors(), rtol=1e-12)
    np.testing.assert_allclose(est.residual_energies() / scale**2, ref.residual_energies(), rtol=1e-12)
    np.testing.assert_allclose(est.effect_tests().log10_p, ref.effect_tests().log10_p, rtol=1e-12)
    # columns of very different sizes: x tiny, y near one
    mixed = RecursiveQR(3, forgetting=forgetting).fit(X * scale, y)
    np.testing.assert_allclose(mixed.coefficients() * scale, ref.coefficients(), rtol=1e-12)
    # the zero column is still recognised, at any scale
    Z = X * scale
    Z[:, 1] = 0.0
    assert RecursiveQR(3).fit(Z, y * scale).identifiable().tolist() == [True, False, True]


def test_estimator_refuses_an_update_beyond_the_double_range_and_changes_nothing():
    X, y = _lstsq_problem(np.random.default_rng(5))
    est = RecursiveQR(3)
    est.update_many(X[:100], y[:100])
    before = (est.R.copy(), est.coefficients(), est.n_samples)
    with pytest.raises(ValueError, match="not changed"):
        est.update_many(X[100:] * 1e160, y[100:] * 1e160)  # energies near 1e320
    assert np.array_equal(est.R, before[0]) and np.array_equal(est.coefficients(), before[1])
    assert est.n_samples == before[2]


# ------------------------------------------------------------------ item 6: outputs
def test_simulate_of_absurd_length_is_refused_with_its_size(tmp_path, capsys):
    code = cli.main(["simulate", str(tmp_path / "x.csv"), "--t-end", "1e9"])
    err = capsys.readouterr().err
    assert code == 2
    assert "100,000,000,001 samples" in err and "8 TB" in err and "Traceback" not in err
    assert not (tmp_path / "x.csv").exists()


def test_simulate_refuses_a_file_type_it_does_not_write(tmp_path, capsys):
    code = cli.main(["simulate", str(tmp_path / "x.xlsx"), "--t-end", "5"])
    assert code == 2 and ".csv or .parquet" in capsys.readouterr().err
    assert not (tmp_path / "x.xlsx").exists()


def test_simulate_onto_a_folder_says_it_is_a_folder(tmp_path, capsys):
    (tmp_path / "d.csv").mkdir()
    assert cli.main(["simulate", str(tmp_path / "d.csv"), "--t-end", "5"]) == 2
    assert "is a directory" in capsys.readouterr().err


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes into read-only folders")
def test_simulate_into_a_read_only_folder_fails_before_simulating(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert cli.main(["simulate", str(ro / "x.csv"), "--t-end", "1e6"]) == 2
        assert "not writable" in capsys.readouterr().err
    finally:
        ro.chmod(0o755)


# ------------------------------------------------------------------ item 8: state files
def _state_file(tmp_path, **changes) -> Path:
    X, y = _lstsq_problem(np.random.default_rng(6))
    est = RecursiveQR(3)
    est.update_many(X, y)
    path = est.save(tmp_path / "good.npz", overwrite=True)
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays.update(changes)
    out = tmp_path / "bad.npz"
    np.savez(out, **arrays)
    return out


def test_state_files_are_validated_on_load(tmp_path):
    good = RecursiveQR.load(_state_file(tmp_path))
    R = good.R
    nan = R.copy()
    nan[1, 2] = np.nan
    inf = R.copy()
    inf[0, 0] = np.inf
    lower = R.copy()
    lower[2, 0] = 0.5
    negative = R.copy()
    negative[1, 1] = -1.0
    cases = {
        "nan": ({"R": nan}, r"'R' holds a non-finite value at \(1, 2\)"),
        "inf": ({"R": inf}, "non-finite"),
        "complex": ({"R": R.astype(complex)}, "'R' must be real numbers, got dtype complex128"),
        "lower": ({"R": lower}, r"not upper triangular \(R\[2, 0\] = 0.5\)"),
        "negative": ({"R": negative}, "negative diagonal"),
        "counts": ({"sums": np.array([-3.0, 1.0, 1.0])}, "not counts"),
        "pending": ({"pending_X": np.full((3, 3), np.nan), "pending_y": np.zeros(3)}, "'pending_X' holds a non-finite"),
        "scale": ({"scale": np.array([1.0, 3.0, 1.0, 1.0])}, "powers of two"),
    }
    for name, (changes, pattern) in cases.items():
        with pytest.raises(ValueError, match=pattern):
            RecursiveQR.load(_state_file(tmp_path, **changes))
        assert name


def test_empty_and_truncated_state_files_are_clear_errors(tmp_path):
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match=r"empty\.npz: empty"):
        RecursiveQR.load(empty)
    whole = _state_file(tmp_path).read_bytes()
    for cut in (10, len(whole) // 2, len(whole) - 30):
        part = tmp_path / f"cut{cut}.npz"
        part.write_bytes(whole[:cut])
        with pytest.raises(ValueError, match="not a RecursiveQR state file") as exc:
            RecursiveQR.load(part)
        assert not isinstance(exc.value, (EOFError, zipfile.BadZipFile))


@pytest.mark.parametrize("forgetting,prior", [(1.0, 0.0), (0.999, 0.05)])
def test_resume_after_restore_is_bit_exact_at_any_split(tmp_path, forgetting, prior):
    rng = np.random.default_rng(7)
    X = rng.standard_normal((1300, 4)) * np.array([1.0, 1e3, 1e-3, 5.0])
    y = X @ np.array([0.5, -1e-3, 2e3, 0.1]) + 0.1 * rng.standard_normal(1300)
    kw = {"forgetting": forgetting, "prior": prior}
    whole = RecursiveQR(4, **kw)
    whole.update_many(X, y)
    theta = np.linalg.lstsq(X, y, rcond=None)[0]
    if prior == 0.0 and forgetting == 1.0:
        np.testing.assert_allclose(whole.coefficients(), theta, rtol=1e-10)
    for split in (1, 63, 64, 65, 500, 777, 1299):
        first = RecursiveQR(4, **kw)
        first.update_many(X[:split], y[:split])
        path = first.save(tmp_path / f"s{split}.npz", overwrite=True)
        resumed = RecursiveQR.load(path)
        resumed.update_many(X[split:], y[split:])
        assert np.array_equal(resumed.R, whole.R), split
        assert np.array_equal(resumed._sums, whole._sums) and np.array_equal(resumed._col_sq, whole._col_sq)
        assert np.array_equal(resumed.all_coefficients(), whole.all_coefficients())
        assert np.array_equal(resumed.residual_energies(), whole.residual_energies())
    one_by_one = RecursiveQR(4, **kw)
    for k in range(len(y)):
        one_by_one.update(X[k], y[k])
    assert np.array_equal(one_by_one.R, whole.R)


# ------------------------------------------------------------------ item 9: smaller
def test_two_effects_of_one_tau_are_refused(tmp_path, run, capsys):
    path = run.to_file(tmp_path / "r.csv")
    code = cli.main(["fit", str(path), "--model", "unbalance,unbalance_in_phase"])
    err = capsys.readouterr().err
    assert code == 2 and "'unbalance' and 'unbalance_in_phase' both estimate 'tau'" in err


@pytest.mark.parametrize("value", ["nan", "inf", "-0.1", "1.0", "abc"])
@pytest.mark.parametrize("command", ["fit", "diagnose"])
def test_ip_is_validated(tmp_path, run, capsys, value, command):
    path = run.to_file(tmp_path / "r.csv")
    with pytest.raises(SystemExit) as exc:
        cli.main([command, str(path), "--model", "unbalance", "--ip", value])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and f"argument --ip: '{value}'" in err and "column" not in err


def test_messages_print_plain_numbers(tmp_path, run):
    data = run.data.copy()
    data[100, 0] = data[99, 0]
    msg = _error(_write_csv(tmp_path / "t.csv", COLUMNS, data))
    assert "np.float64" not in msg and "time 4.95 does not increase (previous 4.95)" in msg


def test_parquet_with_a_text_column_is_read_with_a_note(tmp_path, run):
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = {c: run.data[:, j] for j, c in enumerate(COLUMNS)}
    cols["operator"] = pa.array(["anna"] * len(run))
    pq.write_table(pa.table(cols), tmp_path / "x.parquet")
    meas = load_measurements(tmp_path / "x.parquet")
    np.testing.assert_array_equal(meas.data, run.data)
    assert "ignored column(s) 'operator' ('operator' not numeric)" in meas.source


def test_csv_with_a_text_column_is_read_with_a_note(tmp_path, run):
    path = tmp_path / "x.csv"
    lines = [",".join([*COLUMNS, "note"])] + [",".join([*(repr(float(v)) for v in row), "ok"]) for row in run.data]
    path.write_text("\n".join(lines) + "\n")
    meas = load_measurements(path)
    np.testing.assert_array_equal(meas.data, run.data)
    assert "'note' not numeric" in meas.source


def test_fast_csv_reader_equals_the_careful_parser(tmp_path, run):
    import csv

    path = run.to_file(tmp_path / "r.csv")
    fast = _read_csv_arrow(path, None)
    assert fast is not None  # a clean file takes the fast path
    with open(path, newline="", encoding="utf-8-sig") as fh:
        slow = _parse_csv(path, csv.reader(fh))
    assert fast[0] == slow[0]
    np.testing.assert_array_equal(fast[1], slow[1])
    np.testing.assert_array_equal(fast[2], slow[2])
    header, data, lines = read_table(path)
    assert header == list(COLUMNS) and data.dtype == float and lines[0] == 2 and lines[-1] == len(run) + 1


def test_fast_reader_falls_back_for_exact_lines_and_values(tmp_path, run):
    path = run.to_file(tmp_path / "r.csv")
    text = path.read_text().splitlines()
    text.insert(500, "")  # a blank line: lines after it shift by one
    path.write_text("\n".join(text) + "\n")
    header, data, lines = read_table(path)
    assert lines[498] == 500 and lines[499] == 502
    text[3000] = text[3000].replace(text[3000].split(",")[4], "0.1x", 1)
    path.write_text("\n".join(text) + "\n")
    msg = _error(path)
    assert f"{path}, line 3001, column 'theta_x': '0.1x' is not a number" in msg


def test_large_record_gets_a_note_of_its_cost(tmp_path, monkeypatch, run):
    import rotor_env.measurements.files as io

    monkeypatch.setattr(io, "LARGE_RECORD", 1000)
    meas = load_measurements(run.to_file(tmp_path / "r.csv"))
    assert f"{len(run)} samples: a diagnosis costs about" in meas.source


def test_json_state_meta_is_kept(tmp_path):
    est = RecursiveQR(columns=["a", "b"], groups={"ab": ["a", "b"]})
    path = est.save(tmp_path / "s.npz")
    with np.load(path) as data:
        assert json.loads(str(data["meta"]))["groups"] == {"ab": ["a", "b"]}
    assert RecursiveQR.load(path).groups == {"ab": ("a", "b")}


def test_a_candidate_with_no_physical_rotor_is_turned_down_not_a_crash():
    """A fitted breathing term without a mean crack stiffness has infinite depth: its free run
    cannot be built; the diagnosis turns the candidate down instead of raising (seed 43 of a
    fleet batch did)."""
    from rotor_env.diagnosis import diagnose
    from rotor_env.simulator import RunUp

    meas = simulate(RotorParams().replace(h=0.0), t_end=80.0, dt=0.02, run_up=RunUp(rate=0.04),
                    noise=5e-4, seed=43)
    result = diagnose(meas)
    assert result.verdict in ("explained", "explained_after_adding", "partly_explained", "unexplained")
