"""Simulated run-ups of rotors with faults the effect library does *not* declare.

The honest-verdict tests (``test_verdicts.py``) hand these measurements to the diagnosis
with the model ``unbalance + viscous_damping`` (``+ structural_damping`` when the rotor
has dry friction).  No library effect describes the fault, so the right answer is
``partly_explained`` or ``unexplained``, never a library effect added in its place.

Every generator is built on the project's simulator.  A fault that is a *moment* is a
test-only :class:`rotor_env.effects.Effect` named ``undeclared_*`` (the bow, the 2x
forcing, the anisotropy and the rub are declared by the library too since: their own code
here checks the library's effects); it is registered
only while its run is simulated (:func:`_registered`) and removed again, so the
diagnosis never sees it in the registry and other test modules do not either.  The
probe runout is a *measurement* fault: it is added to a clean simulated run before the
sensor noise.

Conventions (PHYSICS.md): dimensionless units, ``z = theta_y + i theta_x``, a moment
``M_y + i M_x``; the unbalance forcing is ``~ e^{+i phi}`` (order +1, forward).  An
order ``k`` component ``e^{i k phi}`` whirls forward for ``k > 0``, backward for
``k < 0``.

Every generator takes ``(seed, noise=5e-4, rotor=..., run_up=..., t_end=..., dt=...)``
and returns :class:`rotor_env.measurements.Measurements`.  Defaults: run-up 0.01 from
rest, ``t_end = 400``, ``dt = 0.01``; ``**FAST`` (``dt = 0.02``, ``t_end = 300``, up to
speed 3, well past the critical speed ``1/sqrt(1 - ip)``) keeps tests quick.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np

from rotor_env.effects import EFFECTS, PHYSICAL_EFFECTS, Effect, Parameter, register_effect
from rotor_env.measurements import COLUMNS, Measurements
from rotor_env.params import RotorParams
from rotor_env.simulator import RunUp, Simulator

__all__ = [
    "BASE",
    "COAST_DOWN",
    "COAST_DOWN_T_END",
    "FAST",
    "HEALTHY",
    "NOISE",
    "RUN_UP",
    "UNDECLARED",
    "Rotor",
    "anisotropy",
    "at_rest",
    "bow",
    "forcing_2x",
    "forcing_3x",
    "healthy",
    "loose_pedestal",
    "probe_runout",
    "rub",
    "with_rotor",
    "zeros",
]

NOISE = 5e-4
RUN_UP = RunUp(rate=0.01)
#: a coast-down from speed 4: the speed reaches 0 at t = 400, so runs stop at t = 350 (speed 0.5)
COAST_DOWN = RunUp(rate=-0.01, speed0=4.0)
COAST_DOWN_T_END = 350.0
#: the quick variant: half the samples per unit time, up to speed 3
FAST = {"dt": 0.02, "t_end": 300.0}


# --------------------------------------------------------------------- the healthy rotor
@dataclass(frozen=True)
class Rotor:
    """The healthy part of every rotor: unbalance ``tau, beta``, viscous damping ``c``,
    dry friction ``h`` (0: none), inertia ratio ``ip``; linear, symmetric, ``k = 1``."""

    ip: float = 0.3
    tau: float = 0.02
    beta: float = 0.0
    c: float = 0.03
    h: float = 0.0

    @property
    def model(self) -> tuple[str, ...]:
        """The engineer's (correct, fault-free) model of this rotor."""
        base = ("unbalance", "viscous_damping")
        return (*base, "structural_damping") if self.h > 0 else base

    def params(self, fault: str | None = None, **fault_values: float) -> RotorParams:
        values = {
            "tau": self.tau, "beta": self.beta, "c": self.c, "h": self.h,
            "D": 0.0, "k30": 0.0, "k21": 0.0, "k12": 0.0, "k03": 0.0,
            "load_y": 0.0, "load_x": 0.0, "k": 1.0, **fault_values,
        }
        effects = PHYSICAL_EFFECTS if fault is None else (*PHYSICAL_EFFECTS, fault)
        return RotorParams(ip=self.ip, values=values, effects=effects)


