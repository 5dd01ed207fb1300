"""SI rig waveforms streamed into the monitor's dimensionless rows (``rotor-id monitor --rig``).

The batch chain of :mod:`rotor_env.measurements.waveforms` (``load_waveforms(...)
.to_measurements(w_ref)``), done causally, chunk by chunk, memory flat in the stream's
length.  The raw columns come from :class:`~.stream.StreamReader` (CSV/Parquet, stdin,
``--follow``); each step holds back only the samples it still needs:

1. **validation** of the columns the rig names (time, keyphasor or speed, probes):
   finite values, time increasing and uniformly sampled; errors name the file, line,
   column and value, and the rows before the bad line are processed first;
2. **spin**: a keyphasor through :class:`~rotor_env.measurements.keyphasor.KeyphasorTracker`
   (fixed threshold, edges across chunks, the batch path's missing/extra-pulse check,
   the angle from a local cubic spline through the edges: four revolutions held back;
   a train at half the shaft's rate all through is refused from the probes' 1X and 2X
   over the revolutions the DC gap is learned from);
   a speed column integrated by the trapezoid rule, its derivative by central
   differences (one sample held back);
3. **origin**: probe readings to metres; with the rig's ``slow_roll_rpm`` the runout
   pattern (each probe against the shaft angle, :data:`RUNOUT_BINS` bins) is learned
   from the revolutions below that speed at the start of the stream and subtracted
   from every revolution; the DC gap (the static position) is the mean over the first
   :data:`DC_GAP_REVOLUTIONS` revolutions and then **fixed**: a running mean would take
   the slow shift of the shaft's centre that a developing fault (a crack's static
   deflection, a rub, a changing bearing load) produces out of the data the monitor
   watches, and a moving origin would itself read as a change of the model; a whole
   number of revolutions averages the 1X part out.  Then the probes are rotated into the
   model's axes (one plane: translation, two planes: tilt);
4. **decimation** by ``q = TARGET_DT // (dt w_ref)`` with the batch path's linear-phase
   FIR (``scipy.signal.decimate``'s Hamming window of ``20 q + 1`` taps), applied
   centred: each output sample waits for the ``10 q`` samples after it, so the group
   delay is compensated and every sample stays at its own time (the batch's
   ``zero_phase`` filter, sample for sample);
5. **dimensionless rows**: ``t' = (t - t_0) w_ref`` with ``w_ref = 2 pi N / 60`` from
   ``natural_rpm`` (``t_0`` the first row's time), speed over ``w_ref``, acceleration
   over ``w_ref^2``, translation in :data:`~rotor_env.measurements.waveforms.LENGTH_UNIT`
   (mm) or tilt in rad; the rates by the stream's Savitzky-Golay ``SlidingDerivatives`` (as
   ``derive_rates``).  The first revolution (where the filters start) is left out, and
   at the end of the stream the last one, as in the batch path (a row is handed out once
   the stream is a turn past it).

The decimation factor is fixed at the start (the batch path also caps it by the
record's top speed, which a stream does not know ahead): it keeps 32 samples a turn up
to ``2 pi / (32 TARGET_DT)`` = 6.5 times the natural frequency.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .core import COLUMNS
from .files import MeasurementError, check_finite, check_time, first_step
from .keyphasor import KeyphasorError, KeyphasorTracker, check_once_per_turn, spurious_note
from .probes import ProbeSignalWatch, probe_matrix
from .rig import SPEED_UNITS, TIME_UNITS, Rig
from .stream import CHUNK_BYTES, SlidingDerivatives, StreamReader
from .waveforms import LENGTH_UNIT, MAX_PROBE_M, TARGET_DT

__all__ = ["DC_GAP_REVOLUTIONS", "RigClock", "RigStream", "natural_rpm_required"]

#: revolutions at the start of the stream whose mean position is the probes' DC gap
DC_GAP_REVOLUTIONS = 8
#: bins of the slow-roll runout pattern over a turn (the batch path's)
RUNOUT_BINS = 64
#: slow-roll samples held at most while the pattern is learned (then it is fixed)
MAX_SLOW_ROLL_SAMPLES = 1 << 20
_RATES = ["theta_x_dot", "theta_y_dot", "theta_x_ddot", "theta_y_ddot"]


def natural_rpm_required() -> str:
    """The message of ``--rig`` without ``--natural-rpm``."""
    return ("--rig needs --natural-rpm N: the rotor's natural frequency in rpm sets the model's time scale "
            "(t' = t * 2 pi N / 60); take it from a recorded run-up: `rotor-id diagnose RUN.csv --rig RIG.yaml "
            "--json` gives natural_frequency_rpm (and the critical speeds)")


@dataclass(frozen=True)
class RigClock:
    """The monitor's dimensionless time and speed in the rig's units: ``t = t0_s + t' / w_ref``
    (s), ``rpm = speed' * natural_rpm``."""

    natural_rpm: float
    t0_s: float

    @property
    def w_ref(self) -> float:
        return self.natural_rpm * SPEED_UNITS["rpm"]

    def seconds(self, t: float) -> float:
        return self.t0_s + float(t) / self.w_ref

    def rpm(self, speed: float) -> float:
        return float(speed) * self.natural_rpm

    def annotate(self, event: dict) -> dict:
        """The event with its times in s and speeds in rpm beside the dimensionless fields."""
        e = dict(event)
        kind = e.get("event")
        if kind in ("status", "summary"):
            e["t_s"] = self.seconds(e["t"])
            e["rpm"] = self.rpm(e["speed"])
            if kind == "summary":
                e["events"] = [self.annotate(x) for x in e.get("events", [])]
        elif kind in ("appeared", "changed", "disappeared", "unattributed"):  # the monitor's ALARM_EVENTS
            e["t_alarm_s"] = self.seconds(e["t_alarm"])
            e["t_onset_s"] = self.seconds(e["t_onset"])
            ev = e.get("evidence", {})
            if "speed_alarm" in ev:
                e["rpm_alarm"] = self.rpm(ev["speed_alarm"])
                e["rpm_onset"] = self.rpm(ev["speed_onset"])
        return e


