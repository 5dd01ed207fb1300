"""Stable-Baselines3 on the numba vector env: a ``VecEnv`` adapter.

SB3 steps its environments through a ``VecEnv`` (``DummyVecEnv``: one Python ``step``
per sub-env, each in its own ``Monitor``).  The rotor environments also come as one
numba-batched vector env (:mod:`rotor_env.envs.vector`, all sub-envs in one compiled
call); :class:`RotorVecEnv` gives it SB3's interface:

* SB3 resets an ended sub-env in the same ``step`` (its observation is the new episode's
  first, the last one is ``info["terminal_observation"]``; ``info["TimeLimit.truncated"]``
  marks a time limit); the Gymnasium vector env resets on the *next* step, so the adapter
  resets the ended sub-envs at once (``reset_mask``);
* ``seed(s)`` seeds sub-env ``i`` with ``s + i`` at the next reset, as ``DummyVecEnv``
  does; with the same seeds the two give the same episodes step for step (tested).

Wrap it in ``VecMonitor`` for the episode statistics (``DummyVecEnv`` gets them from a
``Monitor`` per sub-env).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

import rotor_env  # noqa: F401 - registers the environments

__all__ = ["RotorVecEnv", "make_numba_vec_env"]


class RotorVecEnv(VecEnv):
    """SB3 ``VecEnv`` over a rotor vector env (``gymnasium.make_vec(ID, num_envs=N)``)."""

    def __init__(self, venv: gym.vector.VectorEnv):
        self.venv = venv
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions: np.ndarray | None = None
        self._seeds: list[int | None] = [None] * self.num_envs

    # ------------------------------------------------------------------ VecEnv API
    def reset(self):
        seeds = self._seeds
        obs, _ = self.venv.reset(seed=None if all(s is None for s in seeds) else seeds)
        self._seeds = [None] * self.num_envs
        self._reset_infos = [{} for _ in range(self.num_envs)]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions).reshape(self.num_envs, -1)

    def step_wait(self):
        obs, rew, terminated, truncated, _ = self.venv.step(self._actions)
        dones = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if dones.any():
            last = obs.copy()
            new_obs, _ = self.venv.reset(options={"reset_mask": dones})
            for i in np.flatnonzero(dones).tolist():
                infos[i]["terminal_observation"] = last[i]
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                obs[i] = new_obs[i]
        return obs, rew.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        if seed is None:
            seed = int(np.random.default_rng().integers(0, 2**31 - 1))
        self._seeds = [seed + i for i in range(self.num_envs)]
        return self._seeds

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self.venv, attr_name) for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        return [getattr(self.venv, method_name)(*method_args, **method_kwargs) for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        frames = self.venv.render()
        return list(frames) if frames is not None else [None] * self.num_envs

    def _indices(self, indices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)


def make_numba_vec_env(env_id: str, n_envs: int, seed: int | None = None, monitor: bool = True, **kwargs):
    """``RotorVecEnv`` of ``n_envs`` rotors (seeded ``seed + i``), in a ``VecMonitor``."""
    from stable_baselines3.common.vec_env import VecMonitor

    venv = RotorVecEnv(gym.make_vec(env_id, num_envs=n_envs, **kwargs))
    if seed is not None:
        venv.seed(seed)
    return VecMonitor(venv) if monitor else venv
