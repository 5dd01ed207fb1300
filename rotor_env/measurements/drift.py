"""The probes' slowly moving mean, measured and fitted with every model.

A proximity probe reads the gap to the shaft, and the gap's mean does not stay put while
the rotor runs:

* on fluid-film bearings the shaft **lifts and moves across its clearance as the speed
  changes** (the shaft centreline plot: tens of um between slow roll and running speed);
* the casing and the shaft **grow with temperature**, and a probe's gap voltage drifts
  with its driver's temperature (a few um over a run);
* a slow random walk of the electronics (flicker noise far below the shaft's orders).

None of it is the rotor model's: the model's static position is a constant (the probes'
offsets, fitted with every model), its response lies at the shaft's orders and its own
natural frequencies, all at or above the slowest 1X.  Left in, a ±2 um linear drift made a
healthy rig ``unexplained`` (2.5× the floor) and a 1 um random walk had a
``nonlinear_stiffness`` named.

**The baseline.**  Each probe's mean over :data:`MEAN_REVOLUTIONS` whole revolutions about
every sample (the shaft angle from the keyphasor; at the record's ends the first or last such
stretch): the mean over whole turns takes out every order of the shaft exactly -- 1X, 2X, ...,
and with two turns the half orders of a rub's or an oil whirl's subharmonic -- as the DC
gap voltage of a shaft centreline plot is read.  Through those means, a least-squares cubic
spline with knots :data:`DRIFT_REVOLUTIONS` revolutions of the slowest speed apart (``h``; the
whole record at most) smooths what the short means leave of the noise and of the
non-integer orders (a free whirl at the natural frequency, attenuated by the turn-mean's
``sinc`` and again by the spline): it passes a slow variation whole, half of one at
``1 / (2 h)`` (an eighth of the slowest 1X), and nearly nothing above ``1 / h``.  A spline
fitted to the readings themselves would not do: its end pieces take a large share of a
partial turn of a 100 um 1X (tens of um).  The baseline's own mean is left in the
readings: the constant gap is the probes' business
(:func:`~rotor_env.measurements.probes.to_model_axes`).

**Fitted, not subtracted.**  The output-error fit carries the baseline with every model
(:attr:`~rotor_env.diagnosis.output_error.ShootingGrid.baseline_spacing`: the prediction
takes the least-squares spline of what it leaves, a variable projection), because a model
can have a slow response of its own: a breathing crack under its static load deflects on
average more or less as the speed changes.  Subtracted from the data alone, that went with
the drift and the crack's fit lost it (the load 30 % off, the breathing depth 0.14 for 0.7);
fitted with the model, only what the model does not predict is taken.  The 1X vectors, which
read the shaft's orders only, are order-tracked from the record less its baseline
(:func:`remove_drift`).  The movement is said in the record's notes (each probe's
peak-to-peak of its two-turn means, in the rig's unit, and the spline's spacing), and
:func:`probe_drift` returns it (:meth:`ProbeDrift.centreline`: each plane's mean position, which
:meth:`~rotor_env.diagnosis.from_rig.RigDiagnosis.plot_centreline` draws).

It is fitted where some probe's baseline is more than :data:`DRIFT_RELEVANT` of its noise
(RMS): a smaller one adds under 1 % to the residual's variance, and the baseline costs the fit
steps (its curvature is the model's, ``J'J``, larger than the projected residual's).

What it cannot take: a random walk of the electronics with power between the baseline's
cut-off and the slowest 1X (a 1 um random walk over a 10 s record left 1.07-1.1x the floor on
healthy records and 1.7x on a tilt rig, whose probes' difference doubles it): noise in the
rotor's band that the band above does not show.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

__all__ = ["DRIFT_RELEVANT", "DRIFT_REVOLUTIONS", "MEAN_REVOLUTIONS", "ProbeDrift", "drift_knot_spacing",
           "drift_note", "probe_drift", "remove_drift", "spline_knots", "turn_means"]

#: knot spacing of the baseline spline, in revolutions at the record's slowest speed
DRIFT_REVOLUTIONS = 4.0
#: whole revolutions each mean is taken over (two: the half orders vanish too)
MEAN_REVOLUTIONS = 2
#: the record's slowest speed: this quantile of its speed (a few revolutions at standstill
#: before a run-up do not make the whole baseline a constant)
SLOWEST_QUANTILE = 0.02
#: the baseline is fitted where some probe's moves by more than this share of its noise (RMS
#: of the spline against the probe's noise per sample): below, it adds under 1 % to the
#: residual's variance, and the fit is left as it was (the baseline slows the fit's
#: convergence: 9 steps for 4 on a crack's final model)
DRIFT_RELEVANT = 0.1
#: fewest samples per knot interval (a short record at a low sample rate: fewer knots)
MIN_SAMPLES_PER_KNOT = 32


@dataclass(frozen=True)
class ProbeDrift:
    """Each probe's slowly moving mean over a record (its own mean removed), in the rig's unit.

    ``knot_spacing_s``: the spline's knot spacing; ``cutoff_hz``: the frequency it passes
    at half gain (``1 / (2 h)``); ``slowest_rpm``: the speed that set it."""

    t: np.ndarray = field(repr=False)
    baseline: dict[str, np.ndarray] = field(repr=False)
    knot_spacing_s: float
    slowest_rpm: float

    @property
    def cutoff_hz(self) -> float:
        return 0.5 / self.knot_spacing_s

    def centreline(self, rig) -> dict[str, np.ndarray]:
        """Each plane's average position ``(N, 2)`` along the model's axes (``u`` at the rig
        file's 0 deg, ``v`` at 90 deg, in the rig's unit), from its probes' baselines by least
        squares (:func:`~rotor_env.measurements.probes.plane_displacements`)."""
        from .probes import plane_displacements

        out = {}
        for plane in rig.plane_names:
            members = [p for p in rig.probes if p.plane == plane]
            X = np.column_stack([self.baseline[p.name] for p in members])
            out[plane] = plane_displacements(np.array([p.angle for p in members]), X)
        return out

    @property
    def rms(self) -> dict[str, float]:
        """Each probe's baseline's root mean square (its mean is zero)."""
        return {nm: float(np.sqrt(np.mean(b * b))) if len(b) else 0.0 for nm, b in self.baseline.items()}

    def relevant(self, noise: dict[str, float]) -> bool:
        """Whether some probe's baseline is more than :data:`DRIFT_RELEVANT` of its noise
        ``noise[probe]`` (per sample, same unit)."""
        return self.knot_spacing_s > 0 and any(r > DRIFT_RELEVANT * noise[nm] for nm, r in self.rms.items())

    @property
    def peak_to_peak(self) -> dict[str, float]:
        """Each probe's baseline from its lowest to its highest point."""
        return {nm: float(np.ptp(b)) if len(b) else 0.0 for nm, b in self.baseline.items()}


