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


def table_of(header: list[str], rows: list[list], *, phase: str = "lag", source: str = "simulated"):
    """The :class:`~rotor_env.measurements.vectors.VectorTable` (with ``runs``) of :func:`campaign_table`'s rows."""
    from ..measurements.vectors import SPEED_UNITS, VectorTable

    probes = tuple(h[: -len("_amp")] for h in header[2::2])
    arr = np.array([r[1:] for r in rows], dtype=float)
    Y = np.column_stack([from_phase(arr[:, 1 + 2 * j], arr[:, 2 + 2 * j], phase) for j in range(len(probes))])
    return VectorTable(speed=arr[:, 0] * SPEED_UNITS["rpm"], t=None, probes=probes, vectors={1: Y},
                       source=source, runs=tuple(str(r[0]) for r in rows),
                       lines=tuple(range(2, len(rows) + 2)))


def coverage_study(seeds, *, planes: int = 1, repeats: int = 3, noise_um: float = 1.0, extra_runs: int = 1,
                   rpms=(1200.0, 1500.0, 2000.0), every_run: bool = True) -> dict:
    """Share of seeds whose 95 % intervals hold the truth, for a linear rotor with random trial weights.

    Each seed draws the reference unbalance (200-1500 g·mm per plane, any angle) and, per
    plane, one trial weight plus ``extra_runs`` runs with weights on random planes (2-15 g at
    100 mm, any angle), simulates ``repeats`` acquisitions per run and speed with circular
    noise ``noise_um``, and balances.  Counted per plane: the reference's unbalance magnitude
    within its profile-likelihood interval (``ref_g_mm``) and angle (``ref_deg``); the same
    with the symmetric half-widths of the JSON (``ref_g_mm_sym``, ``ref_deg_sym``, which
    enclose the intervals); the first-order intervals of the two-stage estimate for
    comparison (``ref_g_mm_first_order``, ``ref_deg_first_order``); split by how far the trial
    weights stood out of the noise (``*_low_snr``: a plane's RMS influence under 10 standard
    errors); with ``every_run`` every calibration run's total unbalance (``runs_*``); the
    influence coefficients' magnitudes; how often a misfit is flagged (a false alarm here);
    how many seeds were refused (a plane the calibration cannot see: not counted in the
    shares) and how many intervals were unbounded (counted as covering).
    """
    from . import balance_data
    from .influence import t_quantile
    from .result import polar_ci
    from .runs import BalanceError, Campaign, Plane, group_table

    names = tuple("AB"[:planes])
    probes = tuple((d, a) for d in range(planes) for a in (45.0, -45.0))
    rotor = DiskRotor(masses_kg=(20.0,) * planes, probes=probes)
    keys = ["ref_g_mm", "ref_deg", "ref_g_mm_sym", "ref_deg_sym", "ref_g_mm_first_order", "ref_deg_first_order",
            "ref_g_mm_low_snr", "ref_deg_low_snr", "ref_g_mm_high_snr", "ref_deg_high_snr", "influence"]
    if every_run:
        keys += ["runs_g_mm", "runs_deg"]
    hits = {k: 0 for k in keys}
    counts = {k: 0 for k in keys}
    false_alarms = n = refused = unbounded = 0

    def count(key: str, ok: bool) -> None:
        hits[key] += bool(ok)
        counts[key] += 1

    for seed in seeds:
        rng = np.random.default_rng(seed)
        U = rng.uniform(200, 1500, planes) * np.exp(1j * rng.uniform(0, 2 * np.pi, planes))
        weights: dict[str, dict[str, tuple[float, float]]] = {}
        for j, name in enumerate(names):
            weights[f"T{j + 1}"] = {name: (float(rng.uniform(2, 15)), float(rng.uniform(0, 360)))}
        for e in range(extra_runs):
            chosen = [nm for nm in names if rng.random() < 0.6] or [names[0]]
            weights[f"X{e + 1}"] = {nm: (float(rng.uniform(2, 15)), float(rng.uniform(0, 360))) for nm in chosen}
        camp = Campaign(tuple(Plane(nm, 100.0) for nm in names), "ref", weights, source="simulated")
        W = camp.trial_matrix("lag")
        runs = {r: W[k] for k, r in enumerate(camp.runs)}
        header, rows = campaign_table(rotor, rpms, U, runs, repeats=repeats, noise_um=noise_um,
                                      seed=seed + 10_000)
        try:
            res = balance_data(group_table(table_of(header, rows), camp), camp)
        except BalanceError:  # a trial weight lost in the noise: refused, as a user would be
            refused += 1
            continue
        fit = res.fit
        false_alarms += bool(res.influence_misfit.get("flagged") or res.unbalance_misfit.get("flagged"))
        n += 1
        band = "low" if min(v["rms_snr"] for v in res.visibility) < 10 else "high"
        # the two-stage estimate's first-order intervals (what the package gave before the profile)
        c0 = fit.reference_combination()
        U2, cov2 = fit.unbalance(c0)
        tq2 = [t_quantile(float(d)) for d in fit.unbalance_dof(c0, U2)]
        for k, run in enumerate(camp.runs):
            if k and not every_run:
                break
            truth = U + W[k]
            est = res.unbalance[run][0]
            for j in range(planes):
                amp, ang = to_phase(np.array([truth[j]]), "lag")
                e_amp, e_ang = to_phase(np.array([est[j]]), "lag")
                iv = res.profile_interval(run, j)
                lo, hi = iv["g_mm"]
                below, above = iv["deg"]
                unbounded += not math.isfinite(hi)
                d = math.remainder(ang[0] - e_ang[0], 360.0)
                ok_a, ok_d = lo <= amp[0] <= hi, -below <= d <= above
                if k:
                    count("runs_g_mm", ok_a)
                    count("runs_deg", ok_d)
                    continue
                count("ref_g_mm", ok_a)
                count("ref_deg", ok_d)
                count(f"ref_g_mm_{band}_snr", ok_a)
                count(f"ref_deg_{band}_snr", ok_d)
                half_a = max(hi - e_amp[0], e_amp[0] - lo)
                count("ref_g_mm_sym", abs(amp[0] - e_amp[0]) <= half_a)
                count("ref_deg_sym", abs(d) <= min(180.0, max(below, above)))
                a2, g2, ca2, cd2 = polar_ci(U2[j], float(np.real(cov2[j, j])), tq2[j], "lag")
                count("ref_g_mm_first_order", abs(a2 - amp[0]) <= ca2)
                count("ref_deg_first_order", abs(math.remainder(g2 - ang[0], 360.0)) <= cd2)
        t_cell = [[t_quantile(float(v)) for v in row] for row in fit.cell_dof]
        for s, rpm in enumerate(fit.data.rpm):
            for p in range(len(fit.data.probes)):
                for j in range(planes):
                    e = np.zeros(planes, dtype=complex)
                    e[j] = 1.0
                    h = rotor.response(rpm, e)[p]  # linear: the response to 1 g·mm
                    a, _, ca, _ = polar_ci(fit.H[s, p, j], float(np.real(fit.cov_theta[s, p, 1 + j, 1 + j])),
                                            t_cell[s][p], "lag")
                    count("influence", abs(a - abs(h)) <= ca)
    out: dict = {k: (hits[k] / counts[k] if counts[k] else None) for k in keys}
    out["counts"] = counts
    out["misfit_flagged"] = false_alarms / n if n else None
    out["seeds"] = n
    out["refused"] = refused
    out["unbounded"] = unbounded
    return out