BASE = Rotor()
#: healthy parameter sets for the false-alarm tests (the third has dry friction)
HEALTHY: dict[str, Rotor] = {
    "light": Rotor(ip=0.2, tau=0.01, beta=0.5, c=0.02),
    "heavy": Rotor(ip=0.4, tau=0.03, beta=2.0, c=0.05),
    "dry friction": Rotor(ip=0.3, tau=0.02, beta=-1.0, c=0.03, h=0.01),
}


# --------------------------------------------------------------------- fault effects
# Column functions follow rotor_env.effects: numba-compilable plain arithmetic, the
# moment is coefficients x columns, coefficients linear in it.

def _bow_columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    s, c = np.sin(phi), np.cos(phi)
    # coefficients (b cos gamma, b sin gamma): M_y = -b sin(phi+gamma), M_x = b cos(phi+gamma)
    return (-s, -c), (c, -s)


def _order2_columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    s, c = np.sin(2.0 * phi), np.cos(2.0 * phi)
    # (f cos g, f sin g): f e^{i(2phi+g)};  (f_b cos g_b, f_b sin g_b): f_b e^{-i(2phi+g_b)}
    return (c, -s, c, -s), (s, c, -s, -c)


def _order3_columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    s, c = np.sin(3.0 * phi), np.cos(3.0 * phi)
    return (c, -s), (s, c)


def _anisotropy_columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    # k_y = 1 + delta, k_x = 1 - delta:  M_y = -delta th_y,  M_x = +delta th_x
    return (-th_y,), (th_x,)


#: the loose pedestal's clearance: beyond |theta_y| = LOOSE_GAP the y support stiffness drops
LOOSE_GAP = 0.04


def _loose_columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    # dead zone: th_y - clip(th_y, -gap, gap), as plain arithmetic (numba, floats and arrays)
    g = LOOSE_GAP
    beyond = 0.5 * ((th_y - g) + np.abs(th_y - g)) + 0.5 * ((th_y + g) - np.abs(th_y + g))
    # coefficient kappa: the y stiffness falls from 1 to 1 - kappa beyond the gap
    return (beyond,), (0.0 * th_x,)


#: the rub's radial clearance: beyond |theta| = RUB_GAP the disk touches the casing
RUB_GAP = 0.04
#: the rub's friction coefficient (a fixed material constant, not identified)
RUB_FRICTION = 0.2


def _rub_columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):
    # this module's own code for the library's ``rub`` (fixed gap and mu, forward spin only):
    # radial contact beyond the clearance, friction against the forward-turning surface:
    # M_y + i M_x = -k_c max(|z| - gap, 0) (1 + i mu) z/|z|
    r = np.sqrt(th_x * th_x + th_y * th_y) + 1e-12
    pen = 0.5 * ((r - RUB_GAP) + np.abs(r - RUB_GAP)) / r
    mu = RUB_FRICTION
    return (-pen * (th_y - mu * th_x),), (-pen * (th_x + mu * th_y),)


def _polar(amp: str, phase: str):
    def to_coef(p):
        return (p[amp] * math.cos(p[phase]), p[amp] * math.sin(p[phase]))

    def from_coef(c):
        return {amp: float(math.hypot(c[0], c[1])), phase: float(math.atan2(c[1], c[0]))}

    return to_coef, from_coef


def _order2_to(p):
    return (*_polar("sim_f2", "sim_f2_phase")[0](p), *_polar("sim_f2_back", "sim_f2_back_phase")[0](p))


def _order2_from(c):
    return {**_polar("sim_f2", "sim_f2_phase")[1](c[:2]), **_polar("sim_f2_back", "sim_f2_back_phase")[1](c[2:])}


def _one(name: str):
    return (lambda p: (float(p[name]),)), (lambda c: {name: float(c[0])})


