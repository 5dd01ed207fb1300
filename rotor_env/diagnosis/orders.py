"""Where a model fails: the residual over time, in rotation orders, and its noise floor."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


# ------------------------------------------------------------------ where it fails
def complex_rows(values: np.ndarray, equation: str) -> np.ndarray:
    """Per-sample complex signal ``eq1 + i eq2`` (``theta_y + i theta_x`` convention).

    In this coordinate the unbalance is ``e^{+i phi}``: positive rotation orders are
    forward whirl.  With one equation only, the real signal is returned.
    """
    if equation == "both":
        return values[0::2] + 1j * values[1::2]
    return values.astype(complex)


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


def failing_windows(t: np.ndarray, r: np.ndarray, width: float = 2.0, factor: float = 2.0,
                    floor: float | None = None, speed: np.ndarray | None = None) -> tuple[list[dict], float]:
    """Time windows where the rolling RMS of ``r`` exceeds ``factor`` x the noise floor.

    ``floor`` defaults to :func:`noise_floor` of ``r``; ``width`` is the rolling window in
    time units (at most the record).  With ``speed`` each window also gives its speed range.
    """
    floor = noise_floor(r) if floor is None else float(floor)
    if len(r) < 2:
        return [], floor
    dt = float(np.median(np.diff(t)))
    n = int(min(max(3, round(width / dt)) if dt > 0 else 3, len(r)))
    kernel = np.ones(n) / n
    rms = np.sqrt(np.convolve(r * r, kernel, mode="same"))
    above = rms > factor * max(floor, 1e-300)
    # runs of samples above the threshold; runs closer than the rolling window are one
    # episode (the rolling RMS dips between them by chance, not because the misfit stops)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], above.astype(np.int8), [0]])))
    runs = [[int(a), int(b) - 1] for a, b in zip(edges[0::2], edges[1::2], strict=True)]
    merged: list[list[int]] = []
    for a, b in runs:
        if merged and a - merged[-1][1] <= n:
            merged[-1][1] = b
        else:
            merged.append([a, b])
    out = []
    for k, j in merged:
        w = {"t_start": float(t[k]), "t_end": float(t[j]),
             "peak_rms_over_floor": float(rms[k : j + 1].max() / max(floor, 1e-300))}
        if speed is not None:
            w["speed_min"] = float(np.min(speed[k : j + 1]))
            w["speed_max"] = float(np.max(speed[k : j + 1]))
        out.append(w)
    return out, floor


def first_rows(values: np.ndarray, equation: str) -> np.ndarray:
    return values[0::2] if equation == "both" else values


# ------------------------------------------------------------------ the noise in the rotor's band
#: the orders of the shaft a model's misfit carries (a crack's 2X and 3X, a misalignment's 2X,
#: a rub's half and third orders, a hinge's or an impact's harmonics): periodogram bins near
#: them are not noise (higher harmonics are weak; the bands' medians ignore them)
MISFIT_ORDERS = (1 / 3, 1 / 2, 2 / 3, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0)
#: half-width of the band around each free whirl frequency left out (a share of it: a rub's
#: contact, the supports' anisotropy or the gyroscopic split move it)
WHIRL_WIDTH = 0.25
#: a window whose residual power stands this far above the windows' median is where the model
#: fails, not noise: it is not read (the noise is stationary; a misfit is not -- a model without
#: its crack leaves it around the critical, where the shooting segments' restarts and the
#: resonance's passage spread it to low frequencies)
FRAME_RATIO = 1.5
#: bins left out either side of an order or a whirl band: the Hann window's main lobe is two
#: bins wide each way and its side lobes fall 18 dB an octave, so four bins off a misfit line
#: 25 times the noise leave nothing a band's median reads (tests/test_coloured_noise.py)
LEAK_BINS = 4
#: periodogram bins a band needs to be read
MIN_BAND_BINS = 32
#: the joint test that the bands read are at the model's level (white above the response):
#: coloured where its p-value is below this (a white record is read as coloured once in a
#: thousand; where it is, the bands' own levels count, which scatter about one)
COLOURED_P = 1e-3
#: the band above the response on the residual's grid moves the noise model's level where it
#: reads this many standard errors from it (:attr:`OffOrderNoise.reference_level`)
REFERENCE_SIGMAS = 3.0


@dataclass(frozen=True)
class OffOrderNoise:
    """The residual's level away from the shaft's orders and the free whirl, band by band,
    against a noise model (:func:`off_order_noise`).

    ``bands``: ``(lo, hi)`` of each octave (cycles per unit of time); ``ratio``: its level over
    the model's, relative to the band above the response (``nan`` where fewer than
    :data:`MIN_BAND_BINS` bins were read); ``se``: its standard error; ``weight``: each band's
    share of the model's noise power; ``bins``: periodogram bins read in it; ``reference``:
    the level of the band above the response itself over the model's (1 where too few bins
    were read), ``reference_se`` its standard error; ``weight_below``: the model's power share
    below the lowest band."""

    bands: tuple[tuple[float, float], ...]
    ratio: np.ndarray
    se: np.ndarray
    weight: np.ndarray
    bins: np.ndarray
    reference: float = 1.0
    reference_se: float = 0.0
    weight_below: float = 0.0

    @property
    def reference_level(self) -> float:
        """The level the noise model takes on the residual's own grid: :attr:`reference` where
        it stands more than :data:`REFERENCE_SIGMAS` standard errors from the model's, else 1.
        The model is read off the raw record's band above the response, up to its Nyquist
        frequency, as one AR(1) shape; noise that is not one (white noise plus a coloured part,
        as a probe driver's filter leaves beside its white noise) is extrapolated from kHz down
        to the grid's band wrongly: a foreign bow at 0.3 um white plus 0.3 um AR(1) (rho 0.7,
        10 kHz) read 1.64x the model's density on the grid above the response and alike in every
        band below it -- the bow's record "unexplained" at 1.32x, nothing named."""
        if self.reference_se > 0 and abs(self.reference - 1.0) > REFERENCE_SIGMAS * self.reference_se:
            return float(self.reference)
        return 1.0

    @property
    def read(self) -> np.ndarray:
        return np.isfinite(self.ratio)

    @property
    def log10_p(self) -> float:
        """log10 of the p-value of "every band read is at the model's level": the sum of the
        squared standardised deviations, chi-square with a degree of freedom a band."""
        from scipy.stats import chi2

        z = (self.ratio[self.read] - 1.0) / self.se[self.read]
        if not z.size:
            return 0.0
        return float(chi2.logsf(float(np.sum(z * z)), z.size) / math.log(10.0))

    @property
    def coloured(self) -> bool:
        """Whether the bands read are not at the model's level (:data:`COLOURED_P`)."""
        return self.log10_p < math.log10(COLOURED_P)

    @property
    def raised(self) -> np.ndarray:
        """The bands read that stand more than two standard errors above the model's level."""
        return self.read & (np.nan_to_num(self.ratio - 2.0 * self.se, nan=0.0) > 1.0)

    @property
    def level(self) -> np.ndarray:
        """Each band's noise level over the model's as the floor counts it: where the bands are
        :attr:`coloured`, a band read at its own, one too narrow to read (the free whirl's, a
        band crowded with orders) between two read ones at their geometric mean, one below the
        lowest read at that one's, else at the model's (1); where they are not, every band at
        the model's."""
        if not self.coloured:
            return np.ones(len(self.bands))
        used = np.where(self.read, self.ratio, 1.0)
        for b, lo, hi in self._between():
            used[b] = math.sqrt(used[lo] * used[hi])
        first = self._first_read()
        if first is not None:
            used[:first] = used[first]
        return used

    def _first_read(self) -> int | None:
        read = np.flatnonzero(self.read)
        return int(read[0]) if read.size else None

    @property
    def level_below(self) -> float:
        """The level below the lowest band, as the floor counts it: the lowest read band's where
        the bands are :attr:`coloured` (the noise's shape there is what the lowest octave
        read says, not the model's), else the model's (1)."""
        first = self._first_read()
        return float(self.level[first]) if self.coloured and first is not None else 1.0

    @property
    def variance_factor_se(self) -> float:
        """The standard error of :attr:`variance_factor` (0 where the bands are not coloured):
        each band read with its own, one between two read ones with the larger of theirs."""
        if not self.coloured:
            return 0.0
        se = np.where(self.read, self.se, 0.0)
        for b, lo, hi in self._between():
            se[b] = max(se[lo], se[hi])
        first = self._first_read()
        below = 0.0
        if first is not None:
            se[:first] = se[first]
            below = self.weight_below * se[first]
        return float(math.sqrt(np.sum((self.weight * se) ** 2) + below * below))

    def _between(self) -> list[tuple[int, int, int]]:
        """Each band not read that has read bands on both sides: ``(band, nearest below,
        nearest above)``."""
        read = np.flatnonzero(self.read)
        return [(int(b), int(read[read < b][-1]), int(read[read > b][0]))
                for b in np.flatnonzero(~self.read) if read.size and read[0] < b < read[-1]]

    def level_at(self, nu: np.ndarray) -> np.ndarray:
        """The noise's density over the model's at the frequencies ``nu`` (cycles per unit of
        time), as the floor counts it (:attr:`floor_factor`): each band's :attr:`level`, below
        the lowest band :attr:`level_below`, above the bands the model's (1), all times
        :attr:`reference_level`."""
        nu = np.asarray(nu, dtype=float)
        out = np.ones_like(nu)
        if self.bands:
            out[nu < self.bands[0][0]] = self.level_below
        for (lo, hi), lv in zip(self.bands, self.level, strict=True):
            out[(nu >= lo) & (nu < hi)] = lv
        return out * self.reference_level

    @property
    def floor_factor(self) -> float:
        """The noise's variance on the residual's grid over the model's: the
        :attr:`variance_factor` of the bands times :attr:`reference_level`."""
        return self.variance_factor * self.reference_level

    @property
    def floor_factor_se(self) -> float:
        """The standard error of :attr:`floor_factor`: the bands' and, where it counts, the
        reference's, combined relative."""
        rel = self.variance_factor_se / self.variance_factor
        if self.reference_level != 1.0:
            rel = math.hypot(rel, self.reference_se / self.reference)
        return rel * self.floor_factor

    @property
    def variance_factor(self) -> float:
        """The noise's variance over the model's: each band at :attr:`level`, below the lowest
        at :attr:`level_below`, above the response at the model's.  Below one where the bands
        read below the model: a model read off a band where a DAQ's anti-alias filter rolls the
        noise off (a 4-pole Butterworth at fs / 2.56 on the probes, 2.5 kHz: one AR(1) shape
        fitted to the roll-off, rho 0.98) overstates the noise in the rotor's band many times --
        the floor came out six times the truth, the record 'explained' at 0.16x and a hinge
        crack named for an open one."""
        return float(max(1e-6, 1.0 + np.sum(self.weight * (self.level - 1.0))
                         + self.weight_below * (self.level_below - 1.0)))