def spline_knots(t0: float, t1: float, h: float) -> np.ndarray:
    """Knot vector of a cubic spline on ``[t0, t1]``: interior knots about ``h`` apart (the
    whole intervals of ``h`` in the span, stretched to end at ``t1``), the ends repeated four
    times."""
    n_int = max(1, int(math.floor((t1 - t0) / h)))
    inner = np.linspace(t0, t1, n_int + 1)
    return np.concatenate([[t0] * 3, inner, [t1] * 3])


def turn_means(phi: np.ndarray, x: np.ndarray, turns: int = MEAN_REVOLUTIONS) -> np.ndarray:
    """The mean of ``x`` over ``turns`` whole revolutions of the shaft angle ``phi`` (rad,
    increasing) centred on every sample -- at the record's ends over its first or last
    ``turns`` revolutions -- by the trapezoidal integral of ``x dphi``; ``None`` where the
    record holds fewer than ``turns`` revolutions."""
    span = 2.0 * math.pi * turns
    if len(phi) < 2 or phi[-1] - phi[0] < span:
        return None
    dphi = np.diff(phi)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * dphi)])
    centre = np.clip(phi, phi[0] + 0.5 * span, phi[-1] - 0.5 * span)
    hi = np.interp(centre + 0.5 * span, phi, cum)
    lo = np.interp(centre - 0.5 * span, phi, cum)
    return (hi - lo) / span


