"""The run-up oracle: a slow–fast–slow schedule optimised with the true parameters.

For each rotor the oracle knows ``params`` and searches a three-phase acceleration
profile (``slow`` below ``v1``, full drive ``a_max`` from ``v1`` to ``v2``, ``after``
above) minimising the run-up's peak amplitude, with the time to reach the target
speed held to the constant-ramp's (``target / 0.01``) — so it shows how close an
agent that must *learn* the rotor can get.  The search simulates the run with
:func:`rotor_env.simulator.integrate` directly (a few ms per trial).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize

from rotor_env.params import RotorParams
from rotor_env.simulator import Simulator, integrate

from .baselines import Policy

__all__ = ["RunUpOracle", "schedule_peak"]


def _schedule(v1: float, v2: float, slow: float, a_max: float, target: float, t_budget: float):
    """Accelerations for the three phases: ``after`` is set so the budget is met exactly."""
    t1 = v1 / slow
    t2 = (v2 - v1) / a_max
    rest = t_budget - t1 - t2
    after = (target - v2) / rest if rest > 0 else a_max
    return slow, min(max(after, 1e-4), a_max)


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
    """Follows the optimised schedule (as a function of speed) for the current rotor."""

    name = "oracle"

    def __init__(self, a_max: float, target_speed: float, t_max: float, rate: float = 0.01,
                 max_evaluations: int = 60) -> None:
        self.a_max, self.target, self.t_max = a_max, target_speed, t_max
        self.max_evaluations = max_evaluations
        self.t_budget = target_speed / rate
        self.plan = (0.0, 0.0, rate, rate)

    def fit(self, params: RotorParams) -> RunUpOracle:
        """Optimise the schedule for ``params`` (Nelder–Mead from the critical speed)."""
        wc = math.sqrt(params.values.get("k", 1.0) / (1.0 - params.ip))

        def cost(z):
            v1, v2, slow = z
            if not (0.05 < v1 < v2 < self.target and 0.002 <= slow <= self.a_max):
                return 10.0
            if v1 / slow + (v2 - v1) / self.a_max >= self.t_budget:
                return 10.0
            s, after = _schedule(v1, v2, slow, self.a_max, self.target, self.t_budget)
            return schedule_peak(params, v1, v2, s, after, self.a_max, self.target, self.t_max)

        # start from the slow-fast-slow guess around the true critical speed
        best = minimize(cost, [0.8 * wc, min(1.3 * wc, 0.95 * self.target), 0.008], method="Nelder-Mead",
                        options={"maxfev": self.max_evaluations, "xatol": 1e-3, "fatol": 1e-4})
        v1, v2, slow = best.x
        s, after = _schedule(v1, v2, slow, self.a_max, self.target, self.t_budget)
        self.plan = (v1, v2, s, after)
        return self

    def act(self, obs):
        v1, v2, slow, after = self.plan
        speed = float(obs[0]) * self.target
        a = slow if speed < v1 else (self.a_max if speed < v2 else after)
        return np.array([2.0 * a / self.a_max - 1.0], dtype=np.float32)
