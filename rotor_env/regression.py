"""From measurements to the linear regression ``y = X theta + e`` (docs/PHYSICS.md section 3).

The regression is generated from the effect declarations: for the first equation

    y   = th_y'' + ip*phid*th_x' - sum_{known effects} theta * col_y - M_y
    X   = [col_y of every estimated effect]

(the second equation is the same with ``x`` columns and ``th_x'' - ip*phid*th_y'``).
*Known* effects have known coefficients and move to ``y``; by default that is the
stiffness with ``k = 1`` (the paper's units) unless ``stiffness`` is estimated.
``"both"`` stacks the two equations: twice the data, and the only way to see ``k30``.

A compiled builder (numba, generated like the simulator's right-hand side) makes
the same code serve a 40 000-row file and the 50 rows of one environment step.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numba import njit

from identifier import RecursiveQR

from .effects import EFFECTS, Effect, get_effect
from .measurements import Measurements

__all__ = [
    "DEFAULT_EFFECTS",
    "PAPER_EFFECTS",
    "PRESETS",
    "Regression",
    "RegressionSpec",
    "build_regression",
]

#: The paper's seven regressors in the order of its Eq. (10): tau, D, c, k21, k12, k03, h.
PAPER_EFFECTS: tuple[str, ...] = (
    "unbalance_in_phase",
    "asymmetry",
    "viscous_damping",
    "nonlinear_stiffness",
    "structural_damping",
)
#: Default: the same order with the unbalance of unknown phase (two columns).
DEFAULT_EFFECTS: tuple[str, ...] = (
    "unbalance",
    "asymmetry",
    "viscous_damping",
    "nonlinear_stiffness",
    "structural_damping",
)
PRESETS: dict[str, tuple[str, ...]] = {"paper": PAPER_EFFECTS, "default": DEFAULT_EFFECTS}

EQUATIONS = ("first", "second", "both")
_PROBE = np.random.default_rng(12345).normal(size=(8, 8))


def _structural_zeros(eff: Effect) -> tuple[np.ndarray, np.ndarray]:
    """Columns that are identically zero in an equation (e.g. ``k30`` in the first)."""
    cy, cx = eff.regressors(*_PROBE)
    return np.all(cy == 0.0, axis=0), np.all(cx == 0.0, axis=0)


@dataclass(frozen=True)
class RegressionSpec:
    """What to regress: estimated effects (in order), equation, known coefficients.

    ``known`` maps effect name -> its parameters (physical, e.g. ``{"k": 1.0}``) for
    effects that are in the rotor but not estimated; they are subtracted from ``y``.
    """

    effects: tuple[str, ...] = DEFAULT_EFFECTS
    equation: str = "first"
    known: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    #: values of the estimated effects' scanned parameters (``{"rub": {"rub_clearance":
    #: 0.04}}``; their defaults where absent): they shape the columns, they are not estimated
    scanned: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    columns: tuple[str, ...] = field(init=False)
    groups: dict[str, tuple[str, ...]] = field(init=False)
    # per estimated effect, the indices of the effect's coefficients kept in eq 1 / eq 2
    _keep: tuple = field(init=False, repr=False)

    def __post_init__(self) -> None:
        effects = tuple(self.effects) if not isinstance(self.effects, str) else PRESETS.get(self.effects)
        if effects is None:
            raise ValueError(f"unknown preset {self.effects!r}; presets: {', '.join(PRESETS)}")
        if not effects:
            raise ValueError("a regression needs at least one effect")
        for e in effects:
            get_effect(e)
        if len(set(effects)) != len(effects):
            raise ValueError(f"effects listed twice: {effects}")
        owner: dict[str, str] = {}
        for e in effects:  # two effects that estimate one physical quantity (tau) read 0 each
            for p in EFFECTS[e].parameter_names:
                if p in owner:
                    raise ValueError(f"effects {owner[p]!r} and {e!r} both estimate {p!r} (the same physical "
                                     "quantity, their columns are collinear): use one of them")
                owner[p] = e
        if self.equation not in EQUATIONS:
            raise ValueError(f"equation must be one of {EQUATIONS}, got {self.equation!r}")
        known = {str(k): dict(v) for k, v in self.known.items()}
        if "stiffness" not in effects and "stiffness" not in known:
            known["stiffness"] = {"k": 1.0}
        for name, vals in known.items():
            eff = get_effect(name)
            if name in effects:
                raise ValueError(f"effect {name!r} is both estimated and known")
            # an orientation left out is the declared default (the axis at the keyphasor notch)
            missing = set(eff.parameter_names) - set(vals) - {p.name for p in eff.orientation_parameters}
            if missing:
                raise ValueError(f"known effect {name!r} lacks parameter(s) {sorted(missing)}")
        columns: list[str] = []
        groups: dict[str, tuple[str, ...]] = {}
        keep = []
        for e in effects:
            eff = EFFECTS[e]
            zy, zx = _structural_zeros(eff)
            if self.equation == "first":
                use = ~zy
            elif self.equation == "second":
                use = ~zx
            else:
                use = ~(zy & zx)
            idx = tuple(int(i) for i in np.flatnonzero(use))
            if not idx:
                raise ValueError(f"effect {e!r} has no columns in the {self.equation} equation")
            keep.append(idx)
            names = tuple(eff.coefficients[i] for i in idx)
            columns.extend(names)
            groups[e] = names
        if len(set(columns)) != len(columns):
            raise ValueError(f"two effects share a coefficient name: {columns}")
        scanned = {}
        for name, vals in dict(self.scanned).items():
            if name not in effects:
                continue  # a scan value of an effect not in this model: not used
            allowed = {p.name for p in EFFECTS[name].argument_parameters}
            unknown = set(vals) - allowed
            if unknown:
                raise ValueError(f"effect {name!r} scans {sorted(allowed)}, not {sorted(unknown)}")
            scanned[name] = {k: float(v) for k, v in vals.items()}
        object.__setattr__(self, "effects", effects)
        object.__setattr__(self, "known", known)
        object.__setattr__(self, "scanned", scanned)
        object.__setattr__(self, "columns", tuple(columns))
        object.__setattr__(self, "groups", groups)
        object.__setattr__(self, "_keep", tuple(keep))

    @property
    def n_columns(self) -> int:
        return len(self.columns)

    @property
    def rows_per_sample(self) -> int:
        return 2 if self.equation == "both" else 1

    @cached_property
    def known_coefficients(self) -> np.ndarray:
        """The known effects' coefficients, in builder order (computed once)."""
        return np.array(
            [c for name, vals in self.known.items() for c in EFFECTS[name].to_coefficients(vals)],
            dtype=float,
        )

    def estimator(self, **kwargs) -> RecursiveQR:
        """A :class:`RecursiveQR` with this regression's column names and effect groups."""
        return RecursiveQR(columns=self.columns, groups=self.groups, **kwargs)

    def physical(self, theta: np.ndarray) -> dict[str, float]:
        """Physical parameters (``tau``, ``beta``, ``D`` ...) from a coefficient vector."""
        out: dict[str, float] = {}
        pos = 0
        for e, idx in zip(self.effects, self._keep, strict=True):
            eff = EFFECTS[e]
            full = np.zeros(len(eff.coefficients))
            full[list(idx)] = theta[pos : pos + len(idx)]
            pos += len(idx)
            out.update(eff.from_coefficients(full))
            out.update(zip((p.name for p in eff.argument_parameters), self.scan_values(e), strict=True))
        return out

    def scan_values(self, effect: str) -> tuple[float, ...]:
        """The values of ``effect``'s scanned parameters the columns are built with."""
        eff = EFFECTS[effect]
        if effect in self.known:
            return eff.scanned_values(self.known[effect])
        return eff.scanned_values(self.scanned.get(effect))

    def builder(self):
        """The compiled row builder ``build(data, ip, known_coef, X, y)`` (cached)."""
        scan = tuple((e, self.scan_values(e)) for e in (*self.known, *self.effects) if EFFECTS[e].argument_parameters)
        key = (self.effects, self.equation, tuple(self.known), self._keep, scan)
        fn = _BUILDERS.get(key)
        if fn is None:
            fn = _compile_builder(self)
            _BUILDERS[key] = fn
        return fn


