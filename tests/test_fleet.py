"""rotor-id batch on Ray (local mode) against the sequential diagnosis of the same files;
a corrupt recording; resuming; Parquet datasets; the start-up cache and --version."""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from rotor_env.cli import main
from rotor_env.fleet import Recording, diagnose_recording, find_recordings, run_batch
from rotor_env.params import Crack, RotorParams
from rotor_env.simulator import RunUp, simulate

ray = pytest.importorskip("ray")



SHORT = {"t_end": 120.0, "dt": 0.02, "run_up": RunUp(rate=0.025), "noise": 5e-4}


def _record(path: Path, seed: int, crack: Crack | None = None) -> Path:
    simulate(RotorParams(values={"h": 0.0}, crack=crack), seed=seed, **SHORT).to_file(path)
    return path


def _sequential(path: Path) -> dict:
    """What ``rotor-id diagnose FILE --json`` says of one file (the independent truth)."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["diagnose", str(path), "--json"]) == 0
    return json.loads(buf.getvalue())


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fleet")
    _record(folder / "m1.csv", seed=1)
    (folder / "site").mkdir()
    _record(folder / "site" / "m2.parquet", seed=2, crack=Crack(70.0, 0.05))
    (folder / "site" / "broken.csv").write_text("t,phi,theta_x,theta_y\n0,0,not-a-number,0\n\x00\x01garbage\n")
    return folder


@pytest.fixture(scope="module")
def batch(fleet, local_ray, tmp_path_factory):
    out = tmp_path_factory.mktemp("results")
    result = run_batch([str(fleet)], out, workers=2, progress=False, log=lambda m: None)
    return out, result


def test_batch_rows_equal_the_sequential_diagnosis(fleet, batch):
    out, result = batch
    table = pq.read_table(out / "results.parquet").to_pylist()
    rows = {r["recording"]: r for r in table}
    assert sorted(rows) == ["m1", "site/broken", "site/m2"]
    for rid, path in (("m1", fleet / "m1.csv"), ("site/m2", fleet / "site" / "m2.parquet")):
        truth = _sequential(path)
        saved = json.loads((out / "recordings" / f"{rid.replace('/', '__')}.json").read_text())
        assert saved["status"] == "ok" and saved["diagnosis"] == truth  # the whole diagnosis, number for number
        row = rows[rid]
        assert row["status"] == "ok" and row["error"] is None
        assert row["verdict"] == truth["verdict"]
        assert row["missing"] == truth["missing"]
        assert row["rms_before"] == truth["rms_before"] and row["rms_after"] == truth["rms_after"]
        assert row["fit_percent_after"] == truth["fit_percent_after"]
        assert {c["name"]: (c["value"], c["standard_error"]) for c in row["coefficients"]} == {
            k: (v, truth["standard_errors"][k]) for k, v in truth["coefficients"].items()}
        assert [o["effect"] for o in row["onsets"]] == list(truth["onset"])


def test_corrupt_recording_gets_an_error_row_and_the_batch_goes_on(batch):
    out, result = batch
    rows = {r["recording"]: r for r in pq.read_table(out / "results.parquet").to_pylist()}
    bad = rows["site/broken"]
    assert bad["status"] == "error" and bad["verdict"] is None
    assert "broken.csv" in bad["error"]
    s = result["summary"]
    assert s["recordings"] == 3 and s["ok"] == 2 and s["errors"] == 1 and s["verdicts"]["error"] == 1
    assert sum(s["verdicts"].values()) == 3
    assert json.loads((out / "summary.json").read_text()) == s
    assert (out / "summary.png").stat().st_size > 1000


def test_rerun_skips_done_recordings(fleet, batch, local_ray):
    out, _ = batch
    stamp = (out / "recordings" / "m1.json").stat().st_mtime_ns
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):  # through the CLI: nothing left to do
        assert main(["batch", str(fleet), "--out", str(out), "--workers", "2", "--json"]) == 0
    said = json.loads(buf.getvalue())
    assert said["done"] == 0 and said["skipped"] == 3 and said["summary"]["ok"] == 2
    assert (out / "recordings" / "m1.json").stat().st_mtime_ns == stamp
    # the same files named by another path are the same recordings
    other = run_batch([os.path.relpath(fleet)], out, workers=2, progress=False, log=lambda m: None)
    assert other["done"] == 0 and other["skipped"] == 3
    # a file replaced since (a new time stamp) is done again, and only that one; --retry-errors
    # re-runs the failed one
    st = (fleet / "m1.csv").stat()
    os.utime(fleet / "m1.csv", ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    again = run_batch([str(fleet)], out, workers=2, progress=False, log=lambda m: None)
    assert again["done"] == 1 and again["skipped"] == 2
    retry = run_batch([str(fleet)], out, workers=2, retry_errors=True, progress=False, log=lambda m: None)
    assert retry["done"] == 1 and retry["summary"]["errors"] == 1
    assert len(pq.read_table(out / "results.parquet")) == 3


def test_parquet_dataset_recording_matches_its_own_file(fleet, tmp_path):
    """A Parquet dataset with a recording id column: each id is one recording."""
    import pyarrow.csv as pcsv

    a = pcsv.read_csv(fleet / "m1.csv")
    b = pq.read_table(fleet / "site" / "m2.parquet")
    ds = pa.concat_tables([a.append_column("recording_id", pa.array([7] * len(a))),
                           b.select(a.column_names).append_column("recording_id", pa.array([9] * len(b)))])
    pq.write_table(ds, tmp_path / "fleet.parquet")
    recs = find_recordings([str(tmp_path / "fleet.parquet")])
    assert [r.id for r in recs] == ["7", "9"]
    row = diagnose_recording(recs[0], {})
    assert row["ok"], row["error"]
    got = json.loads(row["result_json"])
    truth = _sequential(fleet / "m1.csv")
    assert got["source"].endswith("[recording_id=7]")
    got.pop("source"), truth.pop("source")
    assert got == truth


def test_find_recordings_folders_globs_and_clashes(fleet, tmp_path):
    assert [r.id for r in find_recordings([str(fleet)])] == ["m1", "site/broken", "site/m2"]
    assert [r.id for r in find_recordings([str(fleet / "site" / "*.csv")])] == ["broken"]
    (tmp_path / "m1.csv").write_text("t\n")
    with pytest.raises(ValueError, match="two recordings have the id 'm1'"):
        find_recordings([str(fleet / "m1.csv"), str(tmp_path / "m1.csv")])
    with pytest.raises(ValueError, match="matches no file"):
        find_recordings([str(tmp_path / "*.parquet")])
    with pytest.raises(ValueError, match="no such file"):
        find_recordings([str(tmp_path / "absent")])
    # an error inside a worker never raises: it is the row
    row = diagnose_recording(Recording("x", str(tmp_path / "absent.csv")), {})
    assert not row["ok"] and "no such file" in row["error"]


def test_bad_model_refused_before_any_work(fleet, tmp_path):
    with pytest.raises(ValueError, match="no_such_effect"):
        run_batch([str(fleet)], tmp_path / "out", options={"model": "unbalance,no_such_effect"})
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").rglob("*.json"))


# ---------------------------------------------------------------------- start-up
def test_version_is_the_installed_distributions():
    from importlib.metadata import version

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf), pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert buf.getvalue().strip() == f"rotor-id {version('rotor-id')}"


def test_cached_kernel_is_the_in_memory_kernel_and_hits_the_cache_in_a_new_process(tmp_path):
    """The file-backed simulator kernel: the same numbers as the in-memory compile, read
    from numba's cache by a second process."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), ROTOR_ID_CACHE_DIR=str(tmp_path / "k"))
    code = (
        "import json, numpy as np\n"
        "from rotor_env import simulator as s\n"
        "from rotor_env.params import RotorParams\n"
        "m = s.simulate(RotorParams(), t_end=40.0, dt=0.02)\n"
        "b = s._BOUND.get(id(s.compile_accel(tuple(RotorParams().effects))))\n"
        "print(json.dumps({'bound': b is not None, 'hits': sum(b.integrate_bound.stats.cache_hits.values()) if b "
        "else 0, 'x': np.asarray(m.theta_x).tolist()}))\n"
    )

    def run(extra=None):
        out = subprocess.run([sys.executable, "-c", code], env=dict(env, **(extra or {})), capture_output=True,
                             text=True, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])

    first, second = run(), run()
    off = run({"ROTOR_ID_NO_KERNEL_CACHE": "1"})
    assert first["bound"] and second["bound"] and not off["bound"]
    assert first["hits"] == 0 and second["hits"] >= 1
    np.testing.assert_array_equal(first["x"], off["x"])
    np.testing.assert_array_equal(second["x"], off["x"])
    assert any((tmp_path / "k" / "kernels").glob("rotor_id_kernel_*.py"))


def test_row_of_a_vector_table_diagnosis_keeps_criticals_and_nested_values():
    from rotor_env.fleet import flat_row

    record = {"recording": "t1", "source": "t1.csv", "status": "ok", "error": None, "seconds": 1.0, "diagnosis": {
        "kind": "vectors", "verdict": "explained", "missing": [], "rms_before": 0.5, "rms_after": 0.4,
        "criticals": [{"rpm": 1649.7, "damping_ratio": 0.02}],
        "physical": {"viscous_damping": {"c": 0.04}, "unbalance": {"tau": 5.0, "beta": -1e-4}}}}
    row = flat_row(record)
    assert row["kind"] == "vectors" and row["criticals"] == [{"rpm": 1649.7, "damping_ratio": 0.02}]
    assert [(c["name"], c["value"], c["standard_error"]) for c in row["coefficients"]] == [
        ("viscous_damping.c", 0.04, None), ("unbalance.tau", 5.0, None), ("unbalance.beta", -1e-4, None)]
    assert row["fit_percent_after"] is None and row["rms_after"] == 0.4
