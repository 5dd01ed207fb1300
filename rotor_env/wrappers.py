"""Identification in the loop: the on-line identification engine inside a Gymnasium environment.

The engine itself (:class:`~rotor_env.online.IdentificationCore`) lives in
:mod:`rotor_env.online`; these wrappers only lay its features beside the environment's
observation.
"""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from identifier import RecursiveQR

from .online import MEASUREMENT_WIDTH, WRAPPER_EFFECTS, IdentificationBatch, IdentificationCore

__all__ = ["WRAPPER_EFFECTS", "IdentificationWrapper", "VectorIdentificationWrapper"]


class IdentificationWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Runs a :class:`identifier.RecursiveQR` inside a rotor environment.

    At every step it feeds all measurement samples of the step
    (``info["measurements"]``) to the estimator through the regression of
    :mod:`rotor_env.regression` and appends what it identified to the observation.

    Observation
    -----------
    A flat ``Box(float32)``: the wrapped env's observation, the inertia ratio ``ip`` the
    regression uses (known), then for each effect (in the order of ``effects``) its
    coefficient(s) and a significance flag, then (options) ``log10 p`` per effect and
    ``log10 J_n`` (the residual energy)::

        [ env obs | ip | stiffness: k, flag | unbalance: tau cos(beta), tau sin(beta), flag |
          asymmetry: D, flag | viscous_damping: c, flag |
          nonlinear_stiffness: k21, k12, k03, flag | structural_damping: h, flag |
          (log10 p per effect) | (log10 J) ]

    ``wrapper.layout`` maps ``"ip"``, ``"<effect>.coefficients"``, ``"<effect>.significant"``,
    ``"<effect>.log10_p"``, ``"log10_residual_energy"`` to slices of the appended part
    (offset by ``wrapper.offset``).  A flag is 1 when the effect's partial F-test
    (``test="last"``: the full model against the full model without the effect;
    ``"nested"``: the effect added to the effects before it) has ``p < alpha`` — and
    only once the data are informative: at least ``min_samples`` samples, and the
    effect's columns identifiable (a rotor at rest excites nothing).  Coefficients of
    columns that are not identifiable read 0.

    Arguments
    ---------
    effects: effect names, in nested order (default: stiffness + the default preset).
    equation: ``"first"``, ``"second"`` or ``"both"`` (see :mod:`rotor_env.regression`).
    forgetting, prior: of the estimator (``forgetting < 1`` tracks effects that appear
        mid-run, such as a crack).
    alpha, test, min_samples: of the significance flags.
    include_p_values, include_energy: append ``log10 p`` per effect / ``log10 J``.
    keep_estimator: ``reset()`` keeps the estimator's data (same rotor, new episode).
    stick_speed: samples where the disk's speed relative to the shaft is at most this
        are skipped: a disk stuck by dry friction tells nothing about the dynamics and
        would bias the unbalance and damping towards zero (0 keeps every sample).
    noise_floor: the F-tests take the residual standard deviation per regression row
        as at least this (default 1e-4).  On noise-free simulated data what is left is
        integration error, against which any numerical mismatch would be "significant";
        on real, noisy data the floor is far below the noise and changes nothing.

    Known moments: if the env reports ``info["control"]`` (``M_x, M_y`` applied during
    the step), they are subtracted from ``y``.
    """

    def __init__(
        self,
        env: gym.Env,
        effects: Sequence[str] = WRAPPER_EFFECTS,
        *,
        equation: str = "first",
        forgetting: float = 1.0,
        prior: float = 0.0,
        alpha: float = 0.05,
        test: str = "last",
        min_samples: int = 500,
        include_p_values: bool = False,
        include_energy: bool = False,
        keep_estimator: bool = False,
        stick_speed: float = 1e-4,
        noise_floor: float = 1e-4,
    ) -> None:
        # recorded so that gymnasium can re-create the wrapped env from its spec
        gym.utils.RecordConstructorArgs.__init__(
            self, effects=tuple(effects), equation=equation, forgetting=forgetting, prior=prior, alpha=alpha,
            test=test, min_samples=min_samples, include_p_values=include_p_values,
            include_energy=include_energy, keep_estimator=keep_estimator, stick_speed=stick_speed,
            noise_floor=noise_floor,
        )
        gym.Wrapper.__init__(self, env)
        base = env.observation_space
        if not isinstance(base, spaces.Box) or len(base.shape) != 1:
            raise ValueError(f"IdentificationWrapper needs a flat Box observation space, got {base}")
        self.core = IdentificationCore(
            effects, equation=equation, forgetting=forgetting, prior=prior, alpha=alpha, test=test,
            min_samples=min_samples, include_p_values=include_p_values, include_energy=include_energy,
            stick_speed=stick_speed, noise_floor=noise_floor,
        )
        self.keep_estimator = keep_estimator
        self.offset = base.shape[0]
        low, high = self.core.bounds()
        self.observation_space = spaces.Box(
            low=np.concatenate([base.low.astype(np.float32), low]),
            high=np.concatenate([base.high.astype(np.float32), high]),
            dtype=np.float32,
        )

    @property
    def estimator(self) -> RecursiveQR:
        return self.core.estimator

    @property
    def layout(self) -> dict[str, slice]:
        return self.core.layout

    def _obs(self, obs: np.ndarray) -> np.ndarray:
        return np.concatenate([np.asarray(obs, dtype=np.float32), self.core.features()])

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        ip = info["params"].ip if "params" in info else self.core.ip
        if self.keep_estimator and self.core.estimator.n_samples > 0:
            self.core.ip = float(ip)
        else:
            self.core.reset(ip)
        self.core.update(info.get("measurements", np.empty((0, 10))), info.get("control"))
        return self._obs(obs), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        obs = self.core.step_observation(obs, info["measurements"], info.get("control"))
        return obs, reward, terminated, truncated, info


class VectorIdentificationWrapper(gym.vector.VectorWrapper):
    """:class:`IdentificationWrapper` for a vector env: one identifier per sub-env.

    Expects ``info["measurements"]`` of shape ``(num_envs, samples, 10)`` and the
    ``next-step`` autoreset mode: a sub-env that ended is reset on the following
    step, and so is its identifier.
    """

    def __init__(self, env: gym.vector.VectorEnv, effects: Sequence[str] = WRAPPER_EFFECTS, **kwargs) -> None:
        super().__init__(env)
        self.cores = [IdentificationCore(effects, **kwargs) for _ in range(env.num_envs)]
        base = env.single_observation_space
        low, high = self.cores[0].bounds()
        self.single_observation_space = spaces.Box(
            np.concatenate([base.low.astype(np.float32), low]),
            np.concatenate([base.high.astype(np.float32), high]),
            dtype=np.float32,
        )
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, env.num_envs)
        self._done = np.zeros(env.num_envs, dtype=bool)
        # one compiled call steps every sub-env's identifier
        self._batch = IdentificationBatch(self.cores)

    def _ips(self, info) -> np.ndarray:
        if "ip" in info:
            return np.asarray(info["ip"], dtype=float)
        return np.array([c.ip for c in self.cores])

    def _obs(self, obs: np.ndarray) -> np.ndarray:
        feats = np.stack([c.features() for c in self.cores])
        return np.concatenate([np.asarray(obs, dtype=np.float32), feats], axis=1)

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        # options["reset_mask"] resets only those sub-envs: the others keep their identifier
        mask = (options or {}).get("reset_mask")
        mask = np.ones(len(self.cores), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        for c, ip, m in zip(self.cores, self._ips(info), mask, strict=True):
            if m:
                c.reset(ip)
        self._done[mask] = False
        return self._obs(obs), info

    def step(self, actions):
        obs, reward, terminated, truncated, info = self.env.step(actions)
        n_envs = len(self.cores)
        if "measurements" in info:
            meas = np.asarray(info["measurements"], dtype=float)
        elif self._done.all():
            # gymnasium's SyncVectorEnv merges the sub-envs' infos: on a step where every
            # sub-env was reset (all ended together) only reset infos remain, which carry
            # no measurements; no identifier steps then (each is reset below)
            meas = np.zeros((n_envs, 0, MEASUREMENT_WIDTH))
        else:
            stepping = np.flatnonzero(~self._done).tolist()
            raise ValueError(f"info has no 'measurements' although sub-envs {stepping} stepped")
        # a sub-env done on the last step was reset on this one: so is its identifier
        out = self._batch.step(meas, info.get("control"), obs, ~self._done, self._ips(info))
        self._done = np.logical_or(terminated, truncated)
        return out, reward, terminated, truncated, info
