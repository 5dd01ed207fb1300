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
``(cols_y, cols_x)``, two tuples with one entry per coefficient.  They must work on
floats and on numpy arrays alike and be compilable by numba (plain arithmetic,
``np.sin``/``np.cos``/``np.sqrt``), so the simulator can call them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

__all__ = [
    "EFFECTS",
    "FRICTION_EPS",
    "Effect",
    "Parameter",
    "get_effect",
    "register_effect",
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

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    def regressors(self, phi, phid, phidd, th_x, th_y, w_x, w_y, ip) -> tuple[np.ndarray, np.ndarray]:
        """Columns as arrays: ``(X_y, X_x)`` each of shape ``(m, n_coefficients)``."""
        cy, cx = self.columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip)
        m = np.shape(th_x)
        Xy = np.column_stack([np.broadcast_to(np.asarray(c, dtype=float), m) for c in cy])
        Xx = np.column_stack([np.broadcast_to(np.asarray(c, dtype=float), m) for c in cx])
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


def _asymmetry(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    # double-angle from sin/cos(phi): once inlined in the simulator, the compiler shares
    # them with the unbalance's (two trigonometric calls per evaluation instead of four)
    s, c = np.sin(phi), np.cos(phi)
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
    )
)
_to, _from = _identity(("D",))
register_effect(
    Effect(
        name="asymmetry",
        parameters=(Parameter("D", 0.03, "stiffness asymmetry (k_u - k_v)/2k: a crack, a keyway", -0.15, 0.15,
                            "a crack through half the shaft lowers one bending stiffness by about 30 %: |D| <= 0.15"),),
        coefficients=("D",),
        columns=_asymmetry,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="-D (th_y cos2phi + th_x sin2phi),  -D (th_y sin2phi - th_x cos2phi)",
        cause="unsymmetrical shaft stiffness: a breathing or open crack, a keyway, a flat",
        signature="splits the critical speed into sqrt(k-D)..sqrt(k+D), unstable in between; "
        "a whirl at frequency w leaves order 2 - w/speed (a static side load: 2x, the crack's classic "
        "signature); synchronous response stays 1x",
        orders=(1, 2),
    )
)
#: quadratic stiffness: at |theta| = 0.3 the quadratic moment stays below a third of the linear one
_QUADRATIC = (-0.3, 0.3, "a quadratic restoring moment larger than a third of the linear one at 0.3 rad "
              "is not a weak non-linearity of an elastic shaft")
_LOAD_REASON = "a static tilt above 0.1 rad bends the shaft beyond its elastic range"
_to, _from = _identity(("k30", "k21", "k12", "k03"))
register_effect(
    Effect(
        name="nonlinear_stiffness",
        parameters=(
            Parameter("k30", 0.05, "quadratic stiffness: th_x^2 in the x moment", *_QUADRATIC),
            Parameter("k21", 0.04, "quadratic stiffness: th_x^2 in y, 2 th_x th_y in x", *_QUADRATIC),
            Parameter("k12", 0.03, "quadratic stiffness: 2 th_x th_y in y, th_y^2 in x", *_QUADRATIC),
            Parameter("k03", 0.02, "quadratic stiffness: th_y^2 in the y moment", *_QUADRATIC),
        ),
        coefficients=("k30", "k21", "k12", "k03"),
        columns=_nonlinear,
        to_coefficients=_to,
        from_coefficients=_from,
        moment="-(k03 th_y^2 + 2 k12 th_x th_y + k21 th_x^2),  -(k30 th_x^2 + 2 k21 th_x th_y + k12 th_y^2)",
        cause="non-linear elastic restoring moment (a second-order polynomial from one potential)",
        signature="0x (a static offset) and 2x in the fixed frame, growing with amplitude squared",
        orders=(0, 2),
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
