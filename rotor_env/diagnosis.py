"""Diagnosis: compare a model with measurements, find where it fails and what is missing.

Workflow (PHYSICS.md section 7)::

    result = diagnose(meas, model=["unbalance", "viscous_damping"], ip=0.3)
    print(result.summary())            # what is missing, before/after numbers
    result.plot_compare()              # measured vs model response against speed
    result.report("report.html")       # everything, self-contained

**Compare.**  A model is fitted to the *equation error* (batch least squares on the
regression of :mod:`rotor_env.regression`, both equations stacked) and judged by
(a) the residual RMS and R² of that regression and (b) the *output error* of a
free-run simulation of the identified model, driven by the measured spin profile
from the measured initial state: NRMSE fit % of ``theta_x``, ``theta_y`` (MATLAB's
``compare``: ``100 (1 - |y - y_hat| / |y - mean(y)|)``), overall and per speed band.

**Informative window.**  While the disk sticks to the shaft (dry friction, low
speed) or the rotor barely moves, the data carry no information on the dynamics and
bias the damping terms.  The analysis uses the samples from the first time the
amplitude ``|theta|`` exceeds ``window_fraction`` (default 10 %) of its peak.

**Which effect is missing.**  Every candidate effect not in the model is ranked by
the partial F of *adding* it (the restricted model is the current one, so a
candidate such as ``stiffness`` that replaces a known coefficient is tested the same
way).  Forward selection adds the best candidate while both hold:

1. *significant*: ``p < alpha / n`` with ``n`` the number of candidates in that round
   (Bonferroni), and
2. *practically relevant*: the free-run fit improves by at least ``min_fit_gain``
   percentage points (default 2), or the equation-error energy falls by at least
   ``min_energy_drop`` (default 5 %) while the free-run fit does not get worse by
   ``min_fit_gain`` or more.

Rule 2 keeps data that only approximately follow the model (another simulator, a
rig) from raising false alarms on tiny, statistically significant improvements,
while a real effect moves the free-run fit by far more (PHYSICS.md: the equation
error may move by a few % only, the output error plainly).

**Onset.**  For every effect added, a change-point scan splits its coefficient at
time ``t_c`` (before/after) over a grid and takes the ``t_c`` of least residual
energy; the effect is reported as appearing at ``t_c`` when the split is
significant (Bonferroni over the grid) and removes at least 5 % of the energy.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from identifier import RecursiveQR, partial_f

from .effects import EFFECTS, PHYSICAL_EFFECTS, Effect, Parameter, get_effect, register_effect
from .measurements import Measurements
from .outputs import atomic_write, atomic_write_text, check_writable
from .params import RotorParams
from .regression import RegressionSpec, regression_arrays
from .simulator import SimulationError, free_run

__all__ = [
    "DEFAULT_MODEL",
    "Comparison",
    "Diagnosis",
    "Model",
    "diagnose",
    "fit",
    "load_user_effect",
]

DEFAULT_MODEL: tuple[str, ...] = ("unbalance", "viscous_damping")
#: candidates by default: every physical library effect (the paper's in-phase unbalance is a
#: preset variant of ``unbalance``, not a separate candidate)
LIBRARY_CANDIDATES: tuple[str, ...] = (
    "unbalance",
    "viscous_damping",
    "asymmetry",
    "nonlinear_stiffness",
    "structural_damping",
    "stiffness",
    "static_load",
)


# ------------------------------------------------------------------ the model
@dataclass(frozen=True)
class Model:
    """An ordered set of effects; ``model.add("asymmetry")`` gives a new model."""

    effects: tuple[str, ...] = DEFAULT_MODEL

    def __post_init__(self) -> None:
        effects = (self.effects,) if isinstance(self.effects, str) else tuple(self.effects)
        for e in effects:
            get_effect(e)
        if len(set(effects)) != len(effects):
            raise ValueError(f"effect listed twice in the model: {effects}")
        object.__setattr__(self, "effects", effects)

    def add(self, *names: str) -> Model:
        return Model(self.effects + tuple(n for n in names if n not in self.effects))

    def remove(self, *names: str) -> Model:
        return Model(tuple(e for e in self.effects if e not in names))

    def __contains__(self, name: str) -> bool:
        return name in self.effects

    def __iter__(self):
        return iter(self.effects)

    def __len__(self) -> int:
        return len(self.effects)


def _as_model(model) -> Model:
    if model is None:
        return Model()
    if isinstance(model, Model):
        return model
    if isinstance(model, str):
        return Model(tuple(m.strip() for m in model.split(",") if m.strip()))
    return Model(tuple(model))


# ------------------------------------------------------------------ user effects
def effect_from_function(fn: Callable, name: str | None = None) -> Effect:
    """Wrap a column function ``(phi, phid, phidd, th_x, th_y, w_x, w_y, ip) -> (cols_y, cols_x)``.

    The function may also return a single array (or tuple of arrays) for the first
    equation only; the second equation's column is then taken as zero.
    """
    name = name or fn.__name__
    probe = np.random.default_rng(0).normal(size=(7, 5)) * 0.1  # phi .. w_y; ip follows
    try:
        out = fn(*probe, 0.3)
    except Exception as exc:
        raise ValueError(f"user effect {name!r}: calling it on test inputs failed: {exc}") from exc
    cols_y, cols_x = _split_user_output(name, out)
    n = len(cols_y)
    coefs = tuple(f"{name}_{j + 1}" if n > 1 else name for j in range(n))

    if isinstance(out, tuple) and len(out) == 2 and isinstance(out[0], tuple):
        columns = fn
    else:  # first equation only: wrap into the two-equation form

        def columns(phi, phid, phidd, th_x, th_y, w_x, w_y, ip, _fn=fn):
            c = _fn(phi, phid, phidd, th_x, th_y, w_x, w_y, ip)
            return (c,), (0.0 * c,)

    def to_coef(p):
        return tuple(float(p[c]) for c in coefs)

    def from_coef(c):
        return {k: float(v) for k, v in zip(coefs, c, strict=True)}

    return Effect(
        name=name,
        parameters=tuple(Parameter(c, 0.0, f"user effect {name}") for c in coefs),
        coefficients=coefs,
        columns=columns,
        to_coefficients=to_coef,
        from_coefficients=from_coef,
        moment=f"user-defined: {name}",
        cause=(fn.__doc__ or "user-defined effect").strip().splitlines()[0],
        signature="user-defined",
    )


def _split_user_output(name: str, out):
    if isinstance(out, tuple) and len(out) == 2 and isinstance(out[0], tuple):
        cy, cx = out
        if len(cy) != len(cx) or not cy:
            raise ValueError(f"user effect {name!r}: cols_y and cols_x must have the same, non-zero length")
        return cy, cx
    arr = np.asarray(out, dtype=float)
    if arr.ndim != 1:
        raise ValueError(
            f"user effect {name!r} must return one column (an array like its inputs) or "
            f"((cols_y...), (cols_x...)); got shape {arr.shape}"
        )
    return (arr,), (0.0 * arr,)


def load_user_effect(spec: str) -> Effect:
    """``module:attr`` (or ``path/to/file.py:attr``) -> a registered :class:`Effect`."""
    import importlib
    import importlib.util

    if ":" not in spec:
        raise ValueError(f"--effect wants MODULE:NAME (e.g. my_effects:cubic_stiffness), got {spec!r}")
    mod_name, attr = spec.rsplit(":", 1)
    try:
        if mod_name.endswith(".py"):
            path = Path(mod_name)
            if not path.exists():
                raise ValueError(f"--effect {spec}: no such file {path}")
            loader_spec = importlib.util.spec_from_file_location(path.stem, path)
            module = importlib.util.module_from_spec(loader_spec)
            loader_spec.loader.exec_module(module)
        else:
            module = importlib.import_module(mod_name)
    except ImportError as exc:
        raise ValueError(f"--effect {spec}: cannot import {mod_name!r} ({exc})") from None
    obj = getattr(module, attr, None)
    if obj is None:
        raise ValueError(f"--effect {spec}: module {mod_name!r} has no attribute {attr!r}")
    effect = obj if isinstance(obj, Effect) else effect_from_function(obj, attr)
    return register_effect(effect, replace=True)


def _validate_columns(eff: Effect, data: np.ndarray, ip: float) -> None:
    args = (data[:, 1], data[:, 2], data[:, 3], data[:, 4], data[:, 5], data[:, 6], data[:, 7], ip)
    try:
        Xy, Xx = eff.regressors(*args)
    except Exception as exc:
        raise ValueError(f"effect {eff.name!r}: computing its columns failed: {exc}") from exc
    for X, eq in ((Xy, "first"), (Xx, "second")):
        if X.shape != (len(data), len(eff.coefficients)):
            raise ValueError(
                f"effect {eff.name!r}: columns for the {eq} equation have shape {X.shape}, "
                f"expected ({len(data)}, {len(eff.coefficients)})"
            )
        bad = ~np.isfinite(X)
        if bad.any():
            r, c = np.argwhere(bad)[0]
            raise ValueError(
                f"effect {eff.name!r}: column {eff.coefficients[c]!r} ({eq} equation) is not finite "
                f"at sample {r} (t = {data[r, 0]:g}): {X[r, c]!r}"
            )


# ------------------------------------------------------------------ comparison
@dataclass
class Comparison:
    """A model fitted to measurements and compared with them."""

    model: tuple[str, ...]
    columns: tuple[str, ...]
    coefficients: np.ndarray
    standard_errors: np.ndarray
    physical: dict[str, float]
    energy: float              # equation-error residual energy J
    rms: float                 # equation-error residual RMS
    r2: float
    n_rows: int
    n_params: int
    fit_x: float
    fit_y: float
    fit_bands: list[dict]
    significance: dict[str, dict]
    residual: np.ndarray = field(repr=False)
    onsets: dict[str, float] = field(default_factory=dict)
    splits: tuple[str, ...] = ()           # effects with onsets whose value changes (not appears)
    physical_before: dict[str, float] = field(default_factory=dict)  # their values before
    simulated: Measurements | None = field(repr=False, default=None)
    diverged: bool = False

    @property
    def fit_percent(self) -> float:
        return 0.5 * (self.fit_x + self.fit_y)

    def coefficient_dict(self) -> dict[str, float]:
        return {c: float(v) for c, v in zip(self.columns, self.coefficients, strict=True)}


def _fit_percent(meas: np.ndarray, model: np.ndarray) -> float:
    den = np.linalg.norm(meas - meas.mean())
    if den == 0:
        return 0.0
    return float(max(-100.0, 100.0 * (1.0 - np.linalg.norm(meas - model) / den)))


def _model_params(
    model: Sequence[str], physical: dict[str, float], ip: float, known: dict, absent: Iterable[str] = ()
) -> RotorParams:
    """A simulatable rotor from identified physical parameters (absent effects = 0).

    Every physical effect is in the rotor (those not in the model with their known
    values, else 0 — the stiffness scale 1); the paper's ``unbalance_in_phase``
    replaces ``unbalance`` when the model uses it (they share ``tau``).
    """
    base = tuple(e for e in PHYSICAL_EFFECTS if not (e == "unbalance" and "unbalance_in_phase" in model))
    effects = tuple(dict.fromkeys((*base, *model)))
    values: dict[str, float] = {}
    for e in effects:
        for p in EFFECTS[e].parameters:
            if e in absent:
                v = 0.0
            elif e in model:
                v = physical.get(p.name, 0.0)
            elif e in known:
                v = known[e][p.name]
            else:
                v = 1.0 if p.name == "k" else 0.0
            # identified values outside physical bounds (e.g. c < 0) are clipped to them
            values[p.name] = float(min(max(v, p.lower), p.upper))
    return RotorParams(ip=ip, values=values, effects=effects)


def _bands(speed: np.ndarray, n: int = 6) -> list[tuple[float, float]]:
    lo, hi = float(speed.min()), float(speed.max())
    if hi <= lo:
        return [(lo, hi)]
    edges = np.linspace(lo, hi, n + 1)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


class _Data:
    """Measurements restricted to the informative window, with regression caches."""

    def __init__(self, meas: Measurements, ip: float, equation: str, window_fraction: float, t_start: float | None):
        self.full = meas
        amp = np.hypot(meas.theta_x, meas.theta_y)
        if t_start is None:
            peak = float(amp.max())
            k0 = int(np.argmax(amp > window_fraction * peak)) if peak > 0 else 0
            t_start = float(meas.t[k0])
        self.t_start = t_start
        self.meas = meas.slice_time(t_start, None)
        if len(self.meas) < 20:
            raise ValueError(f"only {len(self.meas)} samples after t = {t_start:g}: too few to diagnose")
        self.ip = ip
        self.equation = equation
        self.data = np.ascontiguousarray(self.meas.data)


def _design(data: _Data, model: Sequence[str], known: dict, onsets: dict[str, float],
            splits: Iterable[str] = ()):
    """``spec, X, y, t_rows, columns, groups`` of a model.

    An effect with an onset is zero before it (it *appears*); if it is also in
    ``splits`` it has its own coefficients before the onset (its value *changes*, a
    crack that grows), in extra columns named ``<coefficient>_before``.
    """
    spec = RegressionSpec(effects=tuple(model), equation=data.equation, known=known or {})
    X, y = regression_arrays(spec, data.data, data.ip)
    t_rows = np.repeat(data.meas.t, spec.rows_per_sample)
    columns, groups, extra = list(spec.columns), dict(spec.groups), []
    for e, tc in onsets.items():
        cols = [spec.columns.index(c) for c in spec.groups[e]]
        before = t_rows < tc
        if e in splits:
            extra.append(X[:, cols] * before[:, None])
            names = tuple(f"{c}_before" for c in spec.groups[e])
            columns += names
            groups[f"{e}_before"] = names
        X[np.ix_(before, cols)] = 0.0
    if extra:
        X = np.hstack([X, *extra])
    return spec, X, y, t_rows, tuple(columns), groups


def compare(
    data: _Data,
    model: Sequence[str],
    known: dict | None = None,
    onsets: dict[str, float] | None = None,
    splits: Iterable[str] = (),
    *,
    simulate: bool = True,
) -> Comparison:
    """Fit ``model`` (equation error) and, with ``simulate``, run it free (output error)."""
    onsets = dict(onsets or {})
    splits = tuple(e for e in splits if e in onsets)
    spec, X, y, _, columns, groups = _design(data, model, known or {}, onsets, splits)
    est = RecursiveQR(columns=columns, groups=groups).fit(X, y)
    coef = est.coefficients()
    resid = y - X @ coef
    J = float(resid @ resid)
    tss = float(np.sum((y - y.mean()) ** 2))
    n = spec.n_columns
    physical = spec.physical(coef[:n])
    physical_before: dict[str, float] = {}
    if splits:
        theta_b = coef[:n].copy()
        for e in splits:
            for c in spec.groups[e]:
                theta_b[spec.columns.index(c)] = coef[columns.index(f"{c}_before")]
        pb = spec.physical(theta_b)
        physical_before = {p.name: pb[p.name] for e in splits for p in EFFECTS[e].parameters}
    sig = est.effect_tests().to_dict()
    comp = Comparison(
        model=tuple(model), columns=columns, coefficients=coef, standard_errors=est.standard_errors(),
        physical=physical, energy=J, rms=math.sqrt(J / len(y)), r2=1.0 - J / tss if tss > 0 else 0.0,
        n_rows=len(y), n_params=int(est.identifiable().sum()), fit_x=float("nan"), fit_y=float("nan"),
        fit_bands=[], significance=sig, residual=resid, onsets=onsets, splits=splits,
        physical_before=physical_before,
    )
    if simulate:
        _free_run(comp, data, spec.known)
    return comp


def _free_run(comp: Comparison, data: _Data, known: dict) -> None:
    """Output-error simulation, split where an effect appears (it is absent before)."""
    m = data.meas
    cuts = sorted({tc for tc in comp.onsets.values() if m.t[0] < tc < m.t[-1]})
    bounds = [0, *(int(np.searchsorted(m.t, tc)) for tc in cuts), len(m) - 1]
    state = (m.theta_x[0], m.theta_y[0], m.theta_x_dot[0], m.theta_y_dot[0])
    pieces = []
    try:
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if b <= a:
                continue
            pending = {e for e, tc in comp.onsets.items() if tc > m.t[a]}
            # before its onset an effect is absent, or has its own values if it changes
            physical = {**comp.physical, **{k: v for k, v in comp.physical_before.items()}} \
                if pending & set(comp.splits) else comp.physical
            params = _model_params(comp.model, physical, data.ip, known, pending - set(comp.splits))
            seg = free_run(params, m.t[a : b + 1], m.phi[a : b + 1], m.phi_dot[a : b + 1], state)
            pieces.append(seg.data if not pieces else seg.data[1:])
            state = tuple(seg.data[-1, 4:8])
    except SimulationError:
        comp.diverged = True
        comp.fit_x = comp.fit_y = -100.0
        return
    sim = Measurements(np.vstack(pieces))
    comp.simulated = sim
    comp.fit_x = _fit_percent(m.theta_x, sim.theta_x)
    comp.fit_y = _fit_percent(m.theta_y, sim.theta_y)
    bands = []
    for lo, hi in _bands(m.phi_dot):
        sel = (m.phi_dot >= lo) & (m.phi_dot <= hi)
        if sel.sum() < 10:
            continue
        fx = _fit_percent(m.theta_x[sel], sim.theta_x[sel])
        fy = _fit_percent(m.theta_y[sel], sim.theta_y[sel])
        bands.append({"speed_min": lo, "speed_max": hi, "fit_percent": 0.5 * (fx + fy)})
    comp.fit_bands = bands


# ------------------------------------------------------------------ where it fails
def complex_rows(values: np.ndarray, equation: str) -> np.ndarray:
    """Per-sample complex signal ``eq1 + i eq2`` (``theta_y + i theta_x`` convention).

    In this coordinate the unbalance is ``e^{+i phi}``: positive rotation orders are
    forward whirl.  With one equation only, the real signal is returned.
    """
    if equation == "both":
        return values[0::2] + 1j * values[1::2]
    return values.astype(complex)


def order_map(
    t: np.ndarray, phi: np.ndarray, speed: np.ndarray, signal: np.ndarray,
    revolutions: int = 8, max_order: float = 4.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Amplitude spectrum in rotation orders over windows of ``revolutions`` turns.

    Returns ``(speeds, orders, amplitude)`` with ``amplitude[window, order]``.  The
    signal is resampled on a uniform spin-angle grid (order tracking), so a component
    at ``k`` times the spin frequency stays in bin ``k`` while the speed changes.

    Orders count with the direction of rotation: for a rotor turning backwards
    (``phi`` decreasing) the angle is ``-phi`` and the signal is conjugated, so the
    unbalance is order +1 either way.  The angle must progress overall; brief
    reversals (encoder noise, a stall) are held at the angle already reached, because
    the resampling needs a monotone angle.
    """
    phi = np.asarray(phi, dtype=float)
    signal = np.asarray(signal)
    if phi.size and phi[-1] < phi[0]:  # turning backwards: count angle and orders with the rotation
        phi, signal = -phi, np.conj(signal)
    phi = np.maximum.accumulate(phi) if phi.size else phi
    span = 2 * np.pi * revolutions
    n_per = 64 * revolutions
    starts = np.arange(phi[0], phi[-1] - span, span / 2) if phi.size else np.empty(0)
    speeds, rows = [], []
    freqs = np.fft.fftfreq(n_per, d=1.0 / (64))  # cycles per revolution
    keep = np.abs(freqs) <= max_order
    order = np.argsort(freqs[keep])
    for s in starts:
        grid = s + np.arange(n_per) * (span / n_per)
        re = np.interp(grid, phi, signal.real)
        im = np.interp(grid, phi, signal.imag)
        z = (re + 1j * im) * np.hanning(n_per)
        spec = np.abs(np.fft.fft(z)) / (n_per / 2)
        rows.append(spec[keep][order])
        speeds.append(float(np.interp(s + span / 2, phi, speed)))
    if not rows:
        return np.empty(0), freqs[keep][order], np.empty((0, int(keep.sum())))
    return np.array(speeds), freqs[keep][order], np.array(rows)


def autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    x = x - x.mean()
    n = len(x)
    f = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[: max_lag + 1]
    return ac / ac[0] if ac[0] > 0 else ac


def noise_floor(r: np.ndarray) -> float:
    """Robust white-noise level of a residual: from the MAD of its first differences."""
    d = np.diff(r)
    return float(np.median(np.abs(d - np.median(d))) / 0.6745 / math.sqrt(2.0))


def failing_windows(t: np.ndarray, r: np.ndarray, width: float = 2.0, factor: float = 2.0) -> tuple[list[dict], float]:
    """Time windows where the rolling RMS of ``r`` exceeds ``factor`` x the noise floor."""
    floor = noise_floor(r)
    dt = float(np.median(np.diff(t)))
    n = max(3, round(width / dt))
    kernel = np.ones(n) / n
    rms = np.sqrt(np.convolve(r * r, kernel, mode="same"))
    above = rms > factor * max(floor, 1e-300)
    out = []
    k = 0
    while k < len(above):
        if above[k]:
            j = k
            while j + 1 < len(above) and above[j + 1]:
                j += 1
            out.append({"t_start": float(t[k]), "t_end": float(t[j]),
                        "peak_rms_over_floor": float(rms[k : j + 1].max() / max(floor, 1e-300))})
            k = j + 1
        else:
            k += 1
    return out, floor


