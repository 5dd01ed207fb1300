"""Rotor parameters: frozen, validated, read from the effect declarations."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from .effects import EFFECTS, PHYSICAL_EFFECTS, get_effect

__all__ = ["Crack", "RotorParams"]


def _finite(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"parameter {name!r} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"parameter {name!r} must be finite, got {value!r}")
    return v


@dataclass(frozen=True)
class Crack:
    """A crack appearing at time ``time``: the asymmetry ``D`` jumps to ``D``."""

    time: float
    D: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "time", _finite("crack time", self.time))
        object.__setattr__(self, "D", _finite("crack D", self.D))
        if self.time < 0:
            raise ValueError(f"crack time must be >= 0, got {self.time}")


@dataclass(frozen=True)
class RotorParams:
    """All parameters of a rotor (dimensionless units of docs/PHYSICS.md, section 1.4).

    ``ip`` is the polar/transverse inertia ratio (in [0, 1)); ``values`` holds every
    parameter of the effects in ``effects`` (defaults: the paper's Table 1, read from
    the effect declarations).  Parameters read as attributes: ``params.D``.
    ``crack`` optionally makes ``D`` jump at a time.

    >>> RotorParams().replace(h=0.0).h
    0.0
    """

    ip: float = 0.3
    values: Mapping[str, float] = field(default_factory=dict)
    effects: tuple[str, ...] = PHYSICAL_EFFECTS
    crack: Crack | None = None

    def __post_init__(self) -> None:
        ip = _finite("ip", self.ip)
        if not 0.0 <= ip < 1.0:
            raise ValueError(f"parameter 'ip' must be in [0, 1), got {ip}")
        effects = tuple(self.effects)
        for e in effects:
            get_effect(e)
        known = {p.name: p for e in effects for p in EFFECTS[e].parameters}
        merged = {name: p.default for name, p in known.items()}
        for name, value in self.values.items():
            if name not in known:
                raise ValueError(
                    f"unknown parameter {name!r}; known parameters: {', '.join(self.known_names(effects))}"
                )
            merged[name] = _finite(name, value)
        for name, p in known.items():
            lo, hi = p.domain
            if not lo <= merged[name] <= hi:
                raise ValueError(f"parameter {name!r} must be in [{lo}, {hi}], got {merged[name]}")
        if self.crack is not None and "asymmetry" not in effects:
            raise ValueError("a crack needs the 'asymmetry' effect")
        object.__setattr__(self, "ip", ip)
        object.__setattr__(self, "effects", effects)
        object.__setattr__(self, "values", MappingProxyType(merged))

    @staticmethod
    def known_names(effects: tuple[str, ...] = PHYSICAL_EFFECTS) -> list[str]:
        return ["ip"] + [p.name for e in effects for p in EFFECTS[e].parameters]

    def __getattr__(self, name: str) -> float:
        values = self.__dict__.get("values")
        if values is not None and name in values:
            return values[name]
        raise AttributeError(name)

    def __reduce__(self):
        # the mappingproxy of ``values`` can be neither copied nor pickled: rebuild instead
        # (SB3's DummyVecEnv deep-copies infos, AsyncVectorEnv pickles them)
        return RotorParams, (self.ip, dict(self.values), self.effects, self.crack)

    def replace(self, **changes) -> RotorParams:
        """A copy with some parameters changed (``ip``, ``crack`` or effect parameters)."""
        ip = changes.pop("ip", self.ip)
        crack = changes.pop("crack", self.crack)
        values = dict(self.values)
        values.update(changes)
        return RotorParams(ip=ip, values=values, effects=self.effects, crack=crack)

    def coefficients(self, effect: str, t: float | None = None) -> tuple[float, ...]:
        """Regression coefficients of ``effect`` (after the crack if ``t >= crack.time``)."""
        vals = self.values
        if effect == "asymmetry" and self.crack is not None and t is not None and t >= self.crack.time:
            vals = {**vals, "D": self.crack.D}
        return EFFECTS[effect].to_coefficients(vals)

    def to_dict(self) -> dict:
        out: dict = {"ip": self.ip, **self.values}
        if self.crack is not None:
            out["crack"] = {"time": self.crack.time, "D": self.crack.D}
        return out

    @classmethod
    def from_dict(cls, data: Mapping, effects: tuple[str, ...] = PHYSICAL_EFFECTS) -> RotorParams:
        data = dict(data)
        crack = data.pop("crack", None)
        if isinstance(crack, Mapping):
            crack = Crack(**crack)
        ip = data.pop("ip", 0.3)
        return cls(ip=ip, values=data, effects=effects, crack=crack)
