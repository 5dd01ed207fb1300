r"""The unbalance of every plane from one run-up, no trial weight: a two-disk rotor fitted to the 1X vectors.

The model (the structure of :class:`.simulate.DiskRotor`)
---------------------------------------------------------
One disk per correction plane, in a chain: disk ``i`` of known mass ``m_i`` (the runs file's
``disk_mass_kg``) sits on a support of stiffness ``k_i`` with viscous damping ``c_i``;
neighbouring disks are joined by the shaft's stiffness ``k_s``.  The rotor is isotropic (the
orbits are circular forward whirls) and linear.  An unbalance ``U_i`` (kg·m, lead convention)
at speed ``Omega`` drives disk ``i`` with ``Omega^2 U_i``; the steady 1X response is

.. math::  Q(\Omega) = (K - \Omega^2 M + i \Omega C)^{-1} \Omega^2 U

and a probe at angle ``a`` on disk ``d`` reads ``Q_d e^{-i a}`` (``y = -i x`` for a forward
circular orbit).  The vectors of a slow run-up are taken as steady-state responses (the
free vibration a fast run-up leaks into 1X is not modelled: docs/BALANCING.md §5).

The fit
-------
Unknown: ``log k_i``, ``log k_s``, ``log c_i`` (``2J + 1`` numbers) and ``U`` (``J`` complex).  The
response is linear in ``U`` for given dynamics, so ``U`` is solved by least squares inside
(variable projection) and the dynamics by ``scipy.optimize.least_squares`` from several
starts (the peak of the run-up gives the first natural frequency; the shaft's stiffness is
tried from a tenth to a hundred times the supports').  The noise level is the residuals'
(one level for every probe and speed).  The covariance of all parameters is the
Gauss-Newton one ``s^2 (J^T J)^{-1}``; the 95 % intervals of each plane's unbalance
(magnitude and angle) are first-order with a Student t on the residuals' degrees of freedom.

What the data cannot decide
---------------------------
How the unbalance splits between the planes is seen only through the motion of the disks
*against each other*: the second (out-of-phase) mode, or its quasi-static share below it.
With one mode in the speed range and a shaft much stiffer than the supports, the disks move
together and only the sum ``U_1 + U_2`` (the static unbalance) is determined: their small
quasi-static difference ``Omega^2 (U_1 - U_2) / (2 k_s)`` fits any split with a stiff enough
shaft.  ``split_test``: the F-test of the two-disk fit against that stiff-shaft limit (one
body plus a quasi-static difference, nested), at 5 % divided by the number of speeds (under
the limit the second mode's frequency is not identified and the fit can place it on a noise
feature at any speed: a Bonferroni bound for that search).  ``planes_separated`` needs the
test passed *and* every plane's 95 % half-width below half of ``|sum U|``; otherwise
``cannot_decide`` says so, and the sum is reported with its interval in either case.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

from .influence import t_quantile

__all__ = ["RunUpFit", "disk_response", "fit_run_up"]

#: the planes count as separated only where the stiff-shaft limit is rejected at this level (over the speeds)
SPLIT_P = 0.05


def disk_response(rpm: np.ndarray, masses_kg: np.ndarray, k_support: np.ndarray, k_shaft: float,
                  c: np.ndarray) -> np.ndarray:
    """Disk displacement per unit unbalance: ``(S, J, J)`` complex, m per kg·m (``Omega^2`` included)."""
    J = len(masses_kg)
    K = np.diag(np.asarray(k_support, dtype=float))
    for i in range(J - 1):
        K[i, i] += k_shaft
        K[i + 1, i + 1] += k_shaft
        K[i, i + 1] -= k_shaft
        K[i + 1, i] -= k_shaft
    w = np.asarray(rpm, dtype=float) * 2 * math.pi / 60
    D = (K[None] - (w ** 2)[:, None, None] * np.diag(masses_kg)[None]
         + 1j * w[:, None, None] * np.diag(c)[None])
    return np.linalg.inv(D) * (w ** 2)[:, None, None]


@dataclass
class RunUpFit:
    """The fitted two-disk model of one run-up (module docstring)."""

    U_g_mm: np.ndarray  #: (J,) unbalance per plane, g·mm, lead convention
    cov_g_mm: np.ndarray  #: (J, J) complex covariance (first order)
    dof: float  #: real degrees of freedom of the residuals
    k_support: np.ndarray  #: (J,) N/m
    k_shaft: float  #: N/m
    damping: np.ndarray  #: (J,) N s/m
    noise: float  #: RMS residual per vector (the table's unit)
    natural_rpm: np.ndarray  #: undamped natural frequencies of the fitted model, rpm
    split_test: dict | None = None  #: F-test of the fit against the disks moving as one body

    def to_dict(self, plane_names: tuple[str, ...], phase: str = "lag") -> dict:
        """Per plane ``g_mm, angle_deg, ci95_g_mm, ci95_deg``; the sum; ``planes_separated``."""
        from ..measurements.vectors import to_phase

        tq = t_quantile(self.dof)

        def polar(u: complex, var: float) -> dict:
            amp, ang = to_phase(np.array([u]), phase)
            half = tq * math.sqrt(max(var, 0.0) / 2)
            deg = 180.0 if amp[0] <= half else math.degrees(math.asin(half / amp[0]))
            return {"g_mm": float(amp[0]), "angle_deg": float(np.mod(ang[0], 360.0)), "ci95_g_mm": half,
                    "ci95_deg": deg}

        planes = {nm: polar(self.U_g_mm[j], float(np.real(self.cov_g_mm[j, j])))
                  for j, nm in enumerate(plane_names)}
        one = np.ones(len(plane_names))
        total = polar(complex(self.U_g_mm.sum()), float(np.real(one @ self.cov_g_mm @ one)))
        separated = all(p["ci95_g_mm"] < 0.5 * total["g_mm"] for p in planes.values())
        if self.split_test is not None and self.split_test["p_value"] > self.split_test["level"]:
            separated = False
        out = {"planes": planes, "sum": total, "planes_separated": separated,
               "natural_frequencies_rpm": [float(v) for v in self.natural_rpm],
               "k_support_N_per_m": [float(v) for v in self.k_support], "k_shaft_N_per_m": float(self.k_shaft),
               "damping_N_s_per_m": [float(v) for v in self.damping], "residual_rms": self.noise,
               "dof": self.dof, "split_test": self.split_test}
        if not separated:
            out["cannot_decide"] = (
                "how the unbalance splits between the planes: the run-up shows the disks moving together "
                "(one mode in the speed range, the shaft stiff against the supports), so only the sum "
                f"{total['g_mm']:.4g} g·mm at {total['angle_deg']:.0f} deg (± {total['ci95_g_mm']:.3g} g·mm) is "
                "determined; run up through the second mode, or balance the split with trial weights")
        return out


def fit_run_up(rpm, Y, probes: list[tuple[int, float]], masses_kg, *, amp_scale: float = 1e-6) -> RunUpFit:
    """Fit the two-disk model (module docstring) to one run-up's 1X vectors.

    ``rpm`` (N,); ``Y`` (N, P) complex, lead convention, in the table's unit; ``probes``:
    per column of ``Y`` the disk (plane index) and the probe's angle (degrees, counted in
    the lead sense from the keyphasor); ``masses_kg`` per disk; ``amp_scale``: metres per
    table unit (µm: 1e-6).
    """
    rpm = np.asarray(rpm, dtype=float)
    Y = np.asarray(Y, dtype=complex)
    m = np.asarray(masses_kg, dtype=float)
    J = len(m)
    N, P = Y.shape
    if len(probes) != P:
        raise ValueError(f"{P} probe columns but {len(probes)} probe positions")
    if J > 2:
        raise ValueError(f"the run-up fit models one or two disks, not {J}")
    if N < 4 * J + 2:
        raise ValueError(f"the run-up has {N} speeds; the two-disk fit needs at least {4 * J + 2}")
    disk = np.array([d for d, _ in probes])
    rot = np.exp(-1j * np.radians([a for _, a in probes]))  # (P,) probe angle: Q e^{-ia}
    y = Y.reshape(-1)

    def design(theta: np.ndarray) -> np.ndarray:
        ks, kshaft, cs = np.exp(theta[:J]), float(np.exp(theta[J])), np.exp(theta[J + 1:])
        R = disk_response(rpm, m, ks, kshaft, cs)  # (N, J, J) m per kg m
        B = R[:, disk, :] * rot[None, :, None] / amp_scale  # (N, P, J): table unit per kg m
        return B.reshape(N * P, J)

    def residual(theta: np.ndarray) -> np.ndarray:
        B = design(theta)
        U, *_ = np.linalg.lstsq(B, y, rcond=None)
        r = y - B @ U
        return np.concatenate([r.real, r.imag])

    # starts: the first natural frequency from the peak of the run-up
    peak = rpm[int(np.argmax(np.sum(np.abs(Y) ** 2, axis=1)))]
    w1 = peak * 2 * math.pi / 60
    k0 = m * w1 ** 2
    c0 = 2 * 0.05 * np.sqrt(k0 * m)
    lo = np.concatenate([np.log(k0 * 1e-2), [np.log(k0.min() * 1e-3)], np.log(c0 * 1e-3)])
    hi = np.concatenate([np.log(k0 * 1e2), [np.log(k0.max() * 1e4)], np.log(c0 * 1e3)])
    best = None
    for ratio in (0.1, 1.0, 10.0, 100.0, 1e3):
        x0 = np.concatenate([np.log(k0), [np.log(ratio * k0.mean())], np.log(c0)])
        try:
            r = optimize.least_squares(residual, x0, bounds=(lo, hi), x_scale=1.0, xtol=1e-12, ftol=1e-12)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if best is None or r.cost < best.cost:
            best = r
    if best is None:
        raise ValueError("the two-disk fit did not converge")
    theta = best.x
    B = design(theta)
    U, *_ = np.linalg.lstsq(B, y, rcond=None)
    r = y - B @ U
    n_par = (2 * J + 1) + 2 * J
    dof = 2 * N * P - n_par
    s2 = float(np.sum(np.abs(r) ** 2)) / dof  # the variance of one real component of a vector

    # the Gauss-Newton covariance of (theta, Re U, Im U): residual's real Jacobian
    def full(params: np.ndarray) -> np.ndarray:
        th, u = params[:2 * J + 1], params[2 * J + 1:]
        rr = y - design(th) @ (u[:J] + 1j * u[J:])
        return np.concatenate([rr.real, rr.imag])

    p0 = np.concatenate([theta, U.real, U.imag])
    step = np.concatenate([np.full(2 * J + 1, 1e-6), np.maximum(np.abs(np.concatenate([U.real, U.imag])), 1e-12)
                           * 1e-6 + 1e-12])
    Jm = np.empty((2 * N * P, len(p0)))
    for i in range(len(p0)):
        d = np.zeros_like(p0)
        d[i] = step[i]
        Jm[:, i] = (full(p0 + d) - full(p0 - d)) / (2 * step[i])
    cov_real = np.linalg.pinv(Jm.T @ Jm) * s2
    cu = cov_real[2 * J + 1:, 2 * J + 1:]
    Crr, Cii, Cri = cu[:J, :J], cu[J:, J:], cu[:J, J:]
    cov_U = (Crr + Cii) + 1j * (Cri.T - Cri)  # E[dU dU^H] of the complex estimate
    to_g_mm = 1e6  # kg m -> g mm
    ks, kshaft, cs = np.exp(theta[:J]), float(np.exp(theta[J])), np.exp(theta[J + 1:])
    K = np.diag(ks)
    for i in range(J - 1):
        K[i, i] += kshaft
        K[i + 1, i + 1] += kshaft
        K[i, i + 1] -= kshaft
        K[i + 1, i] -= kshaft
    lam = np.sort(np.real(np.linalg.eigvals(np.linalg.solve(np.diag(m), K))))
    natural = np.sqrt(np.maximum(lam, 0)) * 60 / (2 * math.pi)
    split = None
    if J > 1:
        sign = np.where(disk == 0, 1.0, -1.0)
        rss_stiff = _stiff_shaft_rss(rpm, y, rot, sign, N, P, float(m.sum()), float(k0.sum()), float(c0.sum()),
                                     amp_scale)
        rss = float(np.sum(np.abs(r) ** 2))
        extra = n_par - 6  # the stiff-shaft limit: log k, log c, the sum and the quasi-static difference
        F = max(rss_stiff - rss, 0.0) / extra / s2
        # under the stiff-shaft limit the second mode's frequency is not identified (it can sit at
        # any speed of the run-up and fit a noise feature there: measured p = 0.003 on one seed of
        # eight with the truth 20 times above the range), so the F distribution understates the
        # statistic: Bonferroni over the N speeds where the mode could sit
        level = SPLIT_P / N
        split = {"F": F, "dof": [extra, float(dof)], "p_value": float(stats.f.sf(F, extra, dof)), "level": level,
                 "meaning": "the two-disk fit against its stiff-shaft limit, in which any split of the unbalance "
                            "fits (a shaft stiff enough); the split between the planes is decided where "
                            f"p < {SPLIT_P} / speeds (the second mode could sit at any of them)"}
    return RunUpFit(U * to_g_mm, cov_U * to_g_mm ** 2, float(dof), ks, kshaft, cs, math.sqrt(2 * s2), natural,
                    split)


def _stiff_shaft_rss(rpm, y, rot, sign, N, P, mass, k0, c0, amp_scale) -> float:
    """Residual sum of squares of the two-disk model in the limit of a stiff shaft.

    The disks' mean motion is one body, ``Omega^2 U_sum / (k - Omega^2 m + i Omega c)``; their
    difference is quasi-static, ``± Omega^2 D`` with ``D = (U_1 - U_2) / (2 k_s)`` as ``k_s``
    grows: any split of the unbalance fits it with a shaft stiff enough.  Nested in the
    two-disk model; where the two-disk model does not fit significantly better, the data
    cannot decide the split.
    """
    w = rpm * 2 * math.pi / 60

    def residual(theta: np.ndarray) -> np.ndarray:
        k, c = np.exp(theta)
        b1 = (w ** 2 / (k - w ** 2 * mass + 1j * w * c))[:, None] * rot[None, :] / amp_scale
        b2 = (w ** 2)[:, None] * (rot * sign)[None, :] / amp_scale
        B = np.column_stack([b1.reshape(-1), b2.reshape(-1)])
        u, *_ = np.linalg.lstsq(B, y, rcond=None)
        rr = y - B @ u
        return np.concatenate([rr.real, rr.imag])

    best = None
    for f in (0.5, 1.0, 2.0):
        res = optimize.least_squares(residual, np.log([k0 * f, c0]), xtol=1e-12, ftol=1e-12)
        if best is None or res.cost < best.cost:
            best = res
    return float(2 * best.cost)
