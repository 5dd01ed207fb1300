"""The run-up model's synchronous (1X) response, fitted to order-tracked vectors.

What condition-monitoring systems export for a start-up or coast-down is the 1X vector
of each probe against speed.  This module predicts those vectors from the same effect
declarations the simulator and the regression read (:mod:`rotor_env.effects`), and
fits them.

The model
---------
In the model's dimensionless time ``t' = t w_ref`` (``w_ref`` the non-rotating natural
frequency, a parameter of the fit: it carries the stiffness) the tilt — or, with
``ip = 0``, the translation (Jeffcott) — obeys ``q'' = a(q, q', phi) `` with the
declared effects' moments.  An effect whose moment does not depend on the state is a
*forcing* (unbalance, bow): the response is linear in its coefficients, which are
solved by linear least squares for every trial of the others (variable projection).
The other effects are *structural* (damping, support anisotropy, cross-coupled
stiffness): nonlinear parameters of the fit, with ``w_ref``.  Probe runout is a
measurement term: a constant vector per probe (the slow-roll vector), also linear.

A probe mounted at angle ``alpha`` (from the reference, in the direction of rotation)
reads ``p = u cos(alpha) + v sin(alpha)`` with ``u = th_y``, ``v = th_x`` (docs/PHYSICS.md
1.2: ``z = u + i v`` whirls forward as ``e^{+i phi}``); its 1X vector (``lead``
convention, :mod:`rotor_env.measurements.vectors`) is ``P = Q_u cos(alpha) + Q_v sin(alpha)``.

Quasi-steady or transient
-------------------------
*Quasi-steady*: at each speed the steady-state response
``(-W^2 I - A_q - i W A_w) Q = F`` of the model linearised at that speed.  *Transient*:
the model simulated (RK4, the simulator's compiled kernel) along the table's speed
profile — the time column gives the acceleration — and order-tracked one revolution at a
time at each row, as the data were.  At real start-up rates (e.g. 230 rpm/s through
1650 rpm with zeta = 0.02) the peak is delayed and lowered and ripples (free vibration at
the natural frequency beating against 1X) follow it: only the transient carries them.
``method="auto"`` compares the two at the first fit and keeps the quasi-steady one only
where it is within 1 % of the peak everywhere (it is faster).

The transient run is the simulator's RK4 (48 steps a turn) on one grid in seconds per fit:
where the model does not change with the speed (no gyroscopic term, no rotating effect)
its steps are one linear recursion ``x <- Phi x + G f`` written out from the RK4 stages
(:func:`_rk4_linear`, the same numbers to rounding), compiled, and the forcing's columns
are evaluated once per table; otherwise the compiled kernel integrates it.

2X
--
A table with ``_2x`` columns and a time column is fitted at 1X and 2X together (the probes
of each order side by side).  An effect whose stiffness turns with the shaft (``asymmetry``,
``breathing_crack``: *rotating*) is a nonlinear parameter like a structural one, carried
by the transient run only: a crack turns a static deflection (``static_load``, the side
load, a forcing) into 2X, which resonates where 2x the speed meets the natural frequency —
half the critical.  A 2X forcing (``misalignment``) is linear like the unbalance.  Nothing
of their physics is written here: the run integrates the declared columns and the tracker
reads its 1X and 2X, as the data's tracker did.

Critical speeds and damping ratios
----------------------------------
The eigenvalues ``lambda`` of the linearised model at speed ``W``; a critical is a speed
where a branch's whirl frequency ``|Im lambda|`` equals ``W`` (the 1x line crosses the
Campbell diagram) on a mode that whirls forward at least in part (an isotropic rotor's
backward mode is not excited by unbalance); its damping ratio is ``-Re lambda / |lambda|``.
The same eigenvalues, each signed by its whirl, are the branches of the Campbell diagram
(:func:`whirl_branches`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.interpolate import PchipInterpolator
from scipy.optimize import brentq, least_squares

from ..effects import EFFECTS, DerivedNames, get_effect, synchronous_effects
from ..measurements.vectors import SPEED_UNITS, OrderTracker, VectorTable
from ..simulator import call_integrate_profile, compile_accel, smooth_effects

__all__ = [
    "RUNOUT",
    "SECOND_MODE",
    "VECTOR_EFFECTS",
    "SynchronousModel",
    "VectorFit",
    "critical_speeds",
    "fit_vectors",
    "whirl_branches",
]

#: the measurement term "probe runout": a constant 1X vector per probe
RUNOUT = "runout"
#: a second mode of the rotor-bearing system in the speed range (another critical speed):
#: an isotropic oscillator of its own natural frequency, damping and modal unbalance
SECOND_MODE = "second_mode"
#: effects that show in 1X data and that the synchronous model can carry: those declared
#: ``synchronous=True`` (:attr:`rotor_env.effects.Effect.synchronous`), read from the registry
VECTOR_EFFECTS: Sequence[str] = DerivedNames(synchronous_effects)
#: quasi-steady is used only where it is within this fraction of the peak of the transient
QUASI_STEADY_TOL = 0.01
#: the record starts this many revolutions before the first row (initial transient settles)
LEAD_IN_REVS = 2.0
#: the transient model's grid (about 200 bytes a sample with the tracking) stays below this
MAX_TRANSIENT_SAMPLES = 4_000_000
#: the fitted natural frequency stays within this factor of the run's speeds
W_REF_DECADES = 10.0


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


@dataclass
class VectorFit:
    """A fitted synchronous model: parameters, model vectors, residual, criticals."""

    model: SynchronousModel
    table: VectorTable
    w_ref: float  #: rad/s
    structural: dict[str, np.ndarray]
    forcing: dict[str, np.ndarray]  #: coefficients in the table's amplitude unit
    runout: np.ndarray | None  #: complex per probe
    predicted: np.ndarray  #: complex (rows, probes)
    method: str  #: "quasi-steady" or "transient"
    jacobian: np.ndarray  #: of the stacked residual w.r.t. the parameters ``param_names``
    param_names: tuple[str, ...]
    params: np.ndarray
    success: bool = True
    #: (w_ref in rad/s, viscous damping c) of each extra mode
    extra_modes: tuple[tuple[float, float], ...] = ()
    #: the orders fitted: ``predicted`` holds each order's probes side by side (1X first)
    orders: tuple[int, ...] = (1,)

    @property
    def measured(self) -> np.ndarray:
        """The vectors fitted, (rows, probes * orders)."""
        return np.concatenate([self.table.vectors[n] for n in self.orders], axis=1)

    @property
    def residual(self) -> np.ndarray:
        return self.measured - self.predicted

    @property
    def rms(self) -> float:
        """RMS of the complex residual (per probe, order and row), in the table's amplitude unit."""
        r = self.residual
        return float(np.sqrt(np.nanmean(np.abs(r) ** 2)))

    @property
    def criticals(self) -> list[dict[str, float]]:
        out = critical_speeds(self.model, self.coef(), self.w_ref, self.table.speed)
        for w, c in self.extra_modes:
            iso = _isotropic(self.model.ip)
            out += critical_speeds(iso, iso.coef_vector({"viscous_damping": np.array([c])}), w, self.table.speed)
        return sorted(out, key=lambda d: d["rpm"])

    def coef(self) -> np.ndarray:
        return self.model.coef_vector(self.structural, {k: v for k, v in self.forcing.items() if k != SECOND_MODE})

    def values(self) -> dict[str, dict[str, float]]:
        """Each effect's physical parameters (forcing amplitudes in the table's unit)."""
        out: dict[str, dict[str, float]] = {}
        for name in self.model.effects:
            c = (self.structural | self.forcing)[name]
            out[name] = get_effect(name).from_coefficients(np.asarray(c, dtype=float))
        if self.runout is not None:
            out[RUNOUT] = {p: float(abs(v)) for p, v in zip(self.table.probes, self.runout, strict=True)}
        out["natural_frequency"] = {"rpm": self.w_ref / SPEED_UNITS["rpm"]}
        for w, c in self.extra_modes:
            u = self.forcing.get(SECOND_MODE, np.zeros(2))
            out[SECOND_MODE] = {"natural_frequency_rpm": w / SPEED_UNITS["rpm"], "c": c,
                                "unbalance": float(np.hypot(u[0], u[1]))}
        return out