_BUILDERS: dict[tuple, object] = {}
_ZERO_MOMENTS = np.zeros((4096, 2))  # read-only use: no known moments (the builder reads rows < m)


def _compile_builder(spec: RegressionSpec):
    ns: dict[str, object] = {}
    eqs = {"first": (0,), "second": (1,), "both": (0, 1)}[spec.equation]
    lines = [
        "def build(data, ip, kc, mom, X, y):",
        "    m = data.shape[0]",
        "    for r in range(m):",
        "        phi = data[r, 1]; phid = data[r, 2]; phidd = data[r, 3]",
        "        thx = data[r, 4]; thy = data[r, 5]; wx = data[r, 6]; wy = data[r, 7]",
        "        y1 = data[r, 9] + ip * phid * wx - mom[r, 1]",
        "        y2 = data[r, 8] - ip * phid * wy - mom[r, 0]",
    ]
    fi = 0

    def call(eff: Effect) -> str:
        nonlocal fi
        ns[f"f{fi}"] = njit(inline="always")(eff.columns)
        fi += 1
        # scanned parameters (the rub's clearance) are constants of the builder (in its key)
        extra = "".join(f", {v!r}" for v in spec.scan_values(eff.name))
        return f"        cy, cx = f{fi - 1}(phi, phid, phidd, thx, thy, wx, wy, ip{extra})"

    kj = 0
    for name in spec.known:
        eff = EFFECTS[name]
        lines.append(call(eff))
        for q in range(len(eff.coefficients)):
            lines.append(f"        y1 -= kc[{kj}] * cy[{q}]")
            lines.append(f"        y2 -= kc[{kj}] * cx[{q}]")
            kj += 1
    n_eq = len(eqs)
    for k, eq in enumerate(eqs):
        lines.append(f"        y[{n_eq} * r + {k}] = y{eq + 1}")
    col = 0
    for name, idx in zip(spec.effects, spec._keep, strict=True):
        lines.append(call(EFFECTS[name]))
        for q in idx:
            for k, eq in enumerate(eqs):
                src = "cy" if eq == 0 else "cx"
                lines.append(f"        X[{n_eq} * r + {k}, {col}] = {src}[{q}]")
            col += 1
    exec("\n".join(lines), ns)
    return njit(ns["build"])


