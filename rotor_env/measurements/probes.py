"""Proximity probes -> the model's axes.

A probe mounted at angle ``a`` (from the reference, in the direction of rotation) reads
the displacement towards itself, ``p = u cos(a) + v sin(a)``.  Two (or more) probes of a
plane give ``(u, v)`` by least squares; an X-Y pair 90 degrees apart is the usual case,
any two probes at least 20 degrees apart (mod 180) work.  One plane gives the shaft's
translation there (the Jeffcott model); two planes give the disk's tilt
``(w_B - w_A) / (z_B - z_A)`` (the paper's model).

The probes' DC gap (the static position) is removed: the model's origin is the mean
position over the record.

What a probe's signal must hold (:func:`check_probe_signals`, a clear error otherwise): a
reading that moves (a flat channel is a disconnected probe or an unplugged input), no flat
tops (a probe or driver driven out of its linear range, an input range exceeded, clips the
orbit, which no rotor model follows), and the shaft's once-per-turn vibration: two probes of
a plane see one orbit, each its projection, so their 1X amplitudes differ by the orbit's
ellipticity; a probe whose largest 1X stays under :data:`MIN_1X_SHARE` of its partner's all
through the run reads noise alone (a broken cable, a probe not facing the shaft).
"""

from __future__ import annotations

import numpy as np

from .rig import Rig

__all__ = ["FLAT_REVOLUTIONS", "ProbeSignalWatch", "check_probe_signals", "plane_displacements", "probe_matrix", "quiet_probe", "to_model_axes"]

#: samples at a channel's largest (or smallest) value, as a share of the record, beyond which
#: its tops are flat (clipped) -- and at least this many, in runs of three or more
CLIP_SHARE = 1e-3
CLIP_SAMPLES = 10
#: a probe whose largest 1X stays under this share of its plane partner's reads noise alone
MIN_1X_SHARE = 1.0 / 30.0


def probe_matrix(angles: np.ndarray) -> np.ndarray:
    """(probes, 2) rows ``(cos a, sin a)``: probe readings = matrix @ (u, v)."""
    a = np.asarray(angles, dtype=float)
    return np.column_stack([np.cos(a), np.sin(a)])


def plane_displacements(angles: np.ndarray, readings: np.ndarray) -> np.ndarray:
    """``(u, v)`` per sample (shape ``(m, 2)``) from the readings ``(m, probes)`` of one plane."""
    A = probe_matrix(angles)
    return np.linalg.lstsq(A, np.asarray(readings, dtype=float).T, rcond=None)[0].T


