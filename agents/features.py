"""The identified model as the input of a small policy network.

:class:`rotor_env.IdentificationWrapper` reports every effect's least-squares
coefficients from the first samples on.  While an effect is not significant — or its
columns are still nearly collinear, as the non-linear stiffness terms are at small
amplitude — those numbers can be huge and meaningless, and a single one of them wrecks
the running normalisation (``VecNormalize``) of every later observation: the network
then sees the informative features squashed to zero.  A model-based engineer would hand
the controller the *identified model*, not the raw regression, so :class:`ModelFeatures`

1. keeps the coefficients of the significant effects (clipped to ``+-limit``) and zeroes
   the others — the model the significance tests accept;
2. appends what the model says about the run-up: the speed relative to the identified
   critical speed, ``s = phi_dot / sqrt(k / (1 - ip))`` (the forward-whirl resonance is
   at ``s = 1``), clipped to ``[0, 3]``, and whether it is known (the stiffness is
   significant).

It is part of the *agent* (a trained policy applies it to what the wrapper hands out,
see :class:`agents.training.TrainedPolicy`), so the environment and the wrapper stay
exactly as tested.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .baselines import find_wrapper_attr, layout_from_json, layout_to_json

__all__ = ["ModelFeatureWrapper", "ModelFeatures"]


class ModelFeatures:
    """``obs -> [obs with the significant model only | s, known]`` (see the module).

    ``layout`` and ``offset`` are the identification wrapper's; ``speed_scale`` turns
    ``obs[0]`` into the spin speed.
    """

    EXTRA = 2

    def __init__(self, layout: dict[str, slice], offset: int, speed_scale: float, limit: float = 10.0,
                 compact: bool = False) -> None:
        self.offset, self.speed_scale, self.limit = int(offset), float(speed_scale), float(limit)
        # compact: only the env observation and what the model says about the critical
        # speed (the smallest input that carries the identified model into a run-up)
        self.compact = bool(compact)
        self.layout = layout_from_json(layout_to_json(layout))  # a copy
        self._effects = [(offset + self.layout[k].start, offset + self.layout[k].stop,
                          offset + self.layout[k.replace(".coefficients", ".significant")].start)
                         for k in self.layout if k.endswith(".coefficients")]
        self._k = self.layout.get("stiffness.coefficients")
        self._ip = self.layout["ip"].start + offset

    @classmethod
    def for_env(cls, env: gym.Env, limit: float = 10.0, compact: bool = False) -> ModelFeatures:
        return cls(find_wrapper_attr(env, "layout"), find_wrapper_attr(env, "offset"),
                   float(env.unwrapped._speed_max), limit, compact)

    def to_json(self) -> dict:
        return {"layout": layout_to_json(self.layout), "offset": self.offset,
                "speed_scale": self.speed_scale, "limit": self.limit, "compact": self.compact}

    @classmethod
    def from_json(cls, d: dict) -> ModelFeatures:
        return cls(layout_from_json(d["layout"]), d["offset"], d["speed_scale"], d["limit"],
                   bool(d.get("compact", False)))

    def _critical(self, obs: np.ndarray) -> tuple[float, float]:
        """``(s, known)``: the speed over the identified critical speed, and whether it is known."""
        if self._k is None:
            return 0.0, 0.0
        k = float(obs[self.offset + self._k.start])
        flag = obs[self.offset + self._k.stop] > 0.5  # the flag follows the coefficient
        ip = float(obs[self._ip])
        if not (flag and k > 0.0 and ip < 1.0):
            return 0.0, 0.0
        return min(float(obs[0]) * self.speed_scale / math.sqrt(k / (1.0 - ip)), 3.0), 1.0

    def _one(self, obs: np.ndarray) -> np.ndarray:
        head = obs[: self.offset] if self.compact else obs
        out = np.empty(head.shape[0] + self.EXTRA, dtype=np.float32)
        out[: head.shape[0]] = head
        if not self.compact:
            for start, stop, flag in self._effects:
                keep = obs[flag] > 0.5
                out[start:stop] = np.clip(obs[start:stop], -self.limit, self.limit) if keep else 0.0
        out[-2], out[-1] = self._critical(obs)
        return out

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        if obs.ndim == 1:
            return self._one(obs)
        return np.stack([self._one(o) for o in obs])


class ModelFeatureWrapper(gym.ObservationWrapper):
    """Applies :class:`ModelFeatures` to an identification-wrapped env (for training)."""

    def __init__(self, env: gym.Env, features: ModelFeatures | None = None, compact: bool = False) -> None:
        super().__init__(env)
        self.features = ModelFeatures.for_env(env, compact=compact) if features is None else features
        base = env.observation_space
        if self.features.compact:
            off = self.features.offset
            base = spaces.Box(base.low[:off], base.high[:off], dtype=np.float32)
        self.observation_space = spaces.Box(
            np.concatenate([base.low, np.zeros(ModelFeatures.EXTRA, np.float32)]).astype(np.float32),
            np.concatenate([base.high, np.array([3.0, 1.0], np.float32)]).astype(np.float32),
            dtype=np.float32,
        )

    def observation(self, observation):
        return self.features(observation)
