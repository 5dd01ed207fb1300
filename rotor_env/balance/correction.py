r"""Correction weights, their split onto holes, and the ISO 21940-11 balance grade.

A correction ``C`` (g·mm, lead convention) on a plane of radius ``R`` is a mass
``|C| / R`` g at the angle of ``C`` read in the phase's convention
(:func:`~rotor_env.measurements.vectors.to_phase`: for ``lag`` against the rotation).

**Holes.**  With ``N`` equally spaced positions (``first_hole_deg + 360 i / N``, counted
like the weight angles) the correction at angle ``a`` between holes ``a1 < a < a2`` is
split into ``m1`` at ``a1`` and ``m2`` at ``a2`` whose vector sum is ``C``:
``m1 = m sin(a2 - a) / sin(a2 - a1)``, ``m2 = m sin(a - a1) / sin(a2 - a1)`` (both
non-negative between adjacent holes).

**ISO 21940-11.**  The balance quality grade ``G`` (mm/s) of a rotor of mass ``M`` kg at
the service speed ``Omega`` rad/s with residual unbalance ``U`` g·mm is
``G = (U / M) Omega / 1000`` (``U / M`` in g·mm/kg = µm); the grade class is the
smallest of G 0.4, 1, 2.5, 6.3, 16, 40, 100, 250, 630, 1600, 4000 not below it.  For two
planes the planes' magnitudes are added (the standard's allocation to the planes is then
met plane by plane when each carries its share; the sum is the conservative check).
"""

from __future__ import annotations

import math

import numpy as np

from ..measurements.vectors import to_phase

__all__ = ["GRADES", "iso_grade", "split_to_holes", "weight_of"]

#: the balance quality grades of ISO 21940-11 (mm/s)
GRADES: tuple[float, ...] = (0.4, 1.0, 2.5, 6.3, 16.0, 40.0, 100.0, 250.0, 630.0, 1600.0, 4000.0)


def weight_of(C: complex, radius_mm: float, phase: str = "lag") -> tuple[float, float]:
    """Mass (g) and angle (degrees, in the phase's convention, [0, 360)) of an unbalance ``C`` (g·mm)."""
    amp, ang = to_phase(np.array([C]), phase)
    return float(amp[0] / radius_mm), float(np.mod(ang[0], 360.0))


def split_to_holes(mass_g: float, angle_deg: float, holes: int, first_hole_deg: float = 0.0) -> list[dict]:
    """The two adjacent holes and their masses whose vector sum is the weight (module docstring)."""
    step = 360.0 / holes
    rel = (angle_deg - first_hole_deg) % 360.0
    i = int(math.floor(rel / step + 1e-12)) % holes
    a1 = i * step
    frac = rel - a1
    if frac < 1e-9 * step:
        return [{"hole": i, "angle_deg": (first_hole_deg + a1) % 360.0, "mass_g": mass_g}]
    a2 = a1 + step
    s = math.sin(math.radians(step))
    m1 = mass_g * math.sin(math.radians(a2 - rel)) / s
    m2 = mass_g * math.sin(math.radians(rel - a1)) / s
    return [{"hole": i, "angle_deg": (first_hole_deg + a1) % 360.0, "mass_g": m1},
            {"hole": (i + 1) % holes, "angle_deg": (first_hole_deg + a2) % 360.0, "mass_g": m2}]


def iso_grade(unbalance_g_mm: float, rotor_mass_kg: float, service_rpm: float) -> dict:
    """The achieved grade value ``G`` (mm/s) and the ISO 21940-11 grade class it meets."""
    omega = service_rpm * 2.0 * math.pi / 60.0
    e_um = unbalance_g_mm / rotor_mass_kg
    g = e_um * omega / 1000.0
    cls = next((c for c in GRADES if g <= c + 1e-12), None)
    return {"G_mm_per_s": g, "grade": f"G {cls:g}" if cls is not None else "above G 4000",
            "specific_unbalance_g_mm_per_kg": e_um}
