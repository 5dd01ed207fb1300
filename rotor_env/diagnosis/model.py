"""The model under test: an ordered set of effects, and user (plug-in) effects."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..effects import (
    DerivedNames,
    Effect,
    Parameter,
    candidate_effects,
    get_effect,
    register_effect,
)

DEFAULT_MODEL: tuple[str, ...] = ("unbalance", "viscous_damping")
#: candidates by default: every library effect declared ``candidate=True``, read from the
#: registry when used (the paper's in-phase unbalance is a preset variant of ``unbalance``,
#: not a separate candidate)
LIBRARY_CANDIDATES: Sequence[str] = DerivedNames(candidate_effects)


# ------------------------------------------------------------------ the model
@dataclass(frozen=True)
class Model:
    """An ordered set of effects; ``model.add("asymmetry")`` gives a new model."""

    effects: tuple[str, ...] = DEFAULT_MODEL

    def __post_init__(self) -> None:
        effects = (self.effects,) if isinstance(self.effects, str) else tuple(self.effects)
        for e in effects:
            get_effect(e)
        if len(set(effects)) != len(effects):
            raise ValueError(f"effect listed twice in the model: {effects}")
        object.__setattr__(self, "effects", effects)

    def add(self, *names: str) -> Model:
        return Model(self.effects + tuple(n for n in names if n not in self.effects))

    def remove(self, *names: str) -> Model:
        return Model(tuple(e for e in self.effects if e not in names))

    def __contains__(self, name: str) -> bool:
        return name in self.effects

    def __iter__(self):
        return iter(self.effects)

    def __len__(self) -> int:
        return len(self.effects)


def as_model(model) -> Model:
    if model is None:
        return Model()
    if isinstance(model, Model):
        return model
    if isinstance(model, str):
        return Model(tuple(m.strip() for m in model.split(",") if m.strip()))
    return Model(tuple(model))


# ------------------------------------------------------------------ user effects
def effect_from_function(fn: Callable, name: str | None = None) -> Effect:
    """Wrap a column function ``(phi, phid, phidd, th_x, th_y, w_x, w_y, ip) -> (cols_y, cols_x)``.

    The function may also return a single array (or tuple of arrays) for the first
    equation only; the second equation's column is then taken as zero.
    """
    name = name or fn.__name__
    probe = np.random.default_rng(0).normal(size=(7, 5)) * 0.1  # phi .. w_y; ip follows
    try:
        out = fn(*probe, 0.3)
    except Exception as exc:
        raise ValueError(f"user effect {name!r}: calling it on test inputs failed: {exc}") from exc
    cols_y, cols_x = _split_user_output(name, out)
    n = len(cols_y)
    coefs = tuple(f"{name}_{j + 1}" if n > 1 else name for j in range(n))

    if isinstance(out, tuple) and len(out) == 2 and isinstance(out[0], tuple):
        columns = fn
    else:  # first equation only: wrap into the two-equation form

        def columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip, _fn=fn):
            c = _fn(phi, phid, phidd, th_x, th_y, w_x, w_y, ip)
            return (c,), (0.0 * c,)

    def to_coef(p):
        return tuple(float(p[c]) for c in coefs)

    def from_coef(c):
        return {k: float(v) for k, v in zip(coefs, c, strict=True)}

    return Effect(
        name=name,
        parameters=tuple(Parameter(c, 0.0, f"user effect {name}") for c in coefs),
        coefficients=coefs,
        columns=columns,
        to_coefficients=to_coef,
        from_coefficients=from_coef,
        moment=f"user-defined: {name}",
        cause=(fn.__doc__ or "user-defined effect").strip().splitlines()[0],
        signature="user-defined",
    )


def _split_user_output(name: str, out):
    if isinstance(out, tuple) and len(out) == 2 and isinstance(out[0], tuple):
        cy, cx = out
        if len(cy) != len(cx) or not cy:
            raise ValueError(f"user effect {name!r}: cols_y and cols_x must have the same, non-zero length")
        return cy, cx
    arr = np.asarray(out, dtype=float)
    if arr.ndim != 1:
        raise ValueError(
            f"user effect {name!r} must return one column (an array like its inputs) or "
            f"((cols_y...), (cols_x...)); got shape {arr.shape}"
        )
    return (arr,), (0.0 * arr,)


def load_user_effect(spec: str) -> Effect:
    """``module:attr`` (or ``path/to/file.py:attr``) -> a registered :class:`Effect`."""
    import importlib
    import importlib.util

    if ":" not in spec:
        raise ValueError(f"--effect wants MODULE:NAME (e.g. my_effects:cubic_stiffness), got {spec!r}")
    mod_name, attr = spec.rsplit(":", 1)
    try:
        if mod_name.endswith(".py"):
            path = Path(mod_name)
            if not path.exists():
                raise ValueError(f"--effect {spec}: no such file {path}")
            loader_spec = importlib.util.spec_from_file_location(path.stem, path)
            module = importlib.util.module_from_spec(loader_spec)
            loader_spec.loader.exec_module(module)
        else:
            module = importlib.import_module(mod_name)
    except ImportError as exc:
        raise ValueError(f"--effect {spec}: cannot import {mod_name!r} ({exc})") from None
    obj = getattr(module, attr, None)
    if obj is None:
        raise ValueError(f"--effect {spec}: module {mod_name!r} has no attribute {attr!r}")
    effect = obj if isinstance(obj, Effect) else effect_from_function(obj, attr)
    from ..effects import PACKAGE_EFFECTS  # the library as the package ships it

    if effect.name in PACKAGE_EFFECTS and PACKAGE_EFFECTS[effect.name] is not effect:
        # a plug-in must not silently replace a library effect: every later diagnosis in
        # the process would use the plug-in's physics under the library's name
        raise ValueError(f"--effect {spec}: the name {effect.name!r} is a library effect; give the plug-in "
                         "another name")
    # loading the same plug-in twice replaces the earlier copy
    return register_effect(effect, replace=True)


def validate_columns(eff: Effect, data: np.ndarray, ip: float) -> None:
    args = (data[:, 1], data[:, 2], data[:, 3], data[:, 4], data[:, 5], data[:, 6], data[:, 7], ip)
    try:
        Xy, Xx = eff.regressors(*args)
    except Exception as exc:
        raise ValueError(f"effect {eff.name!r}: computing its columns failed: {exc}") from exc
    for X, eq in ((Xy, "first"), (Xx, "second")):
        if X.shape != (len(data), len(eff.coefficients)):
            raise ValueError(
                f"effect {eff.name!r}: columns for the {eq} equation have shape {X.shape}, "
                f"expected ({len(data)}, {len(eff.coefficients)})"
            )
        bad = ~np.isfinite(X)
        if bad.any():
            r, c = np.argwhere(bad)[0]
            raise ValueError(
                f"effect {eff.name!r}: column {eff.coefficients[c]!r} ({eq} equation) is not finite "
                f"at sample {r} (t = {data[r, 0]:g}): {X[r, c]!r}"
            )
