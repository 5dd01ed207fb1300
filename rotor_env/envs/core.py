"""Compiled per-rotor step of the environments, shared by the single and the vector envs.

One decision step of one rotor is one call of :func:`env_step`: it maps the (already
validated and clipped) action to the spin acceleration or the control moments, advances
the rotor with the simulator's RK4 kernel :func:`rotor_env.simulator.integrate` (so the
dynamics are exactly the simulator's), records the sensor samples, and computes the
reward, the end-of-episode reason and the observation.  The single environment calls it
through a compiled closure (:func:`kernels`), the vector environment loops it over the
batch (serially or with ``prange``), so both run the very same code.

Per-rotor state lives in small float64 arrays (no Python objects per step):

* ``state`` ``[th_x, th_y, w_x, w_y]`` (the simulator's state vector);
* ``dyn``   episode bookkeeping, indices ``D_*`` below;
* ``coef``  the smooth-effect coefficient vector for :data:`ENV_EFFECTS` (absent effects 0);
* ``par``   ``[h, ip, crack sample index (inf: none), crack D]``;
* ``cfg``   the environment's constants (shared by all rotors of a vector env), ``C_*``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..effects import PHYSICAL_EFFECTS
from ..simulator import compile_accel, integrate, smooth_effects

__all__ = ["ENV_EFFECTS", "N_COEF", "N_OBS", "REASONS", "coef_layout", "kernels"]

#: The effects every environment rotor is built from (absent effects have coefficient 0).
ENV_EFFECTS: tuple[str, ...] = PHYSICAL_EFFECTS
_SMOOTH = smooth_effects(ENV_EFFECTS)
N_COEF = sum(e.kernel_width for e in _SMOOTH)
#: Offset of each smooth effect's coefficients in ``coef``.
COEF_OFFSET: dict[str, int] = {}
_j = 0
for _e in _SMOOTH:
    COEF_OFFSET[_e.name] = _j
    _j += _e.kernel_width
IDX_D = COEF_OFFSET["asymmetry"]


def coef_layout(effects: tuple[str, ...]) -> tuple[dict[str, int], int]:
    """Offsets of each smooth effect's coefficients in ``coef`` for an effect set, and its
    length.  The paper's effects come first in every set (the crack switches ``D`` at
    :data:`IDX_D`), the field faults an environment draws follow."""
    if tuple(effects[: len(ENV_EFFECTS)]) != ENV_EFFECTS:
        raise ValueError("an environment's effects start with ENV_EFFECTS")
    offsets, j = {}, 0
    for e in smooth_effects(tuple(effects)):
        offsets[e.name] = j
        j += e.kernel_width  # its coefficients, then its scanned parameters (the rub's clearance)
    return offsets, j

# dyn indices
D_T, D_PHI, D_PHID, D_PHIDD, D_STEP, D_PEAK, D_EFFORT, D_TTS, D_CRACKED, D_REASON = range(10)
N_DYN = 10
# par indices
P_H, P_IP, P_CRACK_SAMPLE, P_CRACK_D = range(4)
N_PAR = 4
# cfg indices
(
    C_MODE, C_T, C_TARGET, C_AMAX, C_CLEAR, C_TMAX, C_WVIB, C_WTIME, C_WEFF, C_FAIL,
    C_MMAX, C_RATE, C_SPEED_SCALE, C_PHIDD_SCALE, C_MAXSTEPS, C_NREC, C_EVERY, C_DTSUB, C_DEADLINE,
) = range(19)
N_CFG = 19

MODE_RUN_UP = 0.0
MODE_BALANCING = 1.0

# end-of-episode reasons (dyn[D_REASON])
R_NONE, R_RUB, R_UNSTABLE, R_TIME_LIMIT = 0, 1, 2, 3
REASONS: tuple[str | None, ...] = (None, "rub", "unstable", "time_limit")

#: Bound of the scaled inclination / rate / amplitude observations (they are clipped).
OBS_BOUND = 10.0
N_OBS = 10
OBS_LOW = np.array([0.0, 0.0, -1.0, -1.0] + [-OBS_BOUND] * 4 + [0.0, 0.0], dtype=np.float32)
OBS_HIGH = np.array([1.0, 1.0, 1.0, 1.0] + [OBS_BOUND] * 4 + [OBS_BOUND, 1.0], dtype=np.float32)
_LO = OBS_LOW.astype(np.float64)
_HI = OBS_HIGH.astype(np.float64)


@njit(cache=False)
def observe(state, dyn, cfg, obs):
    """Write the scaled, clipped float32 observation of one rotor into ``obs``."""
    cl = cfg[C_CLEAR]
    thx, thy, wx, wy = state[0], state[1], state[2], state[3]
    phi = dyn[D_PHI]
    v0 = dyn[D_PHID] / cfg[C_SPEED_SCALE]
    v1 = dyn[D_PHIDD] / cfg[C_PHIDD_SCALE]
    v2 = math.cos(phi)
    v3 = math.sin(phi)
    v4 = thx / cl
    v5 = thy / cl
    v6 = wx / cl
    v7 = wy / cl
    v8 = math.sqrt(thx * thx + thy * thy) / cl
    v9 = dyn[D_T] / cfg[C_TMAX]
    vals = (v0, v1, v2, v3, v4, v5, v6, v7, v8, v9)
    for i in range(N_OBS):
        v = vals[i]
        if not (v == v):  # NaN guard (cannot happen with finite states, kept for safety)
            v = 0.0
        if v < _LO[i]:
            v = _LO[i]
        elif v > _HI[i]:
            v = _HI[i]
        obs[i] = v


@njit(cache=False)
def env_step(accel, state, dyn, coef, par, cfg, u0, u1, out, obs):
    """One decision step of one rotor; returns the reward (see the env docstrings)."""
    n_rec = int(cfg[C_NREC])
    every = int(cfg[C_EVERY])
    dt_sub = cfg[C_DTSUB]
    T = cfg[C_T]
    t0 = dyn[D_T]
    phi0 = dyn[D_PHI]
    phid0 = dyn[D_PHID]
    k = dyn[D_STEP]
    h = par[P_H]
    ip = par[P_IP]
    run_up = cfg[C_MODE] == MODE_RUN_UP
    clipped = False
    if run_up:
        a_max = cfg[C_AMAX]
        target = cfg[C_TARGET]
        a = a_max * 0.5 * (u0 + 1.0)
        room = (target - phid0) / T
        deadline = cfg[C_DEADLINE]
        if deadline >= 0.0:
            # the drive keeps the deadline: a command below the rate still needed to reach
            # the target by then is raised to it (that rate never grows when followed)
            left = deadline - t0
            floor = room if left < T * (1.0 - 1e-9) else (target - phid0) / left
            a = max(a, min(floor, a_max))
        # hold the target speed: never exceed it (a relative 1e-6 absorbs the rounding of
        # the speed summed over the steps and of float32 actions — u = -0.6 is 0.01 less
        # 6e-10 — so that a schedule meant to arrive at a step's end does)
        if a >= room - 1e-6 * target / T:
            a = room if room > 0.0 else 0.0
            clipped = True
        My = 0.0
        Mx = 0.0
        effort_term = (a / a_max) * (a / a_max)
        effort_rate = a * a
    else:
        a = cfg[C_RATE]
        Mx = cfg[C_MMAX] * u0
        My = cfg[C_MMAX] * u1
        effort_term = 0.5 * (u0 * u0 + u1 * u1)
        effort_rate = Mx * Mx + My * My

    # a crack (D jumps) at sample index kc: split the integration there
    j0 = k * n_rec
    kc = par[P_CRACK_SAMPLE]
    if dyn[D_CRACKED] == 0.0 and kc < j0 + n_rec:
        n1 = int(kc - j0) if kc > j0 else 0
        rows = 0
        if n1 > 0:
            rows = integrate(accel, state, t0, phi0, phid0, a, ip, coef, h, My, Mx, n1, every, dt_sub, out[:n1])
        if rows == n1:
            coef[IDX_D] = par[P_CRACK_D]
            dyn[D_CRACKED] = 1.0
            ts = n1 * every * dt_sub
            rows += integrate(
                accel, state, t0 + ts, phi0 + phid0 * ts + 0.5 * a * ts * ts, phid0 + a * ts, a, ip,
                coef, h, My, Mx, n_rec - n1, every, dt_sub, out[n1:],
            )
    else:
        rows = integrate(accel, state, t0, phi0, phid0, a, ip, coef, h, My, Mx, n_rec, every, dt_sub, out)

    for r in range(rows, n_rec):
        for c in range(out.shape[1]):
            out[r, c] = np.nan
    s2 = 0.0
    pk2 = 0.0
    for r in range(rows):
        a2 = out[r, 4] * out[r, 4] + out[r, 5] * out[r, 5]
        s2 += a2
        if a2 > pk2:
            pk2 = a2
    pk = math.sqrt(pk2)
    cl = cfg[C_CLEAR]
    vib = s2 / rows / (cl * cl) if rows > 0 else 1.0
    if vib > 1.0:
        vib = 1.0

    t1 = (k + 1.0) * T
    if run_up:
        phi1 = phi0 + phid0 * T + 0.5 * a * T * T
        phid1 = cfg[C_TARGET] if clipped else phid0 + a * T
    else:  # prescribed profile from rest: closed form, as the simulator's chunks
        phi1 = 0.5 * a * t1 * t1
        phid1 = a * t1
    dyn[D_T] = t1
    dyn[D_PHI] = phi1
    dyn[D_PHID] = phid1
    dyn[D_PHIDD] = a
    dyn[D_STEP] = k + 1.0
    if pk > dyn[D_PEAK]:
        dyn[D_PEAK] = pk
    dyn[D_EFFORT] += effort_rate * T
    if run_up and clipped and not (dyn[D_TTS] == dyn[D_TTS]):
        dyn[D_TTS] = t1

    if rows < n_rec:
        reason = R_UNSTABLE
    elif pk > cl:
        reason = R_RUB
    elif k + 1.0 >= cfg[C_MAXSTEPS]:
        reason = R_TIME_LIMIT
    else:
        reason = R_NONE
    dyn[D_REASON] = reason

    if run_up:
        # without a deadline, the time term: the speed still missing (arrive early)
        missing = (1.0 - phid1 / cfg[C_TARGET]) if cfg[C_DEADLINE] < 0.0 else 0.0
        reward = -(cfg[C_WVIB] * vib + cfg[C_WTIME] * missing + cfg[C_WEFF] * effort_term)
    else:
        reward = -(cfg[C_WVIB] * vib + cfg[C_WEFF] * effort_term)
    if reason == R_RUB or reason == R_UNSTABLE:
        reward -= cfg[C_FAIL]
    observe(state, dyn, cfg, obs)
    return reward


_KERNELS: dict[tuple[str, ...], object] = {}


def _cached_steps(accel):
    """The step kernels for a library effect set's ``accel``, from numba's disk cache.

    A kernel taking ``accel`` as an argument, or calling :func:`env_step` with it, is
    compiled again in every process (5-10 s at each env's first step: numba cannot cache
    a function value).  So :func:`env_step`'s own source is written, with ``accel`` a
    global and ``integrate`` the simulator's generated ``integrate_bound``, into a file
    beside the simulator's generated kernels and compiled with ``cache=True``.  The
    ``prange`` batch stays in memory (a global dispatcher called in ``prange`` runs
    several times slower).  None where that is not possible: compile in memory.
    """
    import inspect
    import os
    import re
    from pathlib import Path

    from .. import simulator

    bound = simulator._BOUND.get(id(accel))
    if bound is None or os.environ.get("ROTOR_ID_NO_KERNEL_CACHE"):
        return None
    lines = inspect.getsource(env_step.py_func).splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith("def "))
    head = lines[i].replace("def env_step(accel, ", "def env_step_bound(")
    body = re.sub(r"\bintegrate\(\s*accel,\s*", "integrate_bound(", "\n".join(lines[i + 1:]))
    if head == lines[i] or re.search(r"\baccel\b", body):
        return None  # the source changed shape: do not guess
    names = sorted(n for n in env_step.py_func.__code__.co_names if n in globals() and n != "integrate")
    text = "\n".join([
        "# generated by rotor_env.envs.core; safe to delete",
        "import math", "",
        "import numpy as np",
        "from numba import njit", "",
        f"from {bound.__name__} import integrate_bound",
        f"from rotor_env.envs.core import {', '.join(names)}", "", "",
        "@njit(cache=True)", head, body, "", "",
        "@njit(cache=True)",
        "def step_one(state, dyn, coef, par, cfg, u0, u1, out, obs):",
        "    return env_step_bound(state, dyn, coef, par, cfg, u0, u1, out, obs)", "", "",
        "@njit(cache=True)",
        "def step_batch_serial(active, states, dyn, coef, par, cfg, u, out, obs, rew):",
        "    for b in range(states.shape[0]):",
        "        if active[b]:",
        "            rew[b] = env_step_bound(states[b], dyn[b], coef[b], par[b], cfg, u[b, 0], u[b, 1], out[b],",
        "                                    obs[b])", "",
    ])
    return simulator.load_generated("rotor_id_env_step", text, (Path(__file__),))


class _Kernels:
    """Compiled kernels over the effect set's ``accel`` (each compiled on first use; from
    numba's disk cache when the acceleration is a library effect set's generated one)."""

    def __init__(self, accel) -> None:
        self.accel = accel
        self._one = None
        self._batch = {}
        self._cached = _cached_steps(accel)

    @property
    def step_one(self):
        """``step_one(state, dyn, coef, par, cfg, u0, u1, out, obs) -> reward``."""
        if self._one is None and self._cached is not None:
            self._one = self._cached.step_one
        if self._one is None:
            accel = self.accel

            @njit(cache=False)
            def step_one(state, dyn, coef, par, cfg, u0, u1, out, obs):
                return env_step(accel, state, dyn, coef, par, cfg, u0, u1, out, obs)

            self._one = step_one
        return self._one

    def step_batch(self, parallel: bool):
        """``step_batch(active, states, dyn, coef, par, cfg, u, out, obs, rew)`` over axis 0."""
        if not parallel and parallel not in self._batch and self._cached is not None:
            self._batch[parallel] = self._cached.step_batch_serial
        if parallel not in self._batch:
            accel = self.accel
            if parallel:
                # accel passes as an argument: a prange loop calling a dispatcher captured
                # from a closure or a global runs several times slower (numba 0.6x)
                def step_batch(active, states, dyn, coef, par, cfg, u, out, obs, rew):
                    _step_batch_parallel(accel, active, states, dyn, coef, par, cfg, u, out, obs, rew)

            else:

                @njit(cache=False)
                def step_batch(active, states, dyn, coef, par, cfg, u, out, obs, rew):
                    for b in range(states.shape[0]):
                        if active[b]:
                            rew[b] = env_step(
                                accel, states[b], dyn[b], coef[b], par[b], cfg, u[b, 0], u[b, 1], out[b], obs[b]
                            )

            self._batch[parallel] = step_batch
        return self._batch[parallel]


@njit(cache=False, parallel=True)
def _step_batch_parallel(accel, active, states, dyn, coef, par, cfg, u, out, obs, rew):
    for b in prange(states.shape[0]):
        if active[b]:
            rew[b] = env_step(accel, states[b], dyn[b], coef[b], par[b], cfg, u[b, 0], u[b, 1], out[b], obs[b])


@njit(cache=False)
def observe_batch(mask, states, dyn, cfg, obs):
    for b in range(states.shape[0]):
        if mask[b]:
            observe(states[b], dyn[b], cfg, obs[b])


def kernels(effects: tuple[str, ...] = ENV_EFFECTS) -> _Kernels:
    """The (lazily compiled) step kernels for an effect set, cached per process."""
    key = tuple(effects)
    if key not in _KERNELS:
        _KERNELS[key] = _Kernels(compile_accel(key))
    return _KERNELS[key]
