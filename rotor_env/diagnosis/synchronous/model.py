"""The synchronous model's effects: which declared effects 1X vectors can carry, and how.

:func:`_classify` sorts an effect by how its moment depends on the state: a *forcing* (the
response is linear in its coefficients), a *structural* or a *rotating* stiffness term (a
nonlinear parameter of the fit).  :class:`SynchronousModel` is a set of such effects with the
measurement terms (:data:`RUNOUT`, :data:`SECOND_MODE`): its coefficient layout in the
simulator's vector and its linearisation at a speed, which :mod:`.response` predicts from,
:mod:`.fit` fits and :mod:`.criticals` reads.  The manual is the package's docstring.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ...effects import EFFECTS, DerivedNames, get_effect, synchronous_effects
from ...simulator import compile_accel, smooth_effects

__all__ = ["RUNOUT", "SECOND_MODE", "VECTOR_EFFECTS", "SynchronousModel", "harmonic_order", "known_effects"]

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

    def fitted_orientations(self, name: str) -> tuple[int, ...]:
        """Which of a rotating effect's argument parameters are orientations fitted with its
        coefficients (indices among :attr:`~rotor_env.effects.Effect.argument_parameters`).

        A crack's axis sits anywhere relative to the keyphasor notch, and with an unbalance
        somewhere else the 1X response depends on the angle between them (the split critical's
        two branches carry the unbalance's components along the stiff and weak axes): with the
        axis held at the notch, a crack 30 deg from it left a 1X/2X table 40x above its floor.
        A fixed-frame stiffness's orientation (the supports' stiff axis) is relative to the
        probes, which are anywhere too.  A forcing's phase is in its linear coefficients."""
        if self.kinds.get(name) not in ("rotating", "structural"):
            return ()
        return tuple(q for q, p in enumerate(get_effect(name).argument_parameters) if p.orientation)

    def n_structural(self, name: str) -> int:
        """Nonlinear parameters of a structural or rotating effect in a fit: for an effect
        harmonic in its orientation (:func:`harmonic_order`) the two Cartesian components of
        its coefficient, else its coefficients then its fitted orientations (rad)."""
        if self.fitted_orientations(name) and harmonic_order(name):
            return 2
        return len(get_effect(name).coefficients) + len(self.fitted_orientations(name))

    def structural_values(self, name: str, v: np.ndarray) -> tuple[np.ndarray, tuple[float, ...]]:
        """A structural or rotating effect's fitted parameters ``v`` as its coefficients and
        its fitted orientations' values (rad)."""
        v = np.atleast_1d(np.asarray(v, dtype=float))
        orient = self.fitted_orientations(name)
        n_coef = len(get_effect(name).coefficients)
        if not orient or len(v) == n_coef:
            return v[:n_coef], ()
        n = harmonic_order(name)
        if n:
            return np.array([math.hypot(v[0], v[1])]), (math.atan2(v[1], v[0]) / n,)
        return v[:n_coef], tuple(float(a) for a in v[n_coef:])

    def structural_start(self, name: str, size: float, angle: float = 0.0) -> np.ndarray:
        """Fit parameters of a new structural or rotating effect: every coefficient at
        ``size``, the orientation at ``angle``."""
        orient = self.fitted_orientations(name)
        if orient and harmonic_order(name):
            n = harmonic_order(name)
            return np.array([size * math.cos(n * angle), size * math.sin(n * angle)])
        return np.array([size] * len(get_effect(name).coefficients) + [angle] * len(orient))

    def coef_vector(self, structural: dict[str, np.ndarray], forcing: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """The simulator's coefficient vector: each effect's coefficients, and after a rotating
        effect's coefficients in ``structural`` its fitted orientations (:meth:`fitted_orientations`)."""
        slots = self._slots()
        coef = np.zeros(sum(e.kernel_width for e in smooth_effects(self.layout)))
        self._argument_defaults(coef)
        coef[slots["stiffness"]] = 1.0
        for d in (structural, forcing or {}):
            for k, v in d.items():
                sl = slots[k]
                if d is structural:
                    v, angles = self.structural_values(k, v)
                    for a, q in zip(angles, self.fitted_orientations(k), strict=False):
                        coef[sl.stop + q] = a
                coef[sl] = v
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


@functools.cache
def harmonic_order(name: str) -> int:
    """``n`` where an effect of one coefficient and one orientation ``a`` has columns
    ``cos(n a) C(0) + sin(n a) C(pi / 2n)`` at every state and spin angle: its moment is then
    linear in the complex coefficient ``D e^{i n a}`` (a shaft asymmetry: ``n = 2``,
    ``-D e^{2 i (phi + a)} conj(z)``), fitted as its two Cartesian components -- smooth
    through ``D = 0``, where the angle alone is undefined, and tested as two coefficients.
    0 for any other effect (checked numerically at random states)."""
    eff = get_effect(name)
    if len(eff.coefficients) != 1 or len(eff.argument_parameters) != 1 or not eff.argument_parameters[0].orientation:
        return 0
    rng = np.random.default_rng(3)
    states = rng.normal(size=(4, 4))
    phis = rng.uniform(0.0, 2 * math.pi, 4)
    for n in (1, 2, 3):
        ok = True
        for a in rng.uniform(0.0, 2 * math.pi, 3):
            for s, ph in zip(states, phis, strict=True):
                got = np.array(eff.columns(ph, 1.3, 0.0, *s, 0.2, a), dtype=float)
                base = np.array(eff.columns(ph, 1.3, 0.0, *s, 0.2, 0.0), dtype=float)
                quad = np.array(eff.columns(ph, 1.3, 0.0, *s, 0.2, math.pi / (2 * n)), dtype=float)
                if not np.allclose(got, math.cos(n * a) * base + math.sin(n * a) * quad, rtol=1e-9, atol=1e-12):
                    ok = False
        if ok:
            return n
    return 0


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
