"""What the instruments add to a rig's waveforms, found and taken out before the diagnosis.

Two artefacts that every rig's probes carry and no rotor model holds:

1. **Lines at a fixed frequency.**  Mains pickup (50 or 60 Hz and its harmonics), a pump,
   a fan or a switching supply nearby: a sinusoid whose frequency does not follow the
   shaft.  During a run-up the shaft's 1X sweeps across it; order tracking then sees the
   line as a 1X vector that turns once for every revolution of beat between the two, and
   the 1X fit reads that as a resonance (a healthy rig with 1 um of 50 Hz hum was
   diagnosed with a ``second_mode``).
2. **The track's runout above 2X.**  A scratch, a dent or a magnetic spot under a probe
   (electrical runout) reads as a pattern fixed to the shaft's angle, the same at every
   speed, with harmonics far beyond 2X.  The output-error fit carries each probe's 1X and
   2X runout with every model (:data:`~rotor_env.diagnosis.output_error.OUTPUT_TERMS`:
   those share orders with the unbalance, bow and crack and must be fitted with them);
   orders 3 and up belong to no linear rotor's response away from its own resonances.

**Lines.**  The record is cut into :data:`SEGMENTS` equal stretches; in each, the
Hann-windowed spectrum of every probe over its running median (the local background).  A
frequency is a line where it stands :data:`LINE_RATIO` above that background (a bin of
Gaussian noise does so with probability ``2**-LINE_RATIO``) in every stretch whose shaft 1X
and 2X keep clear of it, and where at least one stretch has no shaft order near it (a shaft
at constant speed keeps its orders at one frequency each: never a line; :func:`find_lines`).
Its frequency is refined (the coherent sum over the stretches), and its complex amplitude
estimated stretch by stretch, a stretch that strays from their median (a fault's harmonic
crossing it) left out; a **deterministic** line has the same amplitude and phase in every
stretch (:data:`MIN_COHERENCE`): the random response of a lightly damped mode excited by
broadband forces, a narrow peak too, has a new phase in every stretch and is left alone.
The line is subtracted over the whole record with its amplitude interpolated between the
stretches' centres (a slowly drifting hum).

**Runout above 2X.**  Each probe's vectors at orders 3..:data:`TOP_RUNOUT_ORDER` are
tracked over windows of a few revolutions; the pattern fixed to the shaft is the median over
the windows (robust to a fault's harmonics, which a rotor shows only near its resonances
or above a clearance).  An order is taken as runout where it is significant
(:data:`RUNOUT_Z` standard errors of the median), relevant (:data:`RUNOUT_RELEVANT` of the
probe's noise) and the *same at low and high speed*: the
slowest and the fastest third of the revolutions give it within :data:`RUNOUT_AGREEMENT`
of its size (plus their standard errors).  A breathing crack under its static load has a
3X at slow roll that the fast revolutions lack, and is left to the model.

Every removal is said in the record's notes, in the rig's unit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["FixedLine", "RunoutHarmonic", "find_lines", "remove_artefacts", "runout_harmonics"]

#: stretches the record is cut into for the line search
SEGMENTS = 8
#: a line's bin stands this many times above the stretch's running-median background
LINE_RATIO = 25.0
#: half-width (bins) of the running median that sets the background
BACKGROUND_BINS = 30
#: a shaft order closer than this many bins (of a stretch) to a frequency hides it in that stretch
ORDER_GUARD_BINS = 6
#: orders of the shaft kept clear of the line search
MAX_ORDER = 12
#: |mean of the stretches' complex amplitudes| / their rms: a deterministic line is near 1
MIN_COHERENCE = 0.8
#: fewest stretches in which a line must be seen clear of the shaft's orders
MIN_CLEAR_SEGMENTS = 3
#: revolutions in a window of the runout search (Hann-weighted, every half window)
WINDOW_REVOLUTIONS = 4
#: highest runout order looked for
TOP_RUNOUT_ORDER = 30
#: a runout order's median vector must be this many of its standard errors from zero
RUNOUT_Z = 6.0
#: low- and high-speed thirds agree within this share of the pattern's size
RUNOUT_AGREEMENT = 0.25
#: an order smaller than this share of the probe's noise (per sample) is left alone: it adds
#: 2 % to the noise's variance (the order tracker's own leakage from a 100 um 1X is 0.01 um)
RUNOUT_RELEVANT = 0.2


@dataclass(frozen=True)
class FixedLine:
    """A sinusoid at a fixed frequency in the probes' readings (not the shaft's)."""

    frequency_hz: float
    coherence: float  #: |mean stretch amplitude| / rms of the stretch amplitudes (1: steady)
    #: the times (s) of the centres of the stretches its amplitude was read in (clear of the
    #: shaft's 1X and 2X, not disturbed) and each probe's complex amplitude there
    #: (``x = Re(a e^{2 pi i f t})``): the line's course, interpolated between them
    centres: np.ndarray
    stretch_amplitudes: dict[str, np.ndarray]

    @property
    def stretches(self) -> int:
        return len(self.centres)

    @property
    def amplitude(self) -> dict[str, float]:
        """Probe -> mean amplitude (zero-to-peak, the readings' unit)."""
        return {nm: float(abs(np.mean(a))) for nm, a in self.stretch_amplitudes.items()}

    def wave(self, t: np.ndarray, probe: str) -> np.ndarray:
        """The line in ``probe``'s reading at the times ``t`` (amplitude interpolated between
        the stretches, held beyond them)."""
        a = self.stretch_amplitudes[probe]
        amp = np.interp(t, self.centres, a.real) + 1j * np.interp(t, self.centres, a.imag)
        return np.real(amp * np.exp(2j * math.pi * self.frequency_hz * t))


@dataclass(frozen=True)
class RunoutHarmonic:
    """One order of a probe's runout pattern (fixed to the shaft angle, lead convention:
    ``x = Re(V e^{i n phi})``)."""

    probe: str
    order: int
    vector: complex
    std_error: float


def _segments(n: int) -> list[tuple[int, int]]:
    bounds = np.linspace(0, n, SEGMENTS + 1).astype(int)
    return [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _near_orders(freqs: np.ndarray, f_lo: float, f_hi: float, guard: float, orders) -> np.ndarray:
    """True where a shaft order of ``orders``, at speeds in ``[f_lo, f_hi]`` (Hz), is within ``guard`` Hz."""
    near = np.zeros(len(freqs), dtype=bool)
    for k in orders:
        near |= (freqs >= k * f_lo - guard) & (freqs <= k * f_hi + guard)
    return near


def _stretch_amplitudes(t: np.ndarray, x: np.ndarray, segs, f: float) -> np.ndarray:
    """Each stretch's complex amplitude of ``f`` (Hann-weighted, phase against absolute time)."""
    out = np.empty(len(segs), dtype=complex)
    for j, (a, b) in enumerate(segs):
        w = np.hanning(b - a)
        out[j] = 2.0 * np.sum(w * x[a:b] * np.exp(-2j * math.pi * f * t[a:b])) / np.sum(w)
    return out


def find_lines(t: np.ndarray, speed_hz: np.ndarray, readings: dict[str, np.ndarray]) -> list[FixedLine]:
    """The fixed-frequency lines in ``readings`` (module docstring).  ``t`` in s, ``speed_hz``
    the shaft's speed (rev/s) at each sample.  A record too short for :data:`SEGMENTS`
    stretches of 64 samples has none.

    A frequency is a line where it stands :data:`LINE_RATIO` above the background in every
    stretch whose shaft 1X and 2X keep clear of it (at least :data:`MIN_CLEAR_SEGMENTS`), and
    where in at least one stretch no shaft order ``1..MAX_ORDER`` comes near it (a shaft at
    constant speed keeps every order at one frequency: never a line).  Its amplitude is read
    in the stretches clear of 1X and 2X; a stretch whose amplitude strays from their median
    (an order of a fault's response crossing it) is left out."""
    from scipy.ndimage import median_filter

    n = len(t)
    if n < 64 * SEGMENTS:
        return []
    fs = (n - 1) / (t[-1] - t[0])
    segs = _segments(n)
    m = min(b - a for a, b in segs)
    segs = [(a, a + m) for a, _ in segs]
    freqs = np.fft.rfftfreq(m, 1.0 / fs)
    bin_hz = fs / m
    guard = ORDER_GUARD_BINS * bin_hz
    w = np.hanning(m)
    sum_w = float(np.sum(w))
    inside = (freqs >= 4 * bin_hz) & (freqs <= freqs[-1] - 4 * bin_hz)
    clear12, clear_all = [], np.zeros(len(freqs), dtype=bool)
    for a, b in segs:
        sp = np.abs(speed_hz[a:b])
        lo, hi = float(sp.min()), float(sp.max())
        clear12.append(~_near_orders(freqs, lo, hi, guard, (1, 2)) & inside)
        clear_all |= ~_near_orders(freqs, lo, hi, guard, range(1, MAX_ORDER + 1)) & inside
    clear12 = np.array(clear12)
    cand = (clear12.sum(axis=0) >= MIN_CLEAR_SEGMENTS) & clear_all
    names = list(readings)
    centred = {nm: readings[nm] - np.mean(readings[nm]) for nm in names}
    hits = np.zeros(len(freqs), dtype=bool)
    background, strength = {}, {}
    for nm in names:
        above = np.ones(len(freqs), dtype=bool)
        for j, (a, b) in enumerate(segs):
            p = np.abs(np.fft.rfft(w * centred[nm][a:b])) ** 2
            bg = np.maximum(median_filter(p, size=2 * BACKGROUND_BINS + 1, mode="nearest"), 1e-300)
            background[nm, j] = bg
            ratio = p / bg
            strength[nm] = strength.get(nm, 0.0) + np.where(clear12[j], ratio, 0.0)
            # a line between two bins shares its power: the stronger neighbour counts
            ratio = np.maximum(ratio, np.maximum(np.roll(ratio, 1), np.roll(ratio, -1)))
            above &= (ratio >= LINE_RATIO) | ~clear12[j]
        hits |= above & cand
    lines = []
    idx = np.flatnonzero(hits)
    groups = np.split(idx, np.flatnonzero(np.diff(idx) > 2) + 1) if len(idx) else []
    for g in groups:
        # the group's strongest bin over the probes and the stretches clear of 1X and 2X
        k0 = int(g[np.argmax([sum(strength[nm][i] for nm in names) for i in g])])
        sel = [s for s, c in zip(segs, clear12[:, k0], strict=True) if c]
        jsel = [j for j, c in enumerate(clear12[:, k0]) if c]
        f = _refine(t, centred, sel, float(freqs[g[0]]), float(freqs[g[-1]]), bin_hz)
        per, keep_all = {}, np.ones(len(sel), dtype=bool)
        for nm in names:
            a = _stretch_amplitudes(t, centred[nm], sel, f)
            med = complex(np.median(a.real), np.median(a.imag))
            # a stretch's noise on the amplitude: 2 sqrt(E|X|^2) / sum(w), E|X|^2 = median / ln 2
            se = np.array([2.0 * math.sqrt(background[nm, j][k0] / math.log(2.0)) / sum_w for j in jsel])
            keep_all &= np.abs(a - med) <= np.maximum(0.2 * abs(med), 5.0 * se)
            per[nm] = a
        if keep_all.sum() < MIN_CLEAR_SEGMENTS:
            continue
        coh = []
        for nm in names:
            a = per[nm][keep_all]
            per[nm] = a
            rms = math.sqrt(float(np.mean(np.abs(a) ** 2)))
            coh.append((abs(np.mean(a)) / rms if rms > 0 else 0.0, rms))
        # the probe that carries most of it says whether it is steady
        coherence = max(coh, key=lambda c: c[1])[0]
        if coherence < MIN_COHERENCE:
            continue
        centres = np.array([0.5 * (t[a] + t[b - 1]) for (a, b), k in zip(sel, keep_all, strict=True) if k])
        lines.append(FixedLine(f, float(coherence), centres, per))
    return lines


def _refine(t, centred, sel, f_lo: float, f_hi: float, bin_hz: float) -> float:
    """The frequency in ``[f_lo, f_hi]`` (widened by 1.5 bins) whose stretch amplitudes add up most coherently, over every probe."""
    def power(f):
        return sum(abs(np.sum(_stretch_amplitudes(t, x, sel, f))) ** 2 for x in centred.values())

    grid = np.arange(f_lo - 1.5 * bin_hz, f_hi + 1.5 * bin_hz, 0.1 * bin_hz)
    k = int(np.argmax([power(f) for f in grid]))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    for _ in range(25):  # golden section between the neighbours
        c1, c2 = hi - 0.618 * (hi - lo), lo + 0.618 * (hi - lo)
        if power(c1) > power(c2):
            hi = c2
        else:
            lo = c1
    return 0.5 * (lo + hi)


def _revolution_orders(phi: np.ndarray, speed: np.ndarray, X: np.ndarray, orders) -> tuple[dict, np.ndarray, float]:
    """Vectors at ``orders`` (lead convention) over windows of :data:`WINDOW_REVOLUTIONS`
    turns, Hann-weighted in the shaft angle, every half window; their mean speeds; and the
    variance of a vector's component per unit of white-noise variance.  Through a resonance
    the 1X grows by several per cent a turn, and a plain Fourier sum over one turn leaks
    ``1/n`` of that growth into every order n (0.6 % of a 36 um 1X into 3X, twice the noise
    of its median); the window's transform falls as the cube of the distance in orders."""
    W = WINDOW_REVOLUTIONS
    first, last = math.ceil(phi[0] / (2 * math.pi)), math.floor(phi[-1] / (2 * math.pi))
    starts = np.arange(first, last - W + 1, W // 2)
    dphi = np.gradient(phi)
    out = {n: np.empty((len(starts), X.shape[1]), complex) for n in orders}
    rev_speed = np.empty(len(starts))
    var_unit = 0.0
    for r, k in enumerate(starts):
        a, b = np.searchsorted(phi, 2 * math.pi * np.array([k, k + W]))
        ph = phi[a:b]
        w = 0.5 * (1.0 - np.cos((ph - 2 * math.pi * k) / W)) * dphi[a:b]
        sw = float(np.sum(w))
        for n in orders:
            out[n][r] = 2.0 * (np.exp(-1j * n * ph) * w) @ X[a:b] / sw
        rev_speed[r] = float(np.mean(speed[a:b]))
        var_unit += 2.0 * float(np.sum(w * w)) / sw**2
    return out, rev_speed, var_unit / max(len(starts), 1)


def runout_harmonics(t: np.ndarray, phi: np.ndarray, speed: np.ndarray,
                     readings: dict[str, np.ndarray]) -> list[RunoutHarmonic]:
    """Each probe's runout orders 3 and up that are the same at low and high speed
    (module docstring).  ``phi`` the shaft angle (rad), ``speed`` any unit."""
    revs = (phi[-1] - phi[0]) / (2 * math.pi)
    if revs < 30:
        return []
    per_turn = 2 * math.pi / max(float(np.max(np.diff(phi))), 1e-12)
    top = int(min(TOP_RUNOUT_ORDER, math.floor(per_turn / 2.5)))
    orders = tuple(range(3, top + 1))
    if not orders:
        return []
    names = list(readings)
    X = np.column_stack([readings[nm] - np.mean(readings[nm]) for nm in names])
    vectors, rev_speed, var_unit = _revolution_orders(phi, speed, X, orders)
    rank = np.argsort(np.abs(rev_speed), kind="stable")
    third = len(rank) // 3
    slow, fast = rank[:third], rank[-third:]
    out = []
    for n in orders:
        V = vectors[n]
        for j, nm in enumerate(names):
            v = V[:, j]
            med = complex(np.median(v.real), np.median(v.imag))
            # the vectors' scatter per component, robustly: |v - median| is Rayleigh, median
            # 1.1774 sigma; the median's standard error 1.2533 sigma / sqrt(R)
            scat = float(np.median(np.abs(v - med))) / 1.1774
            se = 1.2533 * scat / math.sqrt(len(v))
            # the probe's noise per sample: a window's vector component has variance sigma^2 var_unit
            sigma = scat / math.sqrt(var_unit)
            if not abs(med) > max(RUNOUT_Z * se, RUNOUT_RELEVANT * sigma, 1e-300):
                continue
            lo = complex(np.median(v[slow].real), np.median(v[slow].imag))
            hi = complex(np.median(v[fast].real), np.median(v[fast].imag))
            se3 = 1.2533 * scat / math.sqrt(max(third, 1))
            if abs(lo - hi) <= RUNOUT_AGREEMENT * abs(med) + 4.0 * se3:
                out.append(RunoutHarmonic(nm, n, med, float(se)))
    return out


def remove_artefacts(record):
    """``record`` (a :class:`~rotor_env.measurements.waveforms.RigRecord`) without its
    fixed-frequency lines and its runout above 2X, each removal in the notes.

    The runout first (its harmonics sweep across a line's frequency during a run-up and
    disturb the line's stretches; the runout's median over the windows is not disturbed by
    a line), then the lines, then the runout again on what is left (the line's share of a
    few windows' vectors)."""
    from .probes import to_model_axes

    t, unit = record.t, record.rig.amp_unit
    readings = {nm: np.asarray(x, float).copy() for nm, x in record.readings.items()}
    notes = []
    runout: dict[tuple[str, int], complex] = {}

    def take_runout():
        for h in runout_harmonics(t, record.phi, record.speed, readings):
            readings[h.probe] = readings[h.probe] - np.real(h.vector * np.exp(1j * h.order * record.phi))
            runout[h.probe, h.order] = runout.get((h.probe, h.order), 0.0) + h.vector

    take_runout()
    for ln in find_lines(t, record.speed / (2 * math.pi), readings):
        for nm in readings:
            readings[nm] = readings[nm] - ln.wave(t, nm)
        amp = ", ".join(f"{nm} {a:.3g}" for nm, a in ln.amplitude.items())
        notes.append(f"a line at {ln.frequency_hz:.3f} Hz that does not follow the shaft (mains, a pump, a "
                     f"supply) taken out of the probes ({amp} {unit} zero-to-peak, read in {ln.stretches} "
                     f"stretches of the record clear of the shaft's 1X and 2X; steadiness {ln.coherence:.2f})")
    if notes:
        take_runout()
    if runout:
        by_probe: dict[str, list[str]] = {}
        for (nm, order), vec in sorted(runout.items(), key=lambda kv: (kv[0][0], kv[0][1])):
            by_probe.setdefault(nm, []).append(f"{order}X {abs(vec):.3g}")
        text = "; ".join(f"{nm}: {', '.join(v)}" for nm, v in by_probe.items())
        notes.insert(0, f"runout above 2X (a pattern fixed to the shaft, the same at low and high speed: a scratch "
                        f"or an electrical spot on the track) taken out of the probes ({text} {unit})")
    if not notes:
        return record
    u, v = to_model_axes(record.rig, readings)
    return replace(record, readings=readings, u=u, v=v, notes=(*record.notes, *notes))
