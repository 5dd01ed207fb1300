"""Errors in variables: the bias that sensor noise in the regressors puts on the estimates.

The regression's columns are built from measured inclinations and their rates; their
noise is in the *regressors*, not only in the output.  Least squares then attenuates
the coefficients of noisy columns — the viscous damping ``c`` (a noisy rate) and the
dry friction ``h`` (``v/|v|`` of a noisy relative speed, non-linear: near break-away
the noise flips its sign) come out a few tenths of a per cent low, which on a long
record is one or two standard errors: a 95 % interval that misses the truth a
quarter of the time.  The prefilter (:func:`~rotor_env.diagnosis.compare.prefilter_cutoff`)
removes most of the noise; what stays in its pass band is corrected here.

**SIMEX** (simulation–extrapolation; Cook & Stefanski 1994, Carroll et al.,
*Measurement Error in Nonlinear Models*, ch. 5): the noise is what biases the
estimate, so add *more* of it — ``lambda`` times each channel's own white-noise
variance, ``lambda`` in ``LEVELS``, ``REPLICATES`` draws each — refit the same model
after the same prefilter, and extrapolate the estimate's path ``theta(lambda)`` back
to ``lambda = -1``, the noise-free data.  The extrapolant is a line through the
naive estimate (``lambda = 0``): the bias of these estimates grows as the noise
variance (measured: x4.2-4.9 per doubling of the noise's standard deviation), and a
line keeps the extrapolation's own noise small — each draw moves the estimate by
``sqrt(lambda)`` standard errors, so the slope, weighted by ``B / lambda``, has a
standard deviation of ``SE / sqrt(sum B lambda)`` (0.29 SE here); a quadratic
extrapolant multiplies it several times (tried: coverage fell).  It needs no model of how a column depends on
the noise (any effect, user effects included) and only the channels' noise level,
which is read from the data (:func:`~rotor_env.diagnosis.compare.white_noise_level`).

The correction is reported beside the estimate (``Comparison.eiv_bias``: naive minus
corrected) and the corrected coefficients replace the naive ones; the standard
errors stay the HAC ones of the naive fit (the extrapolation adds little variance:
the coverage over noise seeds is checked in ``tests/test_coverage.py``).
"""

from __future__ import annotations

import copy

import numpy as np

from .compare import Comparison, WindowData, known_values, model_design, physical_values

__all__ = ["LEVELS", "REPLICATES", "correct_errors_in_variables", "simex_correct"]

#: extra noise variances, in units of each channel's own
LEVELS = (1.0, 2.0)
#: antithetic pairs of noise draws per level
REPLICATES = 1
#: the six inclination channels (theta, rates, accelerations) of the ten-column layout
CHANNELS = slice(4, 10)


def _fit_on(data: WindowData, samples: np.ndarray, comp: Comparison) -> np.ndarray:
    view = copy.copy(data)
    view.data = np.ascontiguousarray(samples)
    _, X, y, _, _, _ = model_design(view, comp.model, known_values(comp.model), comp.onsets, comp.splits)
    keep = np.linalg.norm(X, axis=0) > 0
    theta = np.zeros(X.shape[1])
    theta[keep], *_ = np.linalg.lstsq(X[:, keep], y, rcond=None)
    return theta


def simex_correct(data: WindowData, comp: Comparison, seed: int = 0) -> np.ndarray | None:
    """SIMEX-corrected coefficients of ``comp`` (None where there is nothing to correct:
    noise-free data, or no prefilter to reproduce).

    Deterministic: the extra noise is drawn from ``seed``.
    """
    sigma = data.channel_noise
    if data.sos is None or sigma is None or not np.any(sigma > 0):
        return None
    from scipy.signal import sosfiltfilt

    rng = np.random.default_rng(seed)
    raw = data.full.data
    start = data.window_start
    base = comp.coefficients
    moved = np.zeros_like(base)
    for lam in LEVELS:
        for _ in range(REPLICATES):
            extra = rng.standard_normal((len(raw), 6)) * (np.sqrt(lam) * sigma)
            # antithetic pair: +e and -e move the estimate by the same first-order (linear
            # in e, zero-mean) amount in opposite directions; their mean keeps the bias
            for sign in (1.0, -1.0):
                noisy = raw.copy()
                noisy[:, CHANNELS] += sign * extra
                noisy[:, CHANNELS] = sosfiltfilt(data.sos, noisy[:, CHANNELS], axis=0)
                # weight B/lambda on (theta - base)/lambda, times lambda^2: sum of B (theta - base)
                moved += 0.5 * (_fit_on(data, noisy[start:], comp) - base)
    slope = moved / (REPLICATES * sum(LEVELS))
    return base - slope


def correct_errors_in_variables(data: WindowData, comp: Comparison, seed: int = 0) -> Comparison:
    """Replace ``comp``'s coefficients and physical values by the SIMEX-corrected ones (in
    place; ``comp.eiv_bias`` keeps what was removed).  The residual, the tests and the
    standard errors stay those of the fit."""
    corrected = simex_correct(data, comp, seed)
    if corrected is None or comp.eiv_bias is not None:
        return comp
    spec, _, _, _, columns, _ = model_design(data, comp.model, known_values(comp.model), comp.onsets, comp.splits)
    comp.eiv_bias = comp.coefficients - corrected
    comp.coefficients = corrected
    comp.physical, before = physical_values(spec, columns, corrected, comp.splits)
    if comp.splits:
        comp.physical_before = before
    return comp