@dataclass(frozen=True)
class Regression:
    """``y`` (shape ``(rows,)``) and ``X`` (``(rows, n)``) with named, grouped columns.

    ``t`` and ``equation`` (1 or 2) give each row's time and equation; with
    ``"both"`` the rows of one sample are consecutive (eq 1, eq 2).
    """

    spec: RegressionSpec
    X: np.ndarray
    y: np.ndarray
    t: np.ndarray
    equation: np.ndarray

    @property
    def columns(self) -> tuple[str, ...]:
        return self.spec.columns

    @property
    def groups(self) -> dict[str, tuple[str, ...]]:
        return self.spec.groups

    def estimator(self, **kwargs) -> RecursiveQR:
        return self.spec.estimator(**kwargs)

    def select(self, mask: np.ndarray) -> Regression:
        return Regression(self.spec, self.X[mask], self.y[mask], self.t[mask], self.equation[mask])


def build_rows(
    spec: RegressionSpec,
    data: np.ndarray,
    ip: float,
    control: np.ndarray | None = None,
    out: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Fast path: ``(X, y)`` from a raw ``(m, 10)`` measurement array."""
    m = data.shape[0]
    rows = m * spec.rows_per_sample
    if out is None:
        X = np.empty((rows, spec.n_columns))
        y = np.empty(rows)
    else:
        X, y = out
    if control is None:
        mom = _ZERO_MOMENTS if m <= len(_ZERO_MOMENTS) else np.zeros((m, 2))
    else:
        mom = np.ascontiguousarray(np.broadcast_to(np.asarray(control, float), (m, 2)))
    spec.builder()(data, float(ip), spec.known_coefficients, mom, X, y)
    return X, y


def build_regression(
    measurements: Measurements | np.ndarray,
    effects: Sequence[str] | str = DEFAULT_EFFECTS,
    *,
    ip: float,
    equation: str = "first",
    known: Mapping[str, Mapping[str, float]] | None = None,
    control: np.ndarray | None = None,
) -> Regression:
    """Build ``y`` and a named, grouped ``X`` from measurements.

    ``effects`` is a list of effect names (in the order of the nested models) or a
    preset name (``"paper"``, ``"default"``).  ``control`` (shape ``(m, 2)``:
    ``M_x, M_y``) are known external moments, subtracted from ``y``.
    """
    spec = RegressionSpec(effects=effects, equation=equation, known=known or {})
    data = measurements.data if isinstance(measurements, Measurements) else np.asarray(measurements, float)
    if not (np.isfinite(ip) and 0 <= ip < 1):
        raise ValueError(f"ip must be in [0, 1), got {ip!r}")
    X, y = regression_arrays(spec, data, ip, control)
    k = spec.rows_per_sample
    t = np.repeat(data[:, 0], k)
    eq = np.tile(np.array([1, 2]) if k == 2 else np.array([1 if equation == "first" else 2]), len(data))
    return Regression(spec, X, y, t, eq)


#: effect name -> ((ip, scanned values), (X_y, X_x)): one effect's columns on one data set,
#: kept by the caller that owns the data (a diagnosis builds the same columns for every
#: model it tries); one entry per effect, so a scanned parameter's sweep does not pile up
ColumnCache = dict


def regression_arrays(
    spec: RegressionSpec, data: np.ndarray, ip: float, control: np.ndarray | None = None,
    cache: ColumnCache | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(X, y)`` with numpy from the effects' column functions (no compilation).

    Same result as :func:`build_rows` (tested); used for whole files, where it is as
    fast and avoids compiling a builder for every model a diagnosis tries.  ``cache``
    (:data:`ColumnCache`, owned by the caller and only ever used with this ``data``)
    keeps each effect's columns between calls.
    """
    return regression_columns(spec, data, ip, cache), _response(spec, data, ip, control, cache)


def _effect_columns(name: str, args: tuple, scanned, cache: ColumnCache | None) -> tuple[np.ndarray, np.ndarray]:
    eff = EFFECTS[name]
    if cache is None:
        return eff.regressors(*args, scanned=scanned)
    key = (args[-1], eff.scanned_values(scanned))
    hit = cache.get(name)
    if hit is not None and hit[0] == key:
        return hit[1]
    Xy, Xx = eff.regressors(*args, scanned=scanned)
    Xy.setflags(write=False)  # shared between calls: nobody may change them
    Xx.setflags(write=False)
    cache[name] = (key, (Xy, Xx))
    return Xy, Xx


def _args(data: np.ndarray, ip: float) -> tuple:
    return (data[:, 1], data[:, 2], data[:, 3], data[:, 4], data[:, 5], data[:, 6], data[:, 7], ip)


def _interleave(spec: RegressionSpec, a1: np.ndarray, a2: np.ndarray) -> np.ndarray:
    """The rows of the equations the spec uses, in the builder's order (y-equation first)."""
    if spec.equation == "first":
        return a1
    if spec.equation == "second":
        return a2
    out = np.empty((2 * len(a1), *a1.shape[1:]))
    out[0::2], out[1::2] = a1, a2
    return out


def _response(spec: RegressionSpec, data: np.ndarray, ip: float, control: np.ndarray | None,
              cache: ColumnCache | None = None) -> np.ndarray:
    """``y``: the measured moments less the known effects' (and the control's)."""
    args = _args(data, ip)
    mom = np.zeros((len(data), 2)) if control is None else np.broadcast_to(np.asarray(control, float), (len(data), 2))
    y1 = data[:, 9] + ip * data[:, 2] * data[:, 6] - mom[:, 1]
    y2 = data[:, 8] - ip * data[:, 2] * data[:, 7] - mom[:, 0]
    for name, vals in spec.known.items():
        eff = EFFECTS[name]
        Xy, Xx = _effect_columns(name, args, vals, cache)
        # one coefficient at a time, in the compiled builder's order: bit-identical rows
        for q, c in enumerate(eff.to_coefficients(vals)):
            y1 = y1 - float(c) * Xy[:, q]
            y2 = y2 - float(c) * Xx[:, q]
    return _interleave(spec, y1, y2)


def regression_columns(spec: RegressionSpec, data: np.ndarray, ip: float,
                       cache: ColumnCache | None = None) -> np.ndarray:
    """``X`` alone (the columns of the spec's effects; the known effects only move ``y``)."""
    args = _args(data, ip)
    blocks_y, blocks_x = [], []
    for name, idx in zip(spec.effects, spec._keep, strict=True):
        Xy, Xx = _effect_columns(name, args, spec.scanned.get(name), cache)
        blocks_y.append(Xy[:, list(idx)])
        blocks_x.append(Xx[:, list(idx)])
    return _interleave(spec, np.hstack(blocks_y), np.hstack(blocks_x))
