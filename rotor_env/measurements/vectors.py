"""Order tracking and order-tracked vector tables (1X, 2X, ... against speed).

Phase conventions
-----------------
A vector ``X`` at order ``n`` describes the part of a probe's signal that turns ``n``
times per revolution.  Two conventions are in use and both are read and written:

* ``lead`` (mathematical): ``x = Re(X e^{i n phi})`` — the angle of ``X`` leads the
  keyphasor; this is the package's internal convention.
* ``lag`` (instrument, Bently/ADRE, API 670): ``x = A cos(n phi - phase)`` — the phase
  is the angle from the keyphasor pulse to the next positive peak, counted *against*
  the rotation; ``phase_lag = -angle(X)`` (wrapped to [0, 360) degrees).

``phi`` is the spin angle, zero at each keyphasor pulse.

Order tracking
--------------
:func:`order_track` computes, for each block of whole revolutions, the Fourier
coefficient in the shaft angle

    X_n = (1 / (pi R)) * integral over R revolutions of x(phi) e^{-i n phi} d phi

(trapezoidal rule in ``phi``, so a sweep's changing speed needs no resampling).  For
``x = Re(X e^{i n phi})`` it returns ``X`` exactly; other orders average out over whole
revolutions.  The block's speed is its angle over its duration, its time the middle.

``order_track(..., method="lstsq")`` fits the samples of each revolution (between
keyphasor marks, :func:`keyphasor_times`) by least squares with a constant and the
requested orders (:func:`fit_orders`): exact for a signal made of those orders, the
trapezoid's DFT otherwise.  The plots read it (:mod:`rotor_env.plots.field`);
the identification reads the trapezoid.
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numba import njit

__all__ = [
    "AMPLITUDE_UNITS",
    "OrderTrack",
    "VectorTable",
    "VectorTableError",
    "amplitude_unit",
    "fit_orders",
    "from_phase",
    "keyphasor_phase_error",
    "keyphasor_times",
    "load_vector_table",
    "order_map",
    "order_track",
    "to_phase",
]

#: amplitude unit -> metres (V and mV need a sensitivity; see the rig description)
AMPLITUDE_UNITS: dict[str, float] = {"um": 1e-6, "µm": 1e-6, "mil": 25.4e-6, "mm": 1e-3, "m": 1.0}
#: how a table's amplitude is measured -> the factor to the vector's modulus (zero to peak, the
#: package's ``|X|``).  Displacement from proximity probes is customarily given peak to peak
#: (API 670; Bently Nevada's and ADRE's 1X tables: "mil pp", "um pp"), sometimes as an RMS; an
#: amplitude read as zero to peak when it is peak to peak doubles every size the diagnosis reports
#: (the unbalance in g mm, the bow, the runout, the noise floor) while the criticals, the damping
#: and a crack's relative stiffness, ratios of amplitudes, stay the same.
AMPLITUDE_MEASURES: dict[str, float] = {"pk": 1.0, "pp": 0.5, "rms": math.sqrt(2.0)}
#: a table's speed column (the first of these names found, any case) and its time column
SPEED_COLUMNS = ("rpm", "speed_rpm", "speed")
TIME_COLUMNS = ("t", "time", "time_s")
#: speed unit -> rad/s
SPEED_UNITS: dict[str, float] = {"rpm": 2.0 * math.pi / 60.0, "rad/s": 1.0, "hz": 2.0 * math.pi}


#: a speed beyond this is no rotor's (ultracentrifuges and dental turbines stay below)
MAX_RPM = 1e6
#: a 1X amplitude beyond this is beyond any displacement probe's range (metres)
MAX_AMPLITUDE_M = 0.025
#: a 1X amplitude below this (metres) all through a table is below any displacement probe's
#: resolution: no vibration was measured (or not in the unit given)
MIN_AMPLITUDE_M = 1e-9
#: a table whose run spans more revolutions than this is not one start-up (time in ms?);
#: the transient model's grid is 48 samples a revolution
MAX_REVOLUTIONS = 5e4


def _num(x) -> str:
    return repr(float(x))


def _cut(x, chars: int = 200) -> str:
    text = repr(x)
    return text if len(text) <= chars else text[:chars] + "..."


class VectorTableError(ValueError):
    """An order-tracked vector table that cannot be used as it is."""


def to_phase(vectors: np.ndarray, convention: str = "lag") -> tuple[np.ndarray, np.ndarray]:
    """Complex vectors (``lead`` convention) -> amplitude and phase in degrees of ``convention``."""
    _check_convention(convention)
    amp = np.abs(vectors)
    ang = np.degrees(np.angle(vectors))
    return amp, (np.mod(-ang, 360.0) if convention == "lag" else ang)


def from_phase(amp: np.ndarray, phase_deg: np.ndarray, convention: str = "lag") -> np.ndarray:
    """Amplitude and phase (degrees, ``convention``) -> complex vectors in the ``lead`` convention."""
    _check_convention(convention)
    ang = np.radians(phase_deg)
    return np.asarray(amp, dtype=float) * np.exp(-1j * ang if convention == "lag" else 1j * ang)


def amplitude_unit(text: str) -> tuple[str, str]:
    """``"mil pp"``, ``"um-pp"``, ``"um_rms"``, ``"m 0-pk"``, ``"mm"`` -> (unit, measure): a unit of
    :data:`AMPLITUDE_UNITS` and a measure of :data:`AMPLITUDE_MEASURES` (zero to peak, ``pk``,
    when none is given).  A clear error names what is accepted."""
    raw = str(text).strip()
    head, _, rest = raw.replace("-", " ", 1).replace("_", " ", 1).partition(" ")
    unit = head if head == "µm" else head.lower()
    key = "".join(c for c in rest.lower() if c not in " -_")
    measure = _MEASURE_NAMES.get(key)
    if unit not in AMPLITUDE_UNITS or measure is None:
        raise VectorTableError(
            f"--amp-unit {raw!r}: expected one of {', '.join(AMPLITUDE_UNITS)}, optionally followed by how the "
            f"amplitude is measured ({', '.join(AMPLITUDE_MEASURES)}; e.g. 'mil pp' or 'um-pp'; default pk, zero to "
            "peak); volts: convert with the probe sensitivity in the rig description")
    return unit, measure


#: the spellings of a measure (spaces, hyphens and underscores dropped, lower case)
_MEASURE_NAMES = {"": "pk", "pk": "pk", "0pk": "pk", "0p": "pk", "peak": "pk", "zerotopeak": "pk",
                  "pp": "pp", "pkpk": "pp", "peaktopeak": "pp", "rms": "rms"}


def _check_convention(convention: str) -> None:
    if convention not in ("lag", "lead"):
        raise ValueError(f"phase convention must be 'lag' or 'lead', got {convention!r}")


@dataclass(frozen=True)
class OrderTrack:
    """Order-tracked vectors of one or more signals: one row per block of revolutions."""

    t: np.ndarray  #: time of each block's middle
    speed: np.ndarray  #: mean speed of each block (rad per time unit of ``t``)
    vectors: dict[int, np.ndarray]  #: order -> complex (rows,) or (rows, signals), lead convention


def order_track(
    t: np.ndarray,
    x: np.ndarray,
    phi: np.ndarray,
    orders: tuple[int, ...] = (1,),
    revolutions: int = 1,
    *,
    at: np.ndarray | None = None,
    upsample: int = 1,
    method: str = "trapezoid",
) -> OrderTrack:
    """Per-revolution Fourier coefficients of ``x`` (1-D, or 2-D with a signal per column).

    Blocks are ``revolutions`` whole turns of ``phi`` starting at multiples of 2 pi
    (the keyphasor), one after the other; or, with ``at`` (angles), centred on each of
    those angles.  Blocks that do not fit in the record are left out.  A complex signal
    (``x + i y``) is its own analytic form: its vectors use ``1 / (2 pi R)`` (``z = Z e^{i n phi}``
    gives ``Z``).  ``upsample``: cubic interpolation to that many points per sample first.

    ``method``: ``"trapezoid"`` (the module docstring) or ``"lstsq"``: each block's samples
    fitted by least squares (:func:`fit_orders`) between the keyphasor marks
    (:func:`keyphasor_times`; a shaft turning backwards is tracked too, ``revolutions``
    may be any positive number), a real channel with positive ``orders`` only, a complex
    one with signed orders (``-1``: backward) and ``0`` (the mean); a block with too few
    samples gives NaN.  ``at`` and ``upsample`` go with the trapezoid only.
    """
    if method not in ("trapezoid", "lstsq"):
        raise ValueError(f"method must be 'trapezoid' or 'lstsq', got {method!r}")
    t = np.asarray(t, dtype=float)
    phi = np.asarray(phi, dtype=float)
    x = np.asarray(x)
    one = x.ndim == 1
    xs = x[:, None] if one else x
    if len(t) != len(phi) or len(t) != xs.shape[0]:
        raise ValueError("t, x and phi must have the same number of samples")
    if method == "lstsq":
        if at is not None or upsample != 1:
            raise ValueError("order_track: 'at' and 'upsample' go with method='trapezoid'")
        return _track_lstsq(t, xs, phi, orders, revolutions, one)
    if upsample > 1:
        # cubic interpolation between the samples: the trapezoid's error on what is not a
        # whole number of orders in a block (a free whirl beating against 1X) falls as h^4
        from scipy.interpolate import CubicSpline

        fine = np.linspace(0.0, len(t) - 1.0, (len(t) - 1) * upsample + 1)
        k = np.arange(len(t), dtype=float)
        t = np.interp(fine, k, t)
        phi = CubicSpline(k, phi)(fine)
        xs = CubicSpline(k, xs, axis=0)(fine)
    track = OrderTracker(t, phi, orders, revolutions, at=at).track(xs)
    if one:
        return OrderTrack(track.t, track.speed, {n: v[:, 0] for n, v in track.vectors.items()})
    return track


class OrderTracker:
    """:func:`order_track`'s trapezoid for one ``(t, phi)`` and its blocks, set up once.

    Everything that depends on the angle alone (the blocks, their ends interpolated inside
    their sample intervals, ``e^{-i n phi}``) is computed here; :meth:`track` then costs a
    product, a cumulative sum and the ends per signal — for a caller that tracks many
    signals on one angle (the synchronous model's runs at one time scale).
    """

    def __init__(self, t: np.ndarray, phi: np.ndarray, orders: tuple[int, ...] = (1,), revolutions: int = 1,
                 *, at: np.ndarray | None = None) -> None:
        t = np.asarray(t, dtype=float)
        phi = np.asarray(phi, dtype=float)
        if len(t) != len(phi):
            raise ValueError("t and phi must have the same number of samples")
        if revolutions < 1:
            raise ValueError(f"revolutions must be >= 1, got {revolutions}")
        span = 2.0 * math.pi * revolutions
        if at is None:
            first = math.ceil(phi[0] / (2.0 * math.pi)) * 2.0 * math.pi
            starts = np.arange(first, phi[-1] - span + 1e-12, span)
        else:
            starts = np.asarray(at, dtype=float) - 0.5 * span
            starts = starts[(starts >= phi[0]) & (starts + span <= phi[-1])]
        stops = starts + span
        self.n_samples = len(phi)
        self.orders = tuple(orders)
        self.revolutions = revolutions
        self.t = 0.5 * (np.interp(starts, phi, t) + np.interp(stops, phi, t))
        self.speed = span / (np.interp(stops, phi, t) - np.interp(starts, phi, t))
        # cumulative trapezoid of x e^{-i n phi} in phi; a block's integral is the difference
        # of the cumulative integral at its two ends, each end interpolated inside its sample
        # interval (the same trapezoid as on the block's samples plus its interpolated ends)
        self._dphi = np.diff(phi)[:, None]
        self._rot = {n: np.exp(-1j * n * phi)[:, None] for n in self.orders}
        self._ends = []
        for edge in (starts, stops):
            i = np.clip(np.searchsorted(phi, edge, side="right") - 1, 0, len(phi) - 2)
            frac = ((edge - phi[i]) / (phi[i + 1] - phi[i]))[:, None]
            self._ends.append((i, frac, {n: np.exp(-1j * n * edge)[:, None] for n in self.orders},
                               (edge - phi[i])[:, None]))

    def track(self, x: np.ndarray) -> OrderTrack:
        """The per-block Fourier coefficients of ``x`` (1-D, or 2-D with a signal per column)."""
        x = np.asarray(x)
        one = x.ndim == 1
        xs = x[:, None] if one else x
        if xs.shape[0] != self.n_samples:
            raise ValueError("t, x and phi must have the same number of samples")
        out = {}
        norm = (2.0 if np.iscomplexobj(xs) else 1.0) * math.pi * self.revolutions
        if xs.dtype == np.float64 and len(self.t):
            # one pass over each block's samples (compiled): no product and cumulative sum of
            # the whole record per order
            (i0, f0, _, d0), (i1, f1, _, d1) = self._ends
            xc = np.ascontiguousarray(xs)
            for n in self.orders:
                res = np.empty((len(self.t), xs.shape[1]), dtype=complex)
                _block_integrals(xc, self._rot[n][:, 0], self._dphi[:, 0], i0, f0[:, 0], self._ends[0][2][n][:, 0],
                                 d0[:, 0], i1, f1[:, 0], self._ends[1][2][n][:, 0], d1[:, 0], res)
                out[n] = res / norm
            if one:
                out = {n: v[:, 0] for n, v in out.items()}
            return OrderTrack(self.t, self.speed, out)
        for n in self.orders:
            F = xs * self._rot[n]
            cum = np.empty((len(F), xs.shape[1]), dtype=complex)
            cum[0] = 0.0
            np.cumsum(0.5 * (F[1:] + F[:-1]) * self._dphi, axis=0, out=cum[1:])
            ends = []
            for i, frac, rot_e, dist in self._ends:
                x_e = xs[i] + frac * (xs[i + 1] - xs[i])
                ends.append(cum[i] + 0.5 * (F[i] + x_e * rot_e[n]) * dist)
            out[n] = (ends[1] - ends[0]) / norm
        if one:
            out = {n: v[:, 0] for n, v in out.items()}
        return OrderTrack(self.t, self.speed, out)


@njit(cache=True)
def _block_integrals(x, rot, dphi, i0, f0, rot0, d0, i1, f1, rot1, d1, out):  # pragma: no cover - compiled
    """:meth:`OrderTracker.track`'s trapezoid per block, summed over the block's samples only:
    ``out[b, j] = C(end_b) - C(start_b)`` with ``C`` the cumulative trapezoid of ``x rot`` in
    ``phi`` and each end interpolated inside its sample interval."""
    for b in range(out.shape[0]):
        a, e = i0[b], i1[b]
        for j in range(x.shape[1]):
            acc = 0j
            for m in range(a, e):
                acc += 0.5 * (x[m, j] * rot[m] + x[m + 1, j] * rot[m + 1]) * dphi[m]
            xe = x[e, j] + f1[b] * (x[e + 1, j] - x[e, j])
            acc += 0.5 * (x[e, j] * rot[e] + xe * rot1[b]) * d1[b]
            xs = x[a, j] + f0[b] * (x[a + 1, j] - x[a, j])
            acc -= 0.5 * (x[a, j] * rot[a] + xs * rot0[b]) * d0[b]
            out[b, j] = acc


def keyphasor_times(t: np.ndarray, phi: np.ndarray, revolutions: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """``(times, angles)`` where ``phi`` crosses a multiple of ``2 pi`` (the keyphasor mark),
    every ``revolutions`` turns, interpolated between samples; counted with the rotation
    (a shaft turning backwards crosses them downwards)."""
    sign = 1.0 if phi[-1] >= phi[0] else -1.0
    psi = np.maximum.accumulate(sign * phi)  # monotone: brief reversals held (encoder noise)
    step = 2 * math.pi * revolutions
    first = math.ceil(psi[0] / (2 * math.pi) - 1e-12) * 2 * math.pi
    marks = np.arange(first, psi[-1] + 1e-12, step)
    if marks.size == 0:
        return np.empty(0), np.empty(0)
    # psi may hold flat stretches: interpolate on the strictly increasing samples
    keep = np.concatenate([[True], np.diff(psi) > 0])
    return np.interp(marks, psi[keep], t[keep]), sign * marks


def keyphasor_phase_error(t: np.ndarray, phi: np.ndarray) -> float:
    """RMS error (rad) of a keyphasor-derived shaft angle averaged over a revolution.

    The pulse times' second differences cancel a smooth speed profile and leave the timing
    jitter (``var d2 = 6 sigma_t^2``; median of ``d2^2`` over ``6 * 0.455`` for Gaussian
    jitter); the angle at a pulse is off by ``W sigma_t``, and a revolution between two pulses
    carries the mean of their two errors (``/ sqrt 2``).  RMS over the revolutions.
    """
    times, _ = keyphasor_times(np.asarray(t, dtype=float), np.asarray(phi, dtype=float))
    if len(times) < 5:
        return 0.0
    d2 = times[2:] - 2 * times[1:-1] + times[:-2]
    sigma_t = math.sqrt(float(np.median(d2 * d2)) / (6.0 * 0.4549))
    speed = 2 * math.pi / np.diff(times)
    return float(sigma_t * math.sqrt(np.mean(speed * speed)) / math.sqrt(2.0))


def _track_lstsq(t: np.ndarray, xs: np.ndarray, phi: np.ndarray, orders, revolutions: float,
                 one: bool) -> OrderTrack:
    """:func:`order_track` with ``method="lstsq"``: :func:`fit_orders` between consecutive
    keyphasor marks.  ``speed`` is ``2 pi revolutions / (t_b - t_a)`` (positive either way
    round), ``t`` the block's middle."""
    orders = [int(o) for o in orders]
    if not np.iscomplexobj(xs) and any(o <= 0 for o in orders):
        raise ValueError(f"a real channel has positive orders only, got {orders}")
    times, marks = keyphasor_times(t, phi, revolutions)
    n_blocks = max(len(times) - 1, 0)
    out = {o: np.full((n_blocks, xs.shape[1]), np.nan + 0j) for o in orders}
    t_mid = 0.5 * (times[1:] + times[:-1]) if n_blocks else np.empty(0)
    speed = np.abs(np.diff(marks)) / np.diff(times) if n_blocks else np.empty(0)
    bounds = np.searchsorted(t, times)
    for j in range(n_blocks):
        a, b = bounds[j], bounds[j + 1]
        for s in range(xs.shape[1]):
            fitted = fit_orders(phi[a:b], xs[a:b, s], orders, (marks[j], marks[j + 1]))
            for o in orders:
                out[o][j, s] = fitted[o]
    if one:
        out = {o: v[:, 0] for o, v in out.items()}
    return OrderTrack(t_mid, speed, out)


def fit_orders(phi: np.ndarray, x: np.ndarray, orders, span: tuple[float, float] | None = None) -> dict[int, complex]:
    """Least squares of the samples against a constant and the ``orders`` of ``phi``: a
    real ``x ≈ a0 + sum Re(X_n e^{i n phi})``, a complex ``x ≈ a0 + sum X_n e^{i n phi}``
    (order 0 is ``a0``).  ``span``: the block's end angles (the keyphasor marks), so the
    weights cover the whole block.  NaN with too few samples."""
    real = not np.iscomplexobj(x)
    n_cols = 1 + (2 if real else 1) * len([o for o in orders if o != 0])
    if len(x) < n_cols + 2:
        return {o: complex(np.nan, np.nan) for o in orders}
    # each sample weighted by the angle it stands for (trapezoid in phi): on an accelerating
    # shaft the samples crowd at the start of a turn, and unweighted, the orders not fitted
    # (2X when fitting 1X) would leak in; weighted, the fit is the DFT against phi
    lo, hi = span if span is not None else (phi[0], phi[-1])
    edges = np.concatenate([[lo], 0.5 * (phi[1:] + phi[:-1]), [hi]])
    sw = np.sqrt(np.abs(np.diff(edges)))[:, None]
    if real:
        cols = [np.ones(len(x))]
        for o in orders:
            cols += [np.cos(o * phi), -np.sin(o * phi)]  # Re(X e^{i o phi}) = Re X cos - Im X sin
        coef, *_ = np.linalg.lstsq(np.column_stack(cols) * sw, x * sw[:, 0], rcond=None)
        return {o: complex(coef[1 + 2 * q], coef[2 + 2 * q]) for q, o in enumerate(orders)}
    moving = [o for o in orders if o != 0]
    A = np.column_stack([np.ones(len(x))] + [np.exp(1j * o * phi) for o in moving])
    coef, *_ = np.linalg.lstsq(A * sw, x.astype(complex) * sw[:, 0], rcond=None)
    out = {o: complex(coef[1 + q]) for q, o in enumerate(moving)}
    if 0 in orders:
        out[0] = complex(coef[0])
    return out


# ------------------------------------------------------------------ vector tables
@dataclass(frozen=True)
class VectorTable:
    """An order-tracked start-up or coast-down: speed rows, vectors per probe and order.

    ``speed`` in rad/s, ``t`` in s (``None`` when the table has no time column),
    ``vectors[n]`` a complex ``(rows, probes)`` array in the ``lead`` convention and in
    ``amp_unit``; ``angles`` the probes' mounting angles (rad, from the reference in the
    direction of rotation; ``None`` when unknown: each probe is then fitted on its own).
    ``phase_error_rad``: the RMS error of the tracker's shaft angle over a row (a keyphasor
    pulse timed to a fraction of a sample), which moves each vector by about
    ``|X| phase_error_rad`` — row to row correlated, so the rows' roughness does not show it;
    0 when the phases are taken as exact (a table from a monitoring system says nothing of it).
    """

    speed: np.ndarray
    t: np.ndarray | None
    probes: tuple[str, ...]
    vectors: dict[int, np.ndarray]
    amp_unit: str = "um"
    angles: np.ndarray | None = None
    source: str = ""
    notes: tuple[str, ...] = field(default=())
    #: with ``load_vector_table(..., run_column=...)``: the run label of every row (file order)
    runs: tuple[str, ...] | None = None
    #: the file line of every row (errors of a caller that reads the table further name it)
    lines: tuple[int, ...] | None = None
    #: the keyphasor angle's error (pulse timing jitter, rad) of vectors tracked from waveforms
    phase_error_rad: float = 0.0
    #: ``(rows, p)``: the keyphasor angle's error at the rows is ``phase_error_basis @ z``, ``z``
    #: standard normal (:meth:`~.keyphasor.SpinFit.error_basis`: one smooth curve, not white)
    phase_error_basis: np.ndarray | None = None

    @property
    def rpm(self) -> np.ndarray:
        return self.speed / SPEED_UNITS["rpm"]

    def to_csv(self, path: str | os.PathLike, phase: str = "lag", *, overwrite: bool = False) -> None:
        """Write the table as CSV (``t``, ``rpm``, then ``NAME_amp``/``NAME_phase_deg`` per probe and order)."""
        from ..outputs import atomic_write

        cols = ["rpm"] if self.t is None else ["t", "rpm"]
        data = [self.rpm] if self.t is None else [self.t, self.rpm]
        for n in sorted(self.vectors):
            suffix = "" if n == 1 else f"_{n}x"
            for j, p in enumerate(self.probes):
                amp, ph = to_phase(self.vectors[n][:, j], phase)
                prefix = "" if len(self.probes) == 1 else f"{p}_"
                cols += [f"{prefix}amp{suffix}", f"{prefix}phase_deg{suffix}"]
                data += [amp, ph]
        arr = np.column_stack(data)

        def write(tmp: Path) -> None:
            with open(tmp, "w", newline="", encoding="utf-8") as fh:
                w = csv.writer(fh)
                w.writerow(cols)
                for row in arr:
                    w.writerow([repr(float(v)) for v in row])

        atomic_write(Path(path), write, overwrite=overwrite)


def load_vector_table(
    path: str | os.PathLike,
    *,
    amp_unit: str = "um",
    phase: str = "lag",
    speed_unit: str = "rpm",
    angles: dict[str, float] | None = None,
    run_column: str | None = None,
) -> VectorTable:
    """Read an order-tracked table: ``rpm`` (or ``speed``), optional ``t``, and per probe
    ``amp``/``phase_deg`` (one probe) or ``NAME_amp``/``NAME_phase_deg``; 2X and 3X as
    ``..._amp_2x``/``..._phase_deg_2x``.  ``amp_unit``: a unit of :data:`AMPLITUDE_UNITS`,
    optionally with how the amplitude is measured (``"mil pp"``: peak to peak, halved here;
    ``"um rms"``; zero to peak by default: :func:`amplitude_unit`) -- the table holds zero-to-peak
    vectors in the bare unit, and its notes say what was converted.  ``angles``: probe name ->
    mounting angle in degrees (from the rig description).  Errors name the file, column, line
    and value.

    ``run_column`` (a balancing campaign, :mod:`rotor_env.balance`): that column labels
    every row with its run (text or numbers); the rows stay in file order (one run's rows
    are repeat acquisitions at a few speeds: neither a sweep nor at least 8 rows) and
    :attr:`VectorTable.runs` holds the labels.
    """
    from .files import MeasurementError, read_table, table_header

    path = Path(path)
    _check_convention(phase)
    amp_unit, measure = amplitude_unit(amp_unit)
    to_peak = AMPLITUDE_MEASURES[measure]
    unit_text = amp_unit if measure == "pk" else f"{amp_unit} {measure}"  # as the file gives it
    labels: dict[int, str] | None = None
    try:
        if run_column is None:
            # only the table's own columns must be numbers (a timestamp or a note is read as nothing)
            header, data, lines = read_table(path, numeric=[h for h in table_header(path) if _table_column(h)])
        else:
            names_in_file, labels = _text_column(path, run_column)
            header, data, lines = read_table(path, numeric=[h for h in names_in_file
                                                            if h.lower() != run_column.lower()])
    except MeasurementError as exc:
        raise VectorTableError(str(exc)) from None
    if labels is not None:
        # the label column is text: not a probe or speed column below
        keep = [j for j, h in enumerate(header) if h.strip().lower() != run_column.lower()]
        header = [header[j] for j in keep]
        data = data[:, keep]
    header = [h.strip() for h in header]
    lower = [h.lower() for h in header]
    dup = sorted({h for h in lower if lower.count(h) > 1})
    if dup:  # the last of two 'x_amp' columns would silently win
        raise VectorTableError(f"{path}: column(s) {_cut(dup)} appear more than once")
    speed_col = next((c for c in SPEED_COLUMNS if c in lower), None)
    if speed_col is None:
        raise VectorTableError(f"{path}: no speed column: expected 'rpm' (found columns {_cut(header)})")
    unit = "rpm" if speed_col != "speed" else speed_unit
    col = {h.lower(): i for i, h in enumerate(header)}
    probes: dict[str, dict[int, tuple[int, int]]] = {}
    for h in lower:
        for n, suffix in ((1, ""), (2, "_2x"), (3, "_3x"), (1, "_1x")):
            tail = f"amp{suffix}"
            if h == tail or h.endswith("_" + tail):
                name = h[: -len(tail)].rstrip("_") or "probe"
                ph = (h[: -len(tail)] + f"phase_deg{suffix}")
                if ph not in col:
                    raise VectorTableError(f"{path}: column {header[col[h]]!r} has no phase column {ph!r}")
                probes.setdefault(name, {})[n] = (col[h], col[ph])
    if not probes:
        raise VectorTableError(f"{path}: no amplitude columns: expected 'amp' and 'phase_deg' "
                               f"(or NAME_amp, NAME_phase_deg per probe); found {_cut(header)}")
    if any(1 not in v for v in probes.values()):
        bad = next(k for k, v in probes.items() if 1 not in v)
        raise VectorTableError(f"{path}: probe {bad!r} has no 1X columns ({bad}_amp, {bad}_phase_deg)")
    if data.shape[0] < 8 and labels is None:
        raise VectorTableError(f"{path}: only {data.shape[0]} rows; an order-tracked run needs at least 8 speeds")
    used = [col[speed_col]] + [i for v in probes.values() for pair in v.values() for i in pair]
    t_idx = next((col[c] for c in TIME_COLUMNS if c in col), None)
    if t_idx is not None:
        used.append(t_idx)
    for j in used:
        bad = ~np.isfinite(data[:, j])
        if bad.any():
            r = int(np.argmax(bad))
            raise VectorTableError(f"{path}, line {lines[r]}, column {header[j]!r}: value {_num(data[r, j])} is not "
                                   "finite")
    speed = data[:, col[speed_col]] * SPEED_UNITS[unit]
    if (speed <= 0).any():
        r = int(np.argmax(speed <= 0))
        raise VectorTableError(f"{path}, line {lines[r]}, column {header[col[speed_col]]!r}: speed "
                               f"{_num(data[r, col[speed_col]])} is not positive")
    rpm = speed / SPEED_UNITS["rpm"]
    if (rpm > MAX_RPM).any():
        r = int(np.argmax(rpm > MAX_RPM))
        raise VectorTableError(f"{path}, line {lines[r]}, column {header[col[speed_col]]!r}: speed "
                               f"{_num(data[r, col[speed_col]])} ({rpm[r]:.4g} rpm) is beyond any rotor's "
                               f"({MAX_RPM:g} rpm): not a speed in {unit}")
    if float(rpm.max() - rpm.min()) <= 1e-9 * float(rpm.max()):
        raise VectorTableError(f"{path}, column {header[col[speed_col]]!r}: the speed is {_num(rpm[0])} rpm on every "
                               "row; a run-up or coast-down (changing speed) is needed to see a resonance")
    # the limits are on the zero-to-peak amplitude, the same whatever the file's measure
    metres = AMPLITUDE_UNITS[amp_unit] * to_peak
    notes: list[str] = []
    if measure != "pk":
        notes.append(f"the table's amplitudes are {'peak to peak' if measure == 'pp' else 'RMS'} ({amp_unit} "
                     f"{measure}): read as zero to peak ({'halved' if measure == 'pp' else 'times sqrt 2'}); "
                     f"every amplitude reported is zero to peak in {amp_unit}")
    for v in probes.values():
        amp = data[:, v[1][0]]
        if (amp < 0).any():
            r = int(np.argmax(amp < 0))
            raise VectorTableError(f"{path}, line {lines[r]}, column {header[v[1][0]]!r}: amplitude {_num(amp[r])} "
                                   "is negative")
        # a vibration beyond any displacement probe's range: another unit, or no measurement
        big = amp * metres > MAX_AMPLITUDE_M
        if big.any():
            r = int(np.argmax(big))
            raise VectorTableError(f"{path}, line {lines[r]}, column {header[v[1][0]]!r}: amplitude {_num(amp[r])} "
                                   f"{unit_text} is beyond a displacement probe's range ({MAX_AMPLITUDE_M * 1e3:g} mm): "
                                   "is --amp-unit right?")
    amps = data[:, [pair[0] for v in probes.values() for pair in v.values()]]
    if not (amps > 0).any():
        raise VectorTableError(f"{path}: every amplitude is zero: the table holds no vibration to diagnose")
    if float(amps.max()) * metres < MIN_AMPLITUDE_M:
        # 1e-300 um: no probe resolves it, and the fit's noise floor underflows
        raise VectorTableError(f"{path}: the largest amplitude is {_num(amps.max())} {unit_text}, below any displacement "
                               f"probe's resolution ({MIN_AMPLITUDE_M * 1e9:g} nm): no vibration measured; is "
                               "--amp-unit right?")
    phases = data[:, [pair[1] for v in probes.values() for pair in v.values()]]
    if np.all(np.abs(phases) <= 2 * math.pi + 1e-9) and float(np.ptp(phases)) > 1.0:
        # degrees that never leave ±6.3 over a run (and across probes mounted apart) are radians
        raise VectorTableError(f"{path}, column {header[next(pair[1] for v in probes.values() for pair in v.values())]!r}: "
                               f"every phase lies within ±{2 * math.pi:.4g} (from {_num(phases.min())} to "
                               f"{_num(phases.max())}): radians? Give the phases in degrees")
    t = None
    if t_idx is not None and labels is not None:
        t = data[:, t_idx].astype(float)  # each run its own clock: no order across runs
    elif t_idx is not None:
        t = data[:, t_idx].astype(float)
        step = np.diff(t)
        if (step <= 0).any():
            r = int(np.argmax(step <= 0)) + 1
            raise VectorTableError(f"{path}, line {lines[r]}, column {header[t_idx]!r}: time {_num(t[r])} does not "
                                   f"increase (previous {_num(t[r - 1])})")
        revs = float(np.sum(0.5 * (speed[1:] + speed[:-1]) * step)) / (2 * math.pi)
        if revs < 0.5 * (len(t) - 1):
            raise VectorTableError(f"{path}, column {header[t_idx]!r}: the run lasts {revs:.3g} revolutions "
                                   f"(t {_num(t[0])} to {_num(t[-1])} s at {rpm.min():.4g}-{rpm.max():.4g} rpm) for "
                                   f"{len(t)} rows, each tracked over at least one revolution: is the time in seconds "
                                   "(not ms or µs)?")
        if revs > MAX_REVOLUTIONS:
            raise VectorTableError(f"{path}, column {header[t_idx]!r}: the run would last {revs:.4g} revolutions "
                                   f"(t {_num(t[0])} to {_num(t[-1])} s at {rpm.min():.4g}-{rpm.max():.4g} rpm), beyond "
                                   f"{MAX_REVOLUTIONS:g}: is the time in seconds (not ms or µs)?")
    else:
        notes.append("no time column: the synchronous response is taken as quasi-steady")
        if not (np.all(np.diff(speed) > 0) or np.all(np.diff(speed) < 0)):
            # quasi-steady rows stand on their own: order them by speed (the noise floor and
            # the start values read neighbouring rows)
            order = np.argsort(speed, kind="stable")
            data, lines = data[order], lines[order]
            speed = speed[order]
            notes.append("rows sorted by speed (the table's speeds neither rise nor fall throughout)")
    names = tuple(probes)
    vectors = {}
    for n in sorted({n for v in probes.values() for n in v}):
        arr = np.full((data.shape[0], len(names)), np.nan + 0j)
        for j, name in enumerate(names):
            if n in probes[name]:
                a, p = probes[name][n]
                arr[:, j] = from_phase(data[:, a] * to_peak, data[:, p], phase)
        vectors[n] = arr
    ang = None
    if angles is not None:
        missing = [p for p in names if p not in angles]
        if missing:
            raise VectorTableError(f"{path}: probe(s) {missing} of the table are not in the rig description "
                                   f"(it has {sorted(angles)})")
        ang = np.radians([angles[p] for p in names])
        # the probes of one plane see one orbit: one whose 1X stays far under the others' reads
        # noise alone (the waveforms' check, measurements.probes)
        from .probes import quiet_probe

        top = np.nanmax(np.abs(vectors[1]), axis=0) / to_peak  # in the file's measure
        quiet = quiet_probe(dict(zip(names, top.tolist(), strict=True)))
        if quiet:
            raise VectorTableError(f"{path}, column {quiet[0] + '_amp'!r}: its largest 1X amplitude is {quiet[1]}")
    runs = None
    if labels is not None:
        runs = []
        for line in lines:
            lab = labels.get(int(line), "")
            if not lab:
                raise VectorTableError(f"{path}, line {int(line)}, column {run_column!r}: empty run label")
            runs.append(lab)
        runs = tuple(runs)
    return VectorTable(speed=speed, t=t, probes=names, vectors=vectors, amp_unit=amp_unit, angles=ang,
                       source=str(path), notes=tuple(notes), runs=runs,
                       lines=tuple(int(x) for x in lines))


def _table_column(name: str) -> bool:
    """A column the table reader reads: the speed, the time, an amplitude or a phase."""
    low = name.strip().lower()
    return (low in SPEED_COLUMNS or low in TIME_COLUMNS
            or re.search(r"(^|_)(amp|phase_deg)(_[123]x)?$", low) is not None)


def _text_column(path: Path, name: str) -> tuple[list[str], dict[int, str]]:
    """The header and one column read as text: file line (as :func:`~rotor_env.measurements.files.read_table`
    numbers them) -> the cell, stripped.  A number is its text (``1`` stays ``1``)."""
    if path.suffix == ".parquet":
        try:
            import pyarrow.parquet as pq

            table = pq.read_table(path)
        except Exception as exc:
            raise VectorTableError(f"{path}: not a readable Parquet file ({exc})") from None
        header = list(table.column_names)
        match = [h for h in header if h.strip().lower() == name.lower()]
        if not match:
            raise VectorTableError(f"{path}: no {name!r} column (found columns {header})")
        cells = table.column(match[0]).to_pylist()
        return header, {r + 2: ("" if c is None else str(c).strip()) for r, c in enumerate(cells)}
    try:
        from .files import csv_dialect

        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh, delimiter=csv_dialect(path).delimiter)
            header = [h.strip() for h in next(reader, [])]
            match = [j for j, h in enumerate(header) if h.lower() == name.lower()]
            if not match:
                raise VectorTableError(f"{path}: no {name!r} column (found columns {header})")
            j = match[0]
            out = {}
            for row in reader:
                if not row or all(not c.strip() for c in row):
                    continue
                out[reader.line_num] = row[j].strip() if j < len(row) else ""
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise VectorTableError(f"{path}: cannot read the file ({exc})") from None
    return header, out


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
