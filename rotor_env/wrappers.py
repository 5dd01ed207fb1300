"""Identification in the loop: a recursive-QR identifier inside the environment."""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from scipy import special

from identifier import RecursiveQR

from .regression import DEFAULT_EFFECTS, RegressionSpec, build_rows

__all__ = ["WRAPPER_EFFECTS", "IdentificationCore", "IdentificationWrapper", "VectorIdentificationWrapper"]

#: Default effects of the wrapper: the environments randomise the stiffness scale,
#: so it is estimated (``theta`` leaves ``y`` and ``k`` becomes one more effect).
WRAPPER_EFFECTS: tuple[str, ...] = ("stiffness", *DEFAULT_EFFECTS)
_BIG = np.float32(1e6)


class IdentificationCore:
    """The identifier of one rotor: regression rows in, observation features out.

    Shared by :class:`IdentificationWrapper` and its batched variant so that both
    compute exactly the same features.  See :class:`IdentificationWrapper` for the
    options and the feature layout.
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
        self.include_p_values = include_p_values
        self.include_energy = include_energy
        groups = list(self.spec.groups.values())
        self.effects = tuple(self.spec.groups)
        self._masks = self.estimator._group_masks()
        # for the nested test: the number of columns before each effect
        self._starts = np.cumsum([0] + [len(g) for g in groups])[:-1]
        self._ends = self._starts + np.array([len(g) for g in groups])
        self.layout = self._layout()
        self.size = max(s.stop for s in self.layout.values())
        self.ip = 0.3

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
        self.ip = float(ip)

    def update(self, measurements: np.ndarray, control: np.ndarray | None = None) -> None:
        data = np.asarray(measurements, dtype=float)
        # an env that diverged pads the step's remaining samples with NaN: skip those
        data = data[np.isfinite(data).all(axis=1)]
        if data.shape[0] == 0:
            return
        X, y = build_rows(self.spec, np.ascontiguousarray(data), self.ip, control)
        self.estimator.update_many(X, y)

    def significance(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(coefficients, log10_p, significant)`` for the current data."""
        est = self.estimator
        J_without, J_full, coef, ident = est.effect_energies()
        m_eff = est.effective_samples
        p = float(ident.sum())
        if self.test == "last":
            Jr = J_without
            d1 = (self._masks & ident).sum(axis=1).astype(float)
            d2 = np.full(len(d1), m_eff - p)
            Jf = np.full(len(d1), J_full)
        else:  # the paper's nested sequence, an effect's columns added as a block
            E = est.residual_energies()
            Jr, Jf = E[self._starts], E[self._ends]
            cum = np.concatenate([[0], np.cumsum(ident)])
            d1 = (cum[self._ends] - cum[self._starts]).astype(float)
            d2 = m_eff - cum[self._ends].astype(float)
        ok = (d1 > 0) & (d2 > 0) & (est.n_samples >= self.min_samples)
        with np.errstate(all="ignore"):
            F = np.where(ok, ((Jr - Jf) / np.where(ok, d1, 1)) / (np.maximum(Jf, 1e-300) / np.where(ok, d2, 1)), 0.0)
            sf = np.where(ok, special.fdtrc(np.where(ok, d1, 1), np.where(ok, d2, 1), np.maximum(F, 0.0)), 1.0)
        log10_p = np.log10(np.maximum(sf, 1e-300))
        return coef, log10_p, ok & (sf < self.alpha)

    def features(self) -> np.ndarray:
        coef, log10_p, sig = self.significance()
        out = np.empty(self.size, dtype=np.float32)
        out[0] = self.ip
        pos = 1
        for g, mask in enumerate(self._masks):
            k = int(mask.sum())
            out[pos : pos + k] = np.clip(coef[mask], -_BIG, _BIG)
            out[pos + k] = float(sig[g])
            pos += k + 1
        if self.include_p_values:
            out[pos : pos + len(log10_p)] = np.clip(log10_p, -_BIG, 0.0)
            pos += len(log10_p)
        if self.include_energy:
            J = self.estimator.residual_energies()[-1]
            out[pos] = np.clip(np.log10(max(J, 1e-30)), -_BIG, _BIG)
        return out


class IdentificationWrapper(gym.Wrapper):
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
    ) -> None:
        super().__init__(env)
        base = env.observation_space
        if not isinstance(base, spaces.Box) or len(base.shape) != 1:
            raise ValueError(f"IdentificationWrapper needs a flat Box observation space, got {base}")
        self.core = IdentificationCore(
            effects, equation=equation, forgetting=forgetting, prior=prior, alpha=alpha, test=test,
            min_samples=min_samples, include_p_values=include_p_values, include_energy=include_energy,
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
        self.core.update(info["measurements"], info.get("control"))
        return self._obs(obs), reward, terminated, truncated, info


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

    def _ips(self, info) -> np.ndarray:
        if "ip" in info:
            return np.asarray(info["ip"], dtype=float)
        return np.array([c.ip for c in self.cores])

    def _obs(self, obs: np.ndarray) -> np.ndarray:
        feats = np.stack([c.features() for c in self.cores])
        return np.concatenate([np.asarray(obs, dtype=np.float32), feats], axis=1)

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        for c, ip in zip(self.cores, self._ips(info), strict=True):
            c.reset(ip)
        self._done[:] = False
        return self._obs(obs), info

    def step(self, actions):
        obs, reward, terminated, truncated, info = self.env.step(actions)
        meas = info["measurements"]
        ips = self._ips(info)
        control = info.get("control")
        for i, c in enumerate(self.cores):
            if self._done[i]:  # this step was the sub-env's reset
                c.reset(ips[i])
                continue
            c.update(meas[i], None if control is None else control[i])
        self._done = np.logical_or(terminated, truncated)
        return self._obs(obs), reward, terminated, truncated, info
