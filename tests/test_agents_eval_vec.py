"""The SB3 VecEnv adapter over the numba vector env against DummyVecEnv of single envs."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from agents.training import make_env, train
from agents.vec_env import make_numba_vec_env

RUN_UP = "rotor_env/RotorRunUp-v0"


@pytest.mark.parametrize("env_id", [RUN_UP, "rotor_env/RotorBalancing-v0"])
def test_adapter_steps_exactly_as_dummy_vec_env_across_episode_ends(env_id):
    """Same seeds, same actions: the same observations, rewards, dones, terminal
    observations and time-limit flags as DummyVecEnv of the single envs, through resets."""
    n = 3
    ours = make_numba_vec_env(env_id, n, seed=7, monitor=False)
    ref = DummyVecEnv([lambda: make_env(env_id, False) for _ in range(n)])
    ref.seed(7)
    np.testing.assert_array_equal(ours.reset(), ref.reset())
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(1300):
        act = rng.uniform(-1, 1, size=(n, *ref.action_space.shape)).astype(np.float32)
        ours.step_async(act)
        ref.step_async(act)
        o1, r1, d1, i1 = ours.step_wait()
        o2, r2, d2, i2 = ref.step_wait()
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(d1, d2)
        for i in np.flatnonzero(d1):
            ends += 1
            np.testing.assert_array_equal(i1[i]["terminal_observation"], i2[i]["terminal_observation"])
            assert i1[i]["TimeLimit.truncated"] == i2[i].get("TimeLimit.truncated", False)
    assert ends >= n  # every sub-env crossed an episode end


def test_ppo_trains_on_the_numba_vec_env(tmp_path):
    (tmp_path / "hp.yml").write_text("rotor_env/RotorRunUp-v0:\n  ppo:\n    n_envs: 4\n    n_steps: 16\n"
                                     "    batch_size: 64\n    n_epochs: 1\n    policy_kwargs: {net_arch: [8]}\n")
    out = train(RUN_UP, "ppo", 64, identifier=False, out=tmp_path / "p", hyperparams=tmp_path / "hp.yml",
                eval_freq=10_000, eval_episodes=1, progress=False, vec_env="numba", log_every_s=1e9)
    assert (out / "model.zip").stat().st_size > 0
    with pytest.raises(ValueError, match="--no-identifier"):
        train(RUN_UP, "ppo", 64, identifier=True, out=tmp_path / "q", vec_env="numba", progress=False)
    v = VecNormalize(make_numba_vec_env(RUN_UP, 2, seed=0))
    v.reset()
    assert v.num_envs == 2


def test_ppo_on_the_numba_vec_env_evaluates_during_training(tmp_path):
    """``rotor-id train --vec-env numba`` crashed at its first evaluation (the eval env's
    wrappers differed from the training env's: SB3's normalisation sync failed)."""
    (tmp_path / "hp.yml").write_text("rotor_env/RotorRunUp-v0:\n  ppo:\n    n_envs: 4\n    n_steps: 16\n"
                                     "    batch_size: 64\n    n_epochs: 1\n    policy_kwargs: {net_arch: [8]}\n")
    out = train(RUN_UP, "ppo", 64, identifier=False, out=tmp_path / "p", hyperparams=tmp_path / "hp.yml",
                eval_freq=32, eval_episodes=1, progress=False, vec_env="numba", log_every_s=1e9)
    evals = np.load(out / "eval" / "evaluations.npz")
    assert len(evals["timesteps"]) >= 1 and np.isfinite(evals["results"]).all()
