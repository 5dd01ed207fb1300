"""Keyphasor: once-per-revolution pulses -> spin angle, speed and acceleration.

A keyphasor probe sees a notch (or a projection) on the shaft once per turn.  Each
pulse's leading edge is found where the signal crosses a threshold (default halfway
between the signal's low and high levels, the 0.1th and 99.9th percentiles), the time
interpolated linearly between the two samples around the crossing.  A sampled edge is
only known to within a sample (a square pulse: +-dt/2, 0.1 rad at 3000 rpm and 5 kHz),
and that jitter would put a false wobble into the angle, the speed and every order-
tracked vector.  A real keyphasor's edge takes a few samples (a probe tip a few
millimetres wide crossing a notch), and the interpolated crossing is then far finer than
a sample; smoothing the pulse times would bias a fast start-up's angle more than it
removes (tried: a local cubic over 11 turns put 0.04 rad into the first turns), so the
angle is the cubic spline through ``(edge k, 2 pi k)`` (continuous speed and
acceleration).  Sample fast enough that ``speed * dt / 2`` is small where it matters.  The record is cut to the span between the first and the last pulse.
The leading edge is the transition into the pulse's short state: a notch gives a brief
dip, a projection a brief rise — the state the signal spends less time in.  The state
changes with hysteresis, as a comparator's (Schmitt trigger): into the pulse only past
the threshold plus :data:`HYSTERESIS` of the signal's swing, out of it only past the
threshold minus as much, so noise on the keyphasor (0.3 V on a 5 V pulse: a few crossings
at every edge, read as extra pulses) does not chatter; the edge's time is still the
threshold's last crossing before the pulse is entered (a clean edge: the same time as
without the band).

A spurious pulse (a spike of interference on the keyphasor, a ringing edge) splits one
revolution in two: where the two parts together are a revolution as its neighbours say
(:data:`SPURIOUS_RATIO`) and the pulse is one of few (:data:`MAX_SPURIOUS_SHARE`), it is
dropped and said in the record's notes (:func:`spurious_pulse`); otherwise the checks below
refuse the record.

Checks (a clear error naming the file, column, time and line): too few pulses; a
revolution twice as long as its neighbours say (a missed pulse) or half as long (a
double trigger, noise): its period times the speed its neighbours' line predicts,
over 2 pi, outside [0.6, 1.6] (a start from rest, whose periods shrink fast, passes).
A train that starts missing every other pulse (or comes back) is a step in the pulse rate
that the two-sided neighbours half see: each revolution is also set against the line
through the three before it (a speed linear in time, a constant acceleration from or to
rest included, is extrapolated exactly), outside the same [0.6, 1.6] an error naming it.
A train that misses every other pulse all through is regular, at half the shaft's rate:
the periods cannot show it, the probes do (:func:`check_once_per_turn`): the shaft's own
once-per-turn vibration (unbalance, runout, always there) then comes out at order 2 of
the pulses' angle and their order 1 holds nothing but noise.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

__all__ = ["SPIN_KNOT_REVOLUTIONS", "KeyphasorError", "KeyphasorTracker", "SpinFit", "check_once_per_turn",
           "check_periods", "drop_spurious_pulses", "order_amplitudes", "pulse_edges", "smooth_spin", "spin_fit",
           "spin_from_pulses", "spurious_note", "spurious_pulse"]

MIN_PULSES = 5
#: a revolution this much longer (shorter) than its neighbours is a missed (extra) pulse
PERIOD_RATIO = (0.6, 1.6)
#: a pulse is spurious where dropping it leaves a revolution this close to what its
#: neighbours say (its two parts were irregular)
SPURIOUS_RATIO = (0.85, 1.18)
#: at most this share of a record's pulses is dropped as spurious (at least one): more is a
#: keyphasor signal to look at, refused as irregular
MAX_SPURIOUS_SHARE = 0.02
#: the trigger's hysteresis each side of the threshold, a share of the signal's swing (the
#: 0.1 to 99.9 % levels): the pulse is entered past threshold + 0.2 swing, left past
#: threshold - 0.2 swing (noise must reach a fifth of the swing to chatter)
HYSTERESIS = 0.2


def _band(lo: float, hi: float, thr: float) -> float:
    """The trigger's hysteresis for levels ``lo``, ``hi`` and threshold ``thr`` (a given
    threshold near a level narrows it: both of its ends stay inside the swing)."""
    return 0.999 * min(HYSTERESIS * (hi - lo), hi - thr, thr - lo)


def _schmitt_edges(t: np.ndarray, y: np.ndarray, thr: float, band: float, *, armed: bool = False
                   ) -> tuple[np.ndarray, np.ndarray, bool, int]:
    """Leading edges of ``y`` (the pulse is ``y > thr``) with hysteresis ``band``: where the
    trigger enters the pulse (``y`` above ``thr + band`` since it was last below
    ``thr - band``), the first sample after the threshold's last crossing before each entry
    and the crossing's time (linear between the two samples around it), the trigger's
    state after the last sample, and the first sample of the tail an edge may still start
    from (a sample at or below ``thr`` after which the trigger has not entered a pulse;
    ``len(y)`` when none): a stream keeps that tail for its next chunk.  ``armed``: the
    trigger was in a pulse before ``y[0]``."""
    n = len(y)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0), armed, 0
    level = np.where(y > thr + band, 1, np.where(y < thr - band, 0, -1))
    # the trigger's state: the last definite level (-1: still the state before the samples)
    idx = np.where(level >= 0, np.arange(n), -1)
    last = np.maximum.accumulate(idx)
    state = np.where(last >= 0, level[np.maximum(last, 0)], int(armed)).astype(bool)
    before = np.concatenate([[armed], state[:-1]])
    m = np.nonzero(state & ~before)[0]
    # the threshold's last crossing before each entry: the last sample at or below it
    low = np.maximum.accumulate(np.where(y <= thr, np.arange(n), -1))
    j = low[m]
    j = j[j >= 0]  # an entry with no sample below the threshold in these samples: not timed
    frac = (thr - y[j]) / (y[j + 1] - y[j])
    times = t[j] + frac * (t[j + 1] - t[j])
    tail = n
    if not state[-1] and low[-1] >= 0:
        tail = int(low[-1])
    return j + 1, times, bool(state[-1]), tail


class KeyphasorError(ValueError):
    """Keyphasor pulses that cannot give the spin angle (``line``: the file line, where known)."""

    line: int | None = None


def period_ratio(edges: np.ndarray, i: int) -> float | None:
    """Revolution ``i`` (edge ``i`` to ``i + 1``) against its neighbours: its period times the
    speed the line through the neighbours' speeds predicts at its middle, over 2 pi (``None``:
    fewer than two neighbours).

    A start from rest (speed growing from zero) is smooth, a missed pulse halves the speed
    of its revolution, a double trigger doubles it in the two halves it makes -- so the
    neighbours are the 2nd and 3rd on each side, past a partner half.  Revolution ``i``
    needs the edges up to ``i + 4`` (or the end of the record).
    """
    n_periods = len(edges) - 1
    nb = [j for j in (i - 3, i - 2, i + 2, i + 3) if 0 <= j < n_periods]
    if len(nb) < 2:
        return None
    period = np.diff(edges)
    speed = 2.0 * math.pi / period[nb]
    mid = 0.5 * (edges[np.array(nb) + 1] + edges[nb])
    slope, icept = np.polyfit(mid, speed, 1)
    predicted = slope * 0.5 * (edges[i] + edges[i + 1]) + icept
    return float(period[i] * predicted / (2.0 * math.pi)) if predicted > 0 else math.inf


def period_ratio_before(edges: np.ndarray, i: int) -> float | None:
    """Revolution ``i`` against the three before it: its period times the speed the line
    through their speeds predicts at its middle, over 2 pi (``None``: fewer than three before).
    A step of the pulse rate by two (pulses from then on every other turn) is 2, a return 0.5."""
    if i < 3:
        return None
    nb = np.arange(i - 3, i)
    period = np.diff(edges[i - 3 : i + 2])
    speed = 2.0 * math.pi / period[:3]
    mid = 0.5 * (edges[nb + 1] + edges[nb])
    slope, icept = np.polyfit(mid, speed, 1)
    predicted = slope * 0.5 * (edges[i] + edges[i + 1]) + icept
    return float(period[3] * predicted / (2.0 * math.pi)) if predicted > 0 else math.inf


def _times(ratio: float) -> str:
    """``0.48x``; a ratio that is not finite (neighbours a sample apart) in words."""
    return f"{ratio:.2f}x" if math.isfinite(ratio) else "out of all proportion to"


def spurious_pulse(edges: np.ndarray, candidates, *, regular: int | None = None) -> int | None:
    """Of the pulses ``candidates`` (indices into ``edges``, neither the first nor the last),
    the one whose removal leaves the revolution it merges within :data:`SPURIOUS_RATIO` of its
    neighbours, the closest to them; with ``regular``, only where that revolution (before
    the candidate) is then no longer irregular.  ``None`` where none does."""
    best, best_gap = None, math.inf
    for c in candidates:
        if not 0 < c < len(edges) - 1:
            continue
        trial = np.delete(edges, c)
        ratio = period_ratio(trial, c - 1)
        if ratio is None or not SPURIOUS_RATIO[0] <= ratio <= SPURIOUS_RATIO[1] or abs(ratio - 1.0) >= best_gap:
            continue
        if regular is not None and _irregular(trial, regular):
            continue
        best, best_gap = c, abs(ratio - 1.0)
    return best


def _irregular(edges: np.ndarray, i: int) -> bool:
    ratio = period_ratio(edges, i)
    if ratio is not None and not PERIOD_RATIO[0] <= ratio <= PERIOD_RATIO[1]:
        return True
    ratio = period_ratio_before(edges, i)
    return ratio is not None and not PERIOD_RATIO[0] <= ratio <= PERIOD_RATIO[1]


def drop_spurious_pulses(edges: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """``edges`` without the spurious pulses (module docstring) and the indices (in
    ``edges``) of those dropped; at most :data:`MAX_SPURIOUS_SHARE` of them (the irregular
    revolutions left are :func:`check_periods`' to refuse)."""
    limit = max(1, int(MAX_SPURIOUS_SHARE * len(edges)))
    keep = np.ones(len(edges), dtype=bool)
    out = np.asarray(edges, dtype=float)
    dropped: list[int] = []
    i = 0
    while i < len(out) - 1 and len(dropped) < limit:
        if _irregular(out, i):
            c = spurious_pulse(out, (i + 1, i))  # the irregular revolution's two pulses
            if c is not None:
                dropped.append(int(np.nonzero(keep)[0][c]))
                keep[dropped[-1]] = False
                out = np.delete(out, c)
                i = max(c - 4, 0)  # the revolutions that read the dropped one, again
                continue
        i += 1
    return out, sorted(dropped)


def check_periods(edges: np.ndarray, revolutions, threshold: float, *, where: str,
                  line_of: Callable[[int], int] | None = None, first_pulse: int = 0) -> None:
    """The missing/extra-pulse check of :func:`pulse_edges` (and :class:`KeyphasorTracker`):
    each revolution ``i`` of ``revolutions`` whose :func:`period_ratio` is outside
    :data:`PERIOD_RATIO` is an error naming its time and (``line_of(i)``) the file line of
    the first sample after its leading edge.  ``first_pulse``: the number in the record of
    ``edges[0]`` (a tracker holds a window of the edges)."""
    for i in revolutions:
        ratio, against = period_ratio(edges, i), "its neighbours"
        if ratio is None or PERIOD_RATIO[0] <= ratio <= PERIOD_RATIO[1]:
            # both sides fit (or too few): a step in the pulse rate shows against the side before
            ratio, against = period_ratio_before(edges, i), "the three revolutions before it"
            if ratio is None or PERIOD_RATIO[0] <= ratio <= PERIOD_RATIO[1]:
                continue
            kind = ("pulses from here at half the shaft's rate: every other pulse missing" if ratio > 1
                    else "pulses from here at twice the rate: extra pulses (double trigger or noise)")
        else:
            kind = "missing pulse" if ratio > 1 else "extra pulse (double trigger or noise)"
        line = f", line {line_of(i)}" if line_of is not None else ""
        period = edges[i + 1] - edges[i]
        n = first_pulse + i
        exc = KeyphasorError(
            f"{where}{line}: irregular pulses at t = {edges[i]:.6g}: a revolution of {period:.4g} between "
            f"pulses {n + 1} and {n + 2}, {_times(ratio)} {against} ({kind}); check the threshold "
            f"(now {threshold:g}) or the keyphasor signal"
        )
        exc.line = line_of(i) if line_of is not None else None
        raise exc


def pulse_edges(t: np.ndarray, signal: np.ndarray, threshold: float | None = None, *, where: str = "keyphasor",
                lines: np.ndarray | None = None, notes: list[str] | None = None) -> np.ndarray:
    """Times of the pulses' leading edges (see the module docstring); ``notes``: where given,
    a sentence is appended for the spurious pulses dropped."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(signal, dtype=float)
    # 0.1 / 99.9 %: a narrow notch (1 % of a turn) still reaches its level
    lo, hi = np.percentile(x, [0.1, 99.9])
    if not hi > lo:
        raise KeyphasorError(f"{where}: the signal is constant ({lo:g}): no pulses")
    thr = 0.5 * (lo + hi) if threshold is None else float(threshold)
    if not lo < thr < hi:
        raise KeyphasorError(f"{where}: threshold {thr:g} is outside the signal's range [{lo:g}, {hi:g}]")
    # the pulse is the short state: a projection is high briefly, a notch low briefly
    sign = 1.0 if (x > thr).mean() < 0.5 else -1.0
    after, edges, _, _ = _schmitt_edges(t, sign * x, sign * thr, _band(lo, hi, thr))
    if len(after) < MIN_PULSES:
        raise KeyphasorError(f"{where}: only {len(after)} pulses found (threshold {thr:g}); at least {MIN_PULSES} "
                             "revolutions are needed")
    edges0 = edges
    edges, dropped = drop_spurious_pulses(edges)
    if dropped and notes is not None:
        notes.append(spurious_note([(float(edges0[k]), int(lines[after[k]]) if lines is not None else None)
                                    for k in dropped]))
    after = np.delete(after, dropped)
    check_periods(edges, range(len(edges) - 1), thr, where=where,
                  line_of=(lambda i: int(lines[after[i]])) if lines is not None else None)
    return edges


def spurious_note(pulses: list[tuple[float, int | None]]) -> str:
    """The record's note on the spurious pulses dropped: ``(time in s, file line or None)``."""
    where = "; ".join(f"t = {tk:.6g} s" + (f", line {ln}" if ln is not None else "") for tk, ln in pulses[:5])
    more = f" and {len(pulses) - 5} more" if len(pulses) > 5 else ""
    n = len(pulses)
    return (f"{n} spurious keyphasor pulse{'s' if n > 1 else ''} dropped ({where}{more}): each split a revolution "
            "into two parts that add up to the one its neighbours say (interference on the keyphasor, a ringing edge)")


#: the probes' order-1 amplitude (median over revolutions) below this share of their order-2
#: one: no once-per-turn vibration at the pulses' rate, the pulses come every other turn
#: (a real rotor's unbalance keeps its 1X well above a fifth of its 2X, even a misaligned one's)
MIN_ORDER1_SHARE = 0.2


def order_amplitudes(phi: np.ndarray, signal: np.ndarray, orders: tuple[int, ...] = (1, 2)) -> np.ndarray:
    """Amplitude of each order of ``signal`` per whole revolution of ``phi`` (rows: revolutions,
    columns: ``orders``): the mean over the revolution's samples of ``x e^{-i k phi}``, times 2,
    the revolution's mean removed first (a probe's gap)."""
    turn = np.floor((phi - phi[0]) / (2.0 * math.pi)).astype(np.int64)
    full = turn < turn[-1]  # the last sample starts a revolution it does not finish
    turn, ph, x = turn[full], phi[full], np.asarray(signal, dtype=float)[full]
    if not turn.size:
        return np.zeros((0, len(orders)))
    count = np.bincount(turn)
    ok = count > 0
    x = x - (np.bincount(turn, x) / np.maximum(count, 1))[turn]
    out = np.empty((int(ok.sum()), len(orders)))
    for j, k in enumerate(orders):
        re = np.bincount(turn, x * np.cos(k * ph))[ok]
        im = np.bincount(turn, x * np.sin(k * ph))[ok]
        out[:, j] = 2.0 * np.hypot(re, im) / count[ok]
    return out


def check_once_per_turn(phi: np.ndarray, signals: dict[str, np.ndarray], *, where: str,
                        lines: np.ndarray | None = None) -> None:
    """Refuse a pulse train at half the shaft's rate (see the module docstring): the probes
    together (``signals``: name -> reading at the samples of ``phi``) show a median order-1
    amplitude below :data:`MIN_ORDER1_SHARE` of their order-2 one.  ``lines``: the file line
    of each sample (named in the error)."""
    a1 = a2 = 0.0
    for x in signals.values():
        amp = order_amplitudes(phi, x)
        if amp.shape[0] < MIN_PULSES:
            return
        a1 += float(np.median(amp[:, 0]))
        a2 += float(np.median(amp[:, 1]))
    if not a2 > 0 or a1 >= MIN_ORDER1_SHARE * a2:
        return
    span = f", lines {int(lines[0])}-{int(lines[-1])}" if lines is not None and len(lines) else ""
    raise KeyphasorError(
        f"{where}{span}: the probes ({', '.join(signals)}) vibrate at twice the keyphasor's rate all through the "
        f"run: their 1X is {a1 / a2:.2f} of their 2X (a shaft's once-per-turn vibration is at least "
        f"{MIN_ORDER1_SHARE:g}): pulses at half the shaft's rate, every other pulse missing? Check the keyphasor "
        "signal and its threshold (the speeds would come out halved)")


def spin_from_pulses(t: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(inside, phi, speed, acceleration)`` at the samples ``t[inside]`` between the first and last edge."""
    spline = CubicSpline(edges, 2.0 * math.pi * np.arange(len(edges)))
    inside = (t >= edges[0]) & (t <= edges[-1])
    ti = t[inside]
    return inside, spline(ti), spline(ti, 1), spline(ti, 2)


#: samples gathered before the threshold and the pulse's polarity are fixed (at least two
#: leading edges must be among them, so a whole revolution shows which state is short)
LEVEL_SAMPLES = 2048
#: a stream whose first samples this many hold no two pulses has no usable keyphasor
MAX_LEVEL_SAMPLES = 1 << 20
#: edges either side of a revolution's two in its local spline (the not-a-knot spline's
#: end conditions fade by 2 - sqrt(3) = 0.27 a knot: 0.27^3 = 2 % of the end effect, on
#: the third difference of the pulse times, which a smooth speed keeps tiny); the
#: missing/extra-pulse check needs the same three revolutions ahead
SPLINE_HALF_WINDOW = 3
#: fewer raw samples a revolution than this: the pulse edges (and the 1X) are aliased
MIN_SAMPLES_PER_TURN = 8


class KeyphasorTracker:
    """The spin of a keyphasor stream, causal, chunk by chunk (what :func:`pulse_edges` and
    :func:`spin_from_pulses` do with a whole record).

    ``push(t, signal, payload, lines)`` takes the next samples (``payload``: rows carried
    along, e.g. the probes) and returns the samples now known as ``(t, phi, speed,
    acceleration, payload, lines)``; ``finish()`` returns the rest at the end.

    - The threshold (``threshold``, else halfway between the 0.1/99.9 % levels) and the
      pulse's polarity (the short state) are fixed from the first samples (at least
      :data:`LEVEL_SAMPLES` and two leading edges): a threshold that followed the signal
      would move the edges and put a wobble into the angle.
    - An edge between two chunks is found from the samples kept from the chunk before (from
      the threshold's last crossing on, while the pulse is not yet entered past the band).
    - Revolution ``k`` (edge ``k`` to ``k + 1``) is handed out once edge ``k + 4`` is known:
      its missing/extra-pulse check (:func:`check_periods`, the batch path's) reads the
      2nd and 3rd revolutions on each side (so a sample is never handed out before its
      revolution passed the check), and its angle is the cubic spline through
      ``(edge j, 2 pi j)`` for the edges ``k - 3 .. k + 4`` (local; the whole record's
      spline differs from it by the end conditions' fading remainder).  The samples
      are held back until then: four revolutions.
    - Samples before the first edge and after the last are dropped, as in the batch path.
    """

    def __init__(self, threshold: float | None = None, *, where: str = "keyphasor") -> None:
        self.where = where
        self.threshold = threshold
        self._fixed = False
        self._pulse_high = True
        self._level: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        # the samples of the chunk before an edge may still start from (the threshold crossed,
        # the pulse not yet entered past the hysteresis band), and the trigger's state
        self._tail = (np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64))
        self._armed = False
        self._band = 0.0
        self._edges = np.zeros(0)  # a window of the edges; edges[0] is pulse number _e0
        self._edge_lines = np.zeros(0, dtype=np.int64)
        self._e0 = 0
        self._n_edges = 0
        self._next = 0  # the next revolution to hand out (and to check)
        self._dt = math.nan
        self._held_t = np.zeros(0)
        self._held_p: np.ndarray | None = None
        self._held_lines = np.zeros(0, dtype=np.int64)
        #: an irregular revolution found: the samples before it were handed out, none after
        self.error: KeyphasorError | None = None
        #: the spurious pulses dropped: (time, file line of the sample after the edge)
        self.dropped: list[tuple[float, int]] = []

    @property
    def edges_seen(self) -> int:
        return self._n_edges

    # ------------------------------------------------------------------ input
    def push(self, t: np.ndarray, signal: np.ndarray, payload: np.ndarray, lines: np.ndarray):
        if self.error is not None:
            raise self.error
        t = np.asarray(t, dtype=float)
        x = np.asarray(signal, dtype=float)
        payload = np.asarray(payload, dtype=float).reshape(len(t), -1)
        if self._held_p is None:
            self._held_p = np.zeros((0, payload.shape[1]))
        if len(t) > 1 and math.isnan(self._dt):
            self._dt = float(t[1] - t[0])
        if not self._fixed:
            self._level.append((t, x, payload, lines))
            n = sum(len(c[0]) for c in self._level)
            if n < LEVEL_SAMPLES or not self._try_levels(final=False, limit=n >= MAX_LEVEL_SAMPLES):
                return self._empty()
            parts = self._level
            self._level = []
            t, x, payload, lines = (np.concatenate([c[i] for c in parts]) for i in range(4))
        self._find_edges(t, x, lines)
        self._hold(t, payload, lines)
        return self._release(final=False)

    def finish(self):
        """The samples up to the last edge (the last revolutions checked with the neighbours they have)."""
        if self.error is not None:
            raise self.error
        if not self._fixed:
            if not self._level:
                return self._empty()
            parts, self._level = self._level, []
            t, x, payload, lines = (np.concatenate([c[i] for c in parts]) for i in range(4))
            self._levels(x, final=True)
            self._find_edges(t, x, lines)
            self._hold(t, payload, lines)
        if self._n_edges < MIN_PULSES:
            raise KeyphasorError(f"{self.where}: only {self._n_edges} pulses found (threshold {self.threshold:g}); "
                                 f"at least {MIN_PULSES} revolutions are needed")
        return self._release(final=True)

    # ------------------------------------------------------------------ steps
    def _levels(self, x: np.ndarray, *, final: bool) -> bool:
        """Fix the threshold and polarity from the samples ``x``; False: not yet decidable."""
        lo, hi = np.percentile(x, [0.1, 99.9])
        if not hi > lo:
            if final:
                raise KeyphasorError(f"{self.where}: the signal is constant ({lo:g}): no pulses")
            return False
        thr = 0.5 * (lo + hi) if self.threshold is None else float(self.threshold)
        if not lo < thr < hi:
            # a given threshold outside the levels seen so far: no pulse yet (a slow start)
            if final:
                raise KeyphasorError(f"{self.where}: threshold {thr:g} is outside the signal's range "
                                     f"[{lo:g}, {hi:g}]")
            return False
        high = x > thr
        pulse_high = bool(high.mean() < 0.5)
        state = high if pulse_high else ~high
        if not final and np.count_nonzero(~state[:-1] & state[1:]) < 2:
            return False
        self.threshold, self._pulse_high, self._fixed = thr, pulse_high, True
        self._band = _band(lo, hi, thr)
        return True

    def _try_levels(self, *, final: bool, limit: bool) -> bool:
        x = np.concatenate([c[1] for c in self._level])
        ok = self._levels(x, final=final)
        if not ok and limit:
            raise KeyphasorError(f"{self.where}: no two keyphasor pulses in the first {len(x)} samples")
        return ok

    def _find_edges(self, t: np.ndarray, x: np.ndarray, lines: np.ndarray) -> None:
        if not len(t):
            return
        tt, xx, ll = (np.concatenate([a, b]) for a, b in zip(self._tail, (t, x, lines), strict=True))
        sign = 1.0 if self._pulse_high else -1.0
        after, new, armed, tail = _schmitt_edges(tt, sign * xx, sign * self.threshold, self._band,
                                                 armed=self._armed)
        # the tail is re-read with the next chunk, from the state the trigger had there
        self._armed = armed if tail == len(tt) else False
        # a signal that stays inside the band keeps no more than MAX_LEVEL_SAMPLES (memory bounded)
        tail = max(tail, len(tt) - MAX_LEVEL_SAMPLES)
        self._tail = (tt[tail:], xx[tail:], ll[tail:])
        if not len(new):
            return
        before = self._edges[-1:] if len(self._edges) else np.zeros(0)
        periods = np.diff(np.concatenate([before, new]))
        if periods.size and np.isfinite(self._dt):
            short = periods / self._dt < MIN_SAMPLES_PER_TURN
            if short.any():
                j = int(np.argmax(short))
                m = j + 1 - len(before)  # the new edge ending the short revolution
                exc = KeyphasorError(f"{self.where}, line {ll[after[m]]}: only {periods[j] / self._dt:.1f} samples "
                                     f"per revolution at t = {new[m]:.6g}: sample faster")
                exc.line = int(ll[after[m]])
                raise exc
        self._edges = np.concatenate([self._edges, new])
        self._edge_lines = np.concatenate([self._edge_lines, ll[after]])
        self._n_edges += len(new)

    def _hold(self, t: np.ndarray, payload: np.ndarray, lines: np.ndarray) -> None:
        if self._n_edges == 0:
            return  # before the first pulse: no angle, dropped as in the batch path
        if self._next == 0 and not self._held_t.size:
            keep = t >= self._edges[0]
            t, payload, lines = t[keep], payload[keep], lines[keep]
        self._held_t = np.concatenate([self._held_t, t])
        self._held_p = np.concatenate([self._held_p, payload])
        self._held_lines = np.concatenate([self._held_lines, lines])

    def _release(self, *, final: bool):
        edges, e0 = self._edges, self._e0
        last = self._n_edges - 1  # number of the last edge known
        # revolutions [next, stop) can go: those whose edge k + 4 is known (all, at the end)
        stop = last if final else last - SPLINE_HALF_WINDOW
        # the missing/extra-pulse check of every revolution handed out (its neighbours are
        # known); at an irregular one, the revolutions before it go out and the error waits
        # in ``error`` (the caller processes them first)
        i = self._next
        while i < stop:
            try:
                check_periods(edges, (i - e0,), float(self.threshold), where=self.where,
                              line_of=lambda j: int(self._edge_lines[j]), first_pulse=e0)
            except KeyphasorError as exc:
                c = self._spurious_ahead(i - e0)
                if c is None:
                    self.error, stop = exc, i
                    break
                # a spurious pulse not yet handed out: dropped, the revolution checked again
                self.dropped.append((float(edges[c]), int(self._edge_lines[c])))
                self._edges, self._edge_lines = np.delete(edges, c), np.delete(self._edge_lines, c)
                edges = self._edges
                self._n_edges -= 1
                last -= 1
                stop = min(stop, last if final else last - SPLINE_HALF_WINDOW)
                continue
            i += 1
        if stop <= self._next:
            return self._empty()
        t_end = edges[stop - e0]
        n_out = int(np.searchsorted(self._held_t, t_end, side="right" if final else "left"))
        t = self._held_t[:n_out]
        phi, speed, accel = np.empty(n_out), np.empty(n_out), np.empty(n_out)
        rev = np.searchsorted(edges, t, side="right") - 1 + e0  # revolution of each sample
        rev = np.minimum(rev, last - 1)
        for k in range(self._next, stop):
            sel = np.nonzero(rev == k)[0]
            if not sel.size:
                continue
            lo = max(k - SPLINE_HALF_WINDOW, 0)
            hi = min(k + 1 + SPLINE_HALF_WINDOW, last)
            spline = CubicSpline(edges[lo - e0 : hi - e0 + 1], 2.0 * math.pi * np.arange(lo, hi + 1))
            ts = t[sel]
            phi[sel], speed[sel], accel[sel] = spline(ts), spline(ts, 1), spline(ts, 2)
        out = (t, phi, speed, accel, self._held_p[:n_out], self._held_lines[:n_out])
        self._held_t = self._held_t[n_out:]
        self._held_p = self._held_p[n_out:]
        self._held_lines = self._held_lines[n_out:]
        self._next = stop
        # keep the edges the next revolutions' splines and checks read
        drop = max(0, stop - SPLINE_HALF_WINDOW - e0)
        self._edges = self._edges[drop:]
        self._edge_lines = self._edge_lines[drop:]
        self._e0 += drop
        return out

    def _spurious_ahead(self, j: int) -> int | None:
        """A spurious pulse (:func:`spurious_pulse`) among those ahead of revolution ``j`` of
        the window that its check reads (none handed out yet), whose removal leaves that
        revolution regular: the batch path's :func:`drop_spurious_pulses`, causal; ``None``
        where none is, or the record's share of dropped pulses is used up."""
        if len(self.dropped) >= max(1, int(MAX_SPURIOUS_SHARE * self._n_edges)):
            return None
        return spurious_pulse(self._edges, range(j + 1, j + 2 + SPLINE_HALF_WINDOW), regular=j)

    def _empty(self):
        p = self._held_p.shape[1] if self._held_p is not None else 0
        z = np.zeros(0)
        return z, z, z, z, np.zeros((0, p)), np.zeros(0, dtype=np.int64)


#: revolutions between two knots of the spin's least-squares spline: the candidates, the
#: one with the smallest BIC over the pulse times is taken.  The long spacings matter where a
#: keyphasor edge is sharper than a sample: at 2.5 kHz and 5000 rpm each pulse jitters by up
#: to 60 mrad, and a steady run-up is one cubic over hundreds of revolutions (with 64 as the
#: longest, a misaligned rotor at 0.1 um kept 4 % of the noise floor's RMS above it, and a
#: 0.03 % stiffness asymmetry was named to fit that 1X)
SPIN_KNOT_REVOLUTIONS = (4, 8, 16, 32, 64, 128, 256)


def smooth_spin(t: np.ndarray, phi: np.ndarray, *, with_error: bool = False):
    """The spin angle and speed from a least-squares cubic spline through the pulse times.

    The keyphasor's angle interpolates each pulse's time, and a pulse time is only known to a
    fraction of a sample (an edge that rises within one or two samples): at a few thousand
    rpm and 10 kHz that is a few mrad of angle, which the model turns into a 1X error of a few
    mrad times the response — above the noise of a good probe.  The output-error fit needs the
    angle of a shaft whose speed changes smoothly over a run-up or coast-down: a least-squares
    spline with a knot every few revolutions averages the pulses' timing errors and keeps the
    speed's course.  The knot spacing is chosen among :data:`SPIN_KNOT_REVOLUTIONS` by the
    Bayesian information criterion of the pulse angles (a speed that changes faster than a
    spacing — a torsional oscillation, a trip — keeps the finer ones).

    ``with_error``: also the RMS error (rad) of the smoothed angle, ``None`` where it was
    not smoothed: the spline's RMS misfit at the pulses (their angle jitter about it) times
    ``sqrt(p / n)`` (the mean prediction variance of a least-squares fit with ``p``
    coefficients to ``n`` points).  A simulated run through 725-5220 rpm with 1 % keyphasor
    ramps (``rig_simulation``): the per-revolution angle error 26 mrad raw, 2.2-3.9 mrad
    smoothed at 2.5 kHz; 7.7 and 0.47 mrad at 5 kHz; 0.7 and 0.07-0.12 mrad at 10 kHz."""

    fit = spin_fit(t, phi)
    if fit is None:
        return (phi, np.gradient(phi, t), None) if with_error else (phi, np.gradient(phi, t))
    return (fit.spline(t), fit.spline(t, 1), fit.error_rad) if with_error else (fit.spline(t), fit.spline(t, 1))


@dataclass(frozen=True)
class SpinFit:
    """The spin's least-squares spline through the pulses (:func:`smooth_spin`) and what its
    angle's error is: the pulses' angle jitter about it, and the spline space the error of a
    least-squares fit lies in."""

    spline: object            #: scipy BSpline of the angle (rad) against time (s)
    pulse_times: np.ndarray   #: s, the points fitted (the record's two ends first and last)
    jitter_rad: float         #: the pulses' RMS angle misfit about the spline
    #: each point's angle jitter (rad): the misfit's local RMS (a pulse timed to a fraction of a
    #: sample jitters in time, and so in angle by the speed times that: more at speed)
    pulse_jitter: np.ndarray

    @property
    def error_rad(self) -> float:
        """RMS error of the smoothed angle: the jitter times ``sqrt(p / n)`` (the mean
        prediction variance of a least-squares fit with ``p`` coefficients to ``n`` points)."""
        n, p = len(self.pulse_times), len(self.spline.c)
        return self.jitter_rad * math.sqrt(p / n)

    def error_basis(self, t: np.ndarray) -> np.ndarray:
        """``(len(t), p)`` matrix ``L`` such that the smoothed angle's errors at the times ``t``
        are ``L z`` with ``z`` standard normal: independent pulse jitter ``s_k`` through the
        least-squares fit, covariance ``L L' = B(t) M M' B(t)'`` with ``M = (B'B)^-1 B' diag(s)``,
        ``B`` the spline basis at the pulses.  Errors at neighbouring times are nearly the
        same: one smooth curve over a knot interval, not independent noise."""
        from scipy.interpolate import BSpline

        knots, k = self.spline.t, self.spline.k
        x = self.pulse_times
        B = BSpline.design_matrix(x, knots, k).toarray()
        # M M' = (B'B)^-1 B' diag(s^2) B (B'B)^-1: p x p, never n x n (a long record has tens
        # of thousands of pulses)
        C = np.linalg.pinv(B.T @ B)
        Bs = B * self.pulse_jitter[:, None]
        w, V = np.linalg.eigh(C @ (Bs.T @ Bs) @ C)
        root = V * np.sqrt(np.clip(w, 0.0, None))
        Bt = BSpline.design_matrix(np.clip(np.asarray(t, dtype=float), x[0], x[-1]), knots, k).toarray()
        return Bt @ root


def spin_fit(t: np.ndarray, phi: np.ndarray) -> SpinFit | None:
    """The spin's spline (:func:`smooth_spin`): ``None`` where the record is too short to smooth."""
    turns = np.arange(math.ceil(phi[0] / (2 * math.pi)), math.floor(phi[-1] / (2 * math.pi)) + 1)
    if len(turns) < 4 * SPIN_KNOT_REVOLUTIONS[0]:
        return None
    edges = np.interp(2 * math.pi * turns, phi, t)
    # the record's ends pin the spline beyond the first and last pulse (the angle there)
    x = np.concatenate([[t[0]], edges, [t[-1]]])
    y = np.concatenate([[phi[0]], 2 * math.pi * turns, [phi[-1]]])
    best, best_bic, best_err = None, math.inf, None
    for every in SPIN_KNOT_REVOLUTIONS:
        if len(turns) < 3 * every:
            break
        fit = _spin_spline(x, y, edges[every:-every:every])
        if fit is not None and fit[1] < best_bic:
            best, best_bic, best_err = fit
    if best is None:
        return None
    best, _ = _refine_corners(best, best_bic, best_err, x, y, edges)
    e2 = (best(x) - y) ** 2
    # the jitter's local variance: the squared misfit's mean over the neighbouring pulses
    w = np.ones(min(JITTER_WINDOW, len(x)))
    local = np.convolve(e2, w, mode="same") / np.convolve(np.ones_like(e2), w, mode="same")
    return SpinFit(best, x, math.sqrt(float(np.mean(e2))), np.sqrt(local))


#: pulses over which the jitter's local RMS is read (:class:`SpinFit`)
JITTER_WINDOW = 33


#: a pulse the spin's spline misses by more than this many times the pulses' jitter (their
#: misfit's robust spread) lies where the speed's course bends within a knot interval
CORNER_SIGMAS = 5.0
#: rounds of local refinement at most (each halves the knot intervals where the spline misses:
#: from 256 revolutions to 2 in seven)
CORNER_ROUNDS = 8


def _refine_corners(spl, bic: float, err: float, x: np.ndarray, y: np.ndarray, edges: np.ndarray):
    """The spin's spline with knots added where it misses the pulses by far more than their
    jitter: an acceleration that changes within a knot interval (a drive reaching its set
    speed and holding it, a trip, a coast-down starting) -- a uniform spacing chosen for the
    whole run bends too slowly there (a hold at 3000 rpm after a 1000 rpm/s run-up: 14 mrad
    off at the corner, every pulse exact).  The knot intervals around such pulses (and their
    neighbours) are halved, round by round, while the BIC falls."""

    n = len(x)
    for _ in range(CORNER_ROUNDS):
        res = spl(x) - y
        sigma = max(1.4826 * float(np.median(np.abs(res - np.median(res)))), 1e-12)
        inner = spl.t[4:-4]
        # a pulse far off, or a quarter of a knot interval's worth of pulses off to one side
        # together (a corner hidden in the jitter of each pulse shows in their mean; over a
        # whole interval the least-squares fit makes it vanish)
        w = max(2, int(round(0.25 * n / (len(inner) + 1))))
        local = np.convolve(res, np.ones(w) / w, mode="same")
        bad = np.nonzero((np.abs(res) > CORNER_SIGMAS * sigma)
                         | (np.abs(local) > CORNER_SIGMAS * sigma / math.sqrt(w)))[0]
        if not len(bad):
            break
        # the knot intervals around those pulses (and one either side) halved
        bounds = np.concatenate([[x[0]], inner, [x[-1]]])
        hit = np.unique(np.clip(np.searchsorted(bounds, x[bad]) - 1, 0, len(bounds) - 2))
        hit = np.unique(np.clip(np.concatenate([hit - 1, hit, hit + 1]), 0, len(bounds) - 2))
        mids = 0.5 * (bounds[hit] + bounds[hit + 1])
        # an interval keeps at least two pulses on each side of its new knot
        count = np.searchsorted(x, bounds[hit + 1]) - np.searchsorted(x, bounds[hit])
        mids = mids[count >= 4]
        if not len(mids):
            break
        fit = _spin_spline(x, y, np.sort(np.concatenate([inner, mids])))
        if fit is None or not fit[1] < bic:
            break
        spl, bic, err = fit
    return spl, err


def _spin_spline(x: np.ndarray, y: np.ndarray, inner: np.ndarray):
    """The least-squares cubic spline through the pulses ``(x, y)`` with interior knots
    ``inner`` (the record's ends pinned by ``x[0]``, ``x[-1]``), its BIC, and the RMS error of
    its angle (:func:`smooth_spin`); ``None`` where it cannot be fitted."""
    from scipy.interpolate import make_lsq_spline

    n, p = len(x), len(inner) + 4
    try:
        spl = make_lsq_spline(x, y, np.concatenate([[x[0]] * 4, inner, [x[-1]] * 4]), k=3)
    except (ValueError, np.linalg.LinAlgError):
        return None
    rss = float(np.sum((spl(x) - y) ** 2))
    return spl, n * math.log(max(rss / n, 1e-300)) + p * math.log(n), math.sqrt(rss / n * p / n)
