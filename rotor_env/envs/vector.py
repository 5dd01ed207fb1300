"""Numba-batched vector versions of the rotor environments.

``gymnasium.make_vec("rotor_env/RotorRunUp-v0", num_envs=N)`` (``vectorization_mode=
"vector_entry_point"``, the default for these ids) builds :class:`RotorRunUpVectorEnv`;
likewise :class:`RotorBalancingVectorEnv`.  All sub-environments advance in one compiled
call that runs the very same per-rotor step as the single environment
(:func:`rotor_env.envs.core.env_step`), so with the same seeds the two agree exactly.

Conventions (Gymnasium 1.x):

* ``metadata["autoreset_mode"] = AutoresetMode.NEXT_STEP``: a sub-env that ended is reset
  by the *next* ``step`` (its action is ignored; reward 0, not terminated/truncated,
  its ``info["measurements"]`` row is ``NaN`` and ``info["_measurements"]`` is False).
* Seeding: ``reset(seed=s)`` seeds sub-env ``i`` with ``s + i`` (a list gives one seed per
  sub-env), exactly as :class:`gymnasium.vector.SyncVectorEnv` does, and each sub-env
  draws its rotors from its own generator — so sub-env ``i`` reproduces the single env
  reset with ``seed=s + i`` (and its later seedless resets) step by step.
* ``reset(options=...)``: ``"params"`` (one :class:`RotorParams` for all, or a sequence of
  ``num_envs``) and ``"reset_mask"`` (bool array, resets only those sub-envs).
* ``info`` (dict of arrays, each with a ``"_key"`` mask): ``"measurements"``
  ``(N, n_samples, 10)`` float64 (a new array each step), ``"params"`` (object array of
  :class:`RotorParams`), ``"ip"`` (float), ``"peak_amplitude"``, ``"effort"``,
  ``"reason"`` (object array: ``None`` or ``"rub"``/``"unstable"``/``"time_limit"``);
  for the run-up ``"time_to_speed"`` (float, ``NaN`` until reached; its mask says which
  reached it), for balancing ``"control"`` ``(N, 2)``: the moments ``(M_x, M_y)``
  applied during the step.
* ``parallel``: ``None`` (default) uses the ``prange`` kernel when numba has at least 4
  threads and ``num_envs >= 256``, else the serial loop; ``True``/``False`` force it.  On
  2 cores the parallel kernel gains at most 2x and loses it as soon as anything else
  runs on the machine (an OpenMP region waits for its descheduled worker: measured up to
  5x slower than serial on a loaded 2-core box), so there it is opt-in.
* ``render_mode="rgb_array"``: ``render()`` returns a tuple of frames of the first
  ``max_render_envs`` sub-envs (only those keep a history).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numba
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..params import RotorParams
from .balancing import RotorBalancingEnv
from .base import N_COLUMNS, RotorEnvBase
from .core import (
    D_EFFORT,
    D_PEAK,
    D_REASON,
    D_TTS,
    MODE_RUN_UP,
    N_DYN,
    N_OBS,
    N_PAR,
    P_IP,
    R_RUB,
    R_TIME_LIMIT,
    R_UNSTABLE,
    REASONS,
    observe_batch,
)
from .rendering import EpisodeHistory, Renderer
from .run_up import RotorRunUpEnv

__all__ = ["RotorBalancingVectorEnv", "RotorRunUpVectorEnv"]

_REASONS = np.array(REASONS, dtype=object)


class _RotorVectorEnv(VectorEnv):
    _single_cls: type[RotorEnvBase]

    metadata: ClassVar[dict[str, Any]] = {
        "render_modes": ["rgb_array"],
        "render_fps": 30,
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        render_mode: str | None = None,
        *,
        parallel: bool | None = None,
        max_render_envs: int = 4,
        **kwargs: Any,
    ) -> None:
        if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}"
            )
        # the single env holds (and validates) every constant; it is never stepped
        self._tpl = tpl = self._single_cls(render_mode=None, **kwargs)
        n = self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.single_observation_space = tpl.observation_space
        self.single_action_space = tpl.action_space
        self.observation_space = batch_space(tpl.observation_space, n)
        self.action_space = batch_space(tpl.action_space, n)
        self.n_samples = tpl.n_samples
        self.return_measurements = tpl.return_measurements
        self._act_dim = tpl._act_dim
        self._cfg = tpl._cfg
        self._states = np.zeros((n, 4))
        self._dyn = np.zeros((n, N_DYN))
        self._coef = np.zeros((n, tpl._n_coef))
        self._par = np.zeros((n, N_PAR))
        self._u = np.zeros((n, 2))
        self._params = np.full(n, None, dtype=object)
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._autoreset = np.zeros(n, dtype=bool)
        self._started = False
        self._buffer = np.empty((n, self.n_samples, N_COLUMNS))
        if parallel is None:
            parallel = numba.config.NUMBA_NUM_THREADS >= 4 and n >= 256
        self.parallel = bool(parallel)
        self._kernel = None
        n_render = min(n, int(max_render_envs)) if render_mode is not None else 0
        self._hists = [EpisodeHistory() for _ in range(n_render)]
        self._renderers: list[Renderer] = []

    # --------------------------------------------------------------- helpers
    def _reset_one(self, i: int, params: RotorParams | Mapping | None) -> None:
        tpl = self._tpl
        p = tpl._choose_params(self._rngs[i], None if params is None else {"params": params})
        self._states[i], self._dyn[i], self._coef[i], self._par[i] = tpl._load(p)
        self._params[i] = p
        if i < len(self._hists):
            self._hists[i].clear(tpl.clearance, tpl.critical_speed(p), f"{tpl._title} [{i}]")

    def _parse_actions(self, actions: Any) -> np.ndarray:
        shape = (self.num_envs, self._act_dim)
        try:
            arr = np.asarray(actions, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"actions must be a numeric array of shape {shape}, got {actions!r}") from None
        if arr.shape != shape:
            raise ValueError(f"actions must have shape {shape} (the action space), got shape {arr.shape}")
        if np.isnan(arr).any():
            bad = np.flatnonzero(np.isnan(arr).any(axis=1))
            raise ValueError(f"actions contain NaN (sub-environments {bad.tolist()})")
        u = self._u
        np.clip(arr, -1.0, 1.0, out=u[:, : self._act_dim])
        return u

    def _info(self, mask: np.ndarray, out: np.ndarray | None = None, u: np.ndarray | None = None) -> dict[str, Any]:
        n = self.num_envs
        info: dict[str, Any] = {}
        if out is not None:
            info["measurements"] = out
            info["_measurements"] = mask.copy()
        if u is not None and self._tpl._mode != MODE_RUN_UP:
            control = u * self._tpl._m_max
            control[~mask] = 0.0
            info["control"] = control
            info["_control"] = mask.copy()
        all_true = np.ones(n, dtype=bool)
        info["params"] = self._params.copy()
        info["_params"] = all_true.copy()
        info["ip"] = self._par[:, P_IP].copy()
        info["_ip"] = all_true.copy()
        info["peak_amplitude"] = self._dyn[:, D_PEAK].copy()
        info["_peak_amplitude"] = all_true.copy()
        info["effort"] = self._dyn[:, D_EFFORT].copy()
        info["_effort"] = all_true.copy()
        if self._tpl._mode == MODE_RUN_UP:
            tts = self._dyn[:, D_TTS].copy()
            info["time_to_speed"] = tts
            info["_time_to_speed"] = ~np.isnan(tts)
        info["reason"] = _REASONS[self._dyn[:, D_REASON].astype(np.intp)]
        info["_reason"] = all_true
        return info

    # --------------------------------------------------------------- VectorEnv API
    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, (int, np.integer)):
            super().reset(seed=int(seed))
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"a list of seeds must have num_envs={n} entries, got {len(seeds)}")
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is None:
            mask = np.ones(n, dtype=bool)
        else:
            mask = np.asarray(mask)
            if mask.shape != (n,) or mask.dtype != np.bool_ or not mask.any():
                raise ValueError(
                    f"options['reset_mask'] must be a bool array of shape ({n},) with a True entry"
                )
        params = options.pop("params", None)
        if params is not None and not isinstance(params, (RotorParams, Mapping)):
            params = list(params)
            if len(params) != n:
                raise ValueError(f"options['params'] must be one RotorParams or {n} of them")
        for i in np.flatnonzero(mask).tolist():
            if seeds[i] is not None:
                self._rngs[i], _ = seeding.np_random(seeds[i])
            elif self._rngs[i] is None:
                self._rngs[i], _ = seeding.np_random()
            p = params[i] if isinstance(params, list) else params
            self._reset_one(i, p)
        self._autoreset[mask] = False
        self._started = True
        obs = np.empty((n, N_OBS), dtype=np.float32)
        observe_batch(np.ones(n, dtype=bool), self._states, self._dyn, self._cfg, obs)
        info = self._info(mask)
        for key in ("_params", "_ip", "_peak_amplitude", "_effort", "_reason"):
            info[key] = mask.copy()
        return obs, info

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._started:
            raise RuntimeError("call reset() before step()")
        u = self._parse_actions(actions)
        n = self.num_envs
        resetting = self._autoreset
        active = ~resetting
        out = np.empty((n, self.n_samples, N_COLUMNS)) if self.return_measurements else self._buffer
        obs = np.empty((n, N_OBS), dtype=np.float32)
        rew = np.zeros(n)
        kernel = self._kernel
        if kernel is None:
            kernel = self._kernel = self._tpl._kernels.step_batch(self.parallel)
        kernel(active, self._states, self._dyn, self._coef, self._par, self._cfg, u, out, obs, rew)
        if resetting.any():
            for i in np.flatnonzero(resetting).tolist():
                self._reset_one(i, None)
            observe_batch(resetting, self._states, self._dyn, self._cfg, obs)
            out[resetting] = np.nan
        codes = self._dyn[:, D_REASON]
        terminated = (codes == R_RUB) | (codes == R_UNSTABLE)
        truncated = codes == R_TIME_LIMIT
        self._autoreset = terminated | truncated
        info = self._info(active, out if self.return_measurements else None, u)
        for i, hist in enumerate(self._hists):
            if active[i]:
                hist.add(out[i])
        return obs, rew, terminated, truncated, info

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode is None:
            return None
        while len(self._renderers) < len(self._hists):
            self._renderers.append(Renderer("rgb_array", self.metadata["render_fps"], self._tpl._speed_max))
        return tuple(r.draw(h) for r, h in zip(self._renderers, self._hists, strict=True))

    def close_extras(self, **kwargs: Any) -> None:
        for r in self._renderers:
            r.close()
        self._renderers = []

    @property
    def params(self) -> np.ndarray:
        """The current rotors (object array of :class:`RotorParams`)."""
        return self._params.copy()


class RotorRunUpVectorEnv(_RotorVectorEnv):
    """``num_envs`` :class:`RotorRunUpEnv` rotors advanced in one numba call.

    Takes ``num_envs``, ``render_mode``, ``parallel``, ``max_render_envs`` and every
    keyword argument of :class:`RotorRunUpEnv`; see :mod:`rotor_env.envs.vector`.
    """

    _single_cls = RotorRunUpEnv


class RotorBalancingVectorEnv(_RotorVectorEnv):
    """``num_envs`` :class:`RotorBalancingEnv` rotors advanced in one numba call.

    Takes ``num_envs``, ``render_mode``, ``parallel``, ``max_render_envs`` and every
    keyword argument of :class:`RotorBalancingEnv`; see :mod:`rotor_env.envs.vector`.
    """

    _single_cls = RotorBalancingEnv