UNDECLARED: dict[str, Effect] = {
    "undeclared_bow": Effect(
        name="undeclared_bow",
        parameters=(Parameter("sim_bow", 0.015, "bow forcing amplitude (the bow's elastic moment)", 0.0),
                    Parameter("sim_bow_phase", 0.0, "bow phase gamma [rad]")),
        coefficients=("bow_cos", "bow_sin"),
        columns=_bow_columns,
        to_coefficients=_polar("sim_bow", "sim_bow_phase")[0],
        from_coefficients=_polar("sim_bow", "sim_bow_phase")[1],
        moment="M_y + i M_x = b i e^{i(phi + gamma)}",
        cause="a bent (bowed) shaft: its elastic line is offset in a direction fixed to the shaft",
        signature="1x forward of constant amplitude (does not grow with speed^2 as an unbalance)",
        orders=(1,),
    ),
    "undeclared_2x": Effect(
        name="undeclared_2x",
        parameters=(Parameter("sim_f2", 0.008, "forward 2x forcing amplitude", 0.0),
                    Parameter("sim_f2_phase", 0.0, "its phase [rad]"),
                    Parameter("sim_f2_back", 0.0, "backward 2x forcing amplitude", 0.0),
                    Parameter("sim_f2_back_phase", 0.0, "its phase [rad]")),
        coefficients=("f2_cos", "f2_sin", "f2_back_cos", "f2_back_sin"),
        columns=_order2_columns,
        to_coefficients=_order2_to,
        from_coefficients=_order2_from,
        moment="M_y + i M_x = f e^{i(2 phi + g)} + f_b e^{-i(2 phi + g_b)}",
        cause="coupling misalignment: a moment twice per revolution, constant amplitude",
        signature="2x (forward; backward with f_b), amplitude independent of speed",
        orders=(2,),
    ),
    "undeclared_3x": Effect(
        name="undeclared_3x",
        parameters=(Parameter("sim_f3", 0.006, "forward 3x forcing amplitude", 0.0),
                    Parameter("sim_f3_phase", 0.0, "its phase [rad]")),
        coefficients=("f3_cos", "f3_sin"),
        columns=_order3_columns,
        to_coefficients=_polar("sim_f3", "sim_f3_phase")[0],
        from_coefficients=_polar("sim_f3", "sim_f3_phase")[1],
        moment="M_y + i M_x = f e^{i(3 phi + g)}",
        cause="a three-lobed coupling or blade-pass-like excitation, three times per revolution",
        signature="3x forward, amplitude independent of speed",
        orders=(3,),
    ),
    "undeclared_anisotropy": Effect(
        name="undeclared_anisotropy",
        parameters=(Parameter("sim_aniso", 0.08, "support anisotropy delta: k_y = 1+delta, k_x = 1-delta"),),
        coefficients=("sim_aniso",),
        columns=_anisotropy_columns,
        to_coefficients=_one("sim_aniso")[0],
        from_coefficients=_one("sim_aniso")[1],
        moment="M_y = -delta th_y,  M_x = +delta th_x  (M_y + i M_x = -delta conj(z))",
        cause="bearing supports stiffer in y than in x (fixed frame, not turning with the shaft)",
        signature="mirrors the forward 1x response into a backward (-1x) line; splits the critical",
        orders=(-1,),
    ),
    "undeclared_rub": Effect(
        name="undeclared_rub",
        parameters=(Parameter("sim_rub", 0.5, "contact stiffness of the casing beyond the clearance", 0.0),),
        coefficients=("sim_rub",),
        columns=_rub_columns,
        to_coefficients=_one("sim_rub")[0],
        from_coefficients=_one("sim_rub")[1],
        moment="M_y + i M_x = -k_c max(|z| - gap, 0) (1 + i mu) z/|z|",
        cause="a rub: beyond a radial clearance the disk touches the casing (contact stiffness "
        "and friction against the turning surface)",
        signature="while |theta| exceeds the clearance (around the critical): a stiffening and a "
        "cross-coupled friction moment along the whirl, 1x forward for a synchronous circular orbit",
        orders=(1,),
    ),
    "undeclared_loose": Effect(
        name="undeclared_loose",
        parameters=(Parameter("sim_loose", 0.4, "stiffness lost in y beyond the gap", 0.0, 1.0),),
        coefficients=("sim_loose",),
        columns=_loose_columns,
        to_coefficients=_one("sim_loose")[0],
        from_coefficients=_one("sim_loose")[1],
        moment="M_y = kappa (th_y - clip(th_y, -gap, gap)),  M_x = 0",
        cause="a loose pedestal: beyond a clearance in y the support lifts off and its stiffness drops",
        signature="odd harmonics of the whirl (1x, 3x, ...), forward and backward alike "
        "(one direction only), while |theta_y| exceeds the gap",
        orders=(1, 3),
    ),
}


