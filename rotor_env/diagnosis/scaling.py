"""What the data can decide before any diagnosis: excitation, inertia ratio, time scale.

* **Excitation.**  A record whose inclinations never leave the noise, whose shaft does
  not turn, or that is too short carries no information on the dynamics; it gets the
  verdict ``not_identifiable`` with the reason — never "healthy".
* **Inertia ratio ``ip``.**  The gyroscopic moment ``ip * phid * th'`` is linear in
  ``ip``, so ``ip`` is estimated as one more regression coefficient (columns
  ``-phid th_x'`` and ``+phid th_y'``), with the stiffness scale and every library
  effect free (a missing library effect cannot bias it) when it is not given.  A given
  ``ip`` that the data contradict gets a warning with the estimate — only when that
  widest fit reaches the noise floor: a fault outside the library biases the estimate,
  and then the ``ip`` cannot be checked (a note says so).
* **Time scale.**  The model is dimensionless (natural frequency 1).  Data in seconds
  or any other unit show a stiffness scale ``k`` far from 1 (``k`` = the squared natural
  frequency in the data's units); they are rescaled, ``t' = t sqrt(k)``, rates divided
  by ``sqrt(k)`` and accelerations by ``k``, and the scale is reported.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from identifier.hac import hac_covariance

from ..effects import EFFECTS
from ..measurements import Measurements
from ..regression import RegressionSpec, regression_arrays
from .compare import white_noise_level
from .orders import noise_floor

__all__ = ["MIN_REVOLUTIONS", "MIN_SAMPLES", "InertiaEstimate", "NotIdentifiable", "check_excitation",
           "estimate_ip_and_stiffness", "rescale_time"]

MIN_SAMPLES = 200
MIN_REVOLUTIONS = 4.0
#: the inclinations must exceed this many times their own noise level somewhere
MIN_SIGNAL_TO_NOISE = 10.0
#: a stiffness scale outside this range means the data are not in the model's time unit
K_RANGE = (0.5, 2.0)


class NotIdentifiable(ValueError):
    """The record cannot decide anything about the rotor's effects (the reason says why)."""


def check_excitation(meas: Measurements) -> None:
    """Raise :class:`NotIdentifiable` for a record that cannot be diagnosed."""
    if len(meas) < MIN_SAMPLES:
        raise NotIdentifiable(f"not enough data: {len(meas)} samples (at least {MIN_SAMPLES} are needed)")
    turns = abs(float(meas.phi[-1] - meas.phi[0])) / (2 * math.pi)
    if not np.any(meas.phi_dot != 0) or turns < MIN_REVOLUTIONS:
        raise NotIdentifiable(f"no excitation: the shaft turns {turns:.2g} revolutions "
                              f"(at least {MIN_REVOLUTIONS:g} are needed)")
    amp = np.hypot(meas.theta_x, meas.theta_y)
    peak = float(amp.max())
    noise = max(white_noise_level(meas.theta_x), white_noise_level(meas.theta_y))
    if peak == 0.0:
        raise NotIdentifiable("no excitation: the inclinations are zero throughout (the rotor never leaves rest)")
    if noise > 0 and peak < MIN_SIGNAL_TO_NOISE * noise:
        raise NotIdentifiable(f"no excitation: the largest inclination {peak:.3g} is within "
                              f"{MIN_SIGNAL_TO_NOISE:g}x the sensor noise {noise:.3g}")


@dataclass(frozen=True)
class InertiaEstimate:
    """The inertia ratio and stiffness scale the data give (``ip``, ``k`` free).

    ``rms_ratio`` is the RMS of that fit's residual over the noise floor: near 1 the fit
    describes the data and ``ip`` can be trusted (and a given one checked); far above,
    something the library does not hold biases it, and it is only a rough value.
    """

    ip: float
    standard_error: float
    k: float
    rms_ratio: float

    @property
    def trusted(self) -> bool:
        return math.isfinite(self.rms_ratio) and self.rms_ratio <= TRUST_RATIO


#: the widest model's residual within this factor of the noise floor makes ip checkable
TRUST_RATIO = 1.5


