"""Classical and model-based baselines with the ``predict`` shape of an SB3 policy.

Every agent answers ``predict(obs, state=None, episode_start=None, deterministic=True)``
with ``(action, state)`` for one observation or a batch, so evaluation treats them
and trained Stable-Baselines3 models alike.  The model-based agents read the
identified parameters that :class:`rotor_env.IdentificationWrapper` appends to the
observation (its ``layout``), never the true ones.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np

__all__ = [
    "ConstantRamp",
    "Fastest",
    "ModelBasedBalancer",
    "ModelBasedPolicy",
    "ModelBasedRunUp",
    "NoControl",
    "Policy",
    "find_wrapper_attr",
    "layout_from_json",
    "layout_to_json",
    "three_phase_action",
]

#: Prior band of critical speeds of the randomised rotors (k in [0.64, 1.44], ip in [0.1, 0.5]).
PRIOR_CRITICAL = (math.sqrt(0.64 / 0.9), math.sqrt(1.44 / 0.5))


def layout_to_json(layout: dict[str, slice]) -> dict[str, list[int]]:
    """The identification wrapper's ``layout`` as JSON (``[start, stop]`` per entry)."""
    return {k: [v.start, v.stop] for k, v in layout.items()}


def layout_from_json(d: dict[str, list[int]]) -> dict[str, slice]:
    return {k: slice(*v) for k, v in d.items()}


def three_phase_action(speed: float, lo: float, hi: float, slow: float, after: float,
                       a_max: float) -> np.ndarray:
    """The run-up command of a slow–fast–slow schedule: ``slow`` below ``lo``, full
    drive ``a_max`` up to ``hi``, ``after`` above (accelerations mapped to ``u``)."""
    a = slow if speed < lo else (a_max if speed < hi else after)
    return np.array([2.0 * a / a_max - 1.0], dtype=np.float32)


def find_wrapper_attr(env: gym.Env, name: str):
    """An attribute from the outermost wrapper (or the env) that has it."""
    e = env
    while True:
        if name in vars(e) or hasattr(type(e), name):
            return getattr(e, name)
        if not hasattr(e, "env"):
            raise AttributeError(f"no wrapper of {env} has {name!r}")
        e = e.env