def to_model_axes(rig: Rig, readings: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """``(u, v)``: translation in metres (one plane) or tilt in radians (two planes)."""
    per_plane = {}
    for plane in rig.plane_names:
        members = [p for p in rig.probes if p.plane == plane]
        X = np.column_stack([rig.to_metres(readings[p.name]) for p in members])
        X = X - X.mean(axis=0)  # the DC gap
        per_plane[plane] = plane_displacements(np.array([p.angle for p in members]), X)
    if rig.model == "translation":
        w = per_plane[rig.plane_names[0]]
        return w[:, 0], w[:, 1]
    (pa, wa), (pb, wb) = list(per_plane.items())[:2]
    dz = rig.planes[pb] - rig.planes[pa]
    tilt = (wb - wa) / dz
    return tilt[:, 0], tilt[:, 1]


def check_probe_signals(where: str, rig: Rig, readings: dict[str, np.ndarray], phi: np.ndarray,
                        lines: np.ndarray | None = None, error: type[Exception] = ValueError) -> None:
    """Refuse a probe that reads nothing, clips or holds no 1X (module docstring); ``readings``
    in the rig's unit at the samples of the spin angle ``phi``; ``lines``: their file lines."""
    from .keyphasor import order_amplitudes

    unit = rig.displacement
    for p in rig.probes:
        x = np.asarray(readings[p.name], dtype=float)
        lo, hi = float(np.min(x)), float(np.max(x))
        if not hi > lo:
            raise error(_flat(where, p.name, lo, unit))
        for value, side in ((hi, "largest"), (lo, "smallest")):
            count, runs, first = _at_value(x, value)
            if _clipped(count, runs, len(x)):
                line = f", line {int(lines[first])}" if lines is not None else ""
                raise error(_clip(f"{where}{line}", p.name, count, len(x), side, value, unit))
    for plane in rig.plane_names:
        members = [p for p in rig.probes if p.plane == plane]
        if len(members) < 2:
            continue
        quiet = quiet_probe({p.name: float(np.max(order_amplitudes(phi, readings[p.name], (1,))[:, 0], initial=0.0))
                             for p in members}, unit)
        if quiet:
            raise error(_quiet(where, *quiet))


def _at_value(x: np.ndarray, value: float) -> tuple[int, int, int]:
    """Samples of ``x`` at ``value``, those in runs of three or more (each run's samples
    counted once per window of three), and the first such run's start (0 where none)."""
    at = x == value
    runs = at[:-2] & at[1:-1] & at[2:]
    return int(np.count_nonzero(at)), int(np.count_nonzero(runs)), int(np.argmax(runs)) if runs.any() else 0


def _clipped(count: int, runs: int, n: int) -> bool:
    """At least :data:`CLIP_SHARE` of ``n`` samples (and :data:`CLIP_SAMPLES`) at the extreme,
    most in runs of three or more: a flat top, not a quantised peak touched now and then."""
    return count >= max(CLIP_SAMPLES, CLIP_SHARE * n) and runs * 3 >= count


def _flat(where: str, name: str, value: float, unit: str, rows: str = "every row") -> str:
    return (f"{where}, column {name!r}: the reading is {value:g} {unit} on {rows}: a disconnected probe or input "
            "(an orbit needs every probe of its plane)")


def _clip(where: str, name: str, count: int, n: int, side: str, value: float, unit: str) -> str:
    return (f"{where}, column {name!r}: {count} samples ({100 * count / n:.2g} %) sit at the reading's {side} value "
            f"{value:g} {unit}, in flat runs: the probe, its driver or the input range clipped the orbit (out of its "
            "linear range); set the gap or the range and record again")


def _quiet(where: str, name: str, rest: str) -> str:
    return f"{where}, column {name!r}: its largest once-per-turn vibration is {rest}"


class ProbeSignalWatch:
    """:func:`check_probe_signals` for a stream read chunk by chunk (the monitor's
    :class:`~.rig_stream.RigStream`), without keeping the record: a flat channel is refused
    once :data:`FLAT_REVOLUTIONS` revolutions have passed (at once, not at the end); the
    clipping rule on the whole stream's extremes and the quiet-probe rule on its largest 1X
    are read when it ends (as the batch reader reads them: early in a run-up the orbit is
    small, and a slow-roll peak or one track's runout would pass for either).  A flat run
    split between two chunks is counted from the chunk it ends in."""

    def __init__(self, where: str, rig: Rig, error: type[Exception] = ValueError) -> None:
        self.where, self.rig, self.error = where, rig, error
        n = len(rig.probes)
        self.n = 0
        self.turns = 0
        self.largest_1x = np.zeros(n)
        #: the revolution being read: its index and sums (of x e^{-i phi}, x, e^{-i phi}, samples)
        self._turn: int | None = None
        self._sums = (np.zeros(n, complex), np.zeros(n), 0j, 0)
        self._begun = False
        #: per probe and side (largest, smallest): [value, count, runs, first line]
        self.extremes = [[[None, 0, 0, 0], [None, 0, 0, 0]] for _ in range(n)]

    def readings(self, x: np.ndarray, lines: np.ndarray) -> None:
        """A chunk's readings, ``(m, probes)`` in the rig's unit, and their file lines."""
        if not len(x):
            return
        self.n += len(x)
        for j in range(x.shape[1]):
            for k, value in enumerate((float(np.max(x[:, j])), float(np.min(x[:, j])))):
                ext = self.extremes[j][k]
                beyond = ext[0] is None or (value > ext[0] if k == 0 else value < ext[0])
                if beyond or value == ext[0]:
                    count, runs, first = _at_value(x[:, j], value)
                    if beyond:
                        ext[:] = [value, count, runs, int(lines[first])]
                    else:
                        ext[1] += count
                        ext[2] += runs

    def revolutions(self, phi: np.ndarray, x_metres: np.ndarray) -> None:
        """A chunk of the spin angle and the readings in metres: each probe's 1X amplitude per
        whole revolution (:func:`~.keyphasor.order_amplitudes`' mean of ``x e^{-i phi}``, the
        revolution's mean removed, times 2), a revolution carried over the chunks it spans."""
        if not len(phi):
            return
        turn = np.floor(np.asarray(phi, dtype=float) / (2.0 * np.pi)).astype(np.int64)
        rot = np.exp(-1j * np.asarray(phi, dtype=float))
        for k in np.unique(turn):
            at = turn == k
            if self._turn is not None and k != self._turn:
                self._close()
            if self._turn is None or k != self._turn:
                self._turn = int(k)
            s1, s0, e, m = self._sums
            xs = x_metres[at]
            self._sums = (s1 + rot[at] @ xs, s0 + xs.sum(axis=0), e + rot[at].sum(), m + int(at.sum()))
        if self.turns >= FLAT_REVOLUTIONS:
            for j, p in enumerate(self.rig.probes):
                hi, lo = self.extremes[j][0][0], self.extremes[j][1][0]
                if hi is not None and not hi > lo:
                    raise self.error(_flat(self.where, p.name, lo, self.rig.displacement,
                                           f"every row of the first {self.turns} revolutions"))

    def _close(self) -> None:
        """The revolution read so far is whole: its 1X amplitudes taken, the sums started anew."""
        s1, s0, e, m = self._sums
        if m > 0 and self._begun:
            amp = 2.0 * np.abs(s1 - s0 / m * e) / m
            self.largest_1x = np.maximum(self.largest_1x, amp)
            self.turns += 1
        self._sums = (np.zeros_like(s1), np.zeros_like(s0), 0j, 0)
        self._begun = True  # the stream's first revolution is a part of one: not read

    def finish(self) -> None:
        """The clipping and quiet-probe rules on the whole stream (:func:`check_probe_signals`)."""
        unit = self.rig.displacement
        for j, p in enumerate(self.rig.probes):
            for (value, count, runs, line), side in zip(self.extremes[j], ("largest", "smallest"), strict=True):
                if value is not None and _clipped(count, runs, self.n):
                    err = self.error(_clip(f"{self.where}, line {line}", p.name, count, self.n, side, value, unit))
                    err.line = line
                    raise err
        scale = abs(self.rig.to_metres(1.0) - self.rig.to_metres(0.0))
        for plane in self.rig.plane_names:
            members = [j for j, p in enumerate(self.rig.probes) if p.plane == plane]
            if len(members) < 2:
                continue
            quiet = quiet_probe({self.rig.probes[j].name: self.largest_1x[j] / scale for j in members}, unit)
            if quiet:
                raise self.error(_quiet(self.where, *quiet))


#: revolutions a stream's probe must stay flat for to be refused as disconnected
FLAT_REVOLUTIONS = 10


def quiet_probe(largest_1x: dict[str, float], unit: str = "") -> tuple[str, str] | None:
    """The probe of one plane whose largest 1X (``largest_1x``: probe -> amplitude) stays
    under :data:`MIN_1X_SHARE` of its partner's, and the rest of the sentence that says so
    (``"0.152 um against 98 um on 'x' of the same plane: it reads noise alone ..."``);
    ``None`` where every probe holds the orbit's 1X.  The waveforms' rule and the tables'."""
    if len(largest_1x) < 2:
        return None
    top_name = max(largest_1x, key=largest_1x.get)
    top = largest_1x[top_name]
    name = min(largest_1x, key=largest_1x.get)
    a = largest_1x[name]
    if not (top > 0 and a < MIN_1X_SHARE * top):
        return None
    u = f" {unit}" if unit else ""
    return name, (f"{a:.3g}{u} against {top:.3g}{u} on {top_name!r} of the same plane: it reads noise alone "
                  "(a broken cable, a probe not facing the shaft, the wrong column)")