def _widest(model: Sequence[str], candidates: Sequence[str] = ()) -> tuple[str, ...]:
    """The model with every library effect and candidate (user effects) added (``ip`` is
    read with all of them free, so that a missing one cannot bias it), the stiffness last."""
    from .model import LIBRARY_CANDIDATES

    # an effect with a scanned parameter (the rub's clearance) has no columns before its
    # scan: it is left out (at a guessed clearance it would fit something else)
    effects = [e for e in (*model, *LIBRARY_CANDIDATES, *candidates)
               if e != "stiffness" and (e in model or not EFFECTS[e].scanned_parameters)]
    if "unbalance_in_phase" in effects:  # shares tau with the unbalance
        effects = [e for e in effects if e != "unbalance"]
    return (*dict.fromkeys(effects), "stiffness")


def _ip_fit(data: np.ndarray, effects: tuple[str, ...]):
    """Regression columns with the gyroscopic one first (ip = 0 in the builder: the
    unbalance columns carry ``1 - ip`` and their coefficients absorb it)."""
    spec = RegressionSpec(effects=effects, equation="both", known={})
    X, y = regression_arrays(spec, np.ascontiguousarray(data), 0.0)
    gyro = np.empty(len(y))
    gyro[0::2] = -data[:, 2] * data[:, 6]  # first equation: -phid th_x'
    gyro[1::2] = data[:, 2] * data[:, 7]   # second equation: +phid th_y'
    return spec, np.column_stack([gyro, X]), y


def estimate_ip_and_stiffness(meas: Measurements | np.ndarray, model: Sequence[str],
                              raw: np.ndarray | None = None, noise_gain: float = 1.0,
                              candidates: Sequence[str] = (), widest: bool = True) -> InertiaEstimate:
    """``ip`` (HAC standard error, :mod:`identifier.hac`) and ``k`` from a fit of ``model``
    plus every library effect with ``ip`` and ``k`` unknown.

    ``meas`` is a record (its informative part is used) or the samples to fit; with
    ``raw`` (the same samples unfiltered, ``noise_gain`` the prefilter's gain) the noise
    floor of the fit is estimated and ``rms_ratio`` filled in.
    """
    if isinstance(meas, Measurements):
        amp = np.hypot(meas.theta_x, meas.theta_y)
        data = meas.data[amp > 0.1 * amp.max()] if amp.max() > 0 else meas.data
    else:
        data = np.asarray(meas, dtype=float)
    # the time scale needs k alone: the widest model holds effects whose columns share the
    # stiffness direction (a breathing crack's mean opening), which would make k ambiguous
    if widest:
        effects = _widest(model, candidates)
    else:  # the forcing every rotor has (a model may leave the unbalance out: it is a candidate)
        base = [e for e in (*model, "unbalance", "viscous_damping", "static_load") if e != "stiffness"]
        if "unbalance_in_phase" in base:
            base = [e for e in base if e != "unbalance"]
        effects = (*dict.fromkeys(base), "stiffness")
    spec, A, y = _ip_fit(data, effects)
    keep = np.linalg.norm(A, axis=0) > 0
    if not keep[0]:
        return InertiaEstimate(math.nan, math.inf, math.nan, math.inf)
    A = A[:, keep]
    theta, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ theta
    cov = hac_covariance(A, resid, rows_per_time=2)  # both equations per sample
    k_col = 1 + spec.columns.index("k")
    k = float(theta[int(np.sum(keep[:k_col]))]) if keep[k_col] else math.nan
    ratio = math.nan
    if raw is not None:
        _, A_raw, y_raw = _ip_fit(raw, effects)
        r_raw = y_raw - A_raw[:, keep] @ theta
        floor = math.sqrt(0.5 * (noise_floor(r_raw[0::2]) ** 2 + noise_floor(r_raw[1::2]) ** 2)) * noise_gain
        rms = float(np.sqrt(np.mean(resid * resid)))
        ratio = rms / floor if floor > 0 else (1.0 if rms == 0 else math.inf)
    return InertiaEstimate(float(theta[0]), float(math.sqrt(max(cov[0, 0], 0.0))), k, ratio)


def rescale_time(meas: Measurements, k: float) -> Measurements:
    """The record in the model's time unit: ``t' = t sqrt(k)`` (``k``: squared natural frequency)."""
    s = math.sqrt(k)
    d = meas.data.copy()
    d[:, 0] *= s          # t
    d[:, 2] /= s          # phi_dot
    d[:, 3] /= k          # phi_ddot
    d[:, 6:8] /= s        # theta rates
    d[:, 8:10] /= k       # theta accelerations
    return Measurements(d, meas.source, meas.estimated)