class _SpeedColumn:
    """Spin from a speed column: ``phi`` its trapezoid integral from 0, the acceleration its
    central difference (one-sided at the ends: ``numpy.gradient``, as the batch path)."""

    def __init__(self) -> None:
        self._phi = 0.0
        self._last: tuple[np.ndarray, ...] | None = None  # the held sample: t, speed, payload, line
        self._before: tuple[float, float] | None = None  # (t, speed) of the sample before it

    def push(self, t, speed, payload, lines):
        if self._last is not None:
            t = np.concatenate([self._last[0], t])
            speed = np.concatenate([self._last[1], speed])
            payload = np.concatenate([self._last[2], payload])
            lines = np.concatenate([self._last[3], lines])
            phi0 = self._phi
        else:
            phi0 = 0.0
        if len(t) < 2:
            self._last = (t, speed, payload, lines)
            return _empty_spin(payload.shape[1])
        phi = phi0 + np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))])
        prev_t = np.concatenate([[self._before[0]] if self._before else [t[0]], t[:-2]])
        prev_s = np.concatenate([[self._before[1]] if self._before else [speed[0]], speed[:-2]])
        accel = (speed[1:] - prev_s) / (t[1:] - prev_t)
        self._before = (float(t[-2]), float(speed[-2]))
        self._phi = float(phi[-1])
        self._last = (t[-1:], speed[-1:], payload[-1:], lines[-1:])
        return t[:-1], phi[:-1], speed[:-1], accel, payload[:-1], lines[:-1]

    def finish(self):
        if self._last is None or not len(self._last[0]):
            return _empty_spin(0)
        t, s, p, ln = self._last
        if self._before is None:
            raise MeasurementError("a speed column needs at least two samples")
        a = (s - self._before[1]) / (t - self._before[0])
        self._last = None
        return t, np.array([self._phi]), s, a, p, ln


def _empty_spin(p: int):
    z = np.zeros(0)
    return z, z, z, z, np.zeros((0, p)), np.zeros(0, dtype=np.int64)


