"""Dimensionless angle records with estimated rates: diagnosed by output error.

A measurement file that holds the tilt angles but not their rates and accelerations
(``t, phi, theta_x, theta_y``) gets those by differentiating the angles
(:mod:`rotor_env.measurements.files`).  When the angles carry noise, the second
derivative multiplies it by ``(2 pi f)^2`` and the equation error (PHYSICS.md section 3)
becomes noise at every speed: its energy no longer moves when an effect is added, and a
decision taken on it is a decision on noise.  Such a record is diagnosed as a rig's
waveforms are (PHYSICS.md section 9): every candidate fitted to the *measured angles*
through the model's predicted response (:mod:`.output_error`), every decision taken on the
measured-minus-predicted residual against the angles' own noise, read off the band above
the response (:func:`.output_error.noise_std_high_band`).

What stays with the equation error: the check that the record excites anything, the time
scale (a stiffness far from 1 rescales the time) and, when ``ip`` is not given, the
inertia ratio's estimate -- held fixed in the output-error fit (its uncertainty is not in
the output-error intervals: a note says so).  A record whose angles are noise-free to the
working precision (a simulation written without its rates) keeps the equation error,
which is exact there and needs no simulation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from identifier.hac import andrews_bandwidth, long_run_covariance

from ..measurements import Measurements
from ..results import Result
from .oe_diagnosis import OutputErrorDiagnosis, diagnose_output_error
from .output_error import (
    ShootingGrid,
    equation_error_start,
    fit_output_error,
    library_effects,
    noise_ar1_two_channels,
)
from .scaling import rescale_time

__all__ = ["AngleDiagnosis", "angle_noise", "diagnose_angles", "needs_output_error", "profile_ip"]

#: the rates' estimate decides by output error when the angles' noise exceeds this share of
#: their peak (a record written by a simulation without its rates sits near 1e-12; a sensor
#: with 20 bits over its range at 1e-6)
NOISE_SHARE = 1e-5
#: the accelerations whose estimate makes the equation error noise
_ACCELERATIONS = ("theta_x_ddot", "theta_y_ddot")


def angle_noise(meas: Measurements) -> tuple[float, float]:
    """The angles' noise per sample and its lag-one correlation (AR(1)), from the band above
    the response (orders up to 3 of the top speed and the natural frequency, 1 in the
    model's time); the two channels' variances and correlations averaged."""
    t = meas.t
    dt = float(np.median(np.diff(t)))
    top = float(np.nanmax(np.abs(meas.phi_dot))) if len(t) else 0.0
    f_top = 4.0 * max(top, 1.0) / (2 * math.pi)
    return noise_ar1_two_channels(meas.theta_x, meas.theta_y, dt, f_top)


def needs_output_error(meas: Measurements) -> bool:
    """Whether the record's accelerations were estimated from angles whose noise makes the
    equation error noise (see the module docstring)."""
    estimated = set(getattr(meas, "estimated", ()) or ())
    if not estimated.intersection(_ACCELERATIONS) or len(meas) < 512:
        return False
    peak = float(np.nanmax(np.hypot(meas.theta_x - np.mean(meas.theta_x), meas.theta_y - np.mean(meas.theta_y))))
    return peak > 0 and angle_noise(meas)[0] > NOISE_SHARE * peak


def angle_grid(meas: Measurements, ip: float) -> ShootingGrid:
    """The record on the output-error grid, the spin from a least-squares spline through the
    angle's whole turns (a noisy or quantised angle's speed is not differentiated)."""
    from ..measurements.keyphasor import smooth_spin

    # the whole turns are found on the running maximum: a noisy angle may step back a little
    phi_s, speed = smooth_spin(meas.t, np.maximum.accumulate(meas.phi))
    std, rho = angle_noise(meas)
    return ShootingGrid.from_arrays(meas.t, phi_s, speed, meas.theta_x, meas.theta_y, ip,
                                    noise_std=max(std, 1e-15), noise_rho=rho)


def output_error_time_scale(meas: Measurements, model: Sequence[str], ip: float) -> tuple[Measurements, float]:
    """The record in the model's time, the natural frequency read off the output error, and
    the factor the time was multiplied by.

    The equation error's stiffness is biased by the noise of differentiated angles (a
    stiffness 3x too high at 5e-4 rad of noise): the time is rescaled by the output error's
    own stiffness, until it is within 5 % of 1, so that every parameter is relative to the
    shaft's stiffness (a crack's ``D`` is ``Delta k / k``) and the segments hold about two
    natural periods."""
    scale = 1.0
    for _ in range(4):
        grid = angle_grid(meas, ip)
        try:
            k = fit_output_error(grid, model, equation_error_start(grid, model), max_iter=20).value("stiffness.k")
        except (FloatingPointError, np.linalg.LinAlgError, ValueError):
            break
        if not (math.isfinite(k) and k > 0) or abs(k - 1.0) < 0.05:
            break
        meas = rescale_time(meas, k)
        scale *= math.sqrt(k)
    return meas, scale


#: inertia ratios at which the starting model's output error is profiled first
IP_GRID = (0.0, 0.15, 0.3, 0.45, 0.6, 0.75, 0.9)


def profile_ip(grid: ShootingGrid, model: Sequence[str]) -> tuple[float, float, str]:
    """The inertia ratio that minimises the output error of ``model``: the profile over
    :data:`IP_GRID`, then a parabola through the best point and its neighbours, refined by
    one through points 0.03 either side.  ``(ip, 95 % half-width, note)``: the half-width from
    the profile's curvature ``a`` (``rss ~ a (ip - ip*)^2``), ``sqrt(3.84 kappa sigma^2 / a)``
    with ``kappa`` the residual's long-run variance over its variance (Bartlett, Andrews'
    bandwidth): coloured residuals carry less information than white ones."""
    fits: dict[float, object] = {}

    def rss(v: float) -> float:
        v = float(min(max(v, 0.0), 0.95))
        if v not in fits:
            try:
                fits[v] = fit_output_error(replace(grid, ip=v), model, equation_error_start(grid, model), max_iter=15)
            except (FloatingPointError, np.linalg.LinAlgError, ValueError):
                fits[v] = None
        return fits[v].rss if fits[v] is not None else math.inf

    def vertex(xs) -> tuple[float, float]:
        ys = np.array([rss(x) for x in xs])
        if not np.all(np.isfinite(ys)):
            return math.nan, math.nan
        a, b, _ = np.polyfit(np.asarray(xs, float), ys, 2)
        return (float(-b / (2 * a)), float(a)) if a > 0 else (math.nan, math.nan)

    values = [rss(v) for v in IP_GRID]
    i = int(np.argmin(values))
    best, curv = IP_GRID[i], math.nan
    if 0 < i < len(IP_GRID) - 1 or i == 0:
        lo = max(i - 1, 0)
        v, _ = vertex(IP_GRID[lo:lo + 3])
        if math.isfinite(v):
            best = float(min(max(v, 0.0), 0.95))
            v2, curv = vertex([max(best - 0.03, 0.0), max(best - 0.03, 0.0) + 0.03, max(best - 0.03, 0.0) + 0.06])
            if math.isfinite(v2):
                best = float(min(max(v2, 0.0), 0.95))
    half = math.nan
    if math.isfinite(curv):
        f = fits.get(min(fits, key=lambda v: abs(v - best)))
        r = f.residual if f is not None else None
        kappa = 1.0
        if r is not None and len(r) > 8:
            u = r - r.mean(axis=0)
            kappa = max(1.0, float(np.trace(long_run_covariance(u, andrews_bandwidth(u))) / np.sum(u * u)))
        half = math.sqrt(3.84 * kappa * grid.noise_std ** 2 / curv)
    if not math.isfinite(half) or half > 0.45:
        return best, math.nan, (f"ip read off the output error's profile: {best:.3f}, hardly determined (the "
                                "gyroscopic moment is little excited); held there")
    return best, half, f"ip read off the output error's profile over ip: {best:.3f} +- {half:.2g} (95 %), held there"


@dataclass
class AngleDiagnosis(Result):
    """The output-error diagnosis of a dimensionless angle record (estimated rates)."""

    source: str | None
    diagnosis: OutputErrorDiagnosis
    ip: float
    notes: list[str] = field(default_factory=list)

    @property
    def verdict(self) -> str:
        return self.diagnosis.verdict

    @property
    def missing(self) -> list[str]:
        return self.diagnosis.missing

    def to_dict(self) -> dict:
        d = dict(self.diagnosis.to_dict())
        d.update({
            "kind": "angles",
            "source": self.source,
            "ip": self.ip,
            "rms_unit": "rad (output error: measured minus predicted angle, scaled to the record's bandwidth; the "
                        "floor is the angles' noise)",
            "physical": {e: p["values"] for e, p in d["parameters"].items()},
            "notes": [*d.get("notes", []), *self.notes],
        })
        return d

    def summary(self) -> str:
        lines = [f"angle record {self.source} (rates estimated from noisy angles: decided on the output error)",
                 f"VERDICT: {self.verdict}" + (f" -- missing: {', '.join(self.missing)}" if self.missing else ""),
                 self.diagnosis.summary()]
        notes = [*self.diagnosis.notes, *self.notes]
        if notes:
            lines.append("notes:")
            lines += [f"  {n}" for n in notes]
        return "\n".join(lines)

    def report(self, path, *, overwrite: bool = False):
        """An HTML page: the verdict, the summary and the output-error figures."""
        from ..pages import esc

        head = f"<h2>Angle record</h2><p>{esc(self.source)}: rates estimated, decided on the output error.</p>"
        return self.diagnosis.write_report(path, head, title="rotor-id angle diagnosis", overwrite=overwrite,
                                           verdict=self.verdict, extra_text=self.summary())

    def save_figures(self, folder, *, overwrite: bool = True):
        return self.diagnosis.save_figures(folder, overwrite=overwrite)


def diagnose_angles(
    meas: Measurements,
    model: Sequence[str],
    candidates: Sequence[str],
    *,
    ip: float | None,
    alpha: float = 0.05,
    notes: Sequence[str] = (),
    progress: bool = False,
) -> AngleDiagnosis:
    """Diagnose an angle record by output error (module docstring).  ``meas`` in the file's
    time (rescaled here by :func:`output_error_time_scale`); ``ip`` held fixed, or (None)
    read off the output error's profile over ip (:func:`profile_ip`)."""
    notes = list(notes)
    lib = library_effects()
    not_oe = [e for e in model if e not in lib and e != "stiffness"]
    if not_oe:
        raise ValueError(f"the output-error fit cannot carry {', '.join(not_oe)} in the starting model (set-valued "
                         "friction or a user effect); give the rates in the file to use the equation error")
    # the time scale (the output error's stiffness) and an unknown ip are read off the model
    # at hand, which the diagnosis may grow (a crack's 1X change trades against both): read
    # again with the final model, and the diagnosis repeated where either moved
    ip_known = ip is not None
    ipv = float(ip) if ip_known else 0.0
    model_now = list(model)
    result, scale, ip_note = None, 1.0, ""
    for _ in range(3):
        meas, factor = output_error_time_scale(meas, model_now, ipv)
        scale *= factor
        grid = angle_grid(meas, ipv)
        if not ip_known:
            ip_new, half, ip_note_new = profile_ip(grid, model_now)
            if result is not None and factor == 1.0 and abs(ip_new - ipv) <= max(half if math.isfinite(half)
                                                                               else 0.0, 0.005):
                break
            if result is not None:
                notes.append(f"with {', '.join(result.added) or 'the starting model'} the time scale moved by "
                             f"{factor:.4g} and ip from {ipv:.3f} to {ip_new:.3f}: the diagnosis was repeated there")
            ipv, ip_note = ip_new, ip_note_new
            grid = replace(grid, ip=ipv)
        elif result is not None and factor == 1.0:
            break
        result = diagnose_output_error(grid, list(model), list(candidates), alpha=alpha, unit_scale=1.0, unit="rad",
                                       progress=progress)
        model_now = list(result.model_after)
    if scale != 1.0:
        notes.append(f"time rescaled by {scale:.6g} (the output error's stiffness): the data's natural frequency is "
                     f"{scale:.4g} per time unit of the file, the model's is 1")
    if ip_note:
        notes.append(ip_note)
    return AngleDiagnosis(meas.source, result, ipv, notes)