@contextmanager
def _registered(name: str) -> Iterator[None]:
    """``UNDECLARED[name]`` in the effect registry while simulating, removed after
    (only if this call added it)."""
    added = name not in EFFECTS
    if added:
        register_effect(UNDECLARED[name])
    try:
        yield
    finally:
        if added:
            EFFECTS.pop(name, None)


# --------------------------------------------------------------------- running
def _run(params: RotorParams, seed: int | None, noise: float, run_up: RunUp, t_end: float,
         dt: float, initial=(0.0, 0.0, 0.0, 0.0)) -> Measurements:
    meas = Simulator(params).run(t_end=t_end, dt=dt, run_up=run_up, initial=initial)
    return meas.with_noise(noise, seed=seed) if noise else meas


def _static_start(effect: str, params: RotorParams, run_up: RunUp) -> tuple[float, float, float, float]:
    """At rest (speed 0) a speed-independent forcing is a static moment: start from the
    static deflection ``theta = M / k`` it causes, as a real rotor standing still does
    (no spurious ring-down at the natural frequency from a step load at t = 0)."""
    if run_up.speed0 != 0.0:
        return (0.0, 0.0, 0.0, 0.0)
    eff = EFFECTS[effect]
    cy, cx = eff.columns(run_up.phi0, 0.0, run_up.rate, 0.0, 0.0, 0.0, 0.0, params.ip)
    coef = params.coefficients(effect)
    my = sum(a * float(b) for a, b in zip(coef, cy, strict=True))
    mx = sum(a * float(b) for a, b in zip(coef, cx, strict=True))
    return (mx, my, 0.0, 0.0)


def _faulty(effect: str, values: dict, seed, noise, rotor: Rotor, run_up, t_end, dt) -> Measurements:
    with _registered(effect):
        params = rotor.params(effect, **values)
        return _run(params, seed, noise, run_up, t_end, dt, _static_start(effect, params, run_up))


def healthy(seed: int | None, noise: float = NOISE, rotor: Rotor = BASE, run_up: RunUp = RUN_UP,
            t_end: float = 400.0, dt: float = 0.01) -> Measurements:
    """A rotor the model describes exactly: unbalance, viscous damping, optionally dry
    friction (``rotor.h``).  The diagnosis must call it ``explained`` with nothing added."""
    return _run(rotor.params(), seed, noise, run_up, t_end, dt)


def bow(seed: int | None, noise: float = NOISE, rotor: Rotor = BASE, run_up: RunUp = RUN_UP,
        t_end: float = 400.0, dt: float = 0.01, b: float = 0.015, gamma: float = 1.0) -> Measurements:
    """Shaft bow.

    Cause: the shaft is bent; its elastic restoring moment pulls toward a line offset
    by the bow, which turns with the shaft.  Moment: ``M_y + i M_x = b i e^{i(phi+gamma)}``
    (``M_y = -b sin(phi+gamma)``, ``M_x = b cos(phi+gamma)``), constant amplitude ``b``
    — at rest it is a static deflection of size ``b``.  Signature: order +1 forward like
    the unbalance, but not growing with speed²: the unbalance (``(1-ip) tau speed²``,
    0.014 at speed 1 for Table 1) cannot fit it at all speeds; a 1x forward residual
    remains, largest away from speed 1.
    """
    return _faulty("undeclared_bow", {"sim_bow": b, "sim_bow_phase": gamma}, seed, noise, rotor, run_up, t_end, dt)