# ----------------------------------------------------------------- predictions
def vector_probe_matrix(table: VectorTable) -> np.ndarray:
    """(probes, 2) weights of (Q_u, Q_v) in each probe's vector."""
    if table.angles is None:
        # no geometry: one probe (or several, each seen as the u direction)
        return np.tile([1.0, 0.0], (len(table.probes), 1))
    return np.column_stack([np.cos(table.angles), np.sin(table.angles)])


def _poly_fit(f, points: np.ndarray, basis) -> np.ndarray | None:
    """Coefficients of ``f`` (array-valued) in ``basis`` fitted at ``points``, or None when
    the basis does not reproduce ``f`` exactly (checked at the last two points)."""
    vals = np.array([f(*p) for p in points])
    X = np.array([basis(*p) for p in points])
    coef = np.linalg.lstsq(X[:-2], vals[:-2].reshape(len(points) - 2, -1), rcond=None)[0]
    check = X[-2:] @ coef
    if not np.allclose(check, vals[-2:].reshape(2, -1), rtol=1e-9, atol=1e-12 * (1 + np.abs(vals).max())):
        return None
    return coef.reshape((X.shape[1], *vals.shape[1:]))


#: speed polynomials the linearised model and the forcing are tried in (exact for the
#: library: the gyroscopic term is linear in the speed, the unbalance quadratic, and
#: linear in the acceleration); anything else falls back to a row-by-row evaluation
def _speed_basis(w: float, wd: float) -> np.ndarray:
    return np.array([1.0, w, w * w, wd])
_POINTS = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.5, 1.0], [1.5, -0.5], [3.0, 0.7], [0.7, 2.0]])


def _quasi_steady(model: SynchronousModel, coef_struct: np.ndarray, forcing_coefs: list[np.ndarray],
                  W: np.ndarray, Wdot: np.ndarray) -> np.ndarray:
    """Basis responses (rows, 2, n_basis) of the linearised model at each speed."""
    if len(W) <= len(_POINTS):
        # as few rows as the polynomial fit would evaluate the model at: solve each directly
        return _steady_rows(model, coef_struct, forcing_coefs, W, Wdot)
    basis = _speed_basis
    lin = _poly_fit(lambda w, wd: np.stack(model.linearised(coef_struct, w)), _POINTS, basis)
    forc = _poly_fit(lambda w, wd: np.column_stack([model.forcing_1x(c, w, wd) for c in forcing_coefs]),
                     _POINTS, basis) if forcing_coefs else None
    X = (np.column_stack([np.ones_like(W), W, W * W, Wdot]) if basis is _speed_basis
         else np.column_stack([basis(w, wd) for w, wd in zip(W, Wdot, strict=True)]).T)  # (rows, 4)
    if lin is not None and forcing_coefs and forc is not None:
        AA = np.einsum("rb,bkij->rkij", X, lin)
        F = np.einsum("rb,bcn->rcn", X.astype(complex), forc)
        M = -(W * W)[:, None, None] * np.eye(2) - AA[:, 0] - 1j * W[:, None, None] * AA[:, 1]
        return np.linalg.solve(M, F)
    return _steady_rows(model, coef_struct, forcing_coefs, W, Wdot)


def _steady_rows(model: SynchronousModel, coef_struct: np.ndarray, forcing_coefs: list[np.ndarray],
                 W: np.ndarray, Wdot: np.ndarray) -> np.ndarray:
    """:func:`_quasi_steady` row by row: the linearised model solved at each speed."""
    out = np.empty((len(W), 2, len(forcing_coefs)), dtype=complex)
    for k, (w, wd) in enumerate(zip(W, Wdot, strict=True)):
        A_q, A_w = model.linearised(coef_struct, w)
        M = -w * w * np.eye(2) - A_q - 1j * w * A_w
        F = np.column_stack([model.forcing_1x(c, w, wd) for c in forcing_coefs])
        out[k] = np.linalg.solve(M, F)
    return out


@dataclass(frozen=True)
class _Profile:
    """The integration grid of one speed profile: times, angle and speed on the grid, and
    the angle at the middle of each row's revolution."""

    grid: np.ndarray
    phi: np.ndarray
    speed: np.ndarray
    phi_rows: np.ndarray
    tracker: OrderTracker  #: the orders per revolution centred on each row
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def step(self) -> float:
        """The grid's step (without the stages)."""
        if "base" in self._cache:
            base, w_ref = self._cache["base"]
            return base.steps().h * w_ref
        return self.steps().h

    def steps(self) -> _Steps:
        """The RK4 steps of the kernel on this grid: the step and the spin at each step's stages."""
        if "steps" not in self._cache and "base" in self._cache:
            base, w_ref = self._cache["base"]
            b = base.steps()
            self._cache["steps"] = _Steps(b.h * w_ref, tuple((phi, W / w_ref, a / w_ref**2) for phi, W, a in b.stages))
        if "steps" not in self._cache:
            dt = np.diff(self.grid)
            p0, w0 = self.phi[:-1], self.speed[:-1]
            a = (self.speed[1:] - w0) / dt
            half = 0.5 * dt
            stages = ((p0, w0, a), (p0 + w0 * half + 0.5 * a * half * half, w0 + a * half, a),
                      (p0 + w0 * dt + 0.5 * a * dt * dt, w0 + a * dt, a))
            self._cache["steps"] = _Steps(float(np.median(dt)), stages)
        return self._cache["steps"]


