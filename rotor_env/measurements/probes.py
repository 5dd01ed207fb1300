"""Proximity probes -> the model's axes.

A probe mounted at angle ``a`` (from the reference, in the direction of rotation) reads
the displacement towards itself, ``p = u cos(a) + v sin(a)``.  Two (or more) probes of a
plane give ``(u, v)`` by least squares; an X-Y pair 90 degrees apart is the usual case,
any two probes at least 20 degrees apart (mod 180) work.  One plane gives the shaft's
translation there (the Jeffcott model); two planes give the disk's tilt
``(w_B - w_A) / (z_B - z_A)`` (the paper's model).

The probes' DC gap (the static position) is removed: the model's origin is the mean
position over the record.
"""

from __future__ import annotations

import numpy as np

from .rig import Rig

__all__ = ["plane_displacements", "probe_matrix", "to_model_axes"]


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
