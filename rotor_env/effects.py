"""The physical effects of the rotor, each declared once.

Equations of motion (dimensionless, PHYSICS.md section 1), written so that every term
except inertia and the gyroscopic coupling is an *effect*::

    th_y'' = -ip*phid*th_x' + sum_e sum_j theta_ej * col_y_ej + M_y
    th_x'' = +ip*phid*th_y' + sum_e sum_j theta_ej * col_x_ej + M_x

Each effect owns regression coefficients ``theta_ej`` (linear in the moment) and the
matching regressor columns for the first (``y``) and second (``x``) equation.  Its
physical parameters (``tau``, ``beta`` for unbalance) map to those coefficients with
:attr:`Effect.to_coefficients`.  The simulator, the regression, the diagnosis and the
docs all read this table; adding an effect is one :class:`Effect` and one
:func:`register_effect` call.

Column functions take ``(phi, phid, phidd, th_x, th_y, w_x, w_y, ip)`` — spin angle,
speed and acceleration, inclinations and their rates, inertia ratio — and return
``(cols_y, cols_x)``, two tuples with one entry per coefficient.  An effect may have a
parameter that enters the columns non-linearly (the rub's clearance): it is declared
*scanned* (:attr:`Parameter.scan_points`), its value is one more argument of the column
function (after ``ip``, in declaration order, with a default so that the eight-argument
call still works), and the diagnosis finds it by a scan over a grid, as it finds an
onset (:mod:`rotor_env.diagnosis.candidates`).  They must work on
floats and on numpy arrays alike and be compilable by numba (plain arithmetic,
``np.sin``/``np.cos``/``np.sqrt``), so the simulator can call them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

__all__ = [
    "EFFECTS",
    "FRICTION_EPS",
    "DerivedMapping",
    "DerivedNames",
    "Effect",
    "Parameter",
    "candidate_effects",
    "crack_effects",
    "fault_ranges",
    "get_effect",
    "register_effect",
    "synchronous_effects",
    "whirl_effects",
]

#: Regularisation of the relative speed in the dry-friction *regressor*:
#: ``S -> sqrt(S^2 + eps^2)`` (PHYSICS.md: eps = 1e-6 changes the state by < 1e-4).
FRICTION_EPS = 1e-6
#: the domain of a magnitude (damping, friction limit, unbalance, stiffness scale)
_NON_NEGATIVE = (0.0, math.inf)


@dataclass(frozen=True)
class Parameter:
    """A physical parameter of an effect (dimensionless, PHYSICS.md scaling).

    Two ranges: ``domain`` is where the equations are defined (a negative damping or
    friction limit means nothing; :class:`~rotor_env.params.RotorParams` refuses values
    outside it), ``[lower, upper]`` is where a physical rotor can lie, with
    ``bounds_reason`` saying why (the diagnosis rejects a candidate identified outside
    it: curve-fitting, not physics; a simulation may still go there, e.g. to study an
    unstable rotor).
    """

    name: str
    default: float  # the paper's Table 1 value
    description: str
    lower: float = -math.inf
    upper: float = math.inf
    #: why a physical rotor cannot lie outside ``[lower, upper]``: the diagnosis rejects a
    #: candidate whose identified value does (curve-fitting, not physics)
    bounds_reason: str = ""
    domain: tuple[float, float] = (-math.inf, math.inf)
    #: > 0: the parameter enters the columns non-linearly (not a regression coefficient):
    #: the column function takes its value as an argument, and the diagnosis scans it over
    #: this many values spaced geometrically over ``[lower, upper]`` (then refines around
    #: the best); 0: an ordinary parameter, mapped to coefficients by ``to_coefficients``
    scan_points: int = 0
    #: > 0: an *orientation* the keyphasor cannot know (a crack's weak axis on the shaft, the
    #: stiff axis of the supports), periodic with this period [rad].  Like a scanned parameter
    #: it is an argument of the column function (after the scanned ones, in declaration order);
    #: the equation-error regression builds its columns at the declared value (the default, 0:
    #: the axis at the keyphasor notch, the paper's convention), the output-error fit
    #: (:mod:`rotor_env.diagnosis.output_error`) estimates it with the coefficients
    angle_period: float = 0.0
    #: > 0: ``[lower, upper]`` hold at a state amplitude of this size and scale as
    #: ``amplitude_reference / A`` for a record whose peak amplitude is ``A``: a moment
    #: polynomial's coefficient depends on the length unit, and what is physical is the ratio
    #: of its moment to the linear one at the amplitudes reached (:meth:`bounds_at`)
    amplitude_reference: float = 0.0

    def bounds_at(self, amplitude: float | None) -> tuple[float, float]:
        """The plausible range for a record of peak state amplitude ``amplitude`` (the declared
        range where the bounds do not scale, or the amplitude is unknown)."""
        if self.amplitude_reference <= 0 or amplitude is None or not amplitude > 0:
            return self.lower, self.upper
        f = self.amplitude_reference / amplitude
        return self.lower * f, self.upper * f

    @property
    def scanned(self) -> bool:
        return self.scan_points > 0

    @property
    def orientation(self) -> bool:
        """An orientation angle (see :attr:`angle_period`)."""
        return self.angle_period > 0

    @property
    def argument(self) -> bool:
        """Passed to the column function as an argument (scanned, or an orientation)."""
        return self.scanned or self.orientation

    def scan_grid(self) -> np.ndarray:
        """The scan's grid: ``scan_points`` values spaced geometrically over ``[lower, upper]``."""
        if not self.scanned:
            raise ValueError(f"parameter {self.name!r} is not scanned")
        return np.geomspace(self.lower, self.upper, self.scan_points)

    def contains(self, value: float) -> bool:
        """Is ``value`` physically plausible (inside ``[lower, upper]``)?"""
        return self.lower <= value <= self.upper

    def clip_to_domain(self, value: float) -> float:
        return float(min(max(value, self.domain[0]), self.domain[1]))


