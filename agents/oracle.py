"""The run-up oracle: a schedule optimised on the true rotor for the environment's return.

For each rotor the oracle knows ``params`` and searches a three-phase acceleration
profile — the drive's floor (``u = -1``: the rate that just keeps the deadline) below
``v1``, full drive ``a_max`` from ``v1`` to ``v2``, ``after`` above — maximising the
return of the very environment the agents run in (vibration and effort; the deadline is
kept by the drive), by Nelder–Mead from the slow–fast–slow guess around the true
critical speed.  It shows how close an agent that must *learn* the rotor can get.

:func:`schedule_peak` is the physics check of the issue: the peak of a three-phase
run-up simulated with :func:`rotor_env.simulator.integrate` directly.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from scipy.optimize import minimize

from rotor_env.envs import RotorRunUpEnv
from rotor_env.params import RotorParams
from rotor_env.simulator import Simulator, integrate

from .baselines import Policy, three_phase_action

__all__ = ["RunUpOracle", "schedule_peak"]


def schedule_peak(params: RotorParams, v1, v2, slow, after, a_max, target, t_end,
                  step: float = 0.5, n_rec: int = 10) -> float:
    """Peak amplitude of a three-phase run-up from rest to ``target``, then held to ``t_end``.

    The acceleration is chosen per ``step`` (as the environment's decision interval);
    the amplitude is sampled ``n_rec`` times per step.
    """
    sim = Simulator(params)
    coef, h = sim.coefficients()
    state = np.zeros(4)
    out = np.empty((n_rec, 10))
    t, phi, speed, peak = 0.0, 0.0, 0.0, 0.0
    every, dt_sub = sim.substeps(step / n_rec)
    while t < t_end - 1e-9:
        a = slow if speed < v1 else (a_max if speed < v2 else after)
        a = min(a, (target - speed) / step) if speed < target else 0.0
        done = integrate(sim.accel, state, t, phi, speed, a, params.ip, coef, h, 0.0, 0.0, n_rec, every, dt_sub, out)
        if done < n_rec:
            return math.inf
        t, phi, speed = out[-1, 0], out[-1, 1], out[-1, 2]
        peak = max(peak, float(np.max(np.hypot(out[:, 4], out[:, 5]))))
    return peak


class RunUpOracle(Policy):
    """Follows the schedule optimised (as a function of speed) for the current rotor.

    ``env_kwargs`` are the run-up environment's (its rewards and limits); ``fit(params)``
    optimises ``plan = (v1, v2, after)`` for that rotor.
    """

    name = "oracle"

    def __init__(self, env_kwargs: dict | None = None, max_evaluations: int = 40) -> None:
        self.env = RotorRunUpEnv(**(env_kwargs or {}))
        self.a_max, self.target = self.env.a_max, self.env.target_speed
        self.max_evaluations = max_evaluations
        self.plan = (0.0, 0.0, 0.0)  # the floor everywhere: the constant ramp

    @classmethod
    def for_env(cls, env: gym.Env, **kwargs) -> RunUpOracle:
        """The oracle of ``env``'s run-up task (its constructor arguments)."""
        spec = env.unwrapped.spec
        env_kwargs = dict(spec.kwargs) if spec is not None else {}
        env_kwargs.pop("render_mode", None)
        return cls(env_kwargs, **kwargs)

    def episode_return(self, params: RotorParams, plan: tuple[float, float, float]) -> float:
        """The return of one episode on ``params`` following ``plan``."""
        obs, _ = self.env.reset(seed=0, options={"params": params})
        total, done = 0.0, False
        while not done:
            obs, r, term, trunc, _ = self.env.step(self._action(plan, obs))
            total += float(r)
            done = term or trunc
        return total

    def fit(self, params: RotorParams) -> RunUpOracle:
        """Optimise the schedule for ``params`` (Nelder–Mead from the critical speed)."""
        wc = math.sqrt(params.values.get("k", 1.0) / (1.0 - params.ip))

        def cost(z):
            lo, hi, after = z
            if not (0.05 < lo < hi and 0.0 <= after <= self.a_max):
                return 1e9
            return -self.episode_return(params, (lo * wc, hi * wc, after))

        best = minimize(cost, [0.8, 1.3, 0.015], method="Nelder-Mead",
                        options={"maxfev": self.max_evaluations, "xatol": 1e-3, "fatol": 1e-3,
                                 "initial_simplex": [[0.8, 1.3, 0.015], [0.65, 1.3, 0.015], [0.8, 1.6, 0.015],
                                                     [0.8, 1.3, 0.03]]})
        lo, hi, after = best.x
        self.plan = (lo * wc, hi * wc, after)
        return self

    def _action(self, plan: tuple[float, float, float], obs) -> np.ndarray:
        v1, v2, after = plan  # below v1 the drive's floor (u = -1: acceleration 0, raised by the env)
        return three_phase_action(float(obs[0]) * self.target, v1, v2, 0.0, after, self.a_max)

    def act(self, obs):
        return self._action(self.plan, obs)
