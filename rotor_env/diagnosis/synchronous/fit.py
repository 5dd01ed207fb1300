"""The fit of a synchronous model to a table's 1X (and 2X) vectors, by variable projection.

:class:`_Problem` is one model on one table: the nonlinear parameters (``log w_ref``, the
structural coefficients, each extra mode's natural frequency and damping) are fitted by
:func:`scipy.optimize.least_squares`, and for each trial the forcing coefficients and the
runouts are solved by linear least squares on the basis responses of :mod:`.response`.
:func:`fit_vectors` picks the starts and the method and returns a :class:`VectorFit`: the
parameters, the model vectors, the residual, the Jacobian for the HAC tests, the criticals
(:mod:`.criticals`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ...effects import get_effect
from ...measurements.vectors import SPEED_UNITS, VectorTable
from .criticals import critical_speeds
from .model import RUNOUT, SECOND_MODE, SynchronousModel, harmonic_order
from .response import (
    Profile,
    quasi_steady_response,
    scaled_profile,
    speed_profile,
    transient_response,
    vector_orders,
    vector_probe_matrix,
)

__all__ = ["QUASI_STEADY_TOL", "W_REF_DECADES", "VectorFit", "extra_mode_vectors", "fit_vectors"]

#: quasi-steady is used only where it is within this fraction of the peak of the transient
QUASI_STEADY_TOL = 0.01
#: the fitted natural frequency stays within this factor of the run's speeds
W_REF_DECADES = 10.0
#: the solver's budget of residual evaluations per start
MAX_ITERATIONS = 200
#: starts across an orientation's period for a new effect whose orientation enters non-linearly
ORIENTATION_STARTS = 4


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
        return sorted(self.rotor_criticals + self.extra_criticals, key=lambda d: d["rpm"])

    @property
    def rotor_criticals(self) -> list[dict[str, float]]:
        """The criticals of the rotor model itself (one mode; two where the supports split it)."""
        return critical_speeds(self.model, self.coef(), self.w_ref, self.table.speed)

    @property
    def extra_criticals(self) -> list[dict[str, float]]:
        """The criticals of the added modes (:data:`SECOND_MODE`): another mode of the rotor and
        its supports, outside the rotor model."""
        out: list[dict[str, float]] = []
        for w, c in self.extra_modes:
            iso = _isotropic(self.model.ip)
            out += critical_speeds(iso, iso.coef_vector({"viscous_damping": np.array([c])}), w, self.table.speed)
        return out

    def coef(self) -> np.ndarray:
        return self.model.coef_vector(self.structural, {k: v for k, v in self.forcing.items() if k != SECOND_MODE})

    def values(self) -> dict[str, dict[str, float]]:
        """Each effect's physical parameters (forcing amplitudes in the table's unit)."""
        out: dict[str, dict[str, float]] = {}
        for name in self.model.effects:
            if name in self.structural:
                c, angles = self.model.structural_values(name, self.structural[name])
            else:
                c, angles = np.asarray(self.forcing[name], dtype=float), ()
            out[name] = get_effect(name).from_coefficients(c)
            out[name].update(_orientations(self.model, name, out[name], angles))
        if self.runout is not None:
            out[RUNOUT] = {p: float(abs(v)) for p, v in zip(self.table.probes, self.runout, strict=True)}
        out["natural_frequency"] = {"rpm": self.w_ref / SPEED_UNITS["rpm"]}
        for w, c in self.extra_modes:
            u = self.forcing.get(SECOND_MODE, np.zeros(2))
            out[SECOND_MODE] = {"natural_frequency_rpm": w / SPEED_UNITS["rpm"], "c": c,
                                "unbalance": float(np.hypot(u[0], u[1]))}
        return out


def _orientations(model: SynchronousModel, name: str, values: dict[str, float],
                  angles: tuple[float, ...]) -> dict[str, float]:
    """The fitted orientations by name, each within its period (an effect harmonic in its
    orientation has a size >= 0 by construction: the angle carries the sign)."""
    eff = get_effect(name)
    out = {}
    for q, a in zip(model.fitted_orientations(name), angles, strict=True):
        p = eff.argument_parameters[q]
        out[p.name] = float(np.mod(a, p.angle_period))
    return out


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
        self._profiles: dict[float, Profile] = {}
        self._base: Profile | None = None
        self._memo: dict[tuple[bytes, str], np.ndarray] = {}
        self._mode_memo: dict[tuple, np.ndarray] = {}
        scale = np.nanmax(np.abs(self.Y))
        self.scale = float(scale) if scale > 0 else 1.0
        slots = model._slots()
        self.basis: list[tuple[str, int]] = []
        for e in model.forcing:
            for q in range(slots[e].stop - slots[e].start):
                self.basis.append((e, q))
        self.struct_sizes = [(e, model.n_structural(e)) for e in model.structural]
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
                    self._base = speed_profile(self.table.t - self.table.t[0], self.table.speed, self.orders, h=h)
                prof = self._profiles[w_ref] = scaled_profile(self._base, w_ref)
            return transient_response(model, coef, fc, tau, W, coast_down=self.coast_down, profile=prof,
                              orders=self.orders)
        if self.orders != (1,):
            raise ValueError("the quasi-steady model carries 1X only")
        return quasi_steady_response(model, coef, fc, W, self.Wdot_abs / w_ref**2)

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
    max_iterations: int = MAX_ITERATIONS,
) -> VectorFit:
    """Least-squares fit of ``model`` to the 1X vectors of ``table``.

    ``method``: ``"quasi-steady"``, ``"transient"`` (needs a time column) or ``"auto"``
    (see the module docstring).  ``start``: a previous fit whose parameters seed this one
    (the diagnosis adds one effect at a time).  ``max_iterations``: the solver's evaluations
    of the residual (its Jacobian's differences not counted); a fit stopped there has
    ``success`` False and can be continued with ``start=`` it.
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
    new_angles = 1
    if start is not None:
        x = [[math.log(start.w_ref)]]
        for e, n in prob.struct_sizes:
            old = start.structural.get(e)
            if old is not None and len(old) == n:
                x = [xs + list(old) for xs in x]
            elif len(model.fitted_orientations(e)) and not harmonic_order(e):
                # an orientation entering non-linearly: a few starts around its period, ranked
                # by their misfit at a typical size (the best one fitted)
                period = get_effect(e).argument_parameters[model.fitted_orientations(e)[0]].angle_period
                size = _typical_size(e)
                x = [xs + list(model.structural_start(e, size, period * k / ORIENTATION_STARTS))
                     for xs in x for k in range(ORIENTATION_STARTS)]
                new_angles = len(x)
            else:
                x = [xs + list(model.structural_start(e, _nonzero_start(e))) for xs in x]
        extra = [[math.log(w), c] for w, c in start.extra_modes]
        for xs in x:
            if len(extra) < prob.n_extra:
                # a new mode where the fit so far fails most, at a few dampings
                mag = np.sqrt(np.nanmean(np.abs(start.residual) ** 2, axis=1))
                w_new = float(table.speed[int(np.nanargmax(mag))])
                for f, c in ((1.0, 0.06), (0.97, 0.03), (1.03, 0.03), (1.0, 0.2)):
                    starts.append(np.array(xs + [v for m in extra for v in m] + [math.log(w_new * f), c]))
            else:
                starts.append(np.array(xs + [v for m in extra for v in m]))
    starts += [np.asarray(s, dtype=float) for s in extra_starts]
    if start is None:
        for w0, c0 in _initial_guesses(table, model.ip):
            x = [math.log(w0)]
            for e, _ in prob.struct_sizes:
                x += [c0] if e == "viscous_damping" else list(model.structural_start(e, _nonzero_start(e)))
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
        n_free = n - (0 if harmonic_order(e) else len(model.fitted_orientations(e)))
        for q in range(n_free):
            # the simulator's domain (damping >= 0, anisotropy < 1); the plausibility bounds are
            # checked later; an orientation (after the coefficients) is free
            lower[j + q] = 0.0 if e == "viscous_damping" else -0.95
            upper[j + q] = 2.0 if e == "viscous_damping" else 0.95
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
                                diff_step=1e-6, max_nfev=max_iterations)
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
    best = solve(prob, starts, keep=2 if prob.n_extra and chosen == "transient" else (1 if new_angles > 1 else None))
    if method == "auto" and table.t is not None and chosen == "transient" and start is None and prob.orders == (1,):
        # keep the quasi-steady model only where it is as good as the transient one
        Bt = prob.basis_vectors(best.x, "transient")
        Bq = prob.basis_vectors(best.x, "quasi-steady")
        sol, _ = prob.solve_linear(Bt)
        pt, pq = _predict(prob, Bt, sol), _predict(prob, Bq, sol)
        if np.nanmax(np.abs(pt - pq)) <= QUASI_STEADY_TOL * np.nanmax(np.abs(pt)):
            prob.method = "quasi-steady"
    return _finish(prob, best.x, best.success)


