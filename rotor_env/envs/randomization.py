"""Domain randomisation of the environment rotors, and rotor -> kernel arrays.

:func:`sample_params` draws one rotor from a ``numpy.random.Generator`` with a fixed
number of draws (one ``rng.random(N)`` call), so an episode's rotor is a pure function
of the generator state: the single env draws from ``self.np_random`` and sub-env ``i`` of
a vector env from its own generator seeded with ``seed + i`` — the same rotor.

========================  ===================  ===========================================
parameter                 distribution         notes
========================  ===================  ===========================================
``k`` (stiffness)         U(0.64, 1.44)        natural frequency sqrt(k) in [0.8, 1.2]
``ip``                    U(0.1, 0.5)          critical speed sqrt(k/(1-ip)) <= 1.70
``tau`` (unbalance)       U(0.01, 0.03)        always present
``beta`` (unbalance)      U(-pi, pi)           phase of the unbalance
``c`` (viscous)           U(0.02, 0.05)        always present
``D`` (asymmetry)         U(0.01, 0.05)        present with probability 0.5
``h`` (dry friction)      U(0.002, 0.008)      present with probability 0.5 (h/c <= 0.4)
``k30, k21, k12, k03``    U(0, 0.06) each      present with probability 0.5 (together)
========================  ===================  ===========================================

Field faults (``faults={"shaft_bow": 0.3, ...}``: effect -> probability; none by default,
so the default draws are unchanged) are drawn after the table above, with a second single
``rng.random`` call, from :data:`FAULT_RANGES`: every effect declared with a ``fault_range``
(its parameters uniform over the declared ranges, listed in docs/EFFECTS.md), in the order
the effects are registered.  The shaft bow, support anisotropy, cross-coupled stiffness
(kept below the damping: the rotor stays stable), misalignment, breathing crack and rub
(clearances inside the env's clearance 0.6: the casing is touched before the episode ends
on "rub") are declared so.

Absent effects are left out of :attr:`RotorParams.effects` (so ``info["params"]`` says
which effects the rotor has); the simulation gives them coefficient 0.  The ranges keep
the critical speed below the default operating speeds (2.0 run-up, 2.5 balancing) and the
dry-friction whirl (amplitude about ``0.85 h/c``) well inside the default clearance 0.6.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..effects import DerivedMapping, fault_ranges
from ..params import RotorParams
from ..simulator import smooth_effects
from .core import (
    ENV_EFFECTS,
    N_PAR,
    P_CRACK_D,
    P_CRACK_SAMPLE,
    P_H,
    P_IP,
    coef_layout,
)

__all__ = ["FAULT_RANGES", "PRESENCE", "RANGES", "ParamRange", "check_faults", "params_to_arrays",
           "sample_params"]


@dataclass(frozen=True)
class ParamRange:
    """A uniformly drawn parameter: ``name ~ U(low, high)`` belonging to ``effect``."""

    name: str
    low: float
    high: float
    effect: str | None  # None: not an effect parameter (ip)


RANGES: tuple[ParamRange, ...] = (
    ParamRange("k", 0.64, 1.44, "stiffness"),
    ParamRange("ip", 0.1, 0.5, None),
    ParamRange("tau", 0.01, 0.03, "unbalance"),
    ParamRange("beta", -math.pi, math.pi, "unbalance"),
    ParamRange("c", 0.02, 0.05, "viscous_damping"),
    ParamRange("D", 0.01, 0.05, "asymmetry"),
    ParamRange("h", 0.002, 0.008, "structural_damping"),
    ParamRange("k30", 0.0, 0.06, "nonlinear_stiffness"),
    ParamRange("k21", 0.0, 0.06, "nonlinear_stiffness"),
    ParamRange("k12", 0.0, 0.06, "nonlinear_stiffness"),
    ParamRange("k03", 0.0, 0.06, "nonlinear_stiffness"),
)
#: Probability that an optional effect is present (the others always are).
PRESENCE: dict[str, float] = {
    "asymmetry": 0.5,
    "structural_damping": 0.5,
    "nonlinear_stiffness": 0.5,
}
_N_DRAWS = len(RANGES) + len(PRESENCE)
def _fault_ranges() -> dict[str, tuple[ParamRange, ...]]:
    return {name: tuple(ParamRange(p, low, high, name) for p, low, high in ranges)
            for name, ranges in fault_ranges().items()}


#: the field faults an environment can draw, and their ranges: each effect's declared
#: ``fault_range`` (:attr:`rotor_env.effects.Effect.fault_range`), read from the registry when used
FAULT_RANGES: Mapping[str, tuple[ParamRange, ...]] = DerivedMapping(_fault_ranges)


def check_faults(faults: Mapping[str, float] | None) -> dict[str, float]:
    """``faults`` validated: known field faults with probabilities in [0, 1]."""
    out: dict[str, float] = {}
    for name, p in dict(faults or {}).items():
        if name not in FAULT_RANGES:
            raise ValueError(f"faults: unknown field fault {name!r}; the environments draw "
                             f"{', '.join(FAULT_RANGES)}")
        p = float(p)
        if not (math.isfinite(p) and 0.0 <= p <= 1.0):
            raise ValueError(f"faults: the probability of {name!r} must be in [0, 1], got {p!r}")
        out[name] = p
    return out


def sample_params(rng: np.random.Generator, faults: Mapping[str, float] | None = None) -> RotorParams:
    """Draw one rotor (see the module table): one ``rng.random`` call, and one more for
    the field faults when ``faults`` (effect -> probability) names any."""
    faults = check_faults(faults)
    u = rng.random(_N_DRAWS).tolist()
    present = {e: u[len(RANGES) + i] < p for i, (e, p) in enumerate(PRESENCE.items())}
    ip = 0.3
    values: dict[str, float] = {}
    for r, ui in zip(RANGES, u, strict=False):
        v = r.low + (r.high - r.low) * ui
        if r.effect is None:
            ip = v
        elif present.get(r.effect, True):
            values[r.name] = v
    effects = tuple(e for e in ENV_EFFECTS if present.get(e, True))
    if faults:
        ranges = _fault_ranges()
        names = list(ranges)  # a fixed order (registration): the draw does not depend on the dict's
        wanted = [f for f in names if f in faults]
        v = rng.random(len(wanted) + sum(len(ranges[f]) for f in wanted)).tolist()
        k = len(wanted)
        for f in wanted:
            here = v[wanted.index(f)] < faults[f]
            for r in ranges[f]:
                if here:
                    values[r.name] = r.low + (r.high - r.low) * v[k]
                k += 1
            if here:
                effects = (*effects, f)
    return RotorParams(ip=ip, values=values, effects=effects)


#: The paper's Table 1 rotor (``randomize=False``).
TABLE1 = RotorParams()


def params_to_arrays(params: RotorParams, sensor_dt: float,
                     effects: tuple[str, ...] = ENV_EFFECTS) -> tuple[np.ndarray, np.ndarray]:
    """``(coef, par)`` kernel arrays of a rotor for an environment simulating ``effects``
    (absent effects get coefficient 0).

    The crack (if any) switches ``D`` from the sample ``round(crack.time / sensor_dt)`` on.
    """
    if not isinstance(params, RotorParams):
        raise ValueError(f"options['params'] must be a RotorParams, got {type(params).__name__}")
    extra = [e for e in params.effects if e not in effects]
    if extra:
        raise ValueError(
            f"this environment simulates the effects {', '.join(effects)}; "
            f"the rotor has unsupported effect(s) {', '.join(extra)} (field faults: faults={{...}})"
        )
    offsets, n_coef = coef_layout(tuple(effects))
    coef = np.zeros(n_coef)
    for e in smooth_effects(tuple(effects)):
        if e.name in params.effects:
            j = offsets[e.name]
            c = (*params.coefficients(e.name), *e.scanned_values(params.values))
            coef[j : j + len(c)] = c
    par = np.empty(N_PAR)
    par[P_H] = params.h if "structural_damping" in params.effects else 0.0
    par[P_IP] = params.ip
    if params.crack is None:
        par[P_CRACK_SAMPLE] = np.inf
        par[P_CRACK_D] = 0.0
    else:
        par[P_CRACK_SAMPLE] = float(round(params.crack.time / sensor_dt))
        par[P_CRACK_D] = params.crack.D
    return coef, par
