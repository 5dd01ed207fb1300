"""Issue 22, item 1: every command that writes a folder keeps a user's files.

A folder is written only when it is new, empty, or carries rotor-id's marker; ``--force``
replaces only the files the marker lists (a user's files stay, also one that has the
name of a file the command writes); ``--out .`` and a symbolic link to a user's folder
are refused like any folder of the user's.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from rotor_env.cli import main
from rotor_env.outputs import MARKER, OutputFolder

ONE_PLANE = "keyphasor: kp\nprobes: {x: 45, y: -45}\nunits: {displacement: um}\n"


def _user_folder(path, names=("summary.json", "results.parquet", "summary.png", "bode.png", "model.zip")):
    path.mkdir(parents=True, exist_ok=True)
    for n in names:
        (path / n).write_text(f"user's {n}")
    return {n: f"user's {n}" for n in names}


def _intact(path, files):
    for n, text in files.items():
        assert (path / n).read_text() == text, n


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    """A small one-probe 1X table (rpm, amp, phase_deg) of a simulated run-up."""
    from rotor_env.measurements.rig import load_rig
    from rotor_env.params import RotorParams
    from rotor_env.rig_simulation import simulate_rig

    folder = tmp_path_factory.mktemp("table")
    (folder / "rig.yaml").write_text(ONE_PLANE)
    rig = load_rig(folder / "rig.yaml")
    params = RotorParams(ip=0.0, values={"c": 0.04, "tau": 0.005}, effects=("stiffness", "viscous_damping",
                                                                              "unbalance"))
    run = simulate_rig(rig, params, natural_rpm=1650.0, rpm_from=600.0, rpm_to=2400.0, rpm_per_s=400.0,
                       noise=0.3, seed=2, sample_rate=2000.0)
    run.vectors(rig, (1,)).to_csv(folder / "table.csv", phase="lag")
    return folder / "table.csv"


# ------------------------------------------------------------------ batch --out
@pytest.mark.parametrize("how", ["folder", "dot", "symlink"])
def test_batch_never_writes_into_a_users_folder(tmp_path, monkeypatch, table, how):
    pytest.importorskip("ray")
    from rotor_env.fleet import run_batch

    user = tmp_path / "mine"
    files = _user_folder(user)
    out = {"folder": user, "dot": ".", "symlink": tmp_path / "link"}[how]
    if how == "dot":
        monkeypatch.chdir(user)
    if how == "symlink":
        (tmp_path / "link").symlink_to(user, target_is_directory=True)
    with pytest.raises(FileExistsError, match="not written by rotor-id"):
        run_batch([str(table)], out, options={"vectors": True})
    _intact(user, files)
    assert not (user / "recordings").exists()


def test_batch_resumes_its_own_folder_but_never_replaces_a_users_file_in_it(tmp_path, table):
    from rotor_env.fleet import run_batch

    out = tmp_path / "results"
    folder = OutputFolder(out)  # a previous batch's folder (its marker) ...
    folder.write_text("recordings/old.json", "{}")
    (out / "summary.json").write_text("user's summary")  # ... where a user saved a file of that name
    with pytest.raises(FileExistsError, match=r"summary\.json"):
        run_batch([str(table)], out, options={"vectors": True})
    assert (out / "summary.json").read_text() == "user's summary"


def test_batch_results_inside_the_input_folder_are_not_recordings(tmp_path, table):
    from rotor_env.fleet import find_recordings

    data = tmp_path / "data"
    data.mkdir()
    (data / "run1.csv").write_bytes(table.read_bytes())
    results = OutputFolder(data / "results")
    results.write_text("results.parquet", "x")
    results.write_text("recordings/run1.json", "{}")
    ids = [r.id for r in find_recordings([str(data)])]
    assert ids == ["run1"]
    with pytest.raises(ValueError, match="matches no file"):  # a glob that meets only the results
        find_recordings([str(data / "**" / "*.parquet")])


# ------------------------------------------------------------------ diagnose --figures
@pytest.mark.parametrize("path", ["dimensionless", "vectors", "rig"])
def test_diagnose_figures_force_refuses_a_users_folder_on_every_path(tmp_path, table, capsys, path):
    figs = tmp_path / "figs"
    files = _user_folder(figs, ("bode.png", "polar.png", "compare.png"))
    (tmp_path / "rig.yaml").write_text(ONE_PLANE)
    args = {"dimensionless": [str(table)], "vectors": [str(table), "--vectors"],
            "rig": [str(table), "--rig", str(tmp_path / "rig.yaml")]}[path]
    rc = main(["diagnose", *args, "--figures", str(figs), "--force"])
    assert rc == 2
    assert "not written by rotor-id" in capsys.readouterr().err
    _intact(figs, files)


def test_diagnose_figures_force_replaces_its_own_and_keeps_a_users_file(tmp_path, table, capsys):
    figs = tmp_path / "figs"
    previous = OutputFolder(figs)  # a previous run's figures (its marker) ...
    previous.write_text("bode.png", "old figure")
    (figs / "notes.txt").write_text("my notes")  # ... and a user's file dropped in later
    assert main(["diagnose", str(table), "--vectors", "--figures", str(figs)]) == 2  # no --force: refused
    assert "--force" in capsys.readouterr().err
    assert main(["diagnose", str(table), "--vectors", "--figures", str(figs), "--force"]) == 0
    listed = json.loads((figs / MARKER).read_text())["files"]
    assert {"bode.png", "polar.png", "residual.png"} <= set(listed) and "notes.txt" not in listed
    assert (figs / "notes.txt").read_text() == "my notes"
    assert (figs / "bode.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not [p for p in figs.iterdir() if p.name.startswith(".rotor-id-staging")]


# ------------------------------------------------------------------ paper --out
def test_paper_force_refuses_a_users_folder(tmp_path, capsys):
    out = tmp_path / "paper"
    files = _user_folder(out, ("table2.csv", "fig3_response.png"))
    assert main(["paper", "--out", str(out), "--force"]) == 2
    assert "not written by rotor-id" in capsys.readouterr().err
    _intact(out, files)


# ------------------------------------------------------------------ train --out
def test_train_force_never_replaces_a_users_files(tmp_path):
    pytest.importorskip("stable_baselines3")
    from agents.training import train

    env = "rotor_env/RotorRunUp-v0"
    user = tmp_path / "mine"
    files = _user_folder(user, ("model.zip", "run.json", "vecnormalize.npz"))
    with pytest.raises(FileExistsError, match="not written by rotor-id"):
        train(env, "ppo", 64, out=user, force=True, progress=False)
    _intact(user, files)
    # a previous run's folder (its marker) with a user's file beside: --force replaces the
    # run's own files only
    out = tmp_path / "run"
    previous = OutputFolder(out)
    for name in ("model.zip", "run.json", "logs/progress.csv"):
        previous.write_text(name, "previous run")
    (out / "logs" / "my_notes.txt").write_text("keep")
    with pytest.raises(FileExistsError, match="--force"):
        train(env, "ppo", 64, identifier=False, out=out, progress=False)
    tiny = tmp_path / "tiny.yml"  # one short rollout: the folder is what is tested, not the learning
    tiny.write_text(f"{env}:\n  ppo: {{n_envs: 1, n_steps: 32, batch_size: 32, n_epochs: 1}}\n")
    train(env, "ppo", 32, identifier=False, seed=5, out=out, force=True, progress=False, eval_freq=10**9,
          hyperparams=tiny)
    assert json.loads((out / "run.json").read_text())["seed"] == 5
    assert (out / "model.zip").read_bytes()[:2] == b"PK"
    assert (out / "logs" / "my_notes.txt").read_text() == "keep"
    listed = set(json.loads((out / MARKER).read_text())["files"])
    assert {"model.zip", "run.json", "vecnormalize.npz", "logs/progress.csv"} <= listed
    assert "logs/my_notes.txt" not in listed
    assert len(np.load(out / "vecnormalize.npz").files) > 0