class _Origin:
    """Slow-roll runout pattern and DC gap, learned at the start and fixed; readings -> model axes."""

    def __init__(self, rig: Rig, where: str) -> None:
        self.rig = rig
        self.where = where
        self.below = rig.slow_roll_rpm
        self.pattern: np.ndarray | None = None if self.below is not None else np.zeros((0,))
        self.gap: np.ndarray | None = None
        self._buf: list[tuple[np.ndarray, ...]] = []
        self._n = 0
        self._slow_done = self.below is None
        self.notes: list[str] = []
        # per plane: the least-squares map of its probes' readings to (u, v)
        self._planes = []
        for plane in rig.plane_names:
            idx = [i for i, p in enumerate(rig.probes) if p.plane == plane]
            self._planes.append((plane, np.array(idx), np.linalg.pinv(probe_matrix(np.array(
                [rig.probes[i].angle for i in idx])))))

    def push(self, t, phi, speed, accel, x, lines, *, final: bool = False):
        if self.gap is None:
            self._buf.append((t, phi, speed, accel, x, lines))
            self._n += len(t)
            if not self._slow_done:
                rpm = speed / SPEED_UNITS["rpm"]
                if (rpm >= self.below).any() or final or self._n >= MAX_SLOW_ROLL_SAMPLES:
                    self._learn_runout()
            if self._slow_done:
                phis = np.concatenate([b[1] for b in self._buf])
                if phis.size and (final or phis[-1] >= 2 * math.pi * DC_GAP_REVOLUTIONS):
                    parts, self._buf = self._buf, []
                    t, phi, speed, accel, x, lines = (np.concatenate([p[i] for p in parts]) for i in range(6))
                    xc = self._corrected(phi, x)
                    first = phi < 2 * math.pi * DC_GAP_REVOLUTIONS
                    if not first.any():
                        first = np.ones(len(phi), dtype=bool)
                    self.gap = xc[first].mean(axis=0)
                    self._check_pulse_rate(phi, x, lines)
                    return t, phi, speed, accel, self._axes(xc), lines
            return None
        return t, phi, speed, accel, self._axes(self._corrected(phi, x)), lines

    def _check_pulse_rate(self, phi: np.ndarray, x: np.ndarray, lines: np.ndarray) -> None:
        """The batch path's half-rate check (``check_once_per_turn``) on the revolutions the
        DC gap is learned from: a keyphasor at half the shaft's rate all through is regular,
        only the probes show it (their 1X is noise, their 2X the shaft's 1X)."""
        if self.rig.keyphasor is None:
            return
        try:
            check_once_per_turn(phi, {p.name: x[:, j] for j, p in enumerate(self.rig.probes)},
                                where=f"{self.where}, column {self.rig.keyphasor!r}", lines=lines)
        except KeyphasorError as exc:
            err = MeasurementError(str(exc))
            err.line = int(lines[0])
            raise err from None

    def _learn_runout(self) -> None:
        phi = np.concatenate([b[1] for b in self._buf])
        rpm = np.concatenate([b[2] for b in self._buf]) / SPEED_UNITS["rpm"]
        x = np.concatenate([b[4] for b in self._buf])
        fast = np.flatnonzero(rpm >= self.below)
        n_slow = int(fast[0]) if fast.size else len(rpm)
        turns = np.unique(np.floor(phi[:n_slow] / (2 * math.pi)))
        if len(turns) < 2:
            slowest = float(rpm.min()) if rpm.size else math.nan
            raise MeasurementError(f"{self.where}: slow_roll_rpm {self.below:g}: fewer than two revolutions below it "
                                   f"at the start of the stream (the first is at {slowest:.0f} rpm)")
        idx = _runout_bin(phi[:n_slow])
        xs = x[:n_slow] - x[:n_slow].mean(axis=0)
        count = np.bincount(idx, None, RUNOUT_BINS)
        pattern = np.column_stack([np.bincount(idx, xs[:, j], RUNOUT_BINS) / np.maximum(count, 1)
                                   for j in range(x.shape[1])])
        self.pattern = pattern - pattern.mean(axis=0)
        self._slow_done = True
        self.notes.append(f"slow-roll runout (below {self.below:g} rpm, {len(turns)} revolutions at the start) "
                          "subtracted")

    def _corrected(self, phi: np.ndarray, x: np.ndarray) -> np.ndarray:
        if self.pattern is None or not self.pattern.size:
            return x
        centres = (np.arange(RUNOUT_BINS) + 0.5) / RUNOUT_BINS * 2 * math.pi
        ang = phi % (2 * math.pi)
        return x - np.column_stack([np.interp(ang, centres, self.pattern[:, j], period=2 * math.pi)
                                    for j in range(x.shape[1])])

    def _axes(self, x: np.ndarray) -> np.ndarray:
        """``(m, 2)``: ``(u, v)`` in metres (one plane) or radians (the tilt of two planes)."""
        x = x - self.gap
        w = [(plane, x[:, idx] @ pinv.T) for plane, idx, pinv in self._planes]
        if self.rig.model == "translation":
            return w[0][1]
        (pa, wa), (pb, wb) = w[:2]
        return (wb - wa) / (self.rig.planes[pb] - self.rig.planes[pa])