@dataclass(frozen=True)
class _Steps:
    h: float  #: the grid's step
    stages: tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]  #: (phi, speed, accel) at t, t + h/2, t + h


def _profile(tau: np.ndarray, W: np.ndarray, orders: tuple[int, ...] = (1,), h: float | None = None) -> _Profile:
    """The grid a :func:`_transient` run follows (it depends on the time scale only, not on
    the model: a fit's many runs at one ``w_ref`` share it).  Any time unit: ``h`` the step
    in it (default the model time's rule below)."""
    speed = PchipInterpolator(tau, W, extrapolate=True)
    w_max = float(W.max())
    lead = LEAD_IN_REVS * 2 * math.pi / max(float(W[0]), 1e-3)
    # RK4 and the trapezoid in phi: 48 steps a turn keep both below 1e-4 of the peak
    if h is None:
        h = min(0.05, 2 * math.pi / (48.0 * w_max))
    t0, t1 = float(tau[0]) - lead, float(tau[-1]) + 2 * math.pi / max(float(W[-1]), 1e-3)
    n_grid = (t1 + h - t0) / h
    if not n_grid <= MAX_TRANSIENT_SAMPLES:
        # the grid is 48 samples a turn of the fastest row: a table spanning too many turns
        # (time in ms read as s, a phase in radians pulling w_ref away) would take gigabytes
        raise ValueError(f"the transient model of this table would need {n_grid:.3g} integration samples "
                         f"({n_grid * 200 / 1e9:.3g} GB), beyond {MAX_TRANSIENT_SAMPLES:g}: the run spans too many "
                         "revolutions (is the time column in seconds, the phase in degrees?)")
    grid = np.arange(t0, t1 + h, h)
    # before the first row the profile goes on as it came in (linearly): the first row's
    # revolution starts half a turn before its mid-time, and its angle must be the data's
    slope0 = (W[1] - W[0]) / (tau[1] - tau[0]) if len(W) > 1 else 0.0
    before = W[0] + slope0 * (grid - tau[0])
    Wg = np.where(grid < tau[0], before, np.where(grid > tau[-1], W[-1], speed(np.clip(grid, tau[0], tau[-1]))))
    Wg = np.maximum(Wg, 0.2 * float(W.min()))
    phi = np.concatenate(([0.0], np.cumsum(0.5 * (Wg[1:] + Wg[:-1]) * np.diff(grid))))
    # a row is one revolution whose mid-time is t and whose speed is 2 pi / its duration
    # (what per-revolution trackers report): it starts at t - pi / W, at a keyphasor pulse.
    # The angle is zero at the pulses, as in the data: a probe's 1X vector also holds the
    # mirror image of the free whirl (a real signal), which turns with twice the angle
    # offset — the model's angle must be the data's, not just differ by a constant.
    phi -= np.interp(tau[0] - math.pi / W[0], grid, phi)
    phi_rows = np.interp(tau - math.pi / W, grid, phi) + math.pi
    return _Profile(grid, phi, Wg, phi_rows, OrderTracker(grid, phi, orders, at=phi_rows))


def _scaled(base: _Profile, w_ref: float) -> _Profile:
    """A profile in seconds seen in the model's time (``t w_ref``, speed ``/ w_ref``): the
    angle, the rows and the tracker are the same at every ``w_ref``."""
    prof = _Profile(base.grid * w_ref, base.phi, base.speed / w_ref, base.phi_rows, base.tracker)
    prof._cache["base"] = (base, w_ref)
    return prof


@functools.cache
def _speed_power(effect: str, ip: float) -> int | None:
    """``p`` when the effect's columns at zero state scale as ``s^p`` for speed ``s W`` and
    acceleration ``s^2 a`` (the unbalance: 2, a bow or a misalignment: 0), else None."""
    rng = np.random.default_rng(1)
    phi, W, a = rng.uniform(0, 6, 5), rng.uniform(0.2, 2, 5), rng.uniform(-0.01, 0.01, 5)
    z = np.zeros(5)
    cols = get_effect(effect).columns
    ref = np.array([np.broadcast_to(v, (5,)) for v in (*cols(phi, W, a, z, z, z, z, ip)[0],
                                                          *cols(phi, W, a, z, z, z, z, ip)[1])])
    new = np.array([np.broadcast_to(v, (5,)) for v in (*cols(phi, 1.3 * W, 1.69 * a, z, z, z, z, ip)[0],
                                                          *cols(phi, 1.3 * W, 1.69 * a, z, z, z, z, ip)[1])])
    for p in (0, 1, 2, 3):
        if np.allclose(new, ref * 1.3**p, rtol=1e-12, atol=1e-15):
            return p
    return None


def _start_state(model: SynchronousModel, coef_struct: np.ndarray, c: np.ndarray, w0: float,
                 phi0: float) -> np.ndarray:
    """The periodic response at the constant speed ``w0`` (state ``th_x, th_y, w_x, w_y`` at
    ``phi0``), so a run starts without an artificial transient: the forcing's orders 0, 1 and 2
    through the fixed-frame model, then (first order in them) what the rotating effects make
    of that response at orders 1 and 2 — a crack turns a static deflection into 2X."""
    accel = compile_accel(model.layout)
    A_q, A_w = model.linearised(coef_struct, w0)
    ph = np.linspace(0.0, 2 * math.pi, 32, endpoint=False)
    full = coef_struct + c
    fixed = model.fixed_frame(full)

    def harmonics(f: np.ndarray) -> dict[int, np.ndarray]:  # f: (len(ph), 2) -> per order, (u, v)
        return {n: (1.0 if n == 0 else 2.0) / len(ph) * (f.T @ np.exp(-1j * n * ph)) for n in (0, 1, 2)}

    def solve(n: int, F: np.ndarray) -> np.ndarray:
        M = -(n * w0) ** 2 * np.eye(2) - A_q - 1j * n * w0 * A_w
        return np.linalg.solve(M, F) if n else np.linalg.solve(-A_q, F.real).astype(complex)

    f = np.array([accel(p, w0, 0.0, 0.0, 0.0, 0.0, 0.0, model.ip, fixed) for p in ph])
    Q = {n: solve(n, F) for n, F in harmonics(f).items()}
    if model.rotating:
        q = sum(np.real(np.outer(np.exp(1j * n * ph), Qn)) for n, Qn in Q.items())
        r = sum(np.real(np.outer(1j * n * w0 * np.exp(1j * n * ph), Qn)) for n, Qn in Q.items())
        g = np.array([np.subtract(accel(p, w0, 0.0, qq[1], qq[0], rr[1], rr[0], model.ip, full),
                                  accel(p, w0, 0.0, qq[1], qq[0], rr[1], rr[0], model.ip, fixed))
                      for p, qq, rr in zip(ph, q, r, strict=True)])
        for n, G in harmonics(g).items():
            if n:
                Q[n] = Q[n] + solve(n, G)
    u = sum(Q[n] * np.exp(1j * n * phi0) for n in Q)
    du = sum(1j * n * w0 * Q[n] * np.exp(1j * n * phi0) for n in Q)
    return np.array([u[1].real, u[0].real, du[1].real, du[0].real])