# ------------------------------------------------------------------ candidates
@dataclass
class Candidate:
    effect: str
    F: float
    log10_p: float
    rms_after: float
    fit_percent_after: float
    energy_drop: float           # fraction of the equation-error energy removed
    fit_gain: float              # free-run fit % gained
    significant: bool
    relevant: bool
    correlation: float           # multiple correlation of the residual with its columns
    order_overlap: float         # cosine similarity of order spectra (residual vs columns)
    onset: float | None          # the effect appears at this time (None: present throughout)
    story: str
    comparison: Comparison = field(repr=False)

    def to_dict(self) -> dict:
        return {
            "effect": self.effect, "F": self.F, "log10_p": self.log10_p, "rms_after": self.rms_after,
            "fit_percent_after": self.fit_percent_after, "energy_drop": self.energy_drop,
            "fit_gain": self.fit_gain, "significant": self.significant, "relevant": self.relevant,
            "correlation": self.correlation, "order_overlap": self.order_overlap, "onset": self.onset,
            "declared_orders": list(EFFECTS[self.effect].orders), "story": self.story,
        }


def _order_profile(data: _Data, values: np.ndarray) -> np.ndarray:
    m = data.meas
    z = complex_rows(values, data.equation)
    _, _, amp = order_map(m.t, m.phi, m.phi_dot, z)
    return amp.mean(axis=0) if amp.size else np.zeros(1)


