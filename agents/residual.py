"""Residual policies: a learned correction on top of a model-based baseline.

A model-based agent (:class:`agents.baselines.ModelBasedRunUp`,
:class:`agents.baselines.ModelBasedBalancer`) turns the identified model into an action
with a few lines of physics; what it cannot do is adapt the details (how early to
start the fast crossing, how hard to push through a friction whirl) to what the
rotor does.  Residual policy learning (Silver et al. 2018, "Residual Policy Learning";
Johannink et al. 2019, "Residual Reinforcement Learning for Robot Control") lets a
network learn only that correction::

    u = clip(u_base(obs) + scale * clip(u_net(features(obs)), -1, 1), -1, 1)

``u_base`` reads the identification wrapper's observation (the identified stiffness,
unbalance...), so the residual agent uses the identified model twice: through the
baseline's physics and through the features its network sees.  An untrained network
(mean output zero) already acts like the baseline, so training starts from a good
policy instead of from scratch.

:class:`Residual` is that map and its JSON description (stored in ``run.json``);
:class:`ResidualActionWrapper` applies it to an environment for training.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from .baselines import ModelBasedBalancer, ModelBasedRunUp

__all__ = ["BASES", "Residual", "ResidualActionWrapper"]

#: baselines a residual policy can build on: name -> class (``for_env``, ``to_json``, ``from_json``)
BASES: dict[str, type] = {"model_based_runup": ModelBasedRunUp, "model_based_balancer": ModelBasedBalancer}
#: the model-based baseline of each environment
BASE_FOR_ENV = {"rotor_env/RotorRunUp-v0": "model_based_runup",
                "rotor_env/RotorBalancing-v0": "model_based_balancer"}


class Residual:
    """``u = clip(u_base(obs) + scale * clip(u_net, -1, 1), -1, 1)`` (see the module).

    ``base`` is a baseline agent with ``act(obs) -> action`` on the identification
    wrapper's observation; ``scale`` bounds how far the network may move its action.
    """

    def __init__(self, base, scale: float = 1.0) -> None:
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"residual scale must be a positive number, got {scale!r}")
        self.base, self.scale = base, float(scale)
        self.base_name = next((k for k, c in BASES.items() if isinstance(base, c)), None)
        if self.base_name is None:
            raise ValueError(f"no residual base of type {type(base).__name__}; known: {', '.join(BASES)}")

    @classmethod
    def for_env(cls, env: gym.Env, env_id: str, scale: float = 1.0) -> Residual:
        if env_id not in BASE_FOR_ENV:
            raise ValueError(f"no model-based baseline for {env_id!r}; known: {', '.join(BASE_FOR_ENV)}")
        return cls(BASES[BASE_FOR_ENV[env_id]].for_env(env), scale)

    def __call__(self, obs: np.ndarray, net_action: np.ndarray) -> np.ndarray:
        """The applied action for one raw observation (or a batch) and the network's action."""
        obs = np.asarray(obs, dtype=np.float32)
        net = np.clip(np.asarray(net_action, dtype=np.float32), -1.0, 1.0)
        base = self.base.act(obs) if obs.ndim == 1 else np.stack([self.base.act(o) for o in obs])
        return np.clip(base + self.scale * net, -1.0, 1.0).astype(np.float32)

    def to_json(self) -> dict:
        return {"base": self.base_name, "scale": self.scale, "base_args": self.base.to_json()}

    @classmethod
    def from_json(cls, d: dict) -> Residual:
        if d.get("base") not in BASES:
            raise ValueError(f"run.json: unknown residual base {d.get('base')!r}; known: {', '.join(BASES)}")
        return cls(BASES[d["base"]].from_json(d["base_args"]), float(d["scale"]))


class ResidualActionWrapper(gym.Wrapper):
    """Trains a residual: the agent's action is the network's, the env gets :class:`Residual`'s.

    Wrap the identification-wrapped env (its observation is what the baseline reads);
    feature wrappers go outside.  The action space is unchanged (``[-1, 1]``).
    """

    def __init__(self, env: gym.Env, residual: Residual) -> None:
        super().__init__(env)
        self.residual = residual
        self._obs: np.ndarray | None = None

    def reset(self, *, seed=None, options=None):
        self._obs, info = self.env.reset(seed=seed, options=options)
        return self._obs, info

    def step(self, action):
        if self._obs is None:
            raise RuntimeError("call reset() before step()")
        action = np.asarray(action, dtype=np.float32)
        if action.shape != self.action_space.shape or np.isnan(action).any():
            return self.env.step(action)  # the env names the problem (shape, NaN)
        applied = self.residual(self._obs, action)
        self._obs, reward, terminated, truncated, info = self.env.step(applied)
        info["applied_action"] = applied
        return self._obs, reward, terminated, truncated, info