@njit(cache=True)
def _linear_steps(Phi, G1, G2, G4, f1, f2, f4, x0, out, col):  # pragma: no cover - compiled
    """``x[k+1] = Phi x[k] + G1 f1[k] + G2 f2[k] + G4 f4[k]`` from ``x[0] = x0`` (``G``: the
    columns acting on the acceleration, (4, 2)); ``out[k, col:col + 2]`` = ``(th_y, th_x)`` of
    ``x[k]``.  Returns the largest ``|th|`` (NaN stays NaN)."""
    x0_, x1, x2, x3 = x0[0], x0[1], x0[2], x0[3]
    out[0, col], out[0, col + 1] = x1, x0_
    big = max(abs(x0_), abs(x1))
    for k in range(f1.shape[0]):
        a1x, a1y, a2x, a2y, a4x, a4y = f1[k, 0], f1[k, 1], f2[k, 0], f2[k, 1], f4[k, 0], f4[k, 1]
        y0 = (Phi[0, 0] * x0_ + Phi[0, 1] * x1 + Phi[0, 2] * x2 + Phi[0, 3] * x3 + G1[0, 0] * a1x + G1[0, 1] * a1y
              + G2[0, 0] * a2x + G2[0, 1] * a2y + G4[0, 0] * a4x + G4[0, 1] * a4y)
        y1 = (Phi[1, 0] * x0_ + Phi[1, 1] * x1 + Phi[1, 2] * x2 + Phi[1, 3] * x3 + G1[1, 0] * a1x + G1[1, 1] * a1y
              + G2[1, 0] * a2x + G2[1, 1] * a2y + G4[1, 0] * a4x + G4[1, 1] * a4y)
        y2 = (Phi[2, 0] * x0_ + Phi[2, 1] * x1 + Phi[2, 2] * x2 + Phi[2, 3] * x3 + G1[2, 0] * a1x + G1[2, 1] * a1y
              + G2[2, 0] * a2x + G2[2, 1] * a2y + G4[2, 0] * a4x + G4[2, 1] * a4y)
        y3 = (Phi[3, 0] * x0_ + Phi[3, 1] * x1 + Phi[3, 2] * x2 + Phi[3, 3] * x3 + G1[3, 0] * a1x + G1[3, 1] * a1y
              + G2[3, 0] * a2x + G2[3, 1] * a2y + G4[3, 0] * a4x + G4[3, 1] * a4y)
        x0_, x1, x2, x3 = y0, y1, y2, y3
        out[k + 1, col], out[k + 1, col + 1] = x1, x0_
        big = max(big, abs(x0_), abs(x1))
        if not big < 1e3:
            return big
    return big


def _lti_matrix(model: SynchronousModel, coef_struct: np.ndarray) -> np.ndarray | None:
    """The state matrix (``th_x, th_y, w_x, w_y``) of the model when it does not change with
    the speed (no gyroscopic term, no rotating effect), else None."""
    if model.rotating or model.ip != 0.0:
        return None
    A_q, A_w = model.linearised(coef_struct, 0.0)
    B_q, B_w = model.linearised(coef_struct, 1.7)
    if not (np.array_equal(A_q, B_q) and np.array_equal(A_w, B_w)):
        return None
    # (u, v) = (th_y, th_x): reorder to the kernel's (th_x, th_y)
    swap = np.array([[0, 1], [1, 0]])
    A = np.zeros((4, 4))
    A[:2, 2:] = np.eye(2)
    A[2:, :2] = swap @ A_q @ swap
    A[2:, 2:] = swap @ A_w @ swap
    return A


def _forcing_series(model: SynchronousModel, c: np.ndarray, phi: np.ndarray, W: np.ndarray,
                    a: np.ndarray) -> np.ndarray:
    """The forcing part of the acceleration, ``(a_x, a_y)`` per point, of the coefficients ``c``
    (forcing effects only): the effects' own columns at zero state."""
    out = np.zeros((len(phi), 2))
    zero = np.zeros_like(phi)
    for e in model.forcing:
        sl = model._slots()[e]
        ce = c[sl]
        if not ce.any():
            continue
        cy, cx = get_effect(e).columns(phi, W, a, zero, zero, zero, zero, model.ip)
        for q, v in enumerate(ce):
            if v:
                out[:, 0] += v * np.broadcast_to(cx[q], phi.shape)
                out[:, 1] += v * np.broadcast_to(cy[q], phi.shape)
    return out


def _stage_columns(prof: _Profile, effect: str, ip: float) -> list[list[np.ndarray]]:
    """Per RK4 stage, per coefficient: the effect's ``(a_x, a_y)`` columns at zero state."""
    cols = []
    for phi, W, a in prof.steps().stages:
        zero = np.zeros_like(phi)
        cy, cx = get_effect(effect).columns(phi, W, a, zero, zero, zero, zero, ip)
        cols.append([np.column_stack([np.broadcast_to(x, phi.shape), np.broadcast_to(y, phi.shape)])
                     for x, y in zip(cx, cy, strict=True)])
    return cols


def _effect_forcing(prof: _Profile, model: SynchronousModel, c: np.ndarray) -> tuple[tuple[np.ndarray, ...], float]:
    """:func:`_forcing_series` at the three RK4 stages of ``prof`` and a factor to apply to them.
    The forcing depends on the spin only: a unit coefficient's columns are evaluated once per
    table (at its first time scale) where they scale as a power of the time scale (the
    unbalance as its square; :func:`_speed_power`), else once per grid."""
    nz = np.flatnonzero(c)
    slots = model._slots()
    base = prof._cache.get("base")
    owner = [e for e in model.forcing if slots[e].start <= nz[0] < slots[e].stop] if len(nz) == 1 else []
    if owner and c[nz[0]] == 1.0 and base is not None and _speed_power(owner[0], model.ip) is not None:
        e, q = owner[0], int(nz[0] - slots[owner[0]].start)
        bprof, w_ref = base
        rkey = ("ref_columns", e, model.ip)
        if rkey not in bprof._cache:
            bprof._cache[rkey] = (w_ref, [[np.ascontiguousarray(x) for x in stage]
                                          for stage in _stage_columns(prof, e, model.ip)])
        w0, cols = bprof._cache[rkey]
        return tuple(stage[q] for stage in cols), (w0 / w_ref) ** _speed_power(e, model.ip)
    key = ("forcing", model.forcing, model.ip, c.tobytes())
    if key not in prof._cache:
        prof._cache[key] = tuple(_forcing_series(model, c, *stage) for stage in prof.steps().stages)
    return prof._cache[key], 1.0