def _runout_bin(phi: np.ndarray) -> np.ndarray:
    return ((phi % (2 * math.pi)) / (2 * math.pi) * RUNOUT_BINS).astype(int) % RUNOUT_BINS


class _Decimator:
    """Every ``q``-th sample, ``(u, v)`` through the centred linear-phase FIR of
    ``scipy.signal.decimate(..., ftype="fir", zero_phase=True)`` (zeros before the first
    sample and after the last, as there)."""

    def __init__(self, q: int) -> None:
        from scipy.signal import firwin

        self.q = q
        self.half = 10 * q if q > 1 else 0
        self.b = firwin(2 * self.half + 1, 1.0 / q, window="hamming") if q > 1 else np.ones(1)
        self._uv = np.zeros((self.half, 2))  # from global sample -half (the zeros before the start)
        self._uv0 = -self.half
        self._rows = np.zeros((0, 5))  # t, phi, speed, accel, line from global sample _rows0
        self._rows0 = 0
        self._n = 0  # samples in
        self._j = 0  # next output: global sample j q

    def push(self, rows: np.ndarray, uv: np.ndarray, *, final: bool = False) -> tuple[np.ndarray, np.ndarray]:
        self._uv = np.concatenate([self._uv, uv])
        self._rows = np.concatenate([self._rows, rows])
        self._n += len(rows)
        if final:
            self._uv = np.concatenate([self._uv, np.zeros((self.half, 2))])
            j_last = (self._n - 1) // self.q
        else:
            j_last = (self._n - 1 - self.half) // self.q
        if j_last < self._j:
            return np.zeros((0, 5)), np.zeros((0, 2))
        centres = np.arange(self._j, j_last + 1) * self.q
        out_rows = self._rows[centres - self._rows0]
        if self.q > 1:
            first = centres[0] - self.half - self._uv0
            win = sliding_window_view(self._uv, 2 * self.half + 1, axis=0)[first :: self.q][: len(centres)]
            out_uv = win @ self.b[::-1]
        else:
            out_uv = self._uv[centres - self._uv0]
        self._j = j_last + 1
        keep_uv = self._j * self.q - self.half
        self._uv = self._uv[keep_uv - self._uv0 :]
        self._uv0 = keep_uv
        keep_rows = self._j * self.q
        self._rows = self._rows[max(0, keep_rows - self._rows0) :]
        self._rows0 = max(keep_rows, self._rows0)
        return out_rows, out_uv


