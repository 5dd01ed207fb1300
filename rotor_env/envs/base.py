"""Common machinery of the single rotor environments (see :mod:`.run_up`, :mod:`.balancing`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ..measurements import COLUMNS
from ..params import RotorParams
from .core import (
    C_AMAX,
    C_CLEAR,
    C_DEADLINE,
    C_DTSUB,
    C_EVERY,
    C_FAIL,
    C_MAXSTEPS,
    C_MMAX,
    C_MODE,
    C_NREC,
    C_PHIDD_SCALE,
    C_RATE,
    C_SPEED_SCALE,
    C_T,
    C_TARGET,
    C_TMAX,
    C_WEFF,
    C_WTIME,
    C_WVIB,
    D_EFFORT,
    D_PEAK,
    D_PHIDD,
    D_REASON,
    D_TTS,
    ENV_EFFECTS,
    MODE_RUN_UP,
    N_CFG,
    N_DYN,
    N_OBS,
    N_PAR,
    OBS_HIGH,
    OBS_LOW,
    R_RUB,
    R_TIME_LIMIT,
    R_UNSTABLE,
    REASONS,
    coef_layout,
    kernels,
    observe,
)
from .randomization import FAULT_RANGES, TABLE1, check_faults, params_to_arrays, sample_params
from .rendering import EpisodeHistory, Renderer

__all__ = ["MIN_SUBSTEPS", "RotorEnvBase"]

#: Every decision step integrates at least this many RK4 sub-steps.
MIN_SUBSTEPS = 10
N_COLUMNS = len(COLUMNS)


def check_positive(name: str, value: Any, *, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be a finite number {bound}, got {value!r}")
    return v


class RotorEnvBase(gym.Env[np.ndarray, np.ndarray]):
    """Shared implementation; the subclasses hold the manual (their docstrings)."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 30}

    _mode: float = MODE_RUN_UP
    _act_dim: int = 1
    _title: str = "rotor"

    def _setup(
        self,
        *,
        render_mode: str | None,
        randomize: bool,
        clearance: float,
        t_max: float,
        step_dt: float,
        sensor_dt: float,
        max_substep: float,
        w_vibration: float,
        w_time: float,
        w_effort: float,
        fail_penalty: float | None,
        speed_scale: float,
        phidd_scale: float,
        target_speed: float = 0.0,
        a_max: float = 0.0,
        m_max: float = 0.0,
        spin_rate: float = 0.0,
        deadline: float = -1.0,
        return_measurements: bool = True,
        faults: Mapping[str, float] | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}"
            )
        self.render_mode = render_mode
        self.randomize = bool(randomize)
        #: field faults drawn per episode (effect -> probability); the kernel simulates them too
        self.faults = check_faults(faults)
        self._env_effects = (*ENV_EFFECTS, *(f for f in FAULT_RANGES if f in self.faults))
        _, self._n_coef = coef_layout(self._env_effects)
        self.clearance = check_positive("clearance", clearance)
        self.t_max = check_positive("t_max", t_max)
        self.step_dt = check_positive("step_dt", step_dt)
        self.sensor_dt = check_positive("sensor_dt", sensor_dt)
        self.max_substep = check_positive("max_substep", max_substep)
        n_rec = round(self.step_dt / self.sensor_dt)
        if n_rec < 1 or abs(n_rec * self.sensor_dt - self.step_dt) > 1e-9 * self.step_dt:
            raise ValueError(
                f"step_dt ({step_dt}) must be a whole multiple of sensor_dt ({sensor_dt})"
            )
        every = max(1, math.ceil(self.sensor_dt / self.max_substep - 1e-9))
        if n_rec * every < MIN_SUBSTEPS:
            raise ValueError(
                f"a step of {step_dt} with sub-steps <= {max_substep} has only {n_rec * every} "
                f"integration sub-steps; at least {MIN_SUBSTEPS} are required (make step_dt longer "
                f"or max_substep smaller)"
            )
        self.n_samples = int(n_rec)
        self.substeps_per_step = int(n_rec * every)
        self.max_steps = max(1, math.ceil(self.t_max / self.step_dt - 1e-9))
        self.w_vibration = check_positive("w_vibration", w_vibration, allow_zero=True)
        self.w_time = check_positive("w_time", w_time, allow_zero=True)
        self.w_effort = check_positive("w_effort", w_effort, allow_zero=True)
        worst = self.w_vibration + self.w_time + self.w_effort
        self.fail_penalty = (
            self.max_steps * worst if fail_penalty is None
            else check_positive("fail_penalty", fail_penalty, allow_zero=True)
        )
        self.return_measurements = bool(return_measurements)

        cfg = np.zeros(N_CFG)
        cfg[C_MODE] = self._mode
        cfg[C_T] = self.step_dt
        cfg[C_TARGET] = target_speed
        cfg[C_AMAX] = a_max
        cfg[C_CLEAR] = self.clearance
        cfg[C_TMAX] = self.t_max
        cfg[C_WVIB] = self.w_vibration
        cfg[C_WTIME] = self.w_time
        cfg[C_DEADLINE] = deadline
        cfg[C_WEFF] = self.w_effort
        cfg[C_FAIL] = self.fail_penalty
        cfg[C_MMAX] = m_max
        cfg[C_RATE] = spin_rate
        cfg[C_SPEED_SCALE] = speed_scale
        cfg[C_PHIDD_SCALE] = phidd_scale
        cfg[C_MAXSTEPS] = self.max_steps
        cfg[C_NREC] = n_rec
        cfg[C_EVERY] = every
        cfg[C_DTSUB] = self.sensor_dt / every
        self._cfg = cfg
        self._speed_max = speed_scale
        self._m_max = float(m_max)

        self._act_shape = (self._act_dim,)
        self.action_space = spaces.Box(-1.0, 1.0, shape=self._act_shape, dtype=np.float32)
        self.observation_space = spaces.Box(OBS_LOW.copy(), OBS_HIGH.copy(), dtype=np.float32)

        self._state = np.zeros(4)
        self._dyn = self._initial_dyn()
        self._coef = np.zeros(self._n_coef)
        self._par = np.zeros(N_PAR)
        self._params: RotorParams | None = None
        self._done = True
        self._buffer = np.empty((self.n_samples, N_COLUMNS))
        self._kernels = kernels(self._env_effects)
        self._step_one = None
        self._hist = EpisodeHistory() if render_mode is not None else None
        self._renderer = None

    # ---------------------------------------------------------------- helpers
    def _initial_dyn(self) -> np.ndarray:
        dyn = np.zeros(N_DYN)
        dyn[D_PHIDD] = self._cfg[C_RATE] if self._mode != MODE_RUN_UP else 0.0
        dyn[D_TTS] = np.nan
        return dyn

    def _choose_params(self, rng: np.random.Generator, options: Mapping | None) -> RotorParams:
        if options is not None and options.get("params") is not None:
            p = options["params"]
            if isinstance(p, Mapping):
                p = RotorParams.from_dict(p)
            return p
        if self.randomize:
            return sample_params(rng, self.faults)
        return TABLE1

    def _load(self, params: RotorParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(state, dyn, coef, par)`` of a rotor at rest at t = 0."""
        coef, par = params_to_arrays(params, self.sensor_dt, self._env_effects)
        return np.zeros(4), self._initial_dyn(), coef, par

    @staticmethod
    def critical_speed(params: RotorParams) -> float:
        """Undamped synchronous forward critical speed ``sqrt(k / (1 - ip))``."""
        k = params.k if "stiffness" in params.effects else 0.0
        return math.sqrt(k / (1.0 - params.ip))

    def _reset_info(self) -> dict[str, Any]:
        info: dict[str, Any] = {
            "params": self._params, "ip": self._params.ip, "peak_amplitude": 0.0, "effort": 0.0,
        }
        if self._mode == MODE_RUN_UP:
            info["time_to_speed"] = None
        info["reason"] = None
        return info

    def _parse_action(self, action: Any) -> tuple[float, float]:
        if type(action) is np.ndarray and action.shape == self._act_shape and action.dtype.kind == "f":
            vals = action.tolist()
        else:
            try:
                arr = np.asarray(action, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(
                    f"action must be a numeric array of shape {self._act_shape}, got {action!r}"
                ) from None
            if arr.shape != self._act_shape:
                raise ValueError(
                    f"action must have shape {self._act_shape} (the action space), got shape "
                    f"{arr.shape}: {action!r}"
                )
            vals = arr.tolist()
        u0 = vals[0]
        u1 = vals[1] if self._act_dim == 2 else 0.0
        if u0 != u0 or u1 != u1:
            raise ValueError(f"action contains NaN: {action!r}")
        # out-of-range values (including +-inf) are clipped to [-1, 1]
        u0 = -1.0 if u0 < -1.0 else (1.0 if u0 > 1.0 else u0)
        u1 = -1.0 if u1 < -1.0 else (1.0 if u1 > 1.0 else u1)
        return u0, u1

    # -------------------------------------------------------------- Gym API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        params = self._choose_params(self.np_random, options)
        self._state, self._dyn, self._coef, self._par = self._load(params)
        self._params = params
        self._done = False
        obs = np.empty(N_OBS, dtype=np.float32)
        observe(self._state, self._dyn, self._cfg, obs)
        if self._hist is not None:
            self._hist.clear(self.clearance, self.critical_speed(params), self._title)
            if self.render_mode == "human":
                self.render()
        return obs, self._reset_info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._done:
            raise RuntimeError(
                "the episode has ended (or reset() was never called): call reset() before step()"
            )
        u0, u1 = self._parse_action(action)
        out = np.empty((self.n_samples, N_COLUMNS)) if self.return_measurements else self._buffer
        obs = np.empty(N_OBS, dtype=np.float32)
        step_one = self._step_one
        if step_one is None:
            step_one = self._step_one = self._kernels.step_one
        reward = step_one(self._state, self._dyn, self._coef, self._par, self._cfg, u0, u1, out, obs)
        d = self._dyn.tolist()
        code = int(d[D_REASON])
        terminated = code == R_RUB or code == R_UNSTABLE
        truncated = code == R_TIME_LIMIT
        self._done = terminated or truncated
        info: dict[str, Any] = {
            "params": self._params, "ip": self._params.ip, "peak_amplitude": d[D_PEAK], "effort": d[D_EFFORT],
        }
        if self._mode == MODE_RUN_UP:
            tts = d[D_TTS]
            info["time_to_speed"] = None if tts != tts else tts
        else:
            m_max = self._m_max
            info["control"] = np.array((m_max * u0, m_max * u1))
        info["reason"] = REASONS[code]
        if self.return_measurements:
            info["measurements"] = out
        if self._hist is not None:
            self._hist.add(out)
            if self.render_mode == "human":
                self.render()
        return obs, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn(
                "You are calling render method without specifying any render mode. "
                f'You can specify the render_mode at initialization, e.g. gym.make("{self.spec.id if self.spec else "..."}", render_mode="rgb_array")'
            )
            return None
        if self._renderer is None:
            self._renderer = Renderer(self.render_mode, self.metadata["render_fps"], self._speed_max)
        return self._renderer.draw(self._hist)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()

    # ------------------------------------------------------------- extras
    @property
    def params(self) -> RotorParams | None:
        """The current episode's rotor (``None`` before the first reset)."""
        return self._params

    @property
    def sim_state(self) -> tuple[float, ...]:
        """``(t, phi, phi_dot, theta_x, theta_y, theta_x_dot, theta_y_dot)``, unscaled."""
        d = self._dyn
        return (float(d[0]), float(d[1]), float(d[2]), *map(float, self._state))
