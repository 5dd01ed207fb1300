"""The synchronous model's effects: which declared effects 1X vectors can carry, and how.

:func:`_classify` sorts an effect by how its moment depends on the state: a *forcing* (the
response is linear in its coefficients), a *structural* or a *rotating* stiffness term (a
nonlinear parameter of the fit).  :class:`SynchronousModel` is a set of such effects with the
measurement terms (:data:`RUNOUT`, :data:`SECOND_MODE`): its coefficient layout in the
simulator's vector and its linearisation at a speed, which :mod:`.response` predicts from,
:mod:`.fit` fits and :mod:`.criticals` reads.  The manual is the package's docstring.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ...effects import EFFECTS, DerivedNames, get_effect, synchronous_effects
from ...simulator import compile_accel, smooth_effects

__all__ = ["RUNOUT", "SECOND_MODE", "VECTOR_EFFECTS", "SynchronousModel", "known_effects"]

#: the measurement term "probe runout": a constant 1X vector per probe
RUNOUT = "runout"
#: a second mode of the rotor-bearing system in the speed range (another critical speed):
#: an isotropic oscillator of its own natural frequency, damping and modal unbalance
SECOND_MODE = "second_mode"
#: effects that show in 1X data and that the synchronous model can carry: those declared
#: ``synchronous=True`` (:attr:`rotor_env.effects.Effect.synchronous`), read from the registry
VECTOR_EFFECTS: Sequence[str] = DerivedNames(synchronous_effects)


def _classify(name: str) -> str:
    """'forcing' (moment independent of the state), 'structural' (linear in the state,
    fixed frame), 'rotating' (linear in the state, its stiffness turning with the shaft: a
    crack) — or a clear error for an effect the synchronous model cannot carry."""
    eff = get_effect(name)
    if eff.dry_friction:
        raise ValueError(f"effect {name!r} (dry friction) is non-linear: not identifiable from 1X vectors")
    rng = np.random.default_rng(0)
    cols = eff.columns
    base = [np.array(cols(p, 1.3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.2), dtype=float) for p in (0.3, 1.9)]
    states = rng.normal(size=(2, 4))
    if all(np.allclose(np.array(cols(0.3, 1.3, 0.0, *s, 0.2)), base[0]) for s in states):
        return "forcing"
    lin = []
    for phi in (0.3, 1.9):
        s = states[0]
        a = np.array(cols(phi, 1.3, 0.0, *s, 0.2)) - np.array(cols(phi, 1.3, 0.0, 0, 0, 0, 0, 0.2))
        b = np.array(cols(phi, 1.3, 0.0, *(2 * s), 0.2)) - np.array(cols(phi, 1.3, 0.0, 0, 0, 0, 0, 0.2))
        lin.append(a)
        if not np.allclose(b, 2 * a) or np.abs(np.array(cols(phi, 1.3, 0.0, 0, 0, 0, 0, 0.2))).max() > 0:
            raise ValueError(f"effect {name!r} is non-linear or also a forcing: the 1X model cannot carry it")
    if not np.allclose(lin[0], lin[1]):
        # its stiffness turns with the shaft: only the transient model (the run simulated and
        # tracked at 1X and 2X) carries it
        return "rotating"
    return "structural"


@dataclass(frozen=True)
class SynchronousModel:
    """The effects of a 1X model (``stiffness`` is implicit: ``w_ref`` carries it).

    ``runout``: a constant vector per probe is part of the model.  ``modes``: 2 adds a
    second mode (:data:`SECOND_MODE`) beside the rotor model's own.
    """

    effects: tuple[str, ...]
    ip: float = 0.0
    runout: bool = False
    modes: int = 1
    kinds: dict[str, str] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        eff = tuple(e for e in self.effects if e != "stiffness")
        object.__setattr__(self, "effects", eff)
        if not 0.0 <= self.ip < 1.0:
            raise ValueError(f"ip must be in [0, 1), got {self.ip}")
        object.__setattr__(self, "kinds", {e: _classify(e) for e in eff})

    @property
    def layout(self) -> tuple[str, ...]:
        return ("stiffness", *self.effects)

    @property
    def structural(self) -> tuple[str, ...]:
        """The nonlinear parameters' effects: fixed-frame and rotating stiffness terms."""
        return tuple(e for e in self.effects if self.kinds[e] in ("structural", "rotating"))

    @property
    def rotating(self) -> tuple[str, ...]:
        return tuple(e for e in self.effects if self.kinds[e] == "rotating")

    def fixed_frame(self, coef: np.ndarray) -> np.ndarray:
        """``coef`` without the rotating effects (the fixed-frame model their harmonics are
        balanced against; its eigenvalues give the criticals)."""
        if not self.rotating:
            return coef
        out = np.array(coef, dtype=float)
        slots = self._slots()
        for e in self.rotating:
            out[slots[e]] = 0.0
        return out

    @property
    def forcing(self) -> tuple[str, ...]:
        return tuple(e for e in self.effects if self.kinds[e] == "forcing")

    def with_effect(self, name: str) -> SynchronousModel:
        if name == RUNOUT:
            return SynchronousModel(self.effects, self.ip, True, self.modes)
        if name == SECOND_MODE:
            if self.modes >= 2:
                raise ValueError("the model has its second mode already")
            return SynchronousModel(self.effects, self.ip, self.runout, 2)
        return SynchronousModel((*self.effects, name), self.ip, self.runout, self.modes)

    @property
    def names(self) -> tuple[str, ...]:
        return (*self.effects, *((RUNOUT,) if self.runout else ()), *((SECOND_MODE,) if self.modes > 1 else ()))

    # ---------------------------------------------------------- coefficient layout
    def _slots(self) -> dict[str, slice]:
        # an effect's coefficients, then its argument parameters (an orientation, a scanned
        # clearance) in the simulator's coefficient vector (Effect.kernel_width)
        out, j = {}, 0
        for e in smooth_effects(self.layout):
            n = len(e.coefficients)
            out[e.name] = slice(j, j + n)
            j += e.kernel_width
        return out

    def _argument_defaults(self, coef: np.ndarray) -> None:
        j = 0
        for e in smooth_effects(self.layout):
            for q, p in enumerate(e.argument_parameters):
                coef[j + len(e.coefficients) + q] = p.default
            j += e.kernel_width

    def coef_vector(self, structural: dict[str, np.ndarray], forcing: dict[str, np.ndarray] | None = None) -> np.ndarray:
        slots = self._slots()
        coef = np.zeros(sum(e.kernel_width for e in smooth_effects(self.layout)))
        self._argument_defaults(coef)
        coef[slots["stiffness"]] = 1.0
        for d in (structural, forcing or {}):
            for k, v in d.items():
                coef[slots[k]] = v
        return coef

    def linearised(self, coef: np.ndarray, speed: float) -> tuple[np.ndarray, np.ndarray]:
        """``A_q``, ``A_w`` (2x2, coordinates ``(u, v) = (th_y, th_x)``) at dimensionless ``speed``
        (of the fixed-frame model: the rotating effects are left out)."""
        accel = compile_accel(self.layout)
        coef = self.fixed_frame(coef)
        A_q = np.empty((2, 2))
        A_w = np.empty((2, 2))
        for j, (thx, thy) in enumerate(((0.0, 1.0), (1.0, 0.0))):
            ay, ax = accel(0.0, speed, 0.0, thx, thy, 0.0, 0.0, self.ip, coef)
            A_q[:, j] = (ay, ax)
            ay, ax = accel(0.0, speed, 0.0, 0.0, 0.0, thx, thy, self.ip, coef)
            A_w[:, j] = (ay, ax)
        # forcing terms enter at phi = 0 too: take them out (the structural part is linear)
        f = np.array(accel(0.0, speed, 0.0, 0.0, 0.0, 0.0, 0.0, self.ip, coef))
        return A_q - f[:, None], A_w - f[:, None]

    def forcing_1x(self, coef: np.ndarray, speed: float, accel_rate: float) -> np.ndarray:
        """Complex 1X amplitude (lead) of the forcing, per coordinate ``(u, v)``."""
        accel = compile_accel(self.layout)
        ph = np.linspace(0.0, 2 * math.pi, 16, endpoint=False)
        f = np.array([accel(p, speed, accel_rate, 0.0, 0.0, 0.0, 0.0, self.ip, coef) for p in ph])
        return (2.0 / len(ph)) * (f.T @ np.exp(-1j * ph))


def known_effects() -> tuple[str, ...]:
    """The library effects the synchronous model can carry (for error messages)."""
    ok = []
    for name in EFFECTS:
        try:
            if name != "stiffness":
                _classify(name)
                ok.append(name)
        except ValueError:
            pass
    return tuple(ok)