class RigStream:
    """Dimensionless ``(m, 10)`` chunks of an SI rig waveform stream (see the module docstring).

    ``source``: a path, ``"-"`` (stdin) or a binary file object; ``rig``: the rig
    description; ``natural_rpm``: the rotor's natural frequency (the time scale).
    :attr:`clock` converts the monitor's times and speeds back to s and rpm (known once the
    first chunk is out); :attr:`line` is the file line of the last row read.
    """

    def __init__(self, source, rig: Rig, natural_rpm: float, *, follow: bool = False, poll: float = 0.2,
                 idle_exit: float | None = None, chunk_bytes: int = CHUNK_BYTES) -> None:
        if not (natural_rpm is not None and math.isfinite(natural_rpm) and natural_rpm > 0):
            raise ValueError(f"--natural-rpm must be a positive number of rpm, got {natural_rpm!r}")
        self.rig = rig
        self.natural_rpm = float(natural_rpm)
        self.w_ref = self.natural_rpm * SPEED_UNITS["rpm"]
        spin = rig.keyphasor or rig.speed
        self.needed = [rig.time, spin, *(p.name for p in rig.probes)]
        self.reader = StreamReader(source, follow=follow, poll=poll, idle_exit=idle_exit, chunk_bytes=chunk_bytes,
                                   required=self.needed,
                                   missing_hint=f"named in the rig description ({rig.source or 'the rig'})")
        self.name = self.reader.name
        self.line = 1
        self.error_line: int | None = None
        self.clock: RigClock | None = None
        if rig.keyphasor is not None:
            self._spin = KeyphasorTracker(rig.keyphasor_threshold, where=f"{self.name}, column {rig.keyphasor!r}")
        else:
            self._spin = _SpeedColumn()
        self._origin = _Origin(rig, self.name)
        #: the batch reader's probe checks, causal (a flat channel at once; clipping and a
        #: probe reading noise alone when the stream ends)
        self._watch = ProbeSignalWatch(self.name, rig, error=MeasurementError)
        self._scale = LENGTH_UNIT if rig.model == "translation" else 1.0
        self._dt = 0.0  # s
        self._last_t = math.nan
        self._dec: _Decimator | None = None
        self._deriv: SlidingDerivatives | None = None
        self._phi_first = math.nan
        self._phi_last = math.nan
        self._tail = np.zeros((0, len(COLUMNS)))  # rows that may still be in the last revolution
        self.q = 0

    @property
    def notes(self) -> list[str]:
        dropped = getattr(self._spin, "dropped", [])
        return list(self._origin.notes) + ([spurious_note(dropped)] if dropped else [])

    # ------------------------------------------------------------------ the stream
    def __iter__(self) -> Iterator[np.ndarray]:
        for data, lines in self.reader.blocks():
            if not data.shape[0]:
                continue
            n_ok, error = self._check(data, lines)
            if n_ok:
                out = self._push(data[:n_ok], lines[:n_ok])
                if out.shape[0]:
                    yield out
                self.line = int(lines[n_ok - 1])
                error = self._spin_error() or error
            if error is not None:
                raise error
        out = self._finish()
        if out.shape[0]:
            yield out
        error = self._spin_error()
        if error is not None:
            raise error

    def _spin_error(self) -> MeasurementError | None:
        """An irregular keyphasor revolution (the rows before it were handed out)."""
        exc = getattr(self._spin, "error", None)
        return None if exc is None else self._fail(self._keyphasor_line(exc), str(exc))

    def _fail(self, line: int, message: str) -> MeasurementError:
        self.error_line = int(line)
        return MeasurementError(message)

    def _check(self, data: np.ndarray, lines: np.ndarray) -> tuple[int, MeasurementError | None]:
        """Rows valid before the first bad one, and the error of that one (``None``: all valid)."""
        header = self.reader.header
        col = {h: i for i, h in enumerate(header)}
        self._cols = [col[c] for c in self.needed]
        sub = data[:, self._cols]
        first_bad, error = data.shape[0], None
        try:
            check_finite(self.name, sub, self.needed, lines, max_abs=math.inf)
        except MeasurementError as exc:
            first_bad, error = exc.row, self._fail(lines[exc.row], str(exc))
        probes = np.abs(self.rig.to_metres(sub[:first_bad, 2:]))
        big = probes > MAX_PROBE_M
        if big.any():
            r, c = np.argwhere(big)[0]
            first_bad = int(r)
            error = self._fail(lines[r], f"{self.name}, line {lines[r]}, column {self.needed[2 + c]!r}: reading "
                                         f"{float(sub[r, 2 + c])!r} {self.rig.displacement} is beyond a displacement "
                                         f"probe's range ({MAX_PROBE_M * 1e3:g} mm)")
        t = data[:first_bad, self._cols[0]] * TIME_UNITS[self.rig.time_unit]
        self._dt = self._dt or first_step(t, self._last_t)  # the rows before a bad one go out with it
        try:
            check_time(self.name, t, lines, step=self._dt or None, previous=self._last_t, column=self.rig.time,
                       unit=" s")
        except MeasurementError as exc:
            return exc.row, self._fail(lines[exc.row], str(exc))
        return first_bad, error

    def _push(self, data: np.ndarray, lines: np.ndarray) -> np.ndarray:
        t = data[:, self._cols[0]] * TIME_UNITS[self.rig.time_unit]
        self._last_t = float(t[-1])
        self._watch.readings(data[:, self._cols[2:]], lines)
        x = np.column_stack([self.rig.to_metres(data[:, c]) for c in self._cols[2:]])
        spin = data[:, self._cols[1]]
        if self.rig.keyphasor is None:
            spin = spin * SPEED_UNITS[self.rig.speed_unit]
        try:
            released = self._spin.push(t, spin, x, lines)
        except KeyphasorError as exc:
            raise self._fail(self._keyphasor_line(exc), str(exc)) from None
        return self._downstream(released, final=False)

    def _keyphasor_line(self, exc: KeyphasorError) -> int:
        """The file line an irregular pulse was found at (else the last line read)."""
        return exc.line if exc.line is not None else self.line + 1

    def _downstream(self, released, *, final: bool) -> np.ndarray:
        t, phi, speed, accel, x, lines = released
        if not len(t):
            x = np.zeros((0, len(self.rig.probes)))
        try:
            self._watch.revolutions(phi, x)
            if final:
                self._watch.finish()
        except MeasurementError as exc:
            line = getattr(exc, "line", None) or (int(lines[-1]) if len(lines) else self.line)
            raise self._fail(line, str(exc)) from None
        if not len(t) and not final:
            return np.zeros((0, len(COLUMNS)))
        if len(t) and self._dec is None:
            dt_model = self._dt * self.w_ref
            self.q = max(1, int(TARGET_DT // dt_model)) if dt_model > 0 else 1
            self._dec = _Decimator(self.q)
            self._deriv = SlidingDerivatives(_RATES, dt_model * self.q)
        if self._dec is None:
            return np.zeros((0, len(COLUMNS)))
        origin = self._origin.push(t, phi, speed, accel, x, lines, final=final) if (len(t) or final) else None
        if origin is None:
            if not final:
                return np.zeros((0, len(COLUMNS)))
            origin = (*_empty_spin(0)[:4], np.zeros((0, 2)), np.zeros(0, dtype=np.int64))
        t, phi, speed, accel, uv, lines = origin
        rows, uv = self._dec.push(np.column_stack([t, phi, speed, accel, lines]) if len(t) else np.zeros((0, 5)),
                                  uv.reshape(-1, 2), final=final)
        if rows.shape[0]:
            if math.isnan(self._phi_first):
                self._phi_first = float(rows[0, 1])
            self._phi_last = float(rows[-1, 1])
        out = np.zeros((rows.shape[0], len(COLUMNS)))
        out[:, 0] = rows[:, 0]  # s until the rows leave the derivative filter
        out[:, 1] = rows[:, 1]
        out[:, 2] = rows[:, 2] / self.w_ref
        out[:, 3] = rows[:, 3] / self.w_ref**2
        out[:, 4] = uv[:, 1] / self._scale  # th_x = v
        out[:, 5] = uv[:, 0] / self._scale  # th_y = u
        out = self._deriv.push(out) if out.shape[0] else np.zeros((0, len(COLUMNS)))
        if final:
            out = np.concatenate([out, self._deriv.finish()])
        # the first revolution (the filters start) and, at the end, the last are left out:
        # a row goes once a row a turn later has been decimated (it is not in the last turn)
        out = np.concatenate([self._tail, out[out[:, 1] >= self._phi_first + 2 * math.pi]])
        n_out = int(np.searchsorted(out[:, 1], self._phi_last - 2 * math.pi, side="right"))
        out, self._tail = out[:n_out], (out[n_out:] if not final else out[:0])
        if out.shape[0]:
            if self.clock is None:
                self.clock = RigClock(self.natural_rpm, float(out[0, 0]))
            out[:, 0] = (out[:, 0] - self.clock.t0_s) * self.w_ref
        return out

    def _finish(self) -> np.ndarray:
        try:
            released = self._spin.finish()
        except KeyphasorError as exc:
            raise self._fail(self._keyphasor_line(exc), str(exc)) from None
        return self._downstream(released, final=True)
