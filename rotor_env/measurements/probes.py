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

__all__ = ["check_probe_signals", "plane_displacements", "probe_matrix", "quiet_probe", "to_model_axes"]

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
            raise error(f"{where}, column {p.name!r}: the reading is {lo:g} {unit} on every row: a disconnected "
                        "probe or input (an orbit needs every probe of its plane)")
        for value, side in ((hi, "largest"), (lo, "smallest")):
            at = x == value
            count = int(np.count_nonzero(at))
            if count < max(CLIP_SAMPLES, CLIP_SHARE * len(x)):
                continue
            # in runs of three or more: a flat top, not a quantised peak touched now and then
            runs = at[:-2] & at[1:-1] & at[2:]
            if np.count_nonzero(runs) * 3 < count:
                continue
            r = int(np.argmax(runs))
            line = f", line {int(lines[r])}" if lines is not None else ""
            raise error(f"{where}{line}, column {p.name!r}: {count} samples ({100 * count / len(x):.2g} %) sit at the "
                        f"reading's {side} value {value:g} {unit}, in flat runs: the probe, its driver or the input "
                        "range clipped the orbit (out of its linear range); set the gap or the range and record again")
    for plane in rig.plane_names:
        members = [p for p in rig.probes if p.plane == plane]
        if len(members) < 2:
            continue
        quiet = quiet_probe({p.name: float(np.max(order_amplitudes(phi, readings[p.name], (1,))[:, 0], initial=0.0))
                             for p in members}, unit)
        if quiet:
            raise error(f"{where}, column {quiet[0]!r}: its largest once-per-turn vibration is {quiet[1]}")


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