def forcing_2x(seed: int | None, noise: float = NOISE, rotor: Rotor = BASE, run_up: RunUp = RUN_UP,
               t_end: float = 400.0, dt: float = 0.01, f: float = 0.008, gamma: float = 0.5,
               f_back: float = 0.0, gamma_back: float = 0.0) -> Measurements:
    """A pure twice-per-revolution forcing (misalignment-like).

    Cause: a misaligned coupling bends the shaft twice per revolution.  Moment:
    ``M_y + i M_x = f e^{i(2 phi + gamma)}`` (+ ``f_back e^{-i(2 phi + gamma_back)}``),
    amplitude independent of speed.  Signature: order +2 forward (and -2 backward with
    ``f_back``); resonance where twice the speed meets the forward natural frequency
    (speed ``1/sqrt(4 - 2 ip)`` ≈ 0.54).  Neither the asymmetry (a 2x only with a static
    load) nor the quadratic stiffness (2x growing with amplitude²) describes it.
    """
    values = {"sim_f2": f, "sim_f2_phase": gamma, "sim_f2_back": f_back, "sim_f2_back_phase": gamma_back}
    return _faulty("undeclared_2x", values, seed, noise, rotor, run_up, t_end, dt)


def forcing_3x(seed: int | None, noise: float = NOISE, rotor: Rotor = BASE, run_up: RunUp = RUN_UP,
               t_end: float = 400.0, dt: float = 0.01, f: float = 0.006, gamma: float = -0.7) -> Measurements:
    """A pure three-times-per-revolution forcing.

    Cause: a three-jaw coupling, three lobes on a journal.  Moment
    ``M_y + i M_x = f e^{i(3 phi + gamma)}``, constant amplitude.  Signature: order +3
    forward; no library effect has a 3x column.
    """
    return _faulty("undeclared_3x", {"sim_f3": f, "sim_f3_phase": gamma}, seed, noise, rotor, run_up, t_end, dt)


def anisotropy(seed: int | None, noise: float = NOISE, rotor: Rotor = BASE, run_up: RunUp = RUN_UP,
               t_end: float = 400.0, dt: float = 0.01, delta: float = 0.08) -> Measurements:
    """Support anisotropy.

    Cause: the bearing pedestals are stiffer in y than in x (fixed frame):
    ``k_y = 1 + delta``, ``k_x = 1 - delta``.  Moment ``M_y = -delta theta_y``,
    ``M_x = +delta theta_x``, i.e. ``M_y + i M_x = -delta conj(z)``.  Signature: the
    forward (+1) unbalance response is mirrored into a backward (-1x) line; the critical
    speed splits in two.  Unlike the shaft asymmetry (a crack, turning with the shaft:
    ``-D e^{2 i phi} conj(z)``, which keeps a synchronous response forward), nothing in the
    library has a backward synchronous column.
    """
    return _faulty("undeclared_anisotropy", {"sim_aniso": delta}, seed, noise, rotor, run_up, t_end, dt)


def loose_pedestal(seed: int | None, noise: float = NOISE, rotor: Rotor = BASE, run_up: RunUp = RUN_UP,
                   t_end: float = 400.0, dt: float = 0.01, kappa: float = 0.4) -> Measurements:
    """A loose pedestal.

    Cause: a bolt of one pedestal is loose; beyond a clearance (``|theta_y| >
    LOOSE_GAP``) the support lifts off and the y stiffness drops from 1 to ``1 - kappa``.
    Moment ``M_y = kappa (theta_y - clip(theta_y, -gap, gap))``, ``M_x = 0``: piecewise
    linear, odd, in one direction only.  Signature: only while the whirl exceeds the
    gap (around the critical speed); odd harmonics of the whirl — with the default gap
    almost all 1x (measured: 0.46-0.47 of the residual energy at +1 and at -1, 0.01 at
    3x), forward and backward alike since it acts along y only.  No library effect is piecewise linear
    or one-directional (the quadratic stiffness is even: 0x and 2x).
    """
    return _faulty("undeclared_loose", {"sim_loose": kappa}, seed, noise, rotor, run_up, t_end, dt)