def _rk4_linear(A: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The simulator's RK4 step on ``x' = A x + f`` written out: ``x+ = Phi x + G1 f1 + G2 f2 + G4 f4``
    (``f2``: the forcing at the half step, taken by stages 2 and 3)."""
    hA = h * A
    eye = np.eye(4)
    hA2 = hA @ hA
    hA3 = hA2 @ hA
    Phi = eye + hA + hA2 / 2 + hA3 / 6 + hA3 @ hA / 24
    G1 = h / 6 * (eye + hA + hA2 / 2 + hA3 / 4)
    G2 = h / 6 * (4 * eye + 2 * hA + hA2 / 2)
    G4 = h / 6 * eye
    return Phi, G1, G2, G4


def _transient(model: SynchronousModel, coef_struct: np.ndarray, forcing_coefs: list[np.ndarray],
               tau: np.ndarray, W: np.ndarray, *, coast_down: bool, profile: _Profile | None = None,
               orders: tuple[int, ...] = (1,)) -> np.ndarray:
    """Basis responses (rows, 2 * len(orders), n_basis): the model run along the speed profile,
    tracked per revolution at each order, ``(u, v)`` per order (``profile``: :func:`_profile`
    of ``tau, W`` with these orders, when the caller keeps it)."""
    prof = _profile(tau, W, orders) if profile is None else profile
    grid, phi, Wg = prof.grid, prof.phi, prof.speed
    accel = compile_accel(model.layout)
    out = np.empty((len(tau), 2 * len(orders), len(forcing_coefs)), dtype=complex)
    sims = np.empty((len(grid), 2 * len(forcing_coefs)))
    A = _lti_matrix(model, coef_struct)
    if A is not None:
        # the same RK4 steps as the compiled kernel, as one linear recursion: the forcing at
        # every step's stages at once (numpy), then x <- Phi x + g (no acceleration calls)
        Phi, G1, G2, G4 = _rk4_linear(A, prof.step())
        Gs = [np.ascontiguousarray(G[:, 2:]) for G in (G1, G2, G4)]
    for j, c in enumerate(forcing_coefs):
        # start on the steady-state response at the first speed: no artificial transient
        state = _start_state(model, coef_struct, c, float(Wg[0]), float(phi[0]))
        if A is not None:
            (f1, f2, f4), k = _effect_forcing(prof, model, c)
            if not _linear_steps(Phi, k * Gs[0], k * Gs[1], k * Gs[2], f1, f2, f4, state, sims, 2 * j) < 1e3:
                raise FloatingPointError("the synchronous model diverged (unstable parameters)")  # the kernel's bound
            continue
        buf = np.empty((len(grid), 10))
        buf[0, 4], buf[0, 5] = state[0], state[1]
        done = call_integrate_profile(accel, state, grid, phi, Wg, model.ip, coef_struct + c, 0.0, 1, buf)
        if done < len(grid):
            raise FloatingPointError("the synchronous model diverged (unstable parameters)")
        sims[:, 2 * j] = buf[:, 5]  # u = th_y
        sims[:, 2 * j + 1] = buf[:, 4]  # v = th_x
    track = prof.tracker.track(sims)
    if len(track.t) != len(tau):  # pragma: no cover - the grid covers every row by construction
        raise RuntimeError("order tracking lost rows")
    for k, n in enumerate(orders):
        vec = track.vectors[n]
        out[:, 2 * k, :] = vec[:, 0::2]
        out[:, 2 * k + 1, :] = vec[:, 1::2]
    del coast_down
    return out


def vector_orders(table: VectorTable) -> tuple[int, ...]:
    """The orders a fit reads: 1X, and 2X where the table has it, a time column (only the
    transient model carries 2X) and the probes' angles (or one probe)."""
    Y2 = table.vectors.get(2)
    if (Y2 is None or table.t is None or not np.isfinite(Y2).any()
            or (table.angles is None and len(table.probes) > 1)):
        return (1,)
    return (1, 2)


class _Problem:
    """The variable-projection least-squares problem of one model on one table."""

    def __init__(self, model: SynchronousModel, table: VectorTable, method: str,
                 orders: tuple[int, ...] | None = None) -> None:
        self.model, self.table = model, table
        self.orders = vector_orders(table) if orders is None else tuple(orders)
        if model.rotating and method != "transient":
            raise ValueError(f"{', '.join(model.rotating)} turns with the shaft: only the transient model (a table "
                             "with a time column) carries it")
        # probes of each order side by side: (rows, probes * orders)
        self.Y = np.concatenate([table.vectors[n] for n in self.orders], axis=1)
        self.valid = np.isfinite(self.Y)
        self.P = vector_probe_matrix(table)
        self.method = method
        #: w_ref -> the transient runs' grid at that time scale (the Jacobian's columns share it)
        self._profiles: dict[float, _Profile] = {}
        self._base: _Profile | None = None
        self._memo: dict[tuple[bytes, str], np.ndarray] = {}
        self._mode_memo: dict[tuple, np.ndarray] = {}
        scale = np.nanmax(np.abs(self.Y))
        self.scale = float(scale) if scale > 0 else 1.0
        slots = model._slots()
        self.basis: list[tuple[str, int]] = []
        for e in model.forcing:
            for q in range(slots[e].stop - slots[e].start):
                self.basis.append((e, q))
        self.struct_sizes = [(e, slots[e].stop - slots[e].start) for e in model.structural]
        self.n_extra = model.modes - 1
        self.basis += [(SECOND_MODE, q) for _ in range(self.n_extra) for q in range(2)]
        W_abs = table.speed
        self.coast_down = bool(W_abs[-1] < W_abs[0])
        if table.t is not None:
            self.Wdot_abs = np.gradient(W_abs, table.t)
        else:
            self.Wdot_abs = np.zeros_like(W_abs)

    # parameters: [log w_ref, structural coefficients...]
    def unpack(self, x: np.ndarray) -> tuple[float, dict[str, np.ndarray]]:
        w_ref = math.exp(x[0])
        st, j = {}, 1
        for e, n in self.struct_sizes:
            st[e] = np.asarray(x[j : j + n])
            j += n
        return w_ref, st

    def extra_modes(self, x: np.ndarray) -> list[tuple[float, float]]:
        """(w_ref, c) of each extra mode: the last two parameters per mode."""
        j = 1 + sum(n for _, n in self.struct_sizes)
        return [(math.exp(x[j + 2 * m]), float(x[j + 2 * m + 1])) for m in range(self.n_extra)]

    def basis_vectors(self, x: np.ndarray, method: str | None = None) -> np.ndarray:
        """(rows, probes, n_lin) complex basis of the linear parameters (the last few kept: the
        Jacobian's columns of the linear parameters, and the final checks, ask for the same ``x``)."""
        method = method or self.method
        key = (np.asarray(x, dtype=float).tobytes(), method)
        hit = self._memo.get(key)
        if hit is None:
            hit = self._basis_vectors(np.asarray(x, dtype=float), method)
            if len(self._memo) >= 3:
                self._memo.pop(next(iter(self._memo)))
            self._memo[key] = hit
        return hit.copy()

    def _basis_vectors(self, x: np.ndarray, method: str) -> np.ndarray:
        w_ref, st = self.unpack(x)
        own = [(e, q) for e, q in self.basis if e != SECOND_MODE]
        B = self._mode_basis(self.model, self.model.coef_vector(st), own, w_ref, method)
        for w2, c2 in self.extra_modes(x):
            iso = _isotropic(self.model.ip)
            B2 = self._mode_basis(iso, iso.coef_vector({"viscous_damping": np.array([c2])}),
                                  [("unbalance", 0), ("unbalance", 1)], w2, method)
            B = np.concatenate([B, B2], axis=2)
        probes = np.concatenate([np.einsum("pc,rcn->rpn", self.P, B[:, 2 * k : 2 * k + 2])
                                 for k in range(len(self.orders))], axis=1)
        if self.model.runout:
            n_p = len(self.table.probes)
            # a 1X vector per probe (the probe track's runout): the 1X columns only
            R = np.zeros((len(self.table.speed), probes.shape[1], n_p), dtype=complex)
            for p in range(n_p):
                R[:, p, p] = 1.0
            probes = np.concatenate([probes, R], axis=2)
        return probes

    def _mode_basis(self, model: SynchronousModel, coef: np.ndarray, basis, w_ref: float, method: str) -> np.ndarray:
        """(rows, 2, n) responses of one mode to each unit forcing coefficient (the last few kept:
        a difference step in one mode's parameters leaves the other mode's runs as they were)."""
        key = (model.effects, model.ip, model.runout, model.modes, np.asarray(coef, dtype=float).tobytes(),
               tuple(basis), float(w_ref), method)
        hit = self._mode_memo.get(key)
        if hit is None:
            hit = self._mode_basis_run(model, coef, basis, w_ref, method)
            if len(self._mode_memo) >= 6:
                self._mode_memo.pop(next(iter(self._mode_memo)))
            self._mode_memo[key] = hit
        return hit

    def _mode_basis_run(self, model: SynchronousModel, coef: np.ndarray, basis, w_ref: float,
                        method: str) -> np.ndarray:
        fc = []
        for e, q in basis:
            c = np.zeros_like(coef)
            c[model._slots()[e].start + q] = 1.0
            fc.append(c)
        W = self.table.speed / w_ref
        if not fc:
            return np.empty((len(W), 2 * len(self.orders), 0), dtype=complex)
        if method == "transient":
            # time from the first row: a table may carry absolute time stamps (1.7e9 s), whose
            # last digits a dimensionless grid of 0.05 would not resolve
            tau = (self.table.t - self.table.t[0]) * w_ref
            prof = self._profiles.get(w_ref)
            if prof is None:
                if len(self._profiles) >= 4:  # a fit moves w_ref: keep the latest few
                    self._profiles.pop(next(iter(self._profiles)))
                if self._base is None:
                    # one grid in seconds for the whole fit (its step from the first time scale):
                    # the angle, the rows, the tracker and the forcing's columns are set up once
                    h = min(0.05, 2 * math.pi / (48.0 * float(W.max()))) / w_ref
                    self._base = _profile(self.table.t - self.table.t[0], self.table.speed, self.orders, h=h)
                prof = self._profiles[w_ref] = _scaled(self._base, w_ref)
            return _transient(model, coef, fc, tau, W, coast_down=self.coast_down, profile=prof,
                              orders=self.orders)
        if self.orders != (1,):
            raise ValueError("the quasi-steady model carries 1X only")
        return _quasi_steady(model, coef, fc, W, self.Wdot_abs / w_ref**2)

    def expand(self, B: np.ndarray) -> np.ndarray:
        """Without the probes' angles each probe sees the whirl from its own unknown angle:
        its own copy of the forcing coefficients (an isotropic rotor's response is
        ``W e^{-i angle}``: the angle is absorbed into the complex unbalance)."""
        n_f = len(self.basis)
        n_p = len(self.table.probes)
        if self.table.angles is not None or n_p == 1 or n_f == 0:
            return B
        blocks = []
        for p in range(n_p):
            blk = np.zeros_like(B[..., :n_f])
            blk[:, p, :] = B[:, p, :n_f]
            blocks.append(blk)
        return np.concatenate([*blocks, B[..., n_f:]], axis=2)

    @property
    def n_forcing(self) -> int:
        n_p = len(self.table.probes)
        return len(self.basis) * (n_p if self.table.angles is None and n_p > 1 else 1)

    def solve_linear(self, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Real forcing coefficients and complex runouts: least squares on the valid entries."""
        B = self.expand(B)
        n_f = self.n_forcing
        n_p = B.shape[2] - n_f
        v = self.valid
        # real unknowns: n_f forcing coefficients, then (Re, Im) of each runout
        cols = [B[..., j][v] for j in range(n_f)]
        for j in range(n_p):
            cols += [B[..., n_f + j][v], 1j * B[..., n_f + j][v]]
        A = np.column_stack(cols) if cols else np.empty((int(v.sum()), 0), dtype=complex)
        y = self.Y[v]
        Ar = np.vstack([A.real, A.imag])
        yr = np.concatenate([y.real, y.imag])
        sol = np.linalg.lstsq(Ar, yr, rcond=None)[0] if Ar.shape[1] else np.empty(0)
        return sol, (A @ sol if Ar.shape[1] else np.zeros_like(y))

    def residual(self, x: np.ndarray) -> np.ndarray:
        try:
            B = self.basis_vectors(x)
        except (FloatingPointError, np.linalg.LinAlgError):
            return np.full(2 * int(self.valid.sum()), 1e3)
        _, pred = self.solve_linear(B)
        r = (self.Y[self.valid] - pred) / self.scale
        return np.concatenate([r.real, r.imag])


def _isotropic(ip: float) -> SynchronousModel:
    """The plain mode: stiffness, viscous damping and unbalance (an extra mode's model)."""
    return SynchronousModel(("viscous_damping", "unbalance"), ip=ip)


def _initial_guesses(table: VectorTable, ip: float) -> list[tuple[float, float]]:
    """(w_ref, c) starts from the amplitude peak and its half-power width."""
    Y = table.vectors[1]
    amp = np.nanmax(np.abs(Y - Y[:1]), axis=1)
    k = int(np.nanargmax(amp))
    w_peak = float(table.speed[k])
    half = amp >= amp[k] / math.sqrt(2.0)
    lo = k
    while lo > 0 and half[lo - 1]:
        lo -= 1
    hi = k
    while hi < len(amp) - 1 and half[hi + 1]:
        hi += 1
    zeta = float(np.clip((table.speed[hi] - table.speed[lo]) / (2.0 * w_peak), 0.005, 0.3))
    w0 = w_peak * math.sqrt(1.0 - ip)
    return [(w0 * f, 2.0 * zeta * g) for f in (1.0, 0.96, 1.04) for g in (1.0, 0.4, 2.5)]


def fit_vectors(
    table: VectorTable,
    model: SynchronousModel,
    *,
    method: str = "auto",
    start: VectorFit | None = None,
    extra_starts: Sequence[np.ndarray] = (),
) -> VectorFit:
    """Least-squares fit of ``model`` to the 1X vectors of ``table``.

    ``method``: ``"quasi-steady"``, ``"transient"`` (needs a time column) or ``"auto"``
    (see the module docstring).  ``start``: a previous fit whose parameters seed this one
    (the diagnosis adds one effect at a time).
    """
    if method not in ("auto", "quasi-steady", "transient"):
        raise ValueError(f"method must be 'auto', 'quasi-steady' or 'transient', got {method!r}")
    if method == "transient" and table.t is None:
        raise ValueError("the transient model needs a time column in the table")
    chosen = method
    if method == "auto":
        chosen = start.method if start is not None else ("transient" if table.t is not None else "quasi-steady")
    prob = _Problem(model, table, chosen)
    n_struct = sum(n for _, n in prob.struct_sizes) + 2 * prob.n_extra
    starts: list[np.ndarray] = []
    if start is not None:
        x = [math.log(start.w_ref)]
        for e, n in prob.struct_sizes:
            x += list(start.structural.get(e, np.full(n, _nonzero_start(e))))
        extra = [[math.log(w), c] for w, c in start.extra_modes]
        if len(extra) < prob.n_extra:
            # a new mode where the fit so far fails most, at a few dampings
            mag = np.sqrt(np.nanmean(np.abs(start.residual) ** 2, axis=1))
            w_new = float(table.speed[int(np.nanargmax(mag))])
            for f, c in ((1.0, 0.06), (0.97, 0.03), (1.03, 0.03), (1.0, 0.2)):
                starts.append(np.array(x + [v for m in extra for v in m] + [math.log(w_new * f), c]))
        else:
            starts.append(np.array(x + [v for m in extra for v in m]))
    starts += [np.asarray(s, dtype=float) for s in extra_starts]
    if start is None:
        for w0, c0 in _initial_guesses(table, model.ip):
            x = [math.log(w0)]
            for e, n in prob.struct_sizes:
                x += [c0] if e == "viscous_damping" else [_nonzero_start(e)] * n
            starts.append(np.array(x))
    lower = np.full(1 + n_struct, -np.inf)
    upper = np.full(1 + n_struct, np.inf)
    # a natural frequency a decade beyond the run cannot be read from its 1X vectors, and the
    # transient grid (48 steps a turn, 125 a natural period) grows without bound towards it
    lower[0] = math.log(float(table.speed.min()) / W_REF_DECADES)
    upper[0] = math.log(float(table.speed.max()) * W_REF_DECADES)
    for m in range(prob.n_extra):
        k = 1 + n_struct - 2 * (prob.n_extra - m)
        lower[k], upper[k] = math.log(0.3 * float(table.speed.min())), math.log(2.0 * float(table.speed.max()))
        lower[k + 1], upper[k + 1] = 1e-4, 2.0
    j = 1
    for e, n in prob.struct_sizes:
        eff = get_effect(e)
        for q in range(n):
            p = eff.parameters[min(q, len(eff.parameters) - 1)]
            # the simulator's domain (damping >= 0, anisotropy < 1); the plausibility bounds are checked later
            lower[j + q] = 0.0 if e == "viscous_damping" else -0.95
            upper[j + q] = 2.0 if e == "viscous_damping" else 0.95
            del p
        j += n
    def solve(problem: _Problem, xs: list[np.ndarray], keep: int | None = None):
        best = None
        xs = [np.clip(x0, lower + 1e-9, upper - 1e-9) for x0 in xs]
        if keep is not None and len(xs) > keep:
            # the starts ranked by their own misfit (one evaluation each); only the best few
            # are fitted: a two-mode transient evaluation costs tens of milliseconds, and the
            # starts around a new mode converge to the same minimum from either side
            cost = [float(np.sum(problem.residual(x0) ** 2)) for x0 in xs]
            xs = [xs[i] for i in np.argsort(cost)[:keep]]
        for x0 in xs:
            res = least_squares(problem.residual, x0, bounds=(lower, upper), x_scale="jac", method="trf",
                                diff_step=1e-6, max_nfev=200)
            if best is None or res.cost < best.cost:
                best = res
        return best

    if chosen == "transient" and start is None and prob.n_extra == 0:
        # the many starts on the cheap quasi-steady model; the transient refines the best
        # (its peak is delayed: the quasi-steady w_ref is off by a few per cent either way)
        # (nine starts around the peak and its half-power width: the three that fit best)
        best_q = solve(_Problem(model, table, "quasi-steady", orders=(1,)), starts, keep=3)
        starts = [best_q.x + np.r_[d, np.zeros(n_struct)] for d in (0.0, -0.03, 0.03)]
    # a new mode's starts (four around the worst misfit): the two that fit best at the start
    best = solve(prob, starts, keep=2 if prob.n_extra and chosen == "transient" else None)
    if method == "auto" and table.t is not None and chosen == "transient" and start is None and prob.orders == (1,):
        # keep the quasi-steady model only where it is as good as the transient one
        Bt = prob.basis_vectors(best.x, "transient")
        Bq = prob.basis_vectors(best.x, "quasi-steady")
        sol, _ = prob.solve_linear(Bt)
        pt, pq = _predict(prob, Bt, sol), _predict(prob, Bq, sol)
        if np.nanmax(np.abs(pt - pq)) <= QUASI_STEADY_TOL * np.nanmax(np.abs(pt)):
            prob.method = "quasi-steady"
    return _finish(prob, best.x, best.success)


def _nonzero_start(effect: str) -> float:
    return 1e-3 if effect != "viscous_damping" else 0.05


def _predict(prob: _Problem, B: np.ndarray, sol: np.ndarray) -> np.ndarray:
    B = prob.expand(B)
    n_f = prob.n_forcing
    pred = np.einsum("rpn,n->rp", B[..., :n_f], sol[:n_f]) if n_f else np.zeros(B.shape[:2], dtype=complex)
    for j in range(B.shape[2] - n_f):
        pred = pred + B[..., n_f + j] * (sol[n_f + 2 * j] + 1j * sol[n_f + 2 * j + 1])
    return pred


def _finish(prob: _Problem, x: np.ndarray, success: bool) -> VectorFit:
    B = prob.basis_vectors(x)
    sol, _ = prob.solve_linear(B)
    pred = _predict(prob, B, sol)
    w_ref, st = prob.unpack(x)
    n_f = prob.n_forcing
    forcing: dict[str, np.ndarray] = {}
    # the first probe's copy when each probe has its own (no angles): its size is what is reported
    for (e, q), v in zip(prob.basis, sol[: len(prob.basis)], strict=True):
        if e == SECOND_MODE:
            forcing.setdefault(e, np.zeros(2))[q] = v
        else:
            forcing.setdefault(e, np.zeros(len(get_effect(e).coefficients)))[q] = v
    runout = None
    if prob.model.runout:
        runout = sol[n_f::2] + 1j * sol[n_f + 1 :: 2]
    # Jacobian of the whole residual w.r.t. all parameters (nonlinear and linear), for the HAC tests
    names = ["log_w_ref"] + [f"{e}[{q}]" for e, n in prob.struct_sizes for q in range(n)]
    names += [f"{SECOND_MODE}.{k}" for _ in range(prob.n_extra) for k in ("log_w", "c")]
    copies = prob.n_forcing // max(len(prob.basis), 1)
    names += [f"{e}[{q}]" + (f"@{p}" if copies > 1 else "") for p in prob.table.probes[:copies]
              for e, q in prob.basis]
    if runout is not None:
        names += [f"{RUNOUT}[{p}].{c}" for p in prob.table.probes for c in ("re", "im")]
    theta = np.concatenate([x, sol])

    def full(th: np.ndarray) -> np.ndarray:
        Bx = prob.basis_vectors(th[: len(x)])
        r = (prob.Y[prob.valid] - _predict(prob, Bx, th[len(x):])[prob.valid])
        return np.concatenate([r.real, r.imag])

    r0 = full(theta)
    J = np.empty((len(r0), len(theta)))
    for i in range(len(theta)):
        step = 1e-6 * max(1.0, abs(theta[i]))
        tp = theta.copy()
        tp[i] += step
        J[:, i] = (full(tp) - r0) / step
    return VectorFit(prob.model, prob.table, w_ref, st, forcing, runout, pred, prob.method, -J, tuple(names),
                     theta, bool(success), tuple(prob.extra_modes(x)), prob.orders)


# ----------------------------------------------------------------- criticals
def _eigen(model: SynchronousModel, coef: np.ndarray, W: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eigenvalues of the linearised state matrix at ``W`` and each eigenvector's forward
    and backward parts ``|v_u + i v_v|``, ``|v_u - i v_v|``."""
    A_q, A_w = model.linearised(coef, W)
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [A_q, A_w]])
    lam, vec = np.linalg.eig(A)
    return lam, np.abs(vec[0] + 1j * vec[1]), np.abs(vec[0] - 1j * vec[1])


def whirl_modes(model: SynchronousModel, coef: np.ndarray, W: float) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues with positive imaginary part and each one's forward share."""
    lam, fwd, bwd = _eigen(model, coef, W)
    keep = lam.imag > 1e-9
    lam, fwd, bwd = lam[keep], fwd[keep], bwd[keep]
    order = np.argsort(lam.imag)
    return lam[order], (fwd / np.maximum(fwd + bwd, 1e-300))[order]


def whirl_branches(model: SynchronousModel, coef: np.ndarray, speed: np.ndarray) -> dict[str, np.ndarray]:
    """The Campbell diagram's branches: the damped whirl frequencies ``Im lambda`` of the
    linearised model at each dimensionless ``speed``, signed by the whirl of each mode
    (forward where its forward part is at least its backward part; a double eigenvalue,
    the isotropic rotor at rest, is both circles).  ``{"forward": w_f, "backward": w_b}``
    (``w_b < 0`` for a backward whirl), NaN where a mode is over-critically damped;
    where both modes whirl the same way (strong anisotropy), the higher one is the
    ``forward`` branch, each keeping the sign of its own whirl."""
    speed = np.atleast_1d(np.asarray(speed, dtype=float))
    fwd, bwd = np.full(speed.shape, np.nan), np.full(speed.shape, np.nan)
    for j, w in enumerate(speed):
        lam, f, b = _eigen(model, coef, w)
        upper = np.flatnonzero(lam.imag > 1e-12 * max(1.0, float(np.max(np.abs(lam)))))
        if len(upper) == 2 and abs(lam[upper[0]] - lam[upper[1]]) <= 1e-9 * abs(lam[upper[0]]):
            # its eigenvectors are any mix of the forward and the backward circle
            modes = [lam[upper[0]].imag, -lam[upper[0]].imag]
        else:
            modes = [lam[i].imag if f[i] >= b[i] else -lam[i].imag for i in upper]
        modes.sort(reverse=True)
        if len(modes) == 2:
            fwd[j], bwd[j] = modes
        elif len(modes) == 1:  # one mode over-critically damped
            (fwd if modes[0] > 0 else bwd)[j] = modes[0]
    return {"forward": fwd, "backward": bwd}


def critical_speeds(model: SynchronousModel, coef: np.ndarray, w_ref: float, speed: np.ndarray,
                    min_forward_share: float = 0.1) -> list[dict[str, float]]:
    """Critical speeds (rpm) within the run's speed range and their damping ratios, lowest first."""
    W = np.asarray(speed, dtype=float) / w_ref
    lo, hi = float(W.min()), float(W.max())
    grid = np.linspace(0.5 * lo, hi, 400)
    out = []
    n_branch = None
    vals = []
    for w in grid:
        lam, _ = whirl_modes(model, coef, w)
        if n_branch is None:
            n_branch = len(lam)
        vals.append(lam.imag if len(lam) == n_branch else np.full(n_branch, np.nan))
    vals = np.array(vals) - grid[:, None]
    for b in range(n_branch or 0):
        f = vals[:, b]
        for k in np.nonzero(np.sign(f[:-1]) * np.sign(f[1:]) < 0)[0]:
            def g(w, b=b):
                lam, _ = whirl_modes(model, coef, w)
                return lam.imag[b] - w
            try:
                wc = brentq(g, grid[k], grid[k + 1], xtol=1e-12)
            except ValueError:
                continue
            lam, share = whirl_modes(model, coef, wc)
            if share[b] < min_forward_share or not (lo * 0.999 <= wc <= hi * 1.001):
                continue
            out.append({"rpm": wc * w_ref / SPEED_UNITS["rpm"],
                        "damping_ratio": float(-lam[b].real / abs(lam[b])),
                        "forward_share": float(share[b])})
    out = sorted(out, key=lambda d: d["rpm"])
    # a degenerate (isotropic) pair of branches crosses the 1x line once
    merged: list[dict[str, float]] = []
    for c in out:
        if merged and abs(c["rpm"] - merged[-1]["rpm"]) <= 1e-6 * c["rpm"]:
            merged[-1]["forward_share"] = max(merged[-1]["forward_share"], c["forward_share"])
            continue
        merged.append(c)
    return merged


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