@dataclass(frozen=True)
class Effect:
    """One physical effect: parameters, moment, regressor columns and its story.

    Attributes
    ----------
    name: identifier used everywhere (``"asymmetry"``).
    parameters: the physical parameters with Table-1 defaults.
    coefficients: names of the regression coefficients, one per column.
    columns: ``(phi, phid, phidd, th_x, th_y, w_x, w_y, ip) -> (cols_y, cols_x)``.
    to_coefficients: physical parameter values (a mapping) -> coefficient tuple.
    from_coefficients: coefficient array -> physical parameter values (for reports).
    moment: the term in the equations, as text (for the docs).
    cause, signature: the physical story: where it comes from, how it shows.
    orders: rotation orders (multiples of the spin frequency, fixed frame) at which a
        missing effect leaves residual energy; ``()`` when not tied to the spin.
    dry_friction: the moment is set-valued (Coulomb): the simulator integrates it with a
        stick/slip switch model; the columns give its slipping direction.
    caveat: a lookalike the data cannot tell apart from it (reported when it is added).
    lookalikes: library effects with a similar signature; when one of them is added the
        diagnosis reports the evidence that decided between them.
    candidate: the diagnosis tests it by default when the model lacks it
        (:func:`candidate_effects`, the diagnosis's ``LIBRARY_CANDIDATES``).
    fault_range: ``((parameter, low, high), ...)``: the environments can draw it as a
        field fault, each parameter ``U(low, high)`` (:func:`fault_ranges`); ``()``: they do not.
    synchronous: its moment is linear in the state or independent of it, so the 1X
        (synchronous) vector model can carry it (:func:`synchronous_effects`).
    whirl: a linear fixed-frame effect with constant coefficients, part of the whirl
        (Campbell) model of the final diagnosis (:func:`whirl_effects`).
    crack: a crack's stiffness law (:func:`crack_effects`): the waveform diagnosis tries it
        with the side load that makes it breathe, in place of the model's other crack, and
        names it only where it is not a rub (:mod:`rotor_env.diagnosis.oe_diagnosis`).

    These five fields are the only lists of effects: every list of the package is
    derived from them, so that adding an effect is one :func:`register_effect`.
    """

    name: str
    parameters: tuple[Parameter, ...]
    coefficients: tuple[str, ...]
    columns: Callable
    to_coefficients: Callable[[Mapping[str, float]], tuple[float, ...]]
    from_coefficients: Callable[[np.ndarray], dict[str, float]]
    moment: str
    cause: str
    signature: str
    orders: tuple[int, ...] = ()
    dry_friction: bool = False
    #: what these data cannot tell it from (said whenever the diagnosis adds it)
    caveat: str = ""
    #: library effects that look like it (the diagnosis reports what told them apart)
    lookalikes: tuple[str, ...] = ()
    #: tested by the diagnosis by default (a plug-in is tested where it is named)
    candidate: bool = False
    #: the environments' field-fault draw: (parameter, low, high) per parameter, uniform
    fault_range: tuple[tuple[str, float, float], ...] = ()
    #: carried by the 1X (synchronous) vector model
    synchronous: bool = False
    #: part of the linear fixed-frame whirl (Campbell) model
    whirl: bool = False
    #: a crack's stiffness law (one crack per model; named only where it is not a rub)
    crack: bool = False

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def scanned_parameters(self) -> tuple[Parameter, ...]:
        """The parameters that enter the columns non-linearly (extra column arguments)."""
        return tuple(p for p in self.parameters if p.scanned)

    @property
    def argument_parameters(self) -> tuple[Parameter, ...]:
        """The parameters passed to the column function as arguments, in declaration order:
        the scanned ones, then the orientations (see :attr:`Parameter.angle_period`)."""
        return (*self.scanned_parameters, *(p for p in self.parameters if p.orientation and not p.scanned))

    @property
    def orientation_parameters(self) -> tuple[Parameter, ...]:
        return tuple(p for p in self.parameters if p.orientation)

    @property
    def kernel_width(self) -> int:
        """Slots of the effect in the simulator's coefficient vector: its coefficients, then
        the values of its argument parameters (scanned, orientations)."""
        return len(self.coefficients) + len(self.argument_parameters)

    def scanned_values(self, values: Mapping[str, float] | None = None) -> tuple[float, ...]:
        """The column function's argument values (scanned parameters, then orientations)
        from ``values`` (their defaults where absent)."""
        values = values or {}
        return tuple(float(values.get(p.name, p.default)) for p in self.argument_parameters)

    def kernel_values(self, values: Mapping[str, float]) -> tuple[float, ...]:
        """The effect's slots of the simulator's coefficient vector (see :attr:`kernel_width`)."""
        return (*self.to_coefficients(values), *self.scanned_values(values))

    def regressors(self, phi, phid, phidd, th_x, th_y, w_x, w_y, ip,
                   scanned: Mapping[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Columns as arrays: ``(X_y, X_x)`` each of shape ``(m, n_coefficients)``;
        ``scanned``: the values of the scanned parameters (their defaults where absent)."""
        cy, cx = self.columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip, *self.scanned_values(scanned))
        m = np.shape(th_x)
        Xy = np.empty((*m, len(cy)))
        Xx = np.empty((*m, len(cx)))
        for q, (a, b) in enumerate(zip(cy, cx, strict=True)):  # scalars broadcast (a constant column)
            Xy[..., q] = a
            Xx[..., q] = b
        return Xy, Xx


# --------------------------------------------------------------------------- effects
def _unbalance(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    s, c = np.sin(phi), np.cos(phi)
    a = (1.0 - ip) * (phidd * c - phid * phid * s)
    b = (1.0 - ip) * (phidd * s + phid * phid * c)
    # coefficients (tau cos beta, tau sin beta)
    return (a, -b), (b, a)


def _unbalance_in_phase(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    s, c = np.sin(phi), np.cos(phi)
    a = (1.0 - ip) * (phidd * c - phid * phid * s)
    b = (1.0 - ip) * (phidd * s + phid * phid * c)
    return (a,), (b,)


def _viscous(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    return (-w_y,), (-w_x,)


def _asymmetry(phi, phid, phidd, th_x, th_y, w_x, w_y, ip, axis=0.0):
    # double-angle from sin/cos(phi): once inlined in the simulator, the compiler shares
    # them with the unbalance's (two trigonometric calls per evaluation instead of four).
    # ``axis``: the stiff body axis u at the shaft angle ``axis`` from the keyphasor notch,
    # ahead in the direction of rotation: in the fixed frame it points along phi + axis, and
    # a stiffness k + D along a direction at angle a is the moment -D e^{2 i a} conj(z)
    s, c = np.sin(phi + axis), np.cos(phi + axis)
    s2, c2 = 2.0 * s * c, c * c - s * s
    return (-(th_y * c2 + th_x * s2),), (-(th_y * s2 - th_x * c2),)


def _nonlinear(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    xx, xy, yy = th_x * th_x, 2.0 * th_x * th_y, th_y * th_y
    zero = 0.0 * th_x
    # coefficient order: k30, k21, k12, k03
    return (zero, -xx, -xy, -yy), (-xx, -xy, -yy, zero)


def _dry_friction(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    # relative (rotating-frame) velocity of the disk on the shaft, in fixed axes
    v_y = w_y + phid * th_x
    v_x = w_x - phid * th_y
    S = np.sqrt(v_y * v_y + v_x * v_x + FRICTION_EPS * FRICTION_EPS)
    return (-v_y / S,), (-v_x / S,)


def _static_load(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    one, zero = 1.0 + 0.0 * th_x, 0.0 * th_x
    # coefficient order: load_y, load_x
    return (one, zero), (zero, one)


def _stiffness(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    return (-th_y,), (-th_x,)


# --------------------------------------------------------------------------- field faults
# The faults a machine in the field has more often than the paper's effects, each the
# lookalike of one of them.  Complex notation (docs/PHYSICS.md): z = th_y + i th_x, a
# moment M_y + i M_x; e^{+i k phi} is order k, forward for k > 0.

def _shaft_bow(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    s, c = np.sin(phi), np.cos(phi)
    # M = b e^{i(phi + gamma)}: the shaft's elastic line offset by the bow, turning with it;
    # coefficients (b cos gamma, b sin gamma)
    return (c, -s), (s, c)


def _support_anisotropy(phi, phid, phidd, th_x, th_y, w_x, w_y, ip, axis=0.0):
    # stiffer by delta along a fixed direction at ``axis`` from the model's y axis, softer
    # across it: M = -delta e^{2 i axis} conj(z) (axis 0: k_y = 1 + delta, k_x = 1 - delta)
    s2, c2 = np.sin(2.0 * axis), np.cos(2.0 * axis)
    return (-(c2 * th_y + s2 * th_x),), (-(s2 * th_y - c2 * th_x),)


def _cross_coupled(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    # M = i q z: a tangential moment along a forward whirl (it feeds it)
    return (-th_x,), (th_y,)


def _misalignment(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    s, c = np.sin(phi), np.cos(phi)
    s2, c2 = 2.0 * s * c, c * c - s * s
    # M = f e^{i(2phi + g)} + f_b e^{-i(2phi + g_b)}; coefficients
    # (f cos g, f sin g, f_b cos g_b, f_b sin g_b)
    return (c2, -s2, c2, -s2), (s2, c2, -s2, -c2)


def _breathing_crack(phi, phid, phidd, th_x, th_y, w_x, w_y, ip, axis=0.0):
    # ``axis``: the crack's direction on the shaft from the keyphasor notch, ahead in the
    # direction of rotation (in the fixed frame along phi + axis: the whole pattern turns with it)
    s, c = np.sin(phi + axis), np.cos(phi + axis)
    s2, c2 = 2.0 * s * c, c * c - s * s
    # G = z + conj(z) e^{2 i phi} = 2 xi e^{i phi}, xi the deflection across the crack
    g_y = th_y + th_y * c2 + th_x * s2
    g_x = th_x + th_y * s2 - th_x * c2
    # M = (dk/4) (1 + depth cos(phi + alpha)) G; coefficients
    # (dk/4, depth dk/4 cos alpha, depth dk/4 sin alpha)
    return (g_y, c * g_y, -s * g_y), (g_x, c * g_x, -s * g_x)


def _hinge_crack(phi, phid, phidd, th_x, th_y, w_x, w_y, ip, axis=0.0):
    # Gasch's hinge: the crack's mouth n = e^{i(phi + axis)} (fixed frame); the deflection
    # across it xi = Re(conj(n) z) opens the crack while it stretches the mouth (xi > 0) and
    # shuts it otherwise: M = dk max(xi, 0) n.  max as (xi + |xi|)/2: plain arithmetic for
    # numba, floats and arrays alike, and the breathing follows the state, not the angle
    s, c = np.sin(phi + axis), np.cos(phi + axis)
    xi = th_y * c + th_x * s
    opened = 0.5 * (xi + np.abs(xi))
    return (opened * c,), (opened * s,)


#: the rub's default radial clearance (tilt units, rad): the column function's default
RUB_CLEARANCE = 0.04


def _rub(phi, phid, phidd, th_x, th_y, w_x, w_y, ip, clearance=RUB_CLEARANCE):
    # contact beyond the clearance: f = max(|z| - clearance, 0) / |z| (0 at z = 0, plain
    # arithmetic for numba, floats and arrays alike); s = sign(phid): the shaft's surface
    # slides forward on the casing when it spins forward (its speed R phid dwarfs the orbit's
    # |z| w: the contact slips, it does not roll), and the friction on the rotor is backward
    r = np.sqrt(th_x * th_x + th_y * th_y)
    d = r - clearance
    f = 0.5 * (d + np.abs(d)) / (r + 1e-300)
    s = phid / (np.abs(phid) + 1e-300)
    # M = -k_c f z - mu k_c s f i z (i z: the forward tangent); coefficients (k_c, mu k_c)
    return (-f * th_y, s * f * th_x), (-f * th_x, -s * f * th_y)


def _rub_to(p: Mapping[str, float]) -> tuple[float, float]:
    k = float(p["rub_stiffness"])
    return (k, float(p["rub_friction"]) * k)


def _rub_from(c) -> dict[str, float]:
    k = float(c[0])
    return {"rub_stiffness": k, "rub_friction": float(c[1]) / k if k != 0 else math.inf}


def _polar(amp: str, phase: str):
    def to_coef(p: Mapping[str, float]) -> tuple[float, float]:
        return (float(p[amp]) * math.cos(p[phase]), float(p[amp]) * math.sin(p[phase]))

    def from_coef(c) -> dict[str, float]:
        return {amp: float(math.hypot(c[0], c[1])), phase: float(math.atan2(c[1], c[0]))}

    return to_coef, from_coef


def _misalignment_to(p: Mapping[str, float]) -> tuple[float, ...]:
    return (*_polar("misalignment", "misalignment_phase")[0](p),
            *_polar("misalignment_back", "misalignment_back_phase")[0](p))


def _misalignment_from(c) -> dict[str, float]:
    return {**_polar("misalignment", "misalignment_phase")[1](c[:2]),
            **_polar("misalignment_back", "misalignment_back_phase")[1](c[2:])}


def _breathing_to(p: Mapping[str, float]) -> tuple[float, float, float]:
    a0 = 0.25 * float(p["dk_crack"])
    return (a0, a0 * p["breathing_depth"] * math.cos(p["breathing_phase"]),
            a0 * p["breathing_depth"] * math.sin(p["breathing_phase"]))


def _breathing_from(c) -> dict[str, float]:
    a0, amp = float(c[0]), float(math.hypot(c[1], c[2]))
    return {"dk_crack": 4.0 * a0, "breathing_depth": amp / a0 if a0 != 0 else math.inf,
            "breathing_phase": float(math.atan2(c[2], c[1]))}



def _identity(names: tuple[str, ...]):
    def to_coef(p: Mapping[str, float]) -> tuple[float, ...]:
        return tuple(float(p[n]) for n in names)

    def from_coef(c: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(names, c, strict=True)}

    return to_coef, from_coef


def _unbalance_from(c: np.ndarray) -> dict[str, float]:
    return {"tau": float(math.hypot(c[0], c[1])), "beta": float(math.atan2(c[1], c[0]))}


EFFECTS: dict[str, Effect] = {}


def register_effect(effect: Effect, *, replace: bool = False) -> Effect:
    """Add an effect to the library (its parameters must not clash with others')."""
    if not replace and effect.name in EFFECTS:
        raise ValueError(f"effect {effect.name!r} is already registered")
    if len(effect.coefficients) == 0:
        raise ValueError(f"effect {effect.name!r} declares no coefficients")
    for p in effect.scanned_parameters:
        if not (0.0 < p.lower < p.upper < math.inf and p.scan_points >= 2):
            raise ValueError(f"effect {effect.name!r}: the scanned parameter {p.name!r} needs finite bounds "
                             f"0 < lower < upper (a geometric grid) and at least 2 scan points")
    for name, low, high in effect.fault_range:
        if name not in effect.parameter_names or not (math.isfinite(low) and math.isfinite(high) and low <= high):
            raise ValueError(f"effect {effect.name!r}: fault_range entry {(name, low, high)!r} needs one of its "
                             f"parameters {list(effect.parameter_names)} and finite bounds low <= high")
    for other in EFFECTS.values():
        if other.name == effect.name:
            continue
        clash = (set(other.parameter_names) & set(effect.parameter_names)) - _SHARED_PARAMS
        if clash:
            raise ValueError(
                f"effect {effect.name!r} reuses parameter(s) {sorted(clash)} of {other.name!r}"
            )
    EFFECTS[effect.name] = effect
    return effect


class DerivedNames(Sequence):
    """A tuple of effect names derived from the registry when read (never a stale copy):
    an effect registered later is in it.  Compares equal to the tuple it reads as."""

    def __init__(self, derive: Callable[[], tuple[str, ...]]) -> None:
        self._derive = derive

    def __getitem__(self, i):
        return self._derive()[i]

    def __len__(self) -> int:
        return len(self._derive())

    def __iter__(self) -> Iterator[str]:
        return iter(self._derive())

    def __eq__(self, other) -> bool:
        return isinstance(other, Sequence) and tuple(self) == tuple(other)

    def __hash__(self) -> int:
        return hash(tuple(self))

    def __repr__(self) -> str:
        return repr(self._derive())


class DerivedMapping(Mapping):
    """A read-only mapping derived from the registry when read (see :class:`DerivedNames`)."""

    def __init__(self, derive: Callable[[], Mapping]) -> None:
        self._derive = derive

    def __getitem__(self, key):
        return self._derive()[key]

    def __len__(self) -> int:
        return len(self._derive())

    def __iter__(self) -> Iterator:
        return iter(self._derive())

    def __repr__(self) -> str:
        return repr(dict(self._derive()))


def candidate_effects() -> tuple[str, ...]:
    """The effects the diagnosis tests by default, in registration order."""
    return tuple(e.name for e in EFFECTS.values() if e.candidate)


def fault_ranges() -> dict[str, tuple[tuple[str, float, float], ...]]:
    """Effect -> its field-fault ranges, for the effects the environments can draw (registration order)."""
    return {e.name: e.fault_range for e in EFFECTS.values() if e.fault_range}


def synchronous_effects() -> tuple[str, ...]:
    """The effects the 1X vector model can carry, in registration order."""
    return tuple(e.name for e in EFFECTS.values() if e.synchronous)


def crack_effects() -> tuple[str, ...]:
    """The cracks' stiffness laws (open, breathing, hinge), in registration order."""
    return tuple(e.name for e in EFFECTS.values() if e.crack)


def whirl_effects() -> tuple[str, ...]:
    """The linear fixed-frame effects of the whirl (Campbell) model, in registration order."""
    return tuple(e.name for e in EFFECTS.values() if e.whirl)


# unbalance_in_phase is the paper's one-column view of the same physical unbalance
_SHARED_PARAMS = {"tau", "beta"}


def get_effect(name: str) -> Effect:
    """The registered effect called ``name`` (clear error listing the known ones)."""
    try:
        return EFFECTS[name]
    except KeyError:
        raise ValueError(
            f"unknown effect {name!r}; known effects: {', '.join(sorted(EFFECTS))}"
        ) from None


_to, _from = _identity(("c",))
register_effect(
    Effect(
        name="viscous_damping",
        parameters=(Parameter("c", 0.03, "viscous damping coefficient c/sqrt(k I_t)", 0.0, 0.6,
                            "damping ratio c/2 between 0 and 30 %: a rotor beyond it has no visible critical",
                            _NON_NEGATIVE),),
        coefficients=("c",),
        columns=_viscous,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="-c th_y',  -c th_x'",
        cause="aerodynamic and other viscous losses, bearing and seal damping",
        signature="limits the resonance peak; residual at the whirl (1x near the critical speed)",
        orders=(1,),
        lookalikes=('cross_coupled_stiffness',),
        candidate=True,
        synchronous=True,
        whirl=True,
    )
)
register_effect(
    Effect(
        name="unbalance",
        parameters=(
            Parameter("tau", 0.02, "unbalance magnitude (dynamic unbalance of the disk)", 0.0, 0.1,
                      "the tilt of the disk's principal axis [rad]: beyond 0.1 rad (6 deg) no rotor runs",
                      _NON_NEGATIVE),
            Parameter("beta", 0.0, "unbalance phase angle [rad] relative to phi = 0"),
        ),
        coefficients=("tau_cos_beta", "tau_sin_beta"),
        columns=_unbalance,
        to_coefficients=lambda p: (p["tau"] * math.cos(p["beta"]), p["tau"] * math.sin(p["beta"])),
        from_coefficients=_unbalance_from,
        moment="(1-ip) tau (phidd cos(phi+beta) - phid^2 sin(phi+beta)), and the x counterpart",
        cause="the disk's principal axis is tilted against the shaft (dynamic unbalance)",
        signature="synchronous (1x) forcing growing with speed squared",
        orders=(1,),
        lookalikes=('shaft_bow',),
        candidate=True,
        synchronous=True,
    )
)
_to, _from = _identity(("D",))
register_effect(
    Effect(
        name="asymmetry",
        parameters=(Parameter("D", 0.03, "stiffness asymmetry (k_u - k_v)/2k: a crack, a keyway", -0.15, 0.15,
                            "a crack through half the shaft lowers one bending stiffness by about 30 %: |D| <= 0.15"),
                    Parameter("D_axis", 0.0, "angle of the stiff body axis u (the weak axis v is 90 deg on) from "
                              "the keyphasor notch, in the direction of rotation [rad]", angle_period=math.pi)),
        coefficients=("D",),
        columns=_asymmetry,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="-D e^{2 i (phi + axis)} conj(z)  (axis 0: -D (th_y cos2phi + th_x sin2phi),  -D (th_y sin2phi - th_x cos2phi))",
        cause="unsymmetrical shaft stiffness: a breathing or open crack, a keyway, a flat",
        signature="splits the critical speed into sqrt(k-D)..sqrt(k+D), unstable in between; "
        "a whirl at frequency w leaves order 2 - w/speed (a static side load: 2x, the crack's classic "
        "signature); synchronous response stays 1x",
        orders=(1, 2),
        lookalikes=('breathing_crack', 'misalignment', 'support_anisotropy'),
        crack=True,
        candidate=True,
    )
)
#: quadratic stiffness: at the peak amplitude A the quadratic moment k A^2 stays below a tenth
#: of the linear one, |k| A <= 0.09: |k| <= 0.3 at A = 0.3 rad, scaled with 0.3 / A
_QUADRATIC = (-0.3, 0.3, "a quadratic restoring moment larger than a tenth of the linear one at the record's "
              "peak amplitude (|k| <= 0.3 at 0.3) is not a weak non-linearity of an elastic shaft")
_LOAD_REASON = "a static tilt above 0.1 rad bends the shaft beyond its elastic range"
_to, _from = _identity(("k30", "k21", "k12", "k03"))
register_effect(
    Effect(
        name="nonlinear_stiffness",
        parameters=(
            Parameter("k30", 0.05, "quadratic stiffness: th_x^2 in the x moment", *_QUADRATIC,
                      amplitude_reference=0.3),
            Parameter("k21", 0.04, "quadratic stiffness: th_x^2 in y, 2 th_x th_y in x", *_QUADRATIC,
                      amplitude_reference=0.3),
            Parameter("k12", 0.03, "quadratic stiffness: 2 th_x th_y in y, th_y^2 in x", *_QUADRATIC,
                      amplitude_reference=0.3),
            Parameter("k03", 0.02, "quadratic stiffness: th_y^2 in the y moment", *_QUADRATIC,
                      amplitude_reference=0.3),
        ),
        coefficients=("k30", "k21", "k12", "k03"),
        columns=_nonlinear,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="-(k03 th_y^2 + 2 k12 th_x th_y + k21 th_x^2),  -(k30 th_x^2 + 2 k21 th_x th_y + k12 th_y^2)",
        cause="non-linear elastic restoring moment (a second-order polynomial from one potential)",
        signature="0x (a static offset) and 2x in the fixed frame, growing with amplitude squared",
        orders=(0, 2),
        lookalikes=('stiffness', 'misalignment', 'rub'),
        candidate=True,
    )
)
_to, _from = _identity(("h",))
register_effect(
    Effect(
        name="structural_damping",
        parameters=(Parameter("h", 0.01, "dry-friction (structural internal damping) moment limit", 0.0, 0.05,
                            "a friction moment above 5 % of the elastic moment at 1 rad locks the joint: no slip",
                            _NON_NEGATIVE),),
        coefficients=("h",),
        columns=_dry_friction,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="-h (th_y' + phid th_x)/S,  -h (th_x' - phid th_y)/S  (S: relative speed)",
        cause="dry friction between shaft and disk (shrink fits, joints), constant magnitude, "
        "opposing the motion relative to the rotating shaft",
        signature="sticks at low speed; above the critical speed drives a self-excited forward whirl "
        "at the natural frequency that persists (non-synchronous, not a rotation order)",
        orders=(),
        dry_friction=True,
        candidate=True,
    )
)
_to, _from = _identity(("k",))
register_effect(
    Effect(
        name="stiffness",
        parameters=(Parameter("k", 1.0, "shaft stiffness scale (natural frequency sqrt(k))", 0.25, 4.0,
                            "the time unit is set by the natural frequency: k outside [0.25, 4] means the data are "
                            "not in these units (rescale time), not a stiffness change", _NON_NEGATIVE),),
        coefficients=("k",),
        columns=_stiffness,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="-k th_y,  -k th_x",
        cause="the shaft's elastic restoring moment; 1 in the paper's units",
        signature="sets the critical speed sqrt(k); a wrong k leaves residual at the whirl",
        orders=(1,),
        lookalikes=('nonlinear_stiffness', 'support_anisotropy', 'rub'),
        candidate=True,
        whirl=True,
    )
)
_to, _from = _identity(("tau",))
register_effect(
    Effect(
        name="unbalance_in_phase",
        parameters=(Parameter("tau", 0.02, "unbalance magnitude with phase known to be 0", -0.1, 0.1,
                      "as for the unbalance; the sign is the phase 0 or pi"),),
        coefficients=("tau",),
        columns=_unbalance_in_phase,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="(1-ip) tau (phidd cos(phi) - phid^2 sin(phi)): the paper's x1 with beta = 0",
        cause="dynamic unbalance whose phase is known (the paper's preset)",
        signature="synchronous (1x) forcing growing with speed squared",
        orders=(1,),
    )
)

_to, _from = _identity(("load_y", "load_x"))
register_effect(
    Effect(
        name="static_load",
        parameters=(
            Parameter("load_y", 0.0, "constant moment in the y equation (gravity, misalignment)", -0.1, 0.1,
                      _LOAD_REASON),
            Parameter("load_x", 0.0, "constant moment in the x equation", -0.1, 0.1, _LOAD_REASON),
        ),
        coefficients=("load_y", "load_x"),
        columns=_static_load,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="load_y,  load_x (constant)",
        cause="a constant side load: gravity on a horizontal shaft, bearing misalignment, a magnetic pull",
        signature="a static deflection: 0x in the fixed frame (with asymmetry, the crack's 2x)",
        orders=(0,),
        candidate=True,
    )
)

# --------------------------------------------------------------------------- field faults
_to, _from = _polar("bow", "bow_phase")
register_effect(
    Effect(
        name="shaft_bow",
        parameters=(
            Parameter("bow", 0.01, "residual bow of the shaft at the disk [rad]", 0.0, 0.05,
                      "a bow tilting the disk by more than 0.05 rad (3 deg) is a bent shaft no machine runs with",
                      _NON_NEGATIVE),
            Parameter("bow_phase", 0.0, "angle of the bow against phi = 0 [rad]"),
        ),
        coefficients=("bow_cos", "bow_sin"),
        columns=_shaft_bow,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="b e^{i(phi + gamma)}:  b cos(phi+gamma),  b sin(phi+gamma)",
        cause="a bent shaft (thermal bow, sag, a straightening that did not hold): its elastic line is "
        "offset in a direction fixed to the shaft",
        signature="1x forward of constant forcing amplitude: present at slow roll (a static deflection b "
        "turning with the shaft), resonant at the critical; the unbalance's forcing grows with speed^2",
        orders=(1,),
        caveat="a probe runout (an out-of-round or marked probe track) leaves the same 1x pattern in the "
        "equations: one probe plane cannot tell it from a bow; if the 1x at slow roll is runout, subtract it "
        "(diagnose --slow-roll SPEED) and diagnose again, or compare with a second probe plane",
        lookalikes=('unbalance',),
        candidate=True,
        fault_range=(("bow", 0.002, 0.01), ("bow_phase", -math.pi, math.pi)),
        synchronous=True,
    )
)
_to, _from = _identity(("support_anisotropy",))
register_effect(
    Effect(
        name="support_anisotropy",
        parameters=(Parameter("support_anisotropy", 0.05, "support stiffness split (k_y - k_x)/2k, fixed frame",
                              -0.3, 0.3, "supports whose stiffnesses differ by a factor above 1.9 (0.3) are a "
                              "broken pedestal, not an anisotropy"),
                    Parameter("support_axis", 0.0, "angle of the stiff support direction from the model's y axis "
                              "(the probes' frame, not the keyphasor's) [rad]", angle_period=math.pi)),
        coefficients=("support_anisotropy",),
        columns=_support_anisotropy,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="-delta e^{2 i axis} conj(z) (axis 0:  -delta th_y,  +delta th_x)",
        cause="bearing pedestals or foundation stiffer in one direction than the other (fixed frame, "
        "not turning with the shaft)",
        signature="two criticals sqrt(1 -+ delta); elliptic orbits: the forward 1x response mirrored into "
        "a backward (-1x) line, largest between the criticals; no 2x (a shaft asymmetry keeps 1x forward "
        "and shows 2x with a side load)",
        orders=(-1,),
        lookalikes=('asymmetry',),
        candidate=True,
        fault_range=(("support_anisotropy", -0.08, 0.08),),
        synchronous=True,
        whirl=True,
    )
)
_to, _from = _identity(("cross_coupling",))
register_effect(
    Effect(
        name="cross_coupled_stiffness",
        parameters=(Parameter("cross_coupling", 0.01, "cross-coupled stiffness q/k (tangential moment per tilt)",
                              -0.1, 0.1, "a cross-coupling above 0.1 of the direct stiffness exceeds the damping of "
                              "any rotor that reaches its critical (instability threshold q = c w)"),),
        coefficients=("cross_coupling",),
        columns=_cross_coupled,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="i q z:  -q th_x,  +q th_y",
        cause="fluid-film bearings, seals, aerodynamic (Alford) forces: a moment at right angles to the tilt",
        signature="feeds forward whirl: lowers the apparent damping of the forward mode (at a whirl w it "
        "acts as a damping -q/w) and destabilises it above q = c w; unlike damping it does not grow with "
        "the whirl frequency; acts on whatever whirls (the 1x response, the free whirl at the natural "
        "frequency), so it is not tied to a rotation order",
        orders=(),
        lookalikes=('viscous_damping',),
        # the environments' range stays below the damping: the rotor stays stable
        candidate=True,
        fault_range=(("cross_coupling", 0.0, 0.01),),
        synchronous=True,
        whirl=True,
    )
)
register_effect(
    Effect(
        name="misalignment",
        parameters=(
            Parameter("misalignment", 0.005, "forward 2x moment of the misaligned coupling", 0.0, 0.05,
                      "a 2x moment above 0.05 bends the shaft by 3 deg twice per turn: a broken coupling",
                      _NON_NEGATIVE),
            Parameter("misalignment_phase", 0.0, "its phase against 2 phi [rad]"),
            Parameter("misalignment_back", 0.0, "backward 2x moment (a misalignment along a fixed line: "
                      "forward and backward alike)", 0.0, 0.05, "as the forward one", _NON_NEGATIVE),
            Parameter("misalignment_back_phase", 0.0, "its phase [rad]"),
        ),
        coefficients=("misalignment_cos", "misalignment_sin", "misalignment_back_cos", "misalignment_back_sin"),
        columns=_misalignment,
        to_coefficients=_misalignment_to,
        from_coefficients=_misalignment_from,
        moment="f e^{i(2phi + g)} + f_b e^{-i(2phi + g_b)}",
        cause="coupling misalignment (parallel or angular): the coupling bends the shaft twice per "
        "revolution; it also brings a static preload (declare static_load for it)",
        signature="2x (forward, and backward for a fixed-line misalignment) of constant amplitude, at "
        "every speed; weakly resonant where 2x meets a natural frequency (near half the critical). "
        "A crack's 2x needs a side load and grows with the static deflection",
        orders=(2, -2),
        lookalikes=('asymmetry', 'breathing_crack', 'nonlinear_stiffness'),
        candidate=True,
        fault_range=(("misalignment", 0.0, 0.005), ("misalignment_phase", -math.pi, math.pi)),
    )
)
register_effect(
    Effect(
        name="breathing_crack",
        parameters=(
            Parameter("dk_crack", 0.1, "stiffness lost across a fully open crack (Delta k / k)", 0.0, 0.6,
                      "a crack through half the shaft lowers the bending stiffness across it by about 60 %",
                      _NON_NEGATIVE),
            Parameter("breathing_depth", 1.0, "how far the crack opens and closes (0: always half open, "
                      "1: fully open to closed)", 0.0, 1.3, "the opening cannot swing beyond fully open and "
                      "closed (1; +30 % for noise)"),
            Parameter("breathing_phase", 0.0, "angle at which the crack is fully open [rad]"),
            Parameter("crack_axis", 0.0, "direction of the crack on the shaft from the keyphasor notch, in the "
                      "direction of rotation [rad]", angle_period=2 * math.pi),
        ),
        coefficients=("crack_mean", "crack_breathing_cos", "crack_breathing_sin"),
        columns=_breathing_crack,
        to_coefficients=_breathing_to,
        from_coefficients=_breathing_from,
        moment="(dk/4) (1 + depth cos(phi + axis + alpha)) (z + conj(z) e^{2 i (phi + axis)})  (Mayes' cosine "
        "breathing; axis 0 in the paper)",
        cause="a fatigue crack that opens and closes once per turn as the bending across it (gravity, a "
        "side load) changes sign",
        signature="with a side load: 1x, 2x and 3x; resonances at 1/2 and 1/3 of the critical (sub-critical "
        "2x and 3x peaks); the always-open asymmetry has the 2x only",
        orders=(1, 2, 3),
        lookalikes=('asymmetry', 'misalignment'),
        crack=True,
        candidate=True,
        fault_range=(("dk_crack", 0.02, 0.1), ("breathing_depth", 0.5, 1.0),
                     ("breathing_phase", -math.pi, math.pi)),
    )
)

register_effect(
    Effect(
        name="hinge_crack",
        parameters=(
            Parameter("dk_hinge", 0.05, "stiffness lost across the crack while it is open (Delta k / k)", 0.0, 0.6,
                      "a crack through half the shaft lowers the bending stiffness across it by about 60 %",
                      _NON_NEGATIVE),
            Parameter("hinge_axis", 0.0, "direction of the crack's mouth (the normal of its faces, pointing out of "
                      "the crack) on the shaft from the keyphasor notch, in the direction of rotation [rad]",
                      angle_period=2 * math.pi),
        ),
        coefficients=("dk_hinge",),
        columns=_hinge_crack,
        to_coefficients=_identity(("dk_hinge",))[0],
        from_coefficients=_identity(("dk_hinge",))[1],
        moment="dk max(xi, 0) n,  n = e^{i (phi + axis)},  xi = Re(conj(n) z)  (Gasch's hinge: open while the "
        "deflection stretches the mouth, shut otherwise)",
        cause="a transverse fatigue crack whose faces part while the bending across them is tensile and close "
        "flat while it is compressive: the stiffness switches between k - dk and k with the sign of the "
        "deflection across the mouth, not with the shaft's angle (Gasch 1993's hinge model)",
        signature="under a static deflection larger than the vibration (gravity, a side load) it opens and shuts "
        "once per turn like the breathing crack, with a square wave instead of a cosine: 1x, 2x, 3x and "
        "higher, resonances at 1/2 and 1/3 of the critical; where the vibration outgrows the static "
        "deflection (at the critical) it breathes with the whirl: a synchronous whirl keeps it open or shut "
        "and the critical's two sides see different stiffnesses",
        orders=(1, 2, 3),
        lookalikes=("breathing_crack", "asymmetry", "misalignment"),
        crack=True,
        candidate=True,
    )
)

register_effect(
    Effect(
        name="rub",
        parameters=(
            Parameter("rub_stiffness", 0.5, "contact stiffness of the casing (seal) beyond the clearance, per "
                      "unit shaft stiffness", 0.0, 20.0, "a casing pushes, never pulls (>= 0); a contact above 20 "
                      "times the shaft's stiffness rings above 4.5x the natural frequency: an impact, not the "
                      "smooth contact this model is", _NON_NEGATIVE),
            Parameter("rub_friction", 0.2, "Coulomb friction coefficient of the contact (mu)", 0.0, 0.6,
                      "friction opposes the slip (>= 0); dry rubbing pairs (steel on steel, seals, babbitt) lie "
                      "between 0.1 and 0.6", _NON_NEGATIVE),
            Parameter("rub_clearance", RUB_CLEARANCE, "radial clearance to the casing, as a tilt [rad]", 0.005,
                      0.2, "a clearance below 0.005 rad is touched at slow roll (a tight fit, not a rub that comes "
                      "and goes); above 0.2 rad no elastic shaft reaches it", (0.0, math.inf), scan_points=40),
        ),
        coefficients=("rub_contact", "rub_friction_moment"),
        columns=_rub,
        to_coefficients=_rub_to,
        from_coefficients=_rub_from,
        moment="-k_c max(|z| - clearance, 0) (1 + i mu sign(phid)) z/|z|",
        cause="the disk (or a seal) touches the casing where the whirl exceeds the radial clearance: a radial "
        "contact stiffness on the penetration and Coulomb friction against the shaft's sliding surface, which "
        "pushes the rotor backward along its orbit",
        signature="only while |theta| exceeds the clearance (around the critical and in the free whirl after "
        "it): a stiffening (the critical moves up, the peak is cut flat) and a backward tangential moment along "
        "the orbit; a light rub on the synchronous orbit leaves mostly 1x forward, a heavy one with enough "
        "friction drives reverse whirl (-1x), and an off-centre orbit (a side load) touching once per turn "
        "can lock into 1/2x; run-up and coast-down differ (the response trails the sweep: the contact band "
        "lies above the critical running up, below it coasting down; a hard rub adds a jump)",
        orders=(1, -1),
        caveat="the clearance is found by a scan (the contact is non-linear in it); a contact that holds over "
        "the whole record is a stiffness change plus a cross-coupling to these data, so a rub is named only "
        "where the contact comes and goes",
        lookalikes=("stiffness", "nonlinear_stiffness"),
        # the environments' clearances lie inside their casing's 0.6: touched before an episode ends on "rub"
        candidate=True,
        fault_range=(("rub_stiffness", 0.2, 1.0), ("rub_friction", 0.1, 0.3), ("rub_clearance", 0.1, 0.4)),
    )
)

#: The effects the simulator includes by default (the physical rotor of Table 1; the
#: static load is 0 there).
PHYSICAL_EFFECTS: tuple[str, ...] = (
    "stiffness",
    "unbalance",
    "viscous_damping",
    "asymmetry",
    "nonlinear_stiffness",
    "structural_damping",
    "static_load",
)

#: The effects the package itself declares (all of them are registered above; effects
#: registered later, by a user or a test, are not in it): the catalogue ``docs/EFFECTS.md``
#: (:mod:`rotor_env.effects_doc`) renders these, and a plug-in may not take their names.
PACKAGE_EFFECTS = MappingProxyType(dict(EFFECTS))
