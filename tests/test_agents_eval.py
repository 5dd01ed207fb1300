"""rotor-id evaluate --model on a freshly trained model (against SB3's own evaluate_policy
and scipy's t interval), the evaluation JSON, and training's logs without a terminal."""

from __future__ import annotations

import contextlib
import csv
import io
import json

import numpy as np
import pytest
from scipy import stats

pytest.importorskip("stable_baselines3")

from agents.evaluation import EVAL_SEED0, evaluate, load_model, statistics
from agents.training import TrainedPolicy, make_env, train
from rotor_env.cli import main

RUN_UP = "rotor_env/RotorRunUp-v0"
TINY = """rotor_env/RotorRunUp-v0:
  ppo:
    n_envs: 1
    policy: MlpPolicy
    n_steps: 64
    batch_size: 64
    n_epochs: 1
    policy_kwargs: {net_arch: [8]}
"""


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tiny")
    (folder / "hp.yml").write_text(TINY)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        out = train(RUN_UP, "ppo", 192, identifier=False, seed=5, out=folder / "run", hyperparams=folder / "hp.yml",
                    eval_freq=10_000, eval_episodes=1, progress=False, log_every_s=0.0)
    return out, err.getvalue()


def test_training_without_a_terminal_logs_lines_and_csv(trained):
    out, log = trained
    lines = [ln for ln in log.splitlines() if ln.startswith("rotor-id train:")]
    assert any("/192 steps" in ln and "steps/s" in ln for ln in lines), log  # during training
    assert lines[-1].startswith("rotor-id train: 192/192 done (100 %)")
    with open(out / "logs" / "progress.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["time/total_timesteps"]) for r in rows if r["time/total_timesteps"]] == [64, 128, 192]
    meta = json.loads((out / "run.json").read_text())
    assert "csv" in meta["logs"]["formats"]


def test_evaluate_model_equals_sb3_evaluate_policy(trained):
    """Our episode loop on the saved model gives SB3's evaluate_policy returns on the same
    rotors; the spread is numpy's std and scipy's t interval of those returns."""
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import DummyVecEnv

    out, _ = trained
    n = 3
    res = evaluate(RUN_UP, episodes=n, models=[out], baselines=False)
    name = next(iter(res["agents"]))
    assert name == f"model:{out.name}" and len(res["agents"]) == 1
    policy = TrainedPolicy.load(out)
    venv = DummyVecEnv([lambda: make_env(RUN_UP, identifier=False)])
    truth = []
    for i in range(n):
        venv.seed(EVAL_SEED0 + i)
        rewards, _ = evaluate_policy(policy, venv, n_eval_episodes=1, deterministic=True, return_episode_rewards=True,
                                     warn=False)
        truth.append(rewards[0])
    s = res["statistics"][name]["return"]
    assert s["n"] == n
    # DummyVecEnv keeps each reward as float32 (ours: float64): 600 roundings of ~1e-8
    assert s["mean"] == pytest.approx(np.mean(truth), rel=1e-6)
    assert s["std"] == pytest.approx(np.std(truth, ddof=1), rel=1e-4)
    lo, hi = stats.t.interval(0.95, n - 1, loc=np.mean(truth), scale=stats.sem(truth))
    assert s["ci95"] == pytest.approx([lo, hi], rel=1e-5)
    assert res["agents"][name]["return"] == s["mean"]


def test_evaluate_cli_model_json_carries_env_seeds_and_versions(trained, capsys):
    out, _ = trained
    assert main(["evaluate", "--model", str(out / "model.zip"), "--episodes", "2", "--no-baselines", "--seed", "123",
                 "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["env"] == RUN_UP and got["episodes"] == 2 and got["seeds"] == [123, 124]
    assert {"rotor-id", "stable-baselines3", "gymnasium", "numpy", "python"} <= set(got["versions"])
    (name,) = got["agents"]
    st = got["statistics"][name]
    assert set(st) == {"peak_amplitude", "rms_amplitude", "time_to_speed", "effort", "rub_rate", "return"}
    for m in st.values():
        assert m["n"] == 2 and m["ci95"][0] <= m["mean"] <= m["ci95"][1]


def test_model_of_another_env_is_refused(trained):
    out, _ = trained
    with pytest.raises(ValueError, match="trained on rotor_env/RotorRunUp-v0"):
        load_model(out, "rotor_env/RotorBalancing-v0")
    with pytest.raises(ValueError, match="expected a folder written by 'rotor-id train'"):
        load_model(out / "logs")


def test_statistics_is_scipys_t_interval():
    x = np.random.default_rng(0).normal(3.0, 2.0, size=17)
    s = statistics(x)
    lo, hi = stats.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=stats.sem(x))
    assert s["ci95"] == pytest.approx([lo, hi], rel=1e-12)
    assert s["std"] == pytest.approx(np.std(x, ddof=1), rel=1e-12)
    one = statistics([2.5])
    assert one == {"mean": 2.5, "std": None, "ci95": None, "n": 1}