def _slowest_rev_hz(speed: np.ndarray) -> float:
    """The record's slowest speed (rev/s) from its speeds (rad/s): :data:`SLOWEST_QUANTILE`."""
    return float(np.quantile(np.abs(np.asarray(speed, float)), SLOWEST_QUANTILE)) / (2.0 * math.pi)


def drift_knot_spacing(t: np.ndarray, speed: np.ndarray) -> float:
    """The baseline's knot spacing (s) for a record of times ``t`` (s) and shaft speeds
    ``speed`` (rad/s): :data:`DRIFT_REVOLUTIONS` revolutions of its slowest speed, at least
    :data:`MIN_SAMPLES_PER_KNOT` samples, at most the whole record (0 for fewer than two
    samples)."""
    t = np.asarray(t, float)
    duration = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    if duration <= 0:
        return 0.0
    slowest = _slowest_rev_hz(speed)
    h = DRIFT_REVOLUTIONS / slowest if slowest > 0 else math.inf
    return min(max(h, MIN_SAMPLES_PER_KNOT * duration / (len(t) - 1)), duration)


def probe_drift(record) -> ProbeDrift:
    """The slowly moving mean of every probe of ``record`` (a
    :class:`~rotor_env.measurements.waveforms.RigRecord`): the turn means smoothed by the
    least-squares cubic spline of the module docstring, its own mean removed.  A record of
    fewer than :data:`MEAN_REVOLUTIONS` turns, or whose shaft angle does not advance, has no
    baseline (zeros)."""
    from scipy.interpolate import make_lsq_spline

    t = np.asarray(record.t, float)
    phi = np.asarray(record.phi, float)
    h = drift_knot_spacing(t, record.speed)
    slowest = _slowest_rev_hz(record.speed)
    baseline = {nm: np.zeros(len(t)) for nm in record.readings}
    advancing = len(phi) > 1 and bool(np.all(np.diff(phi) > 0))
    if h > 0 and advancing:
        knots = spline_knots(float(t[0]), float(t[-1]), h)
        for nm, x in record.readings.items():
            x = np.asarray(x, float)
            means = turn_means(phi, x - float(np.mean(x)))
            if means is None:
                break
            b = make_lsq_spline(t, means, knots, k=3)(t)
            baseline[nm] = b - float(np.mean(b))
    return ProbeDrift(t=t, baseline=baseline, knot_spacing_s=float(h), slowest_rpm=60.0 * slowest)


def remove_drift(record, drift: ProbeDrift | None = None):
    """``record`` with every probe's slowly moving mean (:func:`probe_drift`) taken out.

    For what reads the shaft's orders only (the 1X vectors): a model whose own mean response
    moves with the speed (a cracked shaft's mean deflection under its load) must be fitted
    with the baseline instead, as the output-error fit does."""
    from .probes import to_model_axes

    drift = probe_drift(record) if drift is None else drift
    readings = {nm: np.asarray(x, float) - drift.baseline[nm] for nm, x in record.readings.items()}
    u, v = to_model_axes(record.rig, readings)
    return replace(record, readings=readings, u=u, v=v)


def drift_note(drift: ProbeDrift, unit: str, fitted: bool) -> str:
    """What the record's slowly moving mean was and how the diagnosis took it."""
    ptp = ", ".join(f"{nm} {p:.3g}" for nm, p in drift.peak_to_peak.items())
    how = (f"fitted with every model: splines {drift.knot_spacing_s:.3g} s apart ({DRIFT_REVOLUTIONS:g} turns at the "
           f"slowest speed, {drift.slowest_rpm:.0f} rpm; half gain at {drift.cutoff_hz:.3g} Hz)" if fitted else
           f"not fitted: under {DRIFT_RELEVANT:g} of the probes' noise (RMS)")
    return (f"the probes' slowly moving mean (the shaft's centreline on its bearings, thermal growth, a drifting "
            f"gap) {how}; its mean over two turns moved by {ptp} {unit} peak to peak")
