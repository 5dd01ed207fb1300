r"""A small rotor with known truth for balancing: disks on a shaft, solved at steady speed.

Each disk ``i`` (one per plane) translates in ``x`` and ``y``: masses ``m_i``, supports
``k_x, k_y`` (anisotropic when they differ) and viscous damping at every disk, a shaft
spring ``k_shaft`` between neighbouring disks.  An unbalance ``U_i`` (g·mm, complex, lead
convention: heavy spot at angle ``arg U_i`` in the direction of rotation from the
keyphasor mark) at speed ``Omega`` is the force ``Re(Omega^2 U_i e^{i Omega t})`` in
``x`` and ``Re(-i Omega^2 U_i e^{i Omega t})`` in ``y``; the steady response solves
``(K - Omega^2 M + i Omega C) Q = F`` and a probe at angle ``a`` of plane ``i`` reads
``Q_x cos a + Q_y sin a`` (its 1X vector, lead convention).  Linear by construction,
except for an optional **clearance**: beyond a radial gap ``g`` a disk meets a stator of
stiffness ``k_c`` (a rub without friction).  For an isotropic rotor the synchronous orbit
stays circular and the contact adds ``k_c (1 - g/|Q|)`` to the support stiffness of that
disk — solved by fixed-point iteration on the orbit radius (harmonic balance, exact for
circular orbits).  Noise: circular Gaussian, ``E|n|^2 = noise^2`` per acquisition.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..measurements.vectors import from_phase, to_phase

__all__ = ["DiskRotor", "campaign_table"]


@dataclass(frozen=True)
class DiskRotor:
    """Disks on a shaft (module docstring); SI inputs, rpm and g·mm at the edges, µm out."""

    masses_kg: tuple[float, ...] = (20.0,)
    natural_rpm: float = 1650.0  #: sqrt(k_x / m) of the first disk on its supports (rpm)
    damping_ratio: float = 0.05
    anisotropy: float = 0.0  #: k_y = k_x (1 + anisotropy)
    shaft_ratio: float = 1.5  #: k_shaft / k_x (coupling between neighbouring disks)
    clearance_um: float | None = None  #: radial gap of a stator at every disk
    contact_ratio: float = 3.0  #: k_c / k_x
    probes: tuple[tuple[int, float], ...] = ((0, 45.0), (0, -45.0))  #: (disk, angle_deg) per probe

    def _matrices(self):
        n = len(self.masses_kg)
        m = np.array(self.masses_kg)
        w = self.natural_rpm * 2 * math.pi / 60
        k = m[0] * w ** 2
        Kx = np.diag(np.full(n, k))
        for i in range(n - 1):
            ks = self.shaft_ratio * k
            Kx[i, i] += ks
            Kx[i + 1, i + 1] += ks
            Kx[i, i + 1] -= ks
            Kx[i + 1, i] -= ks
        Ky = Kx + np.diag(np.full(n, k * self.anisotropy))
        c = 2 * self.damping_ratio * math.sqrt(k * m[0])
        return m, Kx, Ky, np.diag(np.full(n, c)), k

    def response(self, rpm: float, unbalance_g_mm: np.ndarray) -> np.ndarray:
        """Probe vectors (µm, lead convention) at ``rpm`` for the disks' unbalances (g·mm, complex)."""
        U = np.asarray(unbalance_g_mm, dtype=complex) * 1e-6  # kg m
        m, Kx, Ky, C, k = self._matrices()
        n = len(m)
        W = rpm * 2 * math.pi / 60
        extra = np.zeros(n)
        for _ in range(200 if self.clearance_um is not None else 1):
            D = np.zeros((2 * n, 2 * n), dtype=complex)
            D[:n, :n] = Kx + np.diag(extra) - W ** 2 * np.diag(m) + 1j * W * C
            D[n:, n:] = Ky + np.diag(extra) - W ** 2 * np.diag(m) + 1j * W * C
            F = np.concatenate([W ** 2 * U, -1j * W ** 2 * U])
            Q = np.linalg.solve(D, F)
            if self.clearance_um is None:
                break
            radius = np.abs(Q[:n])  # circular orbit: |Q_x| is the radius
            g = self.clearance_um * 1e-6
            new = np.where(radius > g, self.contact_ratio * k * (1 - g / np.maximum(radius, 1e-30)), 0.0)
            if np.allclose(new, extra, rtol=1e-10, atol=1e-9 * k):
                break
            extra = 0.5 * extra + 0.5 * new  # damped: the contact stiffness jumps at the gap
        out = []
        for disk, ang in self.probes:
            a = math.radians(ang)
            out.append((Q[disk] * math.cos(a) + Q[n + disk] * math.sin(a)) / 1e-6)
        return np.array(out)


def campaign_table(rotor: DiskRotor, rpms, unbalance_g_mm, runs: dict[str, np.ndarray], *, repeats: int = 3,
                   noise_um: float = 1.0, seed: int | None = None, phase: str = "lag",
                   probe_names: tuple[str, ...] | None = None) -> tuple[list[str], list[list]]:
    """Header and rows (``run, rpm, NAME_amp, NAME_phase_deg ...``) of a simulated campaign.

    ``runs``: run -> trial unbalance per disk (g·mm, complex, lead) added to ``unbalance_g_mm``.
    """
    rng = np.random.default_rng(seed)
    names = probe_names or tuple(f"p{i + 1}" for i in range(len(rotor.probes)))
    header = ["run", "rpm"] + [c for nm in names for c in (f"{nm}_amp", f"{nm}_phase_deg")]
    rows = []
    base = np.asarray(unbalance_g_mm, dtype=complex)
    for run, W in runs.items():
        for rpm in rpms:
            X = rotor.response(rpm, base + np.asarray(W, dtype=complex))
            for _ in range(repeats):
                noise = (rng.normal(size=X.shape) + 1j * rng.normal(size=X.shape)) * noise_um / math.sqrt(2)
                amp, ph = to_phase(X + noise, phase)
                rows.append([run, rpm] + [v for a, p in zip(amp, ph, strict=True) for v in (float(a), float(p))])
    return header, rows


def weight(mass_g: float, radius_mm: float, angle_deg: float, phase: str = "lag") -> complex:
    """A weight as a complex unbalance (g·mm, lead convention), its angle counted like the phase."""
    return complex(from_phase(np.array(mass_g * radius_mm), np.array(angle_deg), phase))
