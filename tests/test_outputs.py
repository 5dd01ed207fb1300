"""Data safety: --force replaces only what rotor-id wrote; files appear whole or not at all."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from rotor_env import RotorParams, simulate
from rotor_env.cli import main
from rotor_env.measurements.files import load_measurements
from rotor_env.outputs import MARKER, OutputFolder, atomic_write, atomic_write_text


def test_demo_force_never_deletes_a_users_folder(tmp_path, capsys):
    thesis = tmp_path / "thesis.tex"
    thesis.write_text("years of work")
    rc = main(["demo", "--out", str(tmp_path), "--force"])
    assert rc == 2
    assert "not written by rotor-id" in capsys.readouterr().err
    assert thesis.read_text() == "years of work"


def test_demo_force_on_current_directory_is_refused(tmp_path, monkeypatch, capsys):
    (tmp_path / "notes.txt").write_text("keep me")
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--out", ".", "--force"]) == 2
    assert (tmp_path / "notes.txt").read_text() == "keep me"
    assert tmp_path.is_dir()


def test_output_folder_force_removes_only_its_own_files(tmp_path):
    out = tmp_path / "run"
    folder = OutputFolder(out)
    folder.write_text("report.html", "<html>")
    folder.write_text("figures/a.png", "png")
    (out / "figures" / "mine.txt").write_text("user file")  # a user's file dropped in later
    (out / "user.csv").write_text("1,2")
    with pytest.raises(FileExistsError, match="--force"):
        OutputFolder(out)
    again = OutputFolder(out, force=True)
    assert not (out / "report.html").exists() and not (out / "figures" / "a.png").exists()
    assert (out / "figures" / "mine.txt").read_text() == "user file"
    assert (out / "user.csv").read_text() == "1,2"
    assert json.loads((out / MARKER).read_text())["files"] == []
    again.write_text("report.html", "new")
    assert (out / "report.html").read_text() == "new"


def test_output_folder_marker_cannot_reach_outside(tmp_path):
    outside = tmp_path / "precious.txt"
    outside.write_text("x")
    out = tmp_path / "run"
    out.mkdir()
    (out / MARKER).write_text(json.dumps({"files": ["../precious.txt", str(outside)]}))
    OutputFolder(out, force=True)
    assert outside.read_text() == "x"


def test_output_folder_refuses_a_file(tmp_path):
    f = tmp_path / "f"
    f.write_text("x")
    with pytest.raises(ValueError, match="is a file"):
        OutputFolder(f, force=True)
    assert f.read_text() == "x"


def test_atomic_write_refuses_a_file_that_appeared_meanwhile(tmp_path):
    target = tmp_path / "report.html"

    def write(p):
        p.write_text("mine")
        target.write_text("another run's report")  # created while we were writing

    with pytest.raises(FileExistsError):
        atomic_write(target, write)
    assert target.read_text() == "another run's report"
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]  # no temporary left
    atomic_write_text(target, "mine", overwrite=True)
    assert target.read_text() == "mine"


def test_interrupted_simulate_leaves_no_truncated_file(tmp_path, monkeypatch):
    meas = simulate(RotorParams(), t_end=5.0)
    target = tmp_path / "run.csv"
    real = np.savetxt

    def interrupted(fname, X, **kw):
        real(fname, X[: len(X) // 3], **kw)  # part of the file is on disk ...
        raise KeyboardInterrupt              # ... when the user presses Ctrl-C

    monkeypatch.setattr(np, "savetxt", interrupted)
    with pytest.raises(KeyboardInterrupt):
        meas.to_file(target)
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(np, "savetxt", real)
    meas.to_file(target)
    assert len(load_measurements(target)) == len(meas)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_report_into_read_only_folder_fails_before_computing(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        rc = main(["diagnose", str(tmp_path / "missing.csv"), "--report", str(ro / "r.html")])
    finally:
        ro.chmod(0o700)
    assert rc == 2
    assert "not writable" in capsys.readouterr().err


def test_report_target_checked_before_loading(tmp_path, capsys):
    folder = tmp_path / "r.html"
    folder.mkdir()
    rc = main(["diagnose", str(tmp_path / "missing.csv"), "--report", str(folder)])
    assert rc == 2
    assert "is a folder" in capsys.readouterr().err


def test_report_of_another_file_type_is_refused_before_the_work(tmp_path, capsys):
    """Issue 11 item 6: --report x.png would have written HTML into a .png; refused, nothing written."""
    rc = main(["diagnose", str(tmp_path / "missing.csv"), "--report", str(tmp_path / "r.png")])
    assert rc == 2
    assert "HTML" in capsys.readouterr().err and not (tmp_path / "r.png").exists()
