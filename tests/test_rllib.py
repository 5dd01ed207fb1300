"""RLlib training (``rotor-id train --backend rllib``): a one-iteration smoke run that
saves, reloads and evaluates, checked against RLlib's own inference path."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("ray.rllib")
pytest.importorskip("torch")


from agents.rllib import load_rllib_policy, train_rllib
from agents.training import make_env

RUN_UP = "rotor_env/RotorRunUp-v0"
#: one tiny iteration: 2 envs x 64 steps, one epoch of one minibatch
TINY = {"n_envs": 2, "n_steps": 64, "batch_size": 128, "n_epochs": 1}


def _tiny_yaml(tmp_path):
    import yaml

    path = tmp_path / "tiny.yml"
    path.write_text(yaml.safe_dump({RUN_UP: {"ppo": {**TINY, "policy": "MlpPolicy", "gamma": 0.99,
                                                     "policy_kwargs": {"net_arch": [16, 16]}}}}))
    return path


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A policy trained for one iteration, and RLlib's own actions for observations of a rotor."""
    import ray
    import torch
    from ray.rllib.connectors.env_to_module.mean_std_filter import MeanStdFilter

    out = tmp_path_factory.mktemp("rllib") / "policy"
    env = make_env(RUN_UP, identifier=True)  # the raw wrapper, as evaluate feeds the policy
    raw = []
    obs, _ = env.reset(seed=123)
    for k in range(40):
        raw.append(obs)
        obs, *_ = env.step(np.array([0.3 if k % 3 else -0.2], dtype=np.float32))
    raw = np.array(raw, dtype=np.float32)
    env.close()
    reference = {}

    def rllib_actions(algo):
        """The trained module's deterministic actions through RLlib's own pieces."""
        runner = algo.env_runner_group.local_env_runner
        piece = next(c for c in runner._env_to_module.connectors if isinstance(c, MeanStdFilter))
        filt = piece._filters[None]
        module = algo.get_module()
        feats = make_env(RUN_UP, identifier=True, model_features="compact")
        fmap = feats.get_wrapper_attr("features")
        feats.close()
        normed = np.array([filt(fmap(o), update=False) for o in raw], dtype=np.float32)
        with torch.no_grad():
            logits = module.forward_inference({"obs": torch.from_numpy(normed)})["action_dist_inputs"]
            dist = module.get_inference_action_dist_cls().from_logits(logits)
            reference["actions"] = np.clip(dist.to_deterministic().sample().numpy(), -1.0, 1.0)
        reference["normed"] = normed

    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        train_rllib(RUN_UP, 128, out=out, seed=3, eval_episodes=1, overrides=TINY, after_training=rllib_actions)
    finally:
        ray.shutdown()
    return out, raw, reference


def test_saved_policy_acts_as_rllib_does(trained):
    out, raw, ref = trained
    policy = load_rllib_policy(out)
    fmap = policy.features
    ours = np.array([policy.normalize(fmap(o)) for o in raw])
    np.testing.assert_allclose(ours, ref["normed"], rtol=1e-5, atol=1e-6)
    actions = np.array([policy.predict(o)[0] for o in raw])
    np.testing.assert_allclose(actions, ref["actions"], rtol=1e-5, atol=1e-6)
    assert np.ptp(actions) > 0  # a network that answers, not a constant


def test_run_folder_logs_and_metadata(trained):
    out = trained[0]
    run = json.loads((out / "run.json").read_text())
    assert run["backend"] == "rllib" and run["env"] == RUN_UP and run["seed"] == 3
    assert run["env_steps"] >= 128 and run["iterations"] >= 1
    assert run["rllib_training"]["train_batch_size_per_learner"] == TINY["n_envs"] * TINY["n_steps"]
    assert run["eval"]["return"]["n"] == 1 and np.isfinite(run["eval_mean_reward"])
    lines = (out / "logs" / "progress.csv").read_text().splitlines()
    assert lines[0].startswith("iteration,env_steps,") and len(lines) >= 2
    assert float(lines[-1].split(",")[1]) >= 128
    assert list((out / "logs").glob("events.out.tfevents.*"))
    # no pickle anywhere in the folder
    for f in out.rglob("*.npz"):
        with np.load(f, allow_pickle=False) as z:
            assert all(z[k].dtype != object for k in z.files)


def test_evaluate_model_reads_an_rllib_folder(trained):
    out = trained[0]
    proc = subprocess.run([sys.executable, "-m", "rotor_env.cli", "evaluate", "--model", str(out), "--no-baselines",
                           "--episodes", "2", "--json"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    (name,) = result["agents"]
    assert name == f"model:{out.name}" and result["env"] == RUN_UP and result["seeds"] == [50000, 50001]
    stats = result["statistics"][name]["return"]
    assert stats["n"] == 2 and stats["ci95"][0] <= stats["mean"] <= stats["ci95"][1]
    assert "ray" in result["versions"]


def test_cli_trains_with_rllib_and_refuses_sb3_only_options(tmp_path):
    hp = _tiny_yaml(tmp_path)
    bad = subprocess.run([sys.executable, "-m", "rotor_env.cli", "train", "--backend", "rllib", "--env", RUN_UP,
                          "--algo", "sac", "--out", str(tmp_path / "x")], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "PPO" in bad.stderr
    proc = subprocess.run([sys.executable, "-m", "rotor_env.cli", "train", "--backend", "rllib", "--env", RUN_UP,
                           "--steps", "128", "--hyperparams", str(hp), "--eval-episodes", "0",
                           "--out", str(tmp_path / "run")], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "rotor-id train (rllib): 128/128 steps (100 %)" in proc.stderr  # progress without a terminal
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run["network"]["fcnet_hiddens"] == [16, 16]
    assert run["command"].startswith("rotor-id train --backend rllib")
    again = subprocess.run([sys.executable, "-m", "rotor_env.cli", "train", "--backend", "rllib", "--env", RUN_UP,
                            "--steps", "128", "--out", str(tmp_path / "run")], capture_output=True, text=True,
                           timeout=120)
    assert again.returncode != 0 and "--force" in again.stderr  # never overwrites a run silently
