"""Raw rig waveforms (probes and keyphasor, SI units) -> the model's dimensionless measurements.

The chain, each step in its own module:

1. read the columns the rig description names (:mod:`.rig`): time, keyphasor (or a
   speed column), probes; errors name file, column, line and value;
2. spin angle, speed and acceleration from the keyphasor pulses (:mod:`.keyphasor`);
3. probe readings to metres (sensitivity for volts), the DC gap removed, rotated into
   the model's axes; one plane -> translation, two planes -> tilt (:mod:`.probes`);
4. optional slow-roll compensation: the runout pattern (probe reading against shaft
   angle, averaged over the revolutions below ``slow_roll_rpm``) subtracted from every
   revolution, as field engineers compensate;
5. the time scale: ``t' = t w_ref`` with ``w_ref`` the natural frequency identified
   from the 1X vectors (:mod:`rotor_env.diagnosis.synchronous`); displacements in units
   of :data:`LENGTH_UNIT` (translation) or radians (tilt); resampled to at least
   :data:`SAMPLES_PER_TURN` samples per revolution at the top speed (zero-phase FIR
   anti-aliasing), rates estimated as for any angles-only file.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .core import COLUMNS, Measurements
from .keyphasor import (
    KeyphasorError,
    check_once_per_turn,
    pulse_edges,
    spin_fit,
    spin_from_pulses,
)
from .probes import check_probe_signals, to_model_axes
from .rig import SPEED_UNITS, TIME_UNITS, Rig
from .vectors import VectorTable, keyphasor_phase_error, order_track

__all__ = ["LENGTH_UNIT", "RigRecord", "WaveformError", "load_waveforms"]

#: the model's unit of translation (m): amplitudes of rigs (10-500 um) become 0.01-0.5
LENGTH_UNIT = 1e-3
SAMPLES_PER_TURN = 32
#: dimensionless sample interval aimed at (the paper's 0.01-0.05)
TARGET_DT = 0.03


class WaveformError(ValueError):
    """A waveform file that does not fit its rig description."""


@dataclass(frozen=True)
class RigRecord:
    """One run of a rig in SI units: time (s), spin, probes and the model's axes."""

    rig: Rig
    t: np.ndarray
    phi: np.ndarray
    speed: np.ndarray  #: rad/s
    accel: np.ndarray  #: rad/s^2
    readings: dict[str, np.ndarray]  #: probe -> reading in the rig's unit (volts converted to um)
    u: np.ndarray  #: m (translation) or rad (tilt)
    v: np.ndarray
    source: str = ""
    notes: tuple[str, ...] = ()

    @property
    def rpm(self) -> np.ndarray:
        return self.speed / SPEED_UNITS["rpm"]

    def vectors(self, orders: tuple[int, ...] = (1, 2), revolutions: int = 1) -> VectorTable:
        """Order-tracked vectors per revolution: of every probe (one plane, in the rig's unit),
        or of the disk's tilt (two planes: ``tilt_u``, ``tilt_v`` along the model's axes, in urad)."""
        if self.rig.model == "tilt":
            names = ("tilt_u", "tilt_v")
            X = np.column_stack([self.u - self.u.mean(), self.v - self.v.mean()]) * 1e6
            angles, unit = np.array([0.0, 0.5 * math.pi]), "urad"
        else:
            names = tuple(p.name for p in self.rig.probes)
            X = np.column_stack([self.readings[n] - self.readings[n].mean() for n in names])
            angles, unit = np.array([p.angle for p in self.rig.probes]), self.rig.amp_unit
        # cubic upsampling only where a revolution holds few samples (memory: a 50 kHz record
        # is already fine, and four times its length would not fit)
        per_turn = 2 * math.pi / max(float(np.max(np.diff(self.phi))), 1e-12)
        up = int(np.clip(math.ceil(64.0 / per_turn), 1, 4))
        spin = spin_fit(self.t, self.phi)
        phi = self.phi if spin is None else spin.spline(self.t)
        tr = order_track(self.t, X, phi, orders, revolutions, upsample=up)
        return VectorTable(speed=tr.speed, t=tr.t, probes=names, vectors=tr.vectors, amp_unit=unit,
                           angles=angles, source=self.source, notes=self.notes,
                           phase_error_rad=keyphasor_phase_error(self.t, self.phi) if spin is None else spin.error_rad,
                           phase_error_basis=None if spin is None else spin.error_basis(tr.t))

    def compensate_runout(self, runout: dict[str, complex] | None = None, below_rpm: float | None = None) -> RigRecord:
        """Subtract the probes' runout: a 1X vector per probe (``lead``), or the slow-roll
        pattern of each probe against the shaft angle (revolutions below ``below_rpm``)."""
        new = {}
        note = ""
        if runout is not None:
            for n, x in self.readings.items():
                new[n] = x - np.real(runout.get(n, 0.0) * np.exp(1j * self.phi))
            note = "1X runout vectors subtracted"
        else:
            slow = self.rpm < below_rpm
            turns = np.floor(self.phi / (2 * math.pi))
            full = np.unique(turns[slow])
            if len(full) < 2:
                raise WaveformError(f"{self.source}: slow_roll_rpm {below_rpm:g}: fewer than two revolutions below "
                                    f"it (the slowest is {self.rpm.min():.0f} rpm)")
            top = float(self.rpm.max())
            if below_rpm > MAX_SLOW_ROLL_SHARE * top:
                # a "slow roll" over most of the run subtracts the vibration itself (a crack's 1X/2X
                # then reads as a bow): slow roll is well below the run's speeds and its criticals
                raise WaveformError(f"{self.source}: slow_roll_rpm {below_rpm:g} is above {MAX_SLOW_ROLL_SHARE:.0%} of "
                                    f"the run's top speed ({top:.0f} rpm): the slow-roll revolutions would be most of "
                                    "the run; give the speed below which the shaft only shows its runout")
            bins = 64
            idx = ((self.phi % (2 * math.pi)) / (2 * math.pi) * bins).astype(int) % bins
            for n, x in self.readings.items():
                xs = x - x.mean()
                pattern = np.bincount(idx[slow], xs[slow], bins) / np.maximum(np.bincount(idx[slow], None, bins), 1)
                pattern -= pattern.mean()
                centres = (np.arange(bins) + 0.5) / bins * 2 * math.pi
                ang = self.phi % (2 * math.pi)
                new[n] = x - np.interp(ang, centres, pattern, period=2 * math.pi)
            note = f"slow-roll runout (below {below_rpm:g} rpm, {len(full)} revolutions) subtracted"
        u, v = to_model_axes(self.rig, new)
        return replace(self, readings=new, u=u, v=v, notes=(*self.notes, note))

    def tracking_spin(self) -> tuple[np.ndarray, float | None]:
        """The spin angle the vectors are tracked on, and its RMS error (rad; ``None`` where the
        record is too short to smooth): the least-squares spline through the pulse times
        (:func:`~.keyphasor.smooth_spin`, its knots a few to hundreds of revolutions apart).  A
        keyphasor edge sharper than a sample puts tens of milliradians into each pulse's angle
        at a few kHz, which every vector carries times its amplitude (2.6 um on a 100 um peak at
        2.5 kHz); smoothed, a tenth of that."""
        spin = spin_fit(self.t, self.phi)
        return (self.phi, None) if spin is None else (spin.spline(self.t), spin.error_rad)

    def minus_1x(self, t: np.ndarray, vectors: dict[str, np.ndarray], note: str) -> RigRecord:
        """The record without a 1X response that changes along it: ``vectors`` per channel of
        :meth:`vectors` (a probe, in the rig's unit, or ``tilt_u``/``tilt_v`` in urad; ``lead``:
        ``x = Re(X e^{i phi})``) at the times ``t`` (s, increasing), interpolated between them
        and held beyond them; ``note`` says what was taken away.  On a tilt rig the tilt is
        changed and the probes' readings stay as recorded: a tilt does not say how the two
        planes' translations shared it (the model, the vectors and the noise read the tilt)."""
        from scipy.interpolate import CubicSpline

        # the angle :meth:`vectors` tracks on: a 1X taken away on another angle leaves the
        # difference (0.6 % of a second mode's peak at 2.5 kHz)
        phi, _ = self.tracking_spin()

        def at_samples(X: np.ndarray) -> np.ndarray:
            X = np.asarray(X, dtype=complex)
            # cubic between the revolutions: through a resonance the vector turns by tens of
            # degrees a revolution, and straight lines between them cut the circle's chords
            # (2 % of the response, 4x the noise at 0.5 um, on a second mode of 46 um)
            tt = np.clip(self.t, t[0], t[-1])
            inside = CubicSpline(t, X)(tt) if len(t) >= 4 else np.interp(tt, t, X.real) + 1j * np.interp(tt, t, X.imag)
            return np.real(inside * np.exp(1j * phi))

        if self.rig.model == "tilt":
            u = self.u - 1e-6 * at_samples(vectors["tilt_u"])
            v = self.v - 1e-6 * at_samples(vectors["tilt_v"])
            return replace(self, u=u, v=v, notes=(*self.notes, note))
        new = {n: x - at_samples(vectors[n]) if n in vectors else x for n, x in self.readings.items()}
        u, v = to_model_axes(self.rig, new)
        return replace(self, readings=new, u=u, v=v, notes=(*self.notes, note))

    def between_rpm(self, lo: float, hi: float) -> RigRecord:
        """The longest stretch of consecutive samples whose speed lies in ``[lo, hi]`` rpm (a
        sweep's band is one stretch; a run up and down again has two, and the longer is kept);
        the record itself where every sample does.  :class:`WaveformError` where none does."""
        inside = (self.rpm >= lo) & (self.rpm <= hi)
        if inside.all():
            return self
        if not inside.any():
            raise WaveformError(f"{self.source}: no sample between {lo:.0f} and {hi:.0f} rpm "
                                f"(the record runs {self.rpm.min():.0f}-{self.rpm.max():.0f} rpm)")
        edges = np.flatnonzero(np.diff(np.concatenate([[0], inside.astype(np.int8), [0]])))
        starts, ends = edges[0::2], edges[1::2]
        j = int(np.argmax(ends - starts))
        sel = slice(int(starts[j]), int(ends[j]))
        return replace(self, t=self.t[sel], phi=self.phi[sel], speed=self.speed[sel], accel=self.accel[sel],
                       readings={n: x[sel] for n, x in self.readings.items()}, u=self.u[sel], v=self.v[sel])

    def to_measurements(self, w_ref: float) -> Measurements:
        """Dimensionless measurements with ``t' = t w_ref`` (see the module docstring)."""
        from scipy.signal import decimate

        from .files import derive_rates

        dt_raw = float(np.median(np.diff(self.t))) * w_ref
        top = float(self.speed.max()) / w_ref
        target = min(TARGET_DT, 2 * math.pi / (SAMPLES_PER_TURN * max(top, 1e-9)))
        q = max(1, int(target // dt_raw))
        scale = LENGTH_UNIT if self.rig.model == "translation" else 1.0
        if q > 1:
            u = decimate(self.u, q, ftype="fir", zero_phase=True)
            v = decimate(self.v, q, ftype="fir", zero_phase=True)
            sel = slice(None, None, q)
        else:
            u, v, sel = self.u, self.v, slice(None)
        t = (self.t[sel] - self.t[0]) * w_ref
        n = min(len(t), len(u))
        out = np.empty((n, len(COLUMNS)))
        out[:, 0] = t[:n]
        out[:, 1] = self.phi[sel][:n]
        out[:, 2] = self.speed[sel][:n] / w_ref
        out[:, 3] = self.accel[sel][:n] / w_ref**2
        out[:, 4] = v[:n] / scale  # th_x = v
        out[:, 5] = u[:n] / scale  # th_y = u
        for j, src in ((6, 4), (7, 5)):
            out[:, j] = derive_rates(out[:, 0], out[:, src], 1)
        for j, src in ((8, 4), (9, 5)):
            out[:, j] = derive_rates(out[:, 0], out[:, src], 2)
        # the anti-aliasing filter and the rates' end windows ring at the record's two ends:
        # the first and last revolution are left out
        ph = out[:, 1]
        keep = (ph >= ph[0] + 2 * math.pi) & (ph <= ph[-1] - 2 * math.pi)
        if keep.sum() >= 100:
            out = out[keep]
            out[:, 0] -= out[0, 0]
        unit = "mm" if self.rig.model == "translation" else "rad"
        return Measurements(out, source=f"{self.source} (rig: {self.rig.model} in {unit}, t' = t * {w_ref:.6g}/s, "
                                        f"every {q} samples)")


#: a probe reading beyond this (metres) is beyond any displacement probe's range
MAX_PROBE_M = 0.025
#: a run-up whose top speed is outside these (rpm) has its time in another unit
MIN_TOP_RPM = 30.0
MAX_RPM = 1e6
#: slow roll is a small part of the run: above this share of the top speed it is the run itself
MAX_SLOW_ROLL_SHARE = 0.5


def load_waveforms(path: str | os.PathLike, rig: Rig) -> RigRecord:
    """Read a waveform file (CSV or Parquet) as the rig describes it."""
    from .files import MeasurementError, check_finite, check_time, read_table, restore_rounded_time

    path = Path(path)
    # only the rig's columns must be numbers: an acquisition's timestamp, a comment or a
    # channel the rig file does not name is read as nothing
    needed = [rig.time, *(p.name for p in rig.probes), rig.keyphasor or rig.speed]
    try:
        header, data, lines = read_table(path, numeric=needed)
    except MeasurementError as exc:
        raise WaveformError(str(exc)) from None
    names = [h.strip() for h in header]
    dup = sorted({h for h in names if names.count(h) > 1})
    if dup:
        # one of two same-named columns would be read silently (the last: a crack's probe missed)
        raise WaveformError(f"{path}: column(s) {str(dup)[:200]} appear more than once in the header")
    col = {h: i for i, h in enumerate(names)}
    missing = [c for c in needed if c not in col]
    if missing:
        raise WaveformError(f"{path}: column(s) {missing} named in the rig description ({rig.source}) are not in "
                            f"the file (it has {list(col)})")
    if data.shape[0] < 100:
        raise WaveformError(f"{path}: only {data.shape[0]} rows: a run-up needs many revolutions of samples")
    check_finite(path, data[:, [col[c] for c in needed]], needed, lines, max_abs=math.inf, error=WaveformError)
    for p in rig.probes:
        # a reading beyond any displacement probe's range: another unit, or no measurement
        metres = np.abs(rig.to_metres(data[:, col[p.name]]))
        big = metres > MAX_PROBE_M
        if big.any():
            r = int(np.argmax(big))
            raise WaveformError(f"{path}, line {lines[r]}, column {p.name!r}: reading {float(data[r, col[p.name]])!r} "
                                f"{rig.displacement} is beyond a displacement probe's range ({MAX_PROBE_M * 1e3:g} mm): "
                                f"is units.displacement ({rig.displacement}) in {rig.source} right?")
    notes: list[str] = []
    t, rounded = restore_rounded_time(data[:, col[rig.time]] * TIME_UNITS[rig.time_unit], " s")
    if rounded:
        notes.append(rounded)
    dt = check_time(path, t, lines, column=rig.time, unit=" s", error=WaveformError)
    step = np.diff(t)
    if rig.keyphasor is not None:
        try:
            edges = pulse_edges(t, data[:, col[rig.keyphasor]], rig.keyphasor_threshold,
                                where=f"{path}, column {rig.keyphasor!r}", lines=lines, notes=notes)
        except KeyphasorError as exc:
            raise WaveformError(str(exc)) from None
        # fewer than 8 samples a turn: the pulse edges (and the 1X) are aliased
        per_turn = float(np.min(np.diff(edges))) / dt
        if per_turn < 8:
            raise WaveformError(f"{path}: only {per_turn:.1f} samples per revolution at the top speed: sample faster")
        inside, phi, speed, accel = spin_from_pulses(t, edges)
        try:  # a regular train at half the shaft's rate: only the probes show it
            check_once_per_turn(phi, {p.name: data[inside, col[p.name]] for p in rig.probes},
                                where=f"{path}, column {rig.keyphasor!r}", lines=lines[inside])
        except KeyphasorError as exc:
            raise WaveformError(str(exc)) from None
    else:
        speed_all = data[:, col[rig.speed]] * SPEED_UNITS[rig.speed_unit]
        inside = np.ones(len(t), dtype=bool)
        phi = np.concatenate(([0.0], np.cumsum(0.5 * (speed_all[1:] + speed_all[:-1]) * step)))
        speed = speed_all
        accel = np.gradient(speed_all, t)
    top = float(np.max(np.abs(speed))) / (2 * np.pi) * 60.0 if len(speed) else 0.0
    if not MIN_TOP_RPM <= top <= MAX_RPM:
        raise WaveformError(f"{path}: the shaft's top speed would be {top:.4g} rpm (time in {rig.time_unit}, column "
                            f"{rig.time!r}), outside any rotor's run-up ({MIN_TOP_RPM:g} to {MAX_RPM:g} rpm): is "
                            f"units.time in {rig.source} right (ms or µs read as s)?")
    check_probe_signals(str(path), rig, {p.name: data[inside, col[p.name]] for p in rig.probes}, phi,
                        lines[inside], error=WaveformError)
    readings = {}
    for p in rig.probes:
        x = data[inside, col[p.name]]
        readings[p.name] = x if rig.displacement not in ("V", "mV") else rig.to_metres(x) / 1e-6
    r_rig = rig if rig.displacement not in ("V", "mV") else replace(rig, displacement="um",
                                                                   sensitivity_mv_per_um=None)
    u, v = to_model_axes(r_rig, readings)
    rec = RigRecord(r_rig, t[inside], phi, speed, accel, readings, u, v, str(path), tuple(notes))
    if rig.slow_roll_rpm is not None:
        rec = rec.compensate_runout(below_rpm=rig.slow_roll_rpm)
    return rec
