"""The synchronous model's predicted vectors, quasi-steady and transient.

*Quasi-steady*: the model linearised at each row's speed, solved for its steady 1X response.
*Transient*: the model run along the table's speed profile (the simulator's RK4 on one grid;
a model that does not change with the speed as one compiled linear recursion,
:func:`_rk4_linear`) and order-tracked one revolution at a time at 1X (and 2X), as the data
were.  Both give basis responses, one per unit forcing coefficient, which :mod:`.fit` combines
linearly.

:class:`Profile`, :func:`speed_profile`, :func:`scaled_profile`, :func:`quasi_steady_response`
and :func:`transient_response` are what :mod:`.fit` calls: they have no leading underscore
because ``tests/test_import_graph.py`` forbids private names across modules, but they are this
package's internals (its ``__init__`` does not re-export them).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.interpolate import PchipInterpolator

from ...effects import get_effect
from ...measurements.vectors import OrderTracker, VectorTable
from ...simulator import call_integrate_profile, compile_accel
from .model import SynchronousModel

__all__ = ["LEAD_IN_REVS", "MAX_TRANSIENT_SAMPLES", "vector_orders", "vector_probe_matrix"]

#: the record starts this many revolutions before the first row (initial transient settles)
LEAD_IN_REVS = 2.0
#: the transient model's grid (about 200 bytes a sample with the tracking) stays below this
MAX_TRANSIENT_SAMPLES = 4_000_000



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


def quasi_steady_response(model: SynchronousModel, coef_struct: np.ndarray, forcing_coefs: list[np.ndarray],
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
    """:func:`quasi_steady_response` row by row: the linearised model solved at each speed."""
    out = np.empty((len(W), 2, len(forcing_coefs)), dtype=complex)
    for k, (w, wd) in enumerate(zip(W, Wdot, strict=True)):
        A_q, A_w = model.linearised(coef_struct, w)
        M = -w * w * np.eye(2) - A_q - 1j * w * A_w
        F = np.column_stack([model.forcing_1x(c, w, wd) for c in forcing_coefs])
        out[k] = np.linalg.solve(M, F)
    return out


@dataclass(frozen=True)
class Profile:
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


def speed_profile(tau: np.ndarray, W: np.ndarray, orders: tuple[int, ...] = (1,), h: float | None = None) -> Profile:
    """The grid a :func:`transient_response` run follows (it depends on the time scale only, not on
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
    return Profile(grid, phi, Wg, phi_rows, OrderTracker(grid, phi, orders, at=phi_rows))


def scaled_profile(base: Profile, w_ref: float) -> Profile:
    """A profile in seconds seen in the model's time (``t w_ref``, speed ``/ w_ref``): the
    angle, the rows and the tracker are the same at every ``w_ref``."""
    prof = Profile(base.grid * w_ref, base.phi, base.speed / w_ref, base.phi_rows, base.tracker)
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


def _stage_columns(prof: Profile, effect: str, ip: float) -> list[list[np.ndarray]]:
    """Per RK4 stage, per coefficient: the effect's ``(a_x, a_y)`` columns at zero state."""
    cols = []
    for phi, W, a in prof.steps().stages:
        zero = np.zeros_like(phi)
        cy, cx = get_effect(effect).columns(phi, W, a, zero, zero, zero, zero, ip)
        cols.append([np.column_stack([np.broadcast_to(x, phi.shape), np.broadcast_to(y, phi.shape)])
                     for x, y in zip(cx, cy, strict=True)])
    return cols


def _effect_forcing(prof: Profile, model: SynchronousModel, c: np.ndarray) -> tuple[tuple[np.ndarray, ...], float]:
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


def transient_response(model: SynchronousModel, coef_struct: np.ndarray, forcing_coefs: list[np.ndarray],
               tau: np.ndarray, W: np.ndarray, *, coast_down: bool, profile: Profile | None = None,
               orders: tuple[int, ...] = (1,)) -> np.ndarray:
    """Basis responses (rows, 2 * len(orders), n_basis): the model run along the speed profile,
    tracked per revolution at each order, ``(u, v)`` per order (``profile``: :func:`speed_profile`
    of ``tau, W`` with these orders, when the caller keeps it)."""
    prof = speed_profile(tau, W, orders) if profile is None else profile
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
