"""The on-line identification engine: measurement samples in, identified model and tests out.

:class:`IdentificationCore` is the recursive-QR identifier of one rotor (the regression of
:mod:`rotor_env.regression`, the factor updated by the compiled kernels of
:mod:`identifier.kernels`, partial F-tests per effect, features laid out as an observation);
:class:`IdentificationBatch` steps many of them in one compiled call;
:func:`keep_moving_rows` selects the samples that carry information.  The Gymnasium
wrappers (:mod:`rotor_env.wrappers`) and the on-line monitor (:mod:`rotor_env.monitor`)
both run this engine; it imports no Gymnasium.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit
from scipy import special, stats

from identifier import RecursiveQR
from identifier.kernels import clean_factor, nested_energies, snapshot, update_blocks
from identifier.special import fdtrc

from .regression import DEFAULT_EFFECTS, RegressionSpec, build_rows

__all__ = [
    "MEASUREMENT_WIDTH",
    "WRAPPER_EFFECTS",
    "IdentificationBatch",
    "IdentificationCore",
    "keep_moving_rows",
]

#: Default effects of the engine (and so of the wrappers): the environments randomise the
#: stiffness scale, so it is estimated (``theta`` leaves ``y`` and ``k`` becomes one more effect).
WRAPPER_EFFECTS: tuple[str, ...] = ("stiffness", *DEFAULT_EFFECTS)
_BIG = np.float32(1e6)


class IdentificationCore:
    """The identifier of one rotor: regression rows in, observation features out.

    Shared by :class:`~rotor_env.wrappers.IdentificationWrapper`, its batched variant
    (through :class:`IdentificationBatch`) and the on-line monitor, so that all compute
    exactly the same features.  See :class:`~rotor_env.wrappers.IdentificationWrapper`
    for the options and the feature layout.
    """

    def __init__(
        self,
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
        stick_speed: float = 1e-4,
        noise_floor: float = 1e-4,
    ) -> None:
        if test not in ("last", "nested"):
            raise ValueError(f"test must be 'last' or 'nested', got {test!r}")
        if not 0.0 < alpha < 1.0:
            raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
        if int(min_samples) < 0:
            raise ValueError(f"min_samples must be >= 0, got {min_samples!r}")
        self.spec = RegressionSpec(effects=tuple(effects), equation=equation)
        self.estimator: RecursiveQR = self.spec.estimator(forgetting=forgetting, prior=prior)
        self.alpha = float(alpha)
        self.test = test
        self.min_samples = int(min_samples)
        if not stick_speed >= 0:
            raise ValueError(f"stick_speed must be >= 0, got {stick_speed!r}")
        self.stick_speed = float(stick_speed)
        if not noise_floor >= 0:
            raise ValueError(f"noise_floor must be >= 0, got {noise_floor!r}")
        self.noise_floor = float(noise_floor)
        self.include_p_values = include_p_values
        self.include_energy = include_energy
        groups = list(self.spec.groups.values())
        self.effects = tuple(self.spec.groups)
        self._masks = self.estimator._group_masks()
        # for the nested test: the number of columns before each effect
        self._starts = np.cumsum([0] + [len(g) for g in groups])[:-1].astype(np.int64)
        self._ends = (self._starts + np.array([len(g) for g in groups])).astype(np.int64)
        self.layout = self._layout()
        self.size = max(s.stop for s in self.layout.values())
        G, n = self._masks.shape
        # work buffers of the Python-side queries (never handed out)
        self._buf = {"coef": np.empty(n), "F": np.empty(G), "d1": np.empty(G), "d2": np.empty(G),
                     "ok": np.empty(G, dtype=np.bool_), "ident": np.empty(n, dtype=np.bool_)}
        # the options the compiled step reads, packed in one array (see _write_features)
        brackets = self.alpha <= 0.5  # F_crit decreases with d2 only for alpha <= 1/2
        self._cfg = np.array([
            self.estimator.forgetting, self.estimator.rtol, self.min_samples, self.stick_speed,
            self.noise_floor**2, self.alpha, test == "last", include_p_values, include_energy, brackets,
            *(stats.chi2.isf(self.alpha, d) / d for d in range(1, n + 1)),
        ], dtype=float)
        self._bind(np.empty(_state_size(n, G)))
        self._kernel, self._batch_kernel = _step_kernel(self.spec, self._masks, self._starts, self._ends)
        self.ip = 0.3

    def _bind(self, state: np.ndarray) -> None:
        """Make ``state`` (a flat array, see :func:`_state_views`) hold the identifier's state.

        The estimator's ``R``, column norms and sums and the remembered significant F
        values become views of it, so that the compiled step takes one array (a vector
        wrapper binds rows of one stacked array).  The current state is copied in.
        """
        est = self.estimator
        R, col_sq, sums, crit = _state_views(state, est.n, len(self.effects))
        R[...], col_sq[...], sums[...] = est.R, est._col_sq, est._sums
        crit[...] = getattr(self, "_crit", -1.0)
        est.R, est._col_sq, est._sums, self._crit = R, col_sq, sums, crit
        self._state = state

    def _layout(self) -> dict[str, slice]:
        # the inertia ratio the regression uses (known geometry) comes first: a model-based
        # policy needs it with the identified stiffness to place the critical speed
        out: dict[str, slice] = {"ip": slice(0, 1)}
        pos = 1
        for name, cols in self.spec.groups.items():
            out[f"{name}.coefficients"] = slice(pos, pos + len(cols))
            out[f"{name}.significant"] = slice(pos + len(cols), pos + len(cols) + 1)
            pos += len(cols) + 1
        if self.include_p_values:
            for name in self.spec.groups:
                out[f"{name}.log10_p"] = slice(pos, pos + 1)
                pos += 1
        if self.include_energy:
            out["log10_residual_energy"] = slice(pos, pos + 1)
            pos += 1
        return out

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        low = np.full(self.size, -_BIG, dtype=np.float32)
        high = np.full(self.size, _BIG, dtype=np.float32)
        for key, sl in self.layout.items():
            if key.endswith(".significant") or key == "ip":
                low[sl], high[sl] = 0.0, 1.0
            elif key.endswith(".log10_p"):
                low[sl], high[sl] = -_BIG, 0.0
        return low, high

    def reset(self, ip: float) -> None:
        self.estimator.reset()
        self._crit[:, 0] = -1.0
        self.ip = float(ip)

    def update(self, measurements: np.ndarray, control: np.ndarray | None = None) -> None:
        data = np.asarray(measurements, dtype=float)
        # an env that diverged pads the step's remaining samples with NaN: skip those
        if not np.isfinite(data).all():
            data = data[np.isfinite(data).all(axis=1)]
        if control is not None:
            control = np.broadcast_to(np.asarray(control, dtype=float), (len(data), 2))
        moving = _relative_speed(data) > self.stick_speed
        if not moving.all():
            data = data[moving]
            control = None if control is None else control[moving]
        if data.shape[0] == 0:
            return
        X, y = build_rows(self.spec, np.ascontiguousarray(data), self.ip, control)
        # the rows come from the compiled builder on finite data: skip re-validation (hot path)
        self.estimator._run(X, y, None, None)

    def step_features(self, measurements: np.ndarray, control: np.ndarray | None = None) -> np.ndarray:
        """:meth:`update` then :meth:`features`, fused into one compiled call (the hot path).

        Same numbers as the two calls (tested); it only saves the Python overhead.
        """
        return self.step_observation(_NO_OBS, measurements, control)

    def step_observation(
        self, obs: np.ndarray, measurements: np.ndarray, control: np.ndarray | None = None
    ) -> np.ndarray:
        """``[obs | features]`` after the step's samples (a new float32 array).

        One compiled call builds the regression rows, skips the samples that are not
        finite (a diverged env pads the step with NaN) or where the disk sticks, updates
        the factor, runs the tests and writes the observation.
        """
        data = np.asarray(measurements, dtype=float)
        if data.ndim != 2 or data.shape[1] != MEASUREMENT_WIDTH:
            raise ValueError(f"measurements must have shape (samples, {MEASUREMENT_WIDTH}), got {data.shape}")
        if control is None:
            mom = _NO_MOMENT
        else:
            # one moment held over the step (shape (2,)) or one per sample ((samples, 2))
            mom = np.asarray(control, dtype=float).reshape(-1, 2)
            if mom.shape[0] not in (1, data.shape[0]):
                raise ValueError(f"control must have shape (2,) or ({data.shape[0]}, 2), got {np.shape(control)}")
        obs = np.asarray(obs, dtype=np.float32)
        out = np.empty(obs.shape[0] + self.size, dtype=np.float32)
        self._kernel(np.ascontiguousarray(data), np.ascontiguousarray(mom), self._state, self._cfg, self.ip, obs, out)
        return out

    def _test_inputs(self):
        """``(F, d1, d2, ok, coef)`` of every effect's test, from one compiled pass (buffers)."""
        est = self.estimator
        b = self._buf
        _test_stats(est.R, est._col_sq, est.rtol, self._masks, est.effective_samples, self.test == "last",
                    self._starts, self._ends, est.n_samples >= self.min_samples, self.noise_floor**2,
                    b["coef"], b["F"], b["d1"], b["d2"], b["ok"], b["ident"])
        return b["F"], b["d1"], b["d2"], b["ok"], b["coef"]

    def significance(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(coefficients, log10_p, significant)`` for the current data (fresh arrays)."""
        F, d1, d2, ok, coef = self._test_inputs()
        sf = np.where(ok, special.fdtrc(d1, d2, F), 1.0)
        return coef.copy(), np.log10(np.maximum(sf, 1e-300)), ok & (sf < self.alpha)

    def features(self) -> np.ndarray:
        """The appended observation part (a new float32 array)."""
        out = np.empty(self.size, dtype=np.float32)
        est = self.estimator
        _write_features(est.R, est._col_sq, est._sums, self._masks, self._starts, self._ends, self._cfg,
                        self._crit, self.ip, _NO_OBS, out)
        return out


@njit(cache=True, error_model="numpy")
def _test_stats(R, col_sq, rtol, masks, m_eff, last, starts, ends, enough, var_floor, coef, F, d1, d2, ok,
                ident) -> None:
    """Partial F and degrees of freedom of each effect's test, in one pass.

    ``last``: the full model against it without the effect; otherwise the nested
    sequence with the effect's columns added as a block.  ``ok`` is False where the
    test cannot be made (no identifiable column, no degrees of freedom, or not
    ``enough`` samples yet); there ``F = 0`` and ``d1 = d2 = 1`` (harmless for scipy).
    Returns the full model's residual energy ``J_n``.
    """
    G, n = masks.shape
    energies = np.empty(3 * G)
    J_without = energies[:G]
    J_full = snapshot(R, col_sq, rtol, masks, ident, coef, J_without)
    Jr = energies[G : 2 * G]
    Jf = energies[2 * G :]
    if last:
        p = 0
        for k in range(n):
            p += 1 if ident[k] else 0
        for g in range(G):
            q = 0
            for k in range(n):
                q += 1 if (masks[g, k] and ident[k]) else 0
            Jr[g], Jf[g], d1[g], d2[g] = J_without[g], J_full, q, m_eff - p
    else:
        size = n + 1
        work = np.empty((size, size))
        E = np.empty(size)
        clean_factor(R, ident, work, np.empty(size))
        nested_energies(work, E)
        for g in range(G):
            q = 0
            before = 0
            for k in range(ends[g]):
                if ident[k]:
                    q += 1 if k >= starts[g] else 0
                    before += 1
            Jr[g], Jf[g], d1[g], d2[g] = E[starts[g]], E[ends[g]], q, m_eff - before
    for g in range(G):
        ok[g] = enough and d1[g] > 0 and d2[g] > 0
        if ok[g]:
            # the residual variance is taken as at least the noise floor: on noise-free
            # simulated data what is left is integration error, against which any
            # numerical mismatch would look "significant"
            F[g] = max(Jr[g] - Jf[g], 0.0) / d1[g] / max(Jf[g] / d2[g], var_floor, 1e-300)
        else:
            F[g], d1[g], d2[g] = 0.0, 1.0, 1.0
    return J_full


def _relative_speed(data: np.ndarray) -> np.ndarray:
    """Speed of the disk relative to the rotating shaft, per sample (docs/PHYSICS.md 1.5.6: ``S``).

    While the disk sticks to the shaft (dry friction, ``S ~ 0``) the samples carry no
    information on the dynamics and bias the unbalance and damping estimates towards
    zero (the friction holds the unbalance, yet the friction column reads 0); the
    identifier skips them (``stick_speed``).
    """
    v_y = data[:, 7] + data[:, 2] * data[:, 4]
    v_x = data[:, 6] - data[:, 2] * data[:, 5]
    return np.hypot(v_y, v_x)


@njit(cache=True, error_model="numpy")
def keep_moving_rows(data: np.ndarray, X: np.ndarray, y: np.ndarray, per: int, stick_speed: float) -> int:
    """Compact the regression rows in place to the samples that carry information; returns their count.

    Sample ``r`` owns rows ``per*r .. per*r + per - 1`` of ``X, y``.  Kept: samples that
    are finite (a diverged env pads its last step with NaN) and where the disk slips on
    the shaft, ``S > stick_speed`` (``S`` the relative speed, see :func:`_relative_speed`).
    The identification wrapper's step and the on-line monitor (:mod:`rotor_env.monitor`)
    both select their rows here, then update the factor with
    :func:`identifier.kernels.update_blocks`: one core.
    """
    k = 0
    for r in range(data.shape[0]):
        finite = True
        for c in range(data.shape[1]):
            finite = finite and math.isfinite(data[r, c])
        v_y = data[r, 7] + data[r, 2] * data[r, 4]
        v_x = data[r, 6] - data[r, 2] * data[r, 5]
        if finite and math.sqrt(v_y * v_y + v_x * v_x) > stick_speed:
            for q in range(per):
                if k != r * per + q:
                    X[k, :] = X[r * per + q, :]
                    y[k] = y[r * per + q]
                k += 1
    return k


#: columns of a measurement sample (:data:`rotor_env.measurements.COLUMNS`)
MEASUREMENT_WIDTH = 10
_NO_OBS = np.empty(0, dtype=np.float32)
_NO_MOMENT = np.zeros((1, 2))


@njit(error_model="numpy")
def _write_features(R, col_sq, sums, masks, starts, ends, cfg, crit, ip, obs, out) -> None:
    """``out = [obs | ip | coefficients_e..., flag_e | ... | (log10 p_e) | (log10 J)]``.

    ``cfg = [forgetting, rtol, min_samples, stick_speed, noise_floor^2, alpha, last,
    include_p_values, include_energy, brackets on, F_crit(1, inf), ..., F_crit(n, inf)]``
    (see :class:`IdentificationCore`); ``crit[g] = (d1, d2, F)`` of an F found significant
    (``d1 = -1``: none yet).  The flag is ``p < alpha`` on scipy's own ``fdtrc`` (exact for
    every alpha in (0, 1), where an inverse cdf at ``1 - alpha`` would round a tiny alpha
    away).  Not cached on disk: it calls scipy through a raw address
    (:mod:`identifier.special`).
    """
    G, n = masks.shape
    scratch = np.empty(n + 4 * G)
    coef = scratch[:n]
    F = scratch[n : n + G]
    d1 = scratch[n + G : n + 2 * G]
    d2 = scratch[n + 2 * G : n + 3 * G]
    sf = scratch[n + 3 * G :]
    flags = np.empty(G + n, dtype=np.bool_)
    ok = flags[:G]
    ident = flags[G:]
    m_eff = sums[1] * sums[1] / sums[2] if sums[2] > 0 else 0.0
    J = _test_stats(R, col_sq, cfg[1], masks, m_eff, cfg[6] != 0.0, starts, ends, sums[0] >= cfg[2], cfg[4],
                    coef, F, d1, d2, ok, ident)
    for i in range(obs.shape[0]):
        out[i] = obs[i]
    pos = obs.shape[0]
    out[pos] = ip
    pos += 1
    # Without p-values in the observation the flag needs no survival function when the
    # critical value F_crit(d1, d2) is bracketed: it decreases with d2 (alpha <= 0.5) down
    # to chi2_{1-alpha}(d1) / d1, so F <= that limit is never significant, and F above an
    # F already found significant at d2' <= d2 (remembered in ``crit``) always is.
    brackets = cfg[7] == 0.0 and cfg[9] != 0.0
    for g in range(G):
        sf[g] = 1.0
        if not ok[g]:
            sig = False
        elif brackets and F[g] <= cfg[9 + int(d1[g])]:
            sig = False
        elif brackets and crit[g, 0] == d1[g] and d2[g] >= crit[g, 1] and F[g] > crit[g, 2]:
            sig = True
        else:
            sf[g] = fdtrc(d1[g], d2[g], F[g], 0)
            sig = sf[g] < cfg[5]
            if sig and brackets and not (crit[g, 0] == d1[g] and d2[g] >= crit[g, 1]):
                crit[g, 0], crit[g, 1], crit[g, 2] = d1[g], d2[g], F[g]
        for k in range(n):
            if masks[g, k]:
                out[pos] = min(max(coef[k], -1e6), 1e6)
                pos += 1
        out[pos] = 1.0 if sig else 0.0
        pos += 1
    if cfg[7] != 0.0:
        for g in range(G):
            out[pos] = math.log10(max(sf[g], 1e-300))
            pos += 1
    if cfg[8] != 0.0:
        out[pos] = math.log10(max(J, 1e-30))


def _state_size(n: int, G: int) -> int:
    return (n + 1) * (n + 1) + n + 3 + 3 * G


@njit(inline="always")
def _state_views(state, n, G):
    """``(R, col_sq, sums, crit)`` as views of one flat state array (``_state_size`` long)."""
    s = n + 1
    R = state[: s * s].reshape((s, s))
    col_sq = state[s * s : s * s + n]
    sums = state[s * s + n : s * s + n + 3]
    crit = state[s * s + n + 3 : s * s + n + 3 + 3 * G].reshape((G, 3))
    return R, col_sq, sums, crit


_STEP_KERNELS: dict = {}


def _step_kernel(spec: RegressionSpec, masks: np.ndarray, starts: np.ndarray, ends: np.ndarray):
    """Builder + time update + tests + observation in one compiled function (one per spec).

    What the spec fixes (its known coefficients, the effects' columns) is compiled in
    as constants: fewer arguments to unbox on each call (the hot path is ~10 us).
    """
    key = (spec.effects, spec.equation, tuple(spec.known))
    if key in _STEP_KERNELS:
        return _STEP_KERNELS[key]
    build = spec.builder()
    per = spec.rows_per_sample
    kc = spec.known_coefficients.copy()
    masks, starts, ends = masks.copy(), starts.copy(), ends.copy()
    G, n = masks.shape

    @njit(error_model="numpy")
    def kernel(data, mom, state, cfg, ip, obs, out):
        R, col_sq, sums, crit = _state_views(state, n, G)
        m = data.shape[0]
        if mom.shape[0] != m:  # one moment held over the step
            held = np.empty((m, 2))
            for r in range(m):
                held[r, 0], held[r, 1] = mom[0, 0], mom[0, 1]
            mom = held
        X = np.empty((m * per, n))
        y = np.empty(m * per)
        build(data, ip, kc, mom, X, y)
        k = keep_moving_rows(data, X, y, per, cfg[3])
        # the same block-by-block update as RecursiveQR.update_many (no histories)
        update_blocks(R, col_sq, sums, X[:k], y[:k], cfg[0])
        _write_features(R, col_sq, sums, masks, starts, ends, cfg, crit, ip, obs, out)

    @njit(error_model="numpy")
    def batch(data, mom, state, cfg, ip, stepped, obs, out):
        # one call for a vector env: sub-env i steps its identifier if stepped[i], else
        # (just reset) only writes its features
        for i in range(data.shape[0]):
            if stepped[i]:
                kernel(data[i], mom[i], state[i], cfg, ip[i], obs[i], out[i])
            else:
                R, col_sq, sums, crit = _state_views(state[i], n, G)
                _write_features(R, col_sq, sums, masks, starts, ends, cfg, crit, ip[i], obs[i], out[i])

    _STEP_KERNELS[key] = kernel, batch
    return kernel, batch


class IdentificationBatch:
    """Many :class:`IdentificationCore` of the same options stepped by one compiled call.

    The cores' states are stacked in one array; each core keeps views into it, so its
    queries and its in-place resets still work one by one.
    """

    def __init__(self, cores: Sequence[IdentificationCore]) -> None:
        self.cores = list(cores)
        c0 = self.cores[0]
        self._state = np.stack([c._state for c in self.cores])
        for i, c in enumerate(self.cores):
            c._bind(self._state[i])
        self._cfg, self._batch = c0._cfg, c0._batch_kernel
        self._no_moment = np.zeros((len(self.cores), 1, 2))
        self.size = c0.size

    def step(self, measurements: np.ndarray, control, obs: np.ndarray, stepped: np.ndarray,
             ips: np.ndarray) -> np.ndarray:
        """Update the cores where ``stepped`` with their ``(samples, 10)`` rows of
        ``measurements`` (``(cores, samples, 10)``) and the moments ``control``
        (``(cores, samples or 1, 2)`` or None); the others are reset to their inertia
        ratio ``ips[i]`` and only write their features.  Returns ``[obs | features]`` per core."""
        n = len(self.cores)
        meas = np.asarray(measurements, dtype=float)
        if meas.ndim != 3 or meas.shape[0] != n or meas.shape[2] != MEASUREMENT_WIDTH:
            raise ValueError(f"measurements must have shape ({n}, samples, {MEASUREMENT_WIDTH}), got {meas.shape}")
        stepped = np.asarray(stepped, dtype=bool)
        for i in np.flatnonzero(~stepped):
            self.cores[i].reset(ips[i])
        mom = self._no_moment if control is None else np.asarray(control, dtype=float).reshape(n, -1, 2)
        obs = np.asarray(obs, dtype=np.float32)
        out = np.empty((n, obs.shape[1] + self.size), dtype=np.float32)
        ip = np.array([c.ip for c in self.cores])
        self._batch(np.ascontiguousarray(meas), np.ascontiguousarray(mom), self._state, self._cfg, ip, stepped,
                    obs, out)
        return out