GRID = 160  # change-point candidates per scan (the Bonferroni factor of the scan)
#: an onset or change must remove at least this share of the energy the effect explains
ONSET_SHARE = 0.01


def _scan(A: np.ndarray, t_rows: np.ndarray, t_grid: np.ndarray, zero_pre, zero_suf) -> np.ndarray:
    """Residual energy of ``A = [X y]`` with columns ``zero_pre`` absent before each
    ``t_c`` and ``zero_suf`` absent after it, for every ``t_c`` in ``t_grid``.

    One forward and one backward recursive-QR pass give the factors of every prefix
    and suffix; zeroing columns of a factor zeroes them in its rows; stacking the two
    factors and re-triangularising gives the split model's energy (O(n^3) per t_c).
    """
    cuts = np.searchsorted(t_rows, t_grid)
    n = A.shape[1] - 1
    pre, fwd, last = [], RecursiveQR(n), 0
    for c in cuts:
        fwd.update_many(A[last:c, :-1], A[last:c, -1])
        pre.append(fwd.R.copy())
        last = c
    suf, bwd, last = [None] * len(cuts), RecursiveQR(n), len(A)
    for i in range(len(cuts) - 1, -1, -1):
        bwd.update_many(A[cuts[i] : last, :-1], A[cuts[i] : last, -1])
        suf[i] = bwd.R.copy()
        last = cuts[i]
    J = np.empty(len(cuts))
    for i in range(len(cuts)):
        top, bot = pre[i].copy(), suf[i].copy()
        top[:, list(zero_pre)] = 0.0
        bot[:, list(zero_suf)] = 0.0
        # drop columns that are zero on both sides (not identifiable anywhere)
        J[i] = np.linalg.qr(np.vstack([top, bot]), mode="r")[-1, -1] ** 2
    return J


def _grid(data: _Data) -> np.ndarray:
    t = data.meas.t
    return np.linspace(t[0], t[-1], GRID + 2)[1:-1]