class Policy:
    """Base: subclasses implement ``act(obs_1d) -> action_1d``."""

    name = "policy"

    def act(self, obs: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def reset(self) -> None:
        """Called at the start of an episode (stateless agents ignore it)."""

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        obs = np.asarray(observation, dtype=np.float32)
        if obs.ndim == 1:
            return self.act(obs).astype(np.float32), state
        return np.stack([self.act(o) for o in obs]).astype(np.float32), state


class ModelBasedPolicy(Policy):
    """Base of the agents that read the identification wrapper's observation.

    Their constructor takes the wrapper's ``layout`` and ``offset`` first and JSON-able
    numbers after; ``to_json`` lists those arguments so that the agent can be rebuilt
    (e.g. as a residual policy's baseline, from ``run.json``).
    """

    def _bind_layout(self, layout: dict[str, slice], offset: int) -> None:
        self.layout, self.offset = layout_from_json(layout_to_json(layout)), int(offset)

    def to_json(self) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError

    @classmethod
    def from_json(cls, d: dict):
        return cls(**{**d, "layout": layout_from_json(d["layout"])})


class ConstantRamp(Policy):
    """The paper's run-up: constant spin acceleration ``rate`` (default 0.01)."""

    name = "constant_ramp"

    def __init__(self, a_max: float, rate: float = 0.01) -> None:
        self.u = np.array([2.0 * rate / a_max - 1.0], dtype=np.float32)

    def act(self, obs):
        return self.u


class Fastest(Policy):
    """The fastest admissible run-up: full drive (``a_max``) until the target speed."""

    name = "fastest"

    def act(self, obs):
        return np.ones(1, dtype=np.float32)


class NoControl(Policy):
    """No correction moments."""

    name = "no_control"

    def act(self, obs):
        return np.zeros(2, dtype=np.float32)


class ModelBasedRunUp(ModelBasedPolicy):
    """Slow–fast–slow: cross the identified critical band at full drive.

    The critical speed of the forward whirl is ``sqrt(k / (1 - ip))`` with ``k`` the
    identified stiffness (``ip`` known).  Until the stiffness is significant the agent
    assumes the prior band of the randomised rotors.  Below the band it accelerates at
    ``slow``, inside ``[lo * w_c, hi * w_c]`` at full drive, above it at ``after``; the
    defaults reach the target no later than the constant 0.01 ramp.
    """

    name = "model_based"

    def __init__(
        self,
        layout: dict[str, slice],
        offset: int,
        a_max: float,
        target_speed: float,
        slow: float = 0.008,
        after: float = 0.015,
        lo: float = 0.8,
        hi: float = 1.3,
    ) -> None:
        self._bind_layout(layout, offset)
        self.k_idx = offset + layout["stiffness.coefficients"].start
        self.k_flag = offset + layout["stiffness.significant"].start
        self.ip_idx = offset + layout["ip"].start
        self.a_max, self.target = float(a_max), float(target_speed)
        self.slow, self.after, self.lo, self.hi = float(slow), float(after), float(lo), float(hi)

    def to_json(self) -> dict:
        """The constructor's arguments (JSON), e.g. for a residual policy's ``run.json``."""
        return {"layout": layout_to_json(self.layout), "offset": self.offset, "a_max": self.a_max,
                "target_speed": self.target, "slow": self.slow, "after": self.after, "lo": self.lo,
                "hi": self.hi}

    @classmethod
    def for_env(cls, env: gym.Env, **kwargs) -> ModelBasedRunUp:
        u = env.unwrapped
        return cls(find_wrapper_attr(env, "layout"), find_wrapper_attr(env, "offset"), u.a_max,
                   u.target_speed, **kwargs)

    def band(self, obs: np.ndarray) -> tuple[float, float]:
        k, flag, ip = float(obs[self.k_idx]), obs[self.k_flag] > 0.5, float(obs[self.ip_idx])
        if flag and k > 0:
            wc = math.sqrt(k / (1.0 - ip))
            return self.lo * wc, self.hi * wc
        return self.lo * PRIOR_CRITICAL[0], self.hi * PRIOR_CRITICAL[1]

    def act(self, obs):
        speed = float(obs[0]) * self.target
        lo, hi = self.band(obs)
        return three_phase_action(speed, lo, hi, self.slow, self.after, self.a_max)


class ModelBasedBalancer(ModelBasedPolicy):
    """Cancels the identified unbalance moment (magnitude and phase), plus active damping.

    The unbalance moment is the unbalance effect's columns times its identified
    coefficients ``(tau cos beta, tau sin beta)`` — the same declaration the simulator
    uses — evaluated at the observed spin angle, speed and acceleration; the agent
    applies its negative.  A small velocity feedback ``-g theta'`` damps what remains
    (the dry-friction whirl).

    The environment holds each action for a step ``dt`` while the unbalance moment
    turns by ``speed * dt`` (up to ~1.3 rad): a staircase whose synchronous (1x) part
    is ``sinc(speed dt / 2)`` times the held value, lagging by ``speed dt / 2``.  The
    agent therefore evaluates the moment at the mid-step angle and divides by the sinc,
    so the 1x part of what it applies cancels the unbalance exactly; what remains is at
    the step rate, far above the critical speed.
    """

    name = "model_based"

    def __init__(
        self,
        layout: dict[str, slice],
        offset: int,
        m_max: float,
        speed_scale: float,
        phidd_scale: float,
        clearance: float,
        step_dt: float,
        damping_gain: float = 0.3,
    ) -> None:
        from rotor_env.effects import get_effect

        self._bind_layout(layout, offset)
        sl = layout["unbalance.coefficients"]
        self.coef = slice(offset + sl.start, offset + sl.stop)
        self.ip_idx = offset + layout["ip"].start
        self.columns = get_effect("unbalance").columns
        self.m_max, self.speed_scale, self.phidd_scale = float(m_max), float(speed_scale), float(phidd_scale)
        self.clearance, self.gain, self.dt = float(clearance), float(damping_gain), float(step_dt)

    def to_json(self) -> dict:
        """The constructor's arguments (JSON), e.g. for a residual policy's ``run.json``."""
        return {"layout": layout_to_json(self.layout), "offset": self.offset, "m_max": self.m_max,
                "speed_scale": self.speed_scale, "phidd_scale": self.phidd_scale, "clearance": self.clearance,
                "step_dt": self.dt, "damping_gain": self.gain}

    @classmethod
    def for_env(cls, env: gym.Env, **kwargs) -> ModelBasedBalancer:
        u = env.unwrapped
        return cls(find_wrapper_attr(env, "layout"), find_wrapper_attr(env, "offset"), u.m_max,
                   u._speed_max, u.spin_rate, u.clearance, u.step_dt, **kwargs)

    def act(self, obs):
        speed = float(obs[0]) * self.speed_scale
        phidd = float(obs[1]) * self.phidd_scale
        half = 0.5 * self.dt
        phi = math.atan2(float(obs[3]), float(obs[2])) + speed * half + 0.5 * phidd * half * half
        x = (speed + phidd * half) * half
        gain = x / math.sin(x) if x > 1e-6 else 1.0  # 1 / sinc: the hold's 1x attenuation
        ip = float(obs[self.ip_idx])
        cy, cx = self.columns(phi, speed + phidd * half, phidd, 0.0, 0.0, 0.0, 0.0, ip)
        c = obs[self.coef].astype(float) * gain
        m_y = -(c[0] * cy[0] + c[1] * cy[1]) - self.gain * float(obs[7]) * self.clearance
        m_x = -(c[0] * cx[0] + c[1] * cx[1]) - self.gain * float(obs[6]) * self.clearance
        return np.clip(np.array([m_x, m_y]) / self.m_max, -1.0, 1.0).astype(np.float32)