def _structural_name(model: SynchronousModel, effect: str, q: int) -> str:
    """``effect[q]`` for a coefficient (what the Wald tests read), ``effect.NAME`` for a
    fitted orientation (undefined where the effect is absent: not tested)."""
    n_coef = model.n_structural(effect) - (0 if harmonic_order(effect) else len(model.fitted_orientations(effect)))
    if q < n_coef:
        return f"{effect}[{q}]"
    p = get_effect(effect).argument_parameters[model.fitted_orientations(effect)[q - n_coef]]
    return f"{effect}.{p.name}"


def _typical_size(effect: str) -> float:
    """A size at which a new effect's orientation starts are ranked: its declared default's
    coefficients, their largest magnitude."""
    eff = get_effect(effect)
    c = np.asarray(eff.to_coefficients({p.name: p.default for p in eff.parameters}), dtype=float)
    return float(np.abs(c).max()) if c.size and np.abs(c).max() > 0 else 1e-2


def _nonzero_start(effect: str) -> float:
    return 1e-3 if effect != "viscous_damping" else 0.05


def _predict(prob: _Problem, B: np.ndarray, sol: np.ndarray) -> np.ndarray:
    B = prob.expand(B)
    n_f = prob.n_forcing
    pred = np.einsum("rpn,n->rp", B[..., :n_f], sol[:n_f]) if n_f else np.zeros(B.shape[:2], dtype=complex)
    for j in range(B.shape[2] - n_f):
        pred = pred + B[..., n_f + j] * (sol[n_f + 2 * j] + 1j * sol[n_f + 2 * j + 1])
    return pred


def extra_mode_vectors(fit: VectorFit) -> np.ndarray | None:
    """The added modes' share (:data:`SECOND_MODE`) of ``fit.predicted`` (rows, probes *
    orders): the response of another mode of the rotor and its supports, which the rotor
    model does not hold; ``None`` where the fit has none."""
    if not fit.extra_modes:
        return None
    prob = _Problem(fit.model, fit.table, fit.method, orders=fit.orders)
    n_x = 1 + sum(n for _, n in prob.struct_sizes) + 2 * prob.n_extra
    x, sol = fit.params[:n_x], fit.params[n_x:]
    B = prob.expand(prob.basis_vectors(x))
    n_b = len(prob.basis)
    # each probe's own copy of the forcing columns where the table has no probe angles
    cols = [c * n_b + j for c in range(prob.n_forcing // max(n_b, 1)) for j, (e, _) in enumerate(prob.basis)
            if e == SECOND_MODE]
    return np.einsum("rpn,n->rp", B[..., cols], sol[cols])


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
    names = ["log_w_ref"] + [_structural_name(prob.model, e, q) for e, n in prob.struct_sizes for q in range(n)]
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