def _appear_scan(data: _Data, base: Comparison, name: str, known: dict) -> tuple[float, float]:
    """Best onset ``t_c`` for ``name`` appearing mid-run, and the energy with it."""
    spec, X, y, t_rows, _, _ = _design(data, (*base.model, name), known, base.onsets, base.splits)
    cols = [spec.columns.index(c) for c in spec.groups[name]]
    t_grid = _grid(data)
    J = _scan(np.column_stack([X, y]), t_rows, t_grid, cols, [])
    k = int(np.argmin(J))
    return float(t_grid[k]), float(J[k])


def _rank(data: _Data, base: Comparison, candidates: Sequence[str], known: dict, alpha: float,
          min_fit_gain: float, min_energy_drop: float) -> list[Candidate]:
    out = []
    n_cand = max(1, len(candidates))
    res_profile = _order_profile(data, base.residual)
    for name in candidates:
        kn = {k: v for k, v in known.items() if k != name}
        comp = compare(data, (*base.model, name), kn, base.onsets, base.splits)
        q = comp.n_params - base.n_params
        dof = comp.n_rows - comp.n_params
        F, _, lp, _ = partial_f(base.energy, comp.energy, q, dof)
        F, lp, onset = float(F), float(lp), None
        # the same effect appearing mid-run (a crack): scan its onset, pay for the scan
        if q > 0:
            tc, J_app = _appear_scan(data, base, name, kn)
            Fa, _, lpa, _ = partial_f(base.energy, J_app, q, dof)
            lpa = min(0.0, float(lpa) + math.log10(GRID))
            gain = comp.energy - J_app
            # the onset must matter twice: against what is left, and against what the
            # effect explains (on noise-free data what is left is rounding, see _change_time)
            if (lpa < lp and comp.energy > 0 and gain >= min_energy_drop * comp.energy
                    and gain >= ONSET_SHARE * (base.energy - comp.energy)):
                onset = tc
                F, lp = float(Fa), lpa
                comp = compare(data, (*base.model, name), kn, {**base.onsets, name: tc}, base.splits)
        # evidence: correlation of the residual with the candidate's columns, and order overlap
        spec = RegressionSpec(effects=(name,), equation=data.equation, known={})
        Xc, _ = regression_arrays(spec, data.data, data.ip)
        if onset is not None:
            Xc[np.repeat(data.meas.t, spec.rows_per_sample) < onset] = 0.0
        est = RecursiveQR(Xc.shape[1]).fit(Xc, base.residual)
        rr = base.residual @ base.residual
        corr = math.sqrt(max(0.0, 1.0 - est.residual_energies()[-1] / rr)) if rr > 0 else 0.0
        prof = _order_profile(data, Xc @ np.ones(Xc.shape[1]))
        overlap = float(prof @ res_profile / (np.linalg.norm(prof) * np.linalg.norm(res_profile) + 1e-300))
        drop = (base.energy - comp.energy) / base.energy if base.energy > 0 else 0.0
        gain = comp.fit_percent - base.fit_percent
        eff = EFFECTS[name]
        out.append(Candidate(
            effect=name, F=F, log10_p=lp, rms_after=comp.rms, fit_percent_after=comp.fit_percent,
            energy_drop=float(drop), fit_gain=float(gain),
            significant=bool(q > 0 and lp < math.log10(alpha / n_cand)),
            # an equation-error gain that makes the output error clearly worse explains the
            # residual with the wrong physics (e.g. quadratic stiffness for a side load)
            relevant=bool(gain >= min_fit_gain or (drop >= min_energy_drop and gain > -min_fit_gain)),
            correlation=float(corr), order_overlap=overlap, onset=onset,
            story=f"{eff.cause}. Signature: {eff.signature}.", comparison=comp,
        ))
    out.sort(key=lambda c: (c.log10_p, -c.F))
    return out


def _appears_or_changes(data: _Data, comp: Comparison, effect: str, alpha: float,
                        min_energy_drop: float) -> Comparison:
    """An effect found appearing at ``t_c``: was it there before with another value?

    The split model (own coefficients before ``t_c``) replaces the appearing one when
    the extra coefficients are significant and remove at least ``min_energy_drop`` of
    the energy left (a crack that *grows*, D 0.03 -> 0.08, rather than one that opens).
    """
    split = compare(data, comp.model, _known(comp.model), comp.onsets, (*comp.splits, effect))
    q = split.n_params - comp.n_params
    if q <= 0:
        return comp
    _, _, lp, _ = partial_f(comp.energy, split.energy, q, split.n_rows - split.n_params)
    if float(lp) < math.log10(alpha) and comp.energy - split.energy >= min_energy_drop * comp.energy:
        return split
    return comp


def _change_time(data: _Data, comp: Comparison, effect: str, known: dict, alpha: float,
                 min_energy_drop: float) -> float | None:
    """When an effect in the model changes mid-run: split its coefficient at ``t_c``."""
    spec, X, y, t_rows, _, _ = _design(data, comp.model, known, comp.onsets, comp.splits)
    cols = [spec.columns.index(c) for c in spec.groups[effect]]
    n = X.shape[1]
    A = np.column_stack([X, X[:, cols], y])  # the effect's columns twice: before | after
    after = list(range(n, n + len(cols)))
    t_grid = _grid(data)
    J = _scan(A, t_rows, t_grid, after, cols)
    k = int(np.argmin(J))
    q = len(cols)
    dof = len(y) - comp.n_params - q
    _, _, lp, _ = partial_f(comp.energy, J[k], q, dof)
    drop = comp.energy - J[k]
    # energy the effect explains in the model: from its test (F of removing it, tested last)
    sig = comp.significance.get(effect, {})
    explained = sig.get("F", 0.0) * q * comp.energy / max(len(y) - comp.n_params, 1)
    # a change must matter against what is left AND against the effect itself: on
    # noise-free data what is left is integration error, and splitting any coefficient
    # "removes" a large share of it while changing the value by 1e-5
    if (float(lp) + math.log10(GRID) < math.log10(alpha) and drop >= min_energy_drop * comp.energy
            and drop >= ONSET_SHARE * explained):
        return float(t_grid[k])
    return None