def rub(seed: int | None, noise: float = NOISE, rotor: Rotor = BASE, run_up: RunUp = RUN_UP,
        t_end: float = 400.0, dt: float = 0.01, k_contact: float = 0.5) -> Measurements:
    """A rub against the casing (the library declares it now: ``rub``; simulated here with
    this module's own column code, the gap ``RUB_GAP`` and friction ``RUB_FRICTION`` fixed,
    to check the library's effect against an independent implementation).

    Cause: near the critical speed the whirl exceeds the radial clearance ``RUB_GAP`` and
    the disk touches the casing: a contact stiffness ``k_contact`` on the penetration
    and a friction moment (``RUB_FRICTION``) against the forward-turning surface.  Moment
    ``M_y + i M_x = -k_c max(|z| - gap, 0) (1 + i mu) z/|z|``.  Signature: only while
    ``|theta|`` exceeds the gap; for the synchronous, nearly circular orbit it is a 1x
    forward moment (a stiffening plus a cross-coupling) that comes and goes with the
    amplitude — a stiffness change fitted over the whole run is not constant in time.
    """
    return _faulty("undeclared_rub", {"sim_rub": k_contact}, seed, noise, rotor, run_up, t_end, dt)


def probe_runout(seed: int | None, noise: float = NOISE, rotor: Rotor = BASE, run_up: RunUp = RUN_UP,
                 t_end: float = 400.0, dt: float = 0.01, r: float = 0.015, gamma: float = 2.0) -> Measurements:
    """Probe runout (a measurement fault, no moment).

    Cause: the probe track on the shaft is out of round or off-centre, so the sensor
    reads a pattern fixed to the shaft angle on top of the true motion:
    ``theta_y += r cos(phi+gamma)``, ``theta_x += r sin(phi+gamma)`` — ``z += r
    e^{i(phi+gamma)}`` — with the consistent rates and accelerations (``phi_dot``,
    ``phi_ddot``), added to the clean run before the sensor noise.  Signature: order +1
    forward of constant amplitude *in the angles*: in the equation error it is
    ``r e^{i psi} (1 - (1-ip) phi_dot² + i phi_ddot)``, whose speed² part the unbalance
    absorbs, leaving a constant-amplitude 1x forward residual (like a bow).
    """
    clean = healthy(None, 0.0, rotor, run_up, t_end, dt)
    d = clean.data.copy()
    psi = clean.phi + gamma
    w, a = clean.phi_dot, clean.phi_ddot
    s, c = np.sin(psi), np.cos(psi)
    cols = {name: i for i, name in enumerate(COLUMNS)}
    d[:, cols["theta_y"]] += r * c
    d[:, cols["theta_x"]] += r * s
    d[:, cols["theta_y_dot"]] += -r * w * s
    d[:, cols["theta_x_dot"]] += r * w * c
    d[:, cols["theta_y_ddot"]] += r * (-a * s - w * w * c)
    d[:, cols["theta_x_ddot"]] += r * (a * c - w * w * s)
    meas = Measurements(d)
    return meas.with_noise(noise, seed=seed) if noise else meas


# --------------------------------------------------------------------- nothing to identify
def at_rest(seed: int | None, noise: float = NOISE, rotor: Rotor = BASE, t_end: float = 100.0,
            dt: float = 0.02) -> Measurements:
    """A rotor that never leaves rest (no spin): the inclinations are sensor noise only."""
    return healthy(seed, noise, rotor, RunUp(rate=0.0), t_end, dt)


def zeros(n: int = 2000, dt: float = 0.02) -> Measurements:
    """An all-zero file: time runs, every other channel is 0."""
    data = np.zeros((n, 10))
    data[:, 0] = np.arange(n) * dt
    return Measurements(data)


def with_rotor(rotor: Rotor, **changes: float) -> Rotor:
    """A variant of a parameter set (``with_rotor(BASE, ip=0.4)``)."""
    return replace(rotor, **changes)