def off_order_noise(t: np.ndarray, residual: np.ndarray, speed: np.ndarray, whirl, density, *,
                    above: float, orders: tuple[float, ...] = MISFIT_ORDERS) -> OffOrderNoise:
    """The residual's noise level in the rotor's band, read where no model's misfit can be.

    A model's misfit is locked to the shaft -- at its orders (:data:`MISFIT_ORDERS`) -- or
    rings at a free whirl frequency; the probes' noise is neither.  So the residual's
    short-time periodogram (Hann windows, half overlapping) is read only at bins clear of
    every order ``o f_1X`` (by the window's sweep ``o df_1X / 2`` and :data:`LEAK_BINS`) and
    of each free whirl frequency (by :data:`WHIRL_WIDTH` of it), in windows whose residual
    power is within :data:`FRAME_RATIO` of the windows' median.  Each bin is divided by the noise
    model's density there (``density(nu)``, one-sided, integrating to the model's variance),
    and each octave's level is the median of those ratios over ``ln 2`` (a periodogram bin is
    the density times an exponential variable of mean one: the median ignores a few lines and
    a neighbouring mode's free ring), relative to the same read above ``above`` (cycles per
    unit time: above the response, where the model's level was read).  Its standard error is
    that of an exponential sample's median, ``1.44 / sqrt(n)``, with the bins counted a third
    (a Hann window's neighbours and the overlap are correlated).

    The window is as long as the 1X frequency takes to sweep one of its bins (``T = 1 /
    sqrt(|d f_1X / dt|)``) and 2, 4 ... 32 times that: a long window resolves the band below
    the slowest orders (where the sweep does not matter) and smears the orders above; each
    octave is read with the length that keeps the most bins there.

    ``t`` (uniform), ``residual`` ``(N, channels)``, ``speed`` the spin rate (rad per unit
    time), ``whirl(speed)`` the free whirl frequencies (rad per unit time) at a speed.
    """
    t = np.asarray(t, dtype=float)
    r = np.asarray(residual, dtype=float).reshape(len(t), -1)
    speed = np.abs(np.asarray(speed, dtype=float))
    n = len(t)
    empty = OffOrderNoise((), np.empty(0), np.empty(0), np.empty(0), np.empty(0, dtype=int))
    if n < 256:
        return empty
    dt = float(np.median(np.diff(t)))
    nyq = 0.5 / dt
    f1 = speed / (2 * math.pi)
    sweep = float(np.median(np.abs(np.gradient(f1, t))))
    span = 1.0 / math.sqrt(sweep) if sweep > 0 else t[-1] - t[0]
    L0 = int(min(max(round(span / dt), 128), n // 4))
    top = min(above, 0.75 * nyq)
    fine = np.linspace(0.0, nyq, 8193)
    dens = density(fine)
    total = float(np.sum(dens) * (fine[1] - fine[0]))
    reads = [_off_order_bins(r, f1, dt, L, density, whirl, orders) for L in
             sorted({min(L0 * 2 ** j, n // 4) for j in range(6)})]
    # the reference: above the response, read with the shortest window (the most bins there)
    ratio0, at0, _ = reads[0]
    ref_sel = at0 > above
    m_ref = int(ref_sel.sum())
    ref = float(np.median(ratio0[ref_sel]) / math.log(2.0)) if m_ref >= MIN_BAND_BINS else 1.0
    ref_se = 1.44 * math.sqrt(3.0 / m_ref) * ref if m_ref >= MIN_BAND_BINS else 0.0
    lowest = min(LEAK_BINS * df for _, _, df in reads)
    edges = [top]
    while edges[-1] / 2 > lowest:
        edges.append(edges[-1] / 2)
    edges = edges[::-1]
    bands, lev, ses, wt, cnt = [], [], [], [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        best = max(((ratio[(at >= lo) & (at < hi)]) for ratio, at, _ in reads), key=len)
        m = len(best)
        R = float(np.median(best) / math.log(2.0)) / ref if m >= MIN_BAND_BINS else math.nan
        inside = (fine >= lo) & (fine < hi)
        bands.append((float(lo), float(hi)))
        lev.append(R)
        # a median of m exponential variables: standard error 1.44 / sqrt(m) relative, the
        # bins counted a third (a window's neighbours and the half overlap are correlated)
        ses.append(1.44 * math.sqrt(3.0 / max(m, 1)) * R)
        wt.append(float(np.sum(dens[inside]) * (fine[1] - fine[0])) / total if total > 0 else 0.0)
        cnt.append(m)
    below = float(np.sum(dens[fine < edges[0]]) * (fine[1] - fine[0])) / total if total > 0 else 0.0
    return OffOrderNoise(tuple(bands), np.array(lev), np.array(ses), np.array(wt), np.array(cnt, dtype=int),
                         ref, ref_se, below)


def _off_order_bins(r: np.ndarray, f1: np.ndarray, dt: float, L: int, density, whirl,
                    orders: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray, float]:
    """The periodogram bins of windows ``L`` long clear of the orders and the free whirl, in
    windows whose residual power is not far above the others' (:func:`off_order_noise`), each
    over the model's density: ``(ratios, frequencies, bin width)``."""
    from numpy.lib.stride_tricks import sliding_window_view

    win = np.hanning(L)
    nu = np.fft.rfftfreq(L, dt)
    df = float(nu[1])
    model = np.maximum(density(nu), 1e-300)
    hop = L // 2
    starts = np.arange(0, len(r) - L + 1, hop)
    frames = sliding_window_view(f1, L)[starts]
    c1 = frames.mean(axis=1)[:, None]
    d1 = np.ptp(frames, axis=1)[:, None]
    ok = np.broadcast_to((nu > LEAK_BINS * df) & (nu < 0.375 / dt), (len(starts), len(nu))).copy()
    for o in orders:
        ok &= np.abs(nu - o * c1) > o * d1 / 2 + LEAK_BINS * df
    fw = np.abs(np.array([np.atleast_1d(whirl(2 * math.pi * c)) for c in c1[:, 0]], dtype=float)) / (2 * math.pi)
    for j in range(fw.shape[1]):
        w = fw[:, j:j + 1]
        ok &= np.abs(nu - w) > WHIRL_WIDTH * w + LEAK_BINS * df
    segs = [sliding_window_view(r[:, c], L)[starts] for c in range(r.shape[1])]
    segs = [x - x.mean(axis=1, keepdims=True) for x in segs]
    power = sum(np.mean(x * x, axis=1) for x in segs)
    ok &= (power <= FRAME_RATIO * np.median(power))[:, None]
    if not ok.any():
        return np.empty(0), np.empty(0), df
    norm = 2.0 * dt / float(np.sum(win * win))
    ratios, where = [], []
    for seg in segs:
        p = norm * np.abs(np.fft.rfft(seg * win, axis=1)) ** 2
        ratios.append((p / model)[ok])
        where.append(np.broadcast_to(nu, ok.shape)[ok])
    return np.concatenate(ratios), np.concatenate(where), df