# ------------------------------------------------------------------ the result
@dataclass
class Diagnosis:
    """Result of :func:`diagnose`: before/after comparisons, ranking, where it fails."""

    source: str | None
    ip: float
    alpha: float
    equation: str
    t_start: float
    start_model: tuple[str, ...]
    model: tuple[str, ...]
    missing: list[str]
    onset: dict[str, float | None]
    rounds: list[list[Candidate]]
    before: Comparison
    after: Comparison
    windows: list[dict]
    noise_floor: float
    data: _Data = field(repr=False)
    steps: list[Comparison] = field(default_factory=list, repr=False)  # after each addition

    @property
    def candidates(self) -> list[Candidate]:
        return self.rounds[0] if self.rounds else []

    def add(self, *names: str) -> Comparison:
        """The final model with more effects, compared (one call to add an effect)."""
        model = Model(self.model).add(*names).effects
        return compare(self.data, model, _known(model), self.after.onsets, self.after.splits)

    # -------------------------------------------------------------- text/JSON
    def to_dict(self) -> dict:
        return {
            "source": self.source,
            "ip": self.ip,
            "alpha": self.alpha,
            "t_start": self.t_start,
            "start_model": list(self.start_model),
            "model": list(self.model),
            "missing": list(self.missing),
            "onset": dict(self.onset),
            "candidates": [c.to_dict() for c in self.candidates],
            "rounds": [[c.to_dict() for c in r] for r in self.rounds],
            "rms_before": self.before.rms,
            "rms_after": self.after.rms,
            "r2_before": self.before.r2,
            "r2_after": self.after.r2,
            "fit_percent_before": self.before.fit_percent,
            "fit_percent_after": self.after.fit_percent,
            "fit_bands_before": self.before.fit_bands,
            "fit_bands_after": self.after.fit_bands,
            "coefficients": self.after.coefficient_dict(),
            "standard_errors": dict(zip(self.after.columns, map(float, self.after.standard_errors), strict=True)),
            "physical": self.after.physical,
            "changed": list(self.after.splits),
            "physical_before": self.after.physical_before,
            "significance": self.after.significance,
            "failing_windows": self.windows,
            "noise_floor": self.noise_floor,
        }

    def to_json(self, **kwargs) -> str:
        return json.dumps(_jsonable(self.to_dict()), **kwargs)

    def summary(self) -> str:
        b, a = self.before, self.after
        lines = [
            f"rotor-id diagnosis of {self.source or 'measurements'} (ip = {self.ip:g}, alpha = {self.alpha:g})",
            f"informative window: t >= {self.t_start:g} ({len(self.data.meas)} samples)",
            f"starting model: {', '.join(self.start_model)}",
            f"  equation error RMS {b.rms:.4g}, R^2 {b.r2:.4f}; free-run fit {b.fit_percent:.1f} %",
            f"  residual above the noise floor ({self.noise_floor:.3g}) in {len(self.windows)} window(s)"
            + (": " + ", ".join(f"{w['t_start']:.0f}–{w['t_end']:.0f}" for w in self.windows[:6]) if self.windows else ""),
            "",
            "candidates (partial F of adding each to the starting model):",
            f"  {'effect':<22}{'F':>12}{'log10 p':>11}{'RMS after':>11}{'fit % after':>12}  verdict",
        ]
        for c in self.candidates:
            verdict = "MISSING" if c.effect in self.missing else (
                "significant, not relevant" if c.significant else "not significant")
            lines.append(f"  {c.effect:<22}{c.F:12.4g}{c.log10_p:11.4g}{c.rms_after:11.4g}{c.fit_percent_after:12.1f}  {verdict}")
        lines.append("")
        if self.missing:
            lines.append("missing effects, in the order added:")
            for e in self.missing:
                on = self.onset.get(e)
                if e in self.after.splits:
                    change = ", ".join(
                        f"{k} {self.after.physical_before[k]:.4g} -> {self.after.physical[k]:.4g}"
                        for k in self.after.physical_before if k in EFFECTS[e].parameter_names)
                    note = f"  (changes at t ≈ {on:.0f}: {change})"
                else:
                    note = f"  (appears at t ≈ {on:.0f})" if on is not None else "  (present throughout)"
                lines.append(f"  + {e}{note}")
                lines.append(f"      {EFFECTS[e].cause}")
        else:
            lines.append("no missing effect: the model explains the data (to the practical-relevance rule)")
        lines += [
            "",
            f"final model: {', '.join(self.model)}",
            f"  equation error RMS {a.rms:.4g} (was {b.rms:.4g}), R^2 {a.r2:.4f} (was {b.r2:.4f})",
            f"  free-run fit {a.fit_percent:.1f} % (was {b.fit_percent:.1f} %)",
            "  coefficients:",
        ]
        for c, v, s in zip(a.columns, a.coefficients, a.standard_errors, strict=True):
            lines.append(f"    {c:<14}{v: .5g} ± {s:.2g}")
        return "\n".join(lines)

    # -------------------------------------------------------------- figures
    def _ax(self, ax, figsize=(8, 4)):
        """``(figure, axes)``: the caller's ``ax`` or a new figure (matplotlib picks the
        backend: Agg on a machine without a display)."""
        if ax is None:
            import matplotlib.pyplot as plt

            fig, ax = plt.subplots(figsize=figsize)
            return fig, ax
        return ax.figure, ax

    def plot_compare(self, ax=None, which: str = "after"):
        """Measured vs model amplitude |theta| against speed (free-run simulation)."""
        fig, ax = self._ax(ax)
        m = self.data.meas
        ax.plot(m.phi_dot, np.hypot(m.theta_x, m.theta_y), "k", lw=1.2, label="measured")
        for comp, style, label in ((self.before, "C3--", "starting model"), (self.after, "C0", "final model")):
            if which in ("after", "both") or comp is self.before:
                if comp.simulated is not None:
                    s = comp.simulated
                    ax.plot(s.phi_dot, np.hypot(s.theta_x, s.theta_y), style, lw=1,
                            label=f"{label}: {', '.join(comp.model)} (fit {comp.fit_percent:.0f} %)")
        ax.set_xlabel("spin speed (dimensionless)")
        ax.set_ylabel(r"amplitude $|\theta|$")
        ax.legend(fontsize=7)
        ax.set_title("measured vs model response (free run)")
        return fig

    def plot_residual(self, ax=None, which: str = "before"):
        """Equation-error residual against time (and speed on a top axis)."""
        fig, ax = self._ax(ax)
        comp = self.before if which == "before" else self.after
        t = np.repeat(self.data.meas.t, 2 if self.equation == "both" else 1)
        ax.plot(t, comp.residual, lw=0.3, color="C3" if which == "before" else "C0")
        for w in self.windows if which == "before" else []:
            ax.axvspan(w["t_start"], w["t_end"], color="orange", alpha=0.2)
        ax.set_xlabel("t")
        ax.set_ylabel("equation residual")
        ax.set_title(f"residual of the {which} model ({', '.join(comp.model)}); shaded: above noise floor")
        t_m, w_m = self.data.meas.t, self.data.meas.phi_dot
        if np.all(np.diff(w_m) > 0):  # a speed axis only where speed maps one-to-one onto time
            top = ax.secondary_xaxis(
                "top", functions=(lambda x: np.interp(x, t_m, w_m), lambda s: np.interp(s, w_m, t_m)))
            top.set_xlabel("speed")
        return fig

    def plot_order_map(self, ax=None, which: str = "before"):
        """Residual spectrum in rotation orders against speed, 0x/1x/2x marked."""
        fig, ax = self._ax(ax)
        comp = self.before if which == "before" else self.after
        m = self.data.meas
        speeds, orders, amp = order_map(m.t, m.phi, m.phi_dot, complex_rows(comp.residual, self.equation))
        if amp.size:
            mesh = ax.pcolormesh(orders, speeds, np.log10(amp + 1e-12), shading="nearest", cmap="viridis")
            fig.colorbar(mesh, ax=ax, label="log10 amplitude")
        for o in (-2, -1, 0, 1, 2):
            ax.axvline(o, color="w", lw=0.6, ls=":")
            ax.text(o, speeds.max() if amp.size else 1, f"{o}x", color="k", ha="center", va="bottom", fontsize=8)
        ax.set_xlabel("rotation order (+ forward, - backward)")
        ax.set_ylabel("speed")
        ax.set_title(f"order map of the {which}-model residual")
        return fig

    def plot_autocorrelation(self, ax=None, which: str = "before", max_lag: int = 400):
        """Residual autocorrelation with 95 % bounds for white noise."""
        fig, ax = self._ax(ax)
        comp = self.before if which == "before" else self.after
        r = _first_rows(comp.residual, self.equation)
        ac = autocorrelation(r, max_lag)
        dt = self.data.meas.dt
        lags = np.arange(len(ac)) * dt
        ax.plot(lags, ac, lw=1)
        b = 1.96 / math.sqrt(len(r))
        ax.axhspan(-b, b, color="grey", alpha=0.3, label="95 % bounds (white noise)")
        ax.set_xlabel("lag (time)")
        ax.set_ylabel("autocorrelation")
        ax.legend(fontsize=8)
        ax.set_title(f"residual autocorrelation ({which} model)")
        return fig

    def plot_candidates(self, ax=None):
        """The ranking: -log10 p of adding each candidate, with the Bonferroni line."""
        fig, ax = self._ax(ax)
        c = self.candidates
        names = [x.effect for x in c]
        vals = [max(-x.log10_p, 1e-3) for x in c]
        colors = ["C3" if x.effect in self.missing else "C7" for x in c]
        ax.barh(names, vals, color=colors)
        ax.set_xscale("log")
        ax.axvline(-math.log10(self.alpha / max(1, len(c))), color="k", ls="--", lw=1, label="alpha / n")
        ax.invert_yaxis()
        ax.set_xlabel(r"$-\log_{10} p$ of adding the effect")
        ax.legend(fontsize=8)
        ax.set_title("which effect is missing (red: added)")
        return fig

    def plot_before_after(self, ax=None):
        """Equation-error RMS and free-run fit % along the forward selection."""
        fig, ax = self._ax(ax)
        steps = [self.before, *self.steps]
        labels = ["start"] + [f"+ {e}" for e in self.missing]
        x = np.arange(len(steps))
        ax.bar(x - 0.2, [s.fit_percent for s in steps], 0.4, color="C0", label="free-run fit %")
        ax.set_ylabel("fit %")
        ax2 = ax.twinx()
        ax2.bar(x + 0.2, [s.rms for s in steps], 0.4, color="C3", label="equation RMS")
        ax2.set_ylabel("equation error RMS")
        ax.set_xticks(x, labels, rotation=15, fontsize=8)
        ax.set_title("before and after adding the missing effects")
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        ax2.legend(h1 + h2, l1 + l2, fontsize=8, loc="lower right")  # on top of both bar sets
        return fig

    #: the figures :meth:`figures` draws, by file name
    FIGURES = ("compare", "residual", "order_map", "autocorrelation", "candidates", "before_after")

    def figures(self) -> dict[str, object]:
        return {
            "compare": self.plot_compare(which="both"),
            "residual": self.plot_residual(),
            "order_map": self.plot_order_map(),
            "autocorrelation": self.plot_autocorrelation(),
            "candidates": self.plot_candidates(),
            "before_after": self.plot_before_after(),
        }

    def save_figures(self, folder: str | Path, *, overwrite: bool = True) -> list[Path]:
        """Every figure as ``folder/<name>.png`` (each written atomically)."""
        import matplotlib.pyplot as plt

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for name, fig in self.figures().items():
            paths.append(atomic_write(
                folder / f"{name}.png",
                lambda p, fig=fig: fig.savefig(p, format="png", dpi=110, bbox_inches="tight"),
                overwrite=overwrite,
            ))
            plt.close(fig)
        return paths

    def report(self, path: str | Path, *, overwrite: bool = False) -> Path:
        """A self-contained HTML report (figures embedded as PNG)."""
        import matplotlib.pyplot as plt

        path = check_writable(path, overwrite=overwrite)  # before the figures are drawn
        imgs = {}
        for name, fig in self.figures().items():
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
            plt.close(fig)
            imgs[name] = base64.b64encode(buf.getvalue()).decode()

        def img(name):
            return f'<img alt="{name}" src="data:image/png;base64,{imgs[name]}">'

        cand_rows = "".join(
            f"<tr class='{'missing' if c.effect in self.missing else ''}'><td>{c.effect}</td><td>{c.F:.4g}</td>"
            f"<td>{c.log10_p:.4g}</td><td>{c.rms_after:.4g}</td><td>{c.fit_percent_after:.1f}</td>"
            f"<td>{c.correlation:.2f}</td><td>{c.order_overlap:.2f}</td><td>{html.escape(c.story)}</td></tr>"
            for c in self.candidates
        )
        win_rows = "".join(
            f"<tr><td>{w['t_start']:.1f}</td><td>{w['t_end']:.1f}</td><td>{w['peak_rms_over_floor']:.1f}</td></tr>"
            for w in self.windows
        ) or "<tr><td colspan=3>none</td></tr>"
        coef_rows = "".join(
            f"<tr><td>{c}</td><td>{v:.5g}</td><td>{s:.2g}</td></tr>"
            for c, v, s in zip(self.after.columns, self.after.coefficients, self.after.standard_errors, strict=True)
        )
        missing = ", ".join(
            f"<b>{e}</b>" + (f" (from t ≈ {self.onset[e]:.0f})" if self.onset.get(e) is not None else "")
            for e in self.missing
        ) or "none"
        doc = f"""<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">
<title>rotor-id diagnosis</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:auto;padding:1em;color:#222}}
table{{border-collapse:collapse;margin:.5em 0}}td,th{{border:1px solid #bbb;padding:3px 8px;font-size:13px}}
tr.missing{{background:#fde0dc}}img{{max-width:100%}}pre{{background:#f4f4f4;padding:.5em}}</style></head><body>
<h1>rotor-id diagnosis</h1>
<h2>Summary</h2>
<p>Data: {html.escape(str(self.source))}; ip = {self.ip:g}; alpha = {self.alpha:g}; informative window t &ge; {self.t_start:g}.</p>
<p>Starting model: {', '.join(self.start_model)}. Missing: {missing}. Final model: {', '.join(self.model)}.</p>
<table><tr><th></th><th>equation RMS</th><th>R²</th><th>free-run fit %</th></tr>
<tr><td>before</td><td>{self.before.rms:.4g}</td><td>{self.before.r2:.4f}</td><td>{self.before.fit_percent:.1f}</td></tr>
<tr><td>after</td><td>{self.after.rms:.4g}</td><td>{self.after.r2:.4f}</td><td>{self.after.fit_percent:.1f}</td></tr></table>
<h2>Compare</h2>{img('compare')}
<h2>Where it fails</h2>{img('residual')}{img('order_map')}{img('autocorrelation')}
<p>Windows where the residual stands above the noise floor ({self.noise_floor:.3g}):</p>
<table><tr><th>t start</th><th>t end</th><th>peak RMS / floor</th></tr>{win_rows}</table>
<h2>Which effect is missing</h2>{img('candidates')}
<table><tr><th>effect</th><th>F</th><th>log10 p</th><th>RMS after</th><th>fit % after</th><th>corr.</th><th>order overlap</th><th>physical story</th></tr>{cand_rows}</table>
<h2>Before and after</h2>{img('before_after')}
<table><tr><th>coefficient</th><th>estimate</th><th>std. error</th></tr>{coef_rows}</table>
<pre>{html.escape(self.summary())}</pre>
</body></html>"""
        return atomic_write_text(path, doc, overwrite=overwrite)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _first_rows(values: np.ndarray, equation: str) -> np.ndarray:
    return values[0::2] if equation == "both" else values


def _known(model: Iterable[str], k: float = 1.0) -> dict:
    return {} if "stiffness" in model else {"stiffness": {"k": k}}


# ------------------------------------------------------------------ entry points
def fit(
    measurements: Measurements,
    model: Sequence[str] | Model | str = DEFAULT_MODEL,
    *,
    ip: float = 0.3,
    equation: str = "both",
    window_fraction: float = 0.1,
    t_start: float | None = None,
) -> Comparison:
    """Fit one model and compare it with the measurements (no search)."""
    model = _as_model(model)
    data = _Data(measurements, ip, equation, window_fraction, t_start)
    for e in model:
        _validate_columns(EFFECTS[e], data.data, ip)
    return compare(data, model.effects, _known(model.effects))


def diagnose(
    measurements: Measurements,
    model: Sequence[str] | Model | str = DEFAULT_MODEL,
    *,
    candidates: Sequence[str] | None = None,
    ip: float = 0.3,
    alpha: float = 0.05,
    equation: str = "both",
    min_fit_gain: float = 2.0,
    min_energy_drop: float = 0.05,
    window_fraction: float = 0.1,
    t_start: float | None = None,
    max_rounds: int = 6,
    progress: bool = False,
) -> Diagnosis:
    """Compare ``model`` with the measurements, rank and add the missing effects.

    See the module docstring for the rules.  ``candidates`` defaults to every library
    effect not in the model (user effects registered with ``--effect`` are added by
    the caller).
    """
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    model = _as_model(model)
    if candidates is None:
        candidates = [c for c in LIBRARY_CANDIDATES if c not in model]
    else:
        candidates = [get_effect(c).name for c in candidates if c not in model]
    if "unbalance_in_phase" in model:
        candidates = [c for c in candidates if c != "unbalance"]
    data = _Data(measurements, ip, equation, window_fraction, t_start)
    for e in (*model, *candidates):
        _validate_columns(EFFECTS[e], data.data, ip)
    pbar = None
    if progress:
        from tqdm.auto import tqdm

        pbar = tqdm(total=max_rounds, desc="diagnosing", unit="round", leave=False)
    current = compare(data, model.effects, _known(model.effects))
    before = current
    # the first equation's rows: one residual per sample, white where the model is right
    windows, floor = failing_windows(data.meas.t, _first_rows(before.residual, equation))
    rounds: list[list[Candidate]] = []
    missing: list[str] = []
    steps: list[Comparison] = []
    remaining = list(candidates)
    while remaining and len(rounds) < max_rounds:
        ranked = _rank(data, current, remaining, _known(current.model), alpha, min_fit_gain, min_energy_drop)
        rounds.append(ranked)
        if pbar is not None:
            pbar.update(1)
        chosen = next((c for c in ranked if c.significant and c.relevant), None)
        if chosen is None or not ranked[0].significant:
            break
        missing.append(chosen.effect)
        current = chosen.comparison
        if chosen.onset is not None:
            current = _appears_or_changes(data, current, chosen.effect, alpha, min_energy_drop)
        steps.append(current)
        remaining.remove(chosen.effect)
    if pbar is not None:
        pbar.close()
    onset = {
        e: current.onsets.get(e)
        if e in current.onsets
        else _change_time(data, current, e, _known(current.model), alpha, min_energy_drop)
        for e in missing
    }
    diag = Diagnosis(
        source=measurements.source, ip=ip, alpha=alpha, equation=equation, t_start=data.t_start,
        start_model=model.effects, model=current.model, missing=missing, onset=onset, rounds=rounds,
        before=before, after=current, windows=windows, noise_floor=floor, data=data, steps=steps,
    )
    return diag
