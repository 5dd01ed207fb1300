"""The sequential test: a CUSUM whose threshold follows from the target in-control ARL.

Block evidence
--------------
The stream is cut into blocks of ``B`` samples.  For each monitored effect ``g`` (its
``q`` regressor columns ``Z_g``) and each block, the *score* of a change of the
effect's coefficients against the reference model (the forgetting-window fit of all
effects before the block) is

    e = y - X theta_ref                       (the block's prediction error)
    Z~ = Z_g - X_o (X_o' X_o)^-1 X_o' Z_g     (Z_g without what the other columns explain)
    s = Z~' e,      A = Z~' Z~

``Z~`` is orthogonal to the other effects' columns inside the block, so a change of
another effect leaves ``s`` alone (attribution), and ``s`` only carries the reference's
error of effect ``g`` itself: ``s = Z~' eps + A (theta_g - theta_ref,g)``.  Under "no
change", with the residual's autocovariance ``gamma(l)`` (pooled over the past blocks,
Bartlett weights ``w_l = 1 - l/(L+1)``: a positive semi-definite long-run estimate, as
Newey-West) and the reference's covariance ``C_g``,

    V = sum_{|l| <= L} w_l gamma(l) sum_r z~_r z~_{r+l}'  +  A C_g A
    chi = s' V^-1 s  ~  chi2(q).

What the HAC term still misses (noise in the regressors, a slowly varying misfit) is
measured, not assumed: the calibration factor ``kappa_g`` is the in-control mean of
``chi / q`` (batch means of the block statistic, winsorised at the chi2(q) 99 %
quantile and divided by that winsorised mean's null value), and ``chi / max(1, kappa_g)``
is used.  The block statistic is turned into a standard normal by its probability
integral transform,

    Z_k = Phi^-1(F_chi2(q)(chi_k / kappa_g)),

so that every effect, whatever ``q``, feeds the same Gaussian CUSUM.

Isolation: which effect changed
-------------------------------
The CUSUMs detect; naming the effect is a second question (detection, then isolation, as
in Willsky & Jones' generalized likelihood ratio for abrupt changes).  The partial score
above is orthogonal to the other effects' columns *inside a block*, yet a step still
reaches another effect's CUSUM through the reference: after the block that straddles the
step, the forgetting fit has absorbed part of it into whichever of its nearly collinear
effects the data cannot tell apart.  On a synchronous orbit a crack's moment is a 1X
forcing, as an unbalance's is; at 0.001 um of probe noise on a rig the asymmetry's blocks
could no longer be sized, and the crack's step was named ``changed unbalance``.

So at an alarm, on its deciding block (the block after the crossing one, wholly after a
step), each effect's change *alone* is fitted to the block's prediction error ``e``:

    E_h = e' X_h (X_h' X_h)^-1 X_h' e / (lr kappa_h),     score_h = E_h - q_h

(``lr`` the noise's long-run variance per row, ``kappa_h`` the effect's calibration:
``E_h`` is chi2(q_h) where nothing changed, so ``score_h`` is the energy explained beyond what
noise alone would give).  Where the best score is below the 99 % point of chi2(q_best) the
block alone decides nothing (a change that built up over the CUSUM's blocks, a growing
crack) and the CUSUM's own effect is named, sized from its sums.  Otherwise the candidates
are the effects within the 99 % point of chi2(q_best + q_h) of the best: one candidate is
named (its value after: the reference on the deciding block plus its fitted change), several
make an ``unattributed`` event that lists them, each with its values, and names none.  On
the monitor's own scenarios (``benchmarks/monitor.py``) a crack's step and a lost balance
weight are each named right; on the rig the crack at 0.001 um scores 1417 against the
unbalance's 1397, 20 apart where the margin is 13.3.

CUSUM and its threshold (the derivation)
-----------------------------------------
Page's CUSUM for a shift of the mean of ``Z`` from 0 to ``delta``:

    S_k = max(0, S_{k-1} + Z_k - delta / 2),     alarm when S_k > h.

Its log-likelihood-ratio increments are ``delta (Z_k - delta/2)``; the CUSUM is the
sequence of SPRTs restarted at 0, so (Wald) its run length is the number of SPRTs
times their length.  With Siegmund's (1985) correction for the overshoot of a Gaussian
random walk over the boundary (``rho = 0.5826`` times the standard deviation, at each
of the two boundaries: ``h -> h + 2 * 0.583 = h + 1.166``), the in-control average run
length in blocks is

    ARL0(h) = (exp(2 k b) - 1 - 2 k b) / (2 k^2),     k = delta/2,  b = h + 1.166.

With ``G`` effects watched, the monitor alarms when any of the ``G`` CUSUMs does; the
false-alarm rates add at most (Bonferroni), so each CUSUM gets
``ARL0_g = G * ARL0 / B`` blocks for a target ``ARL0`` in samples, and ``h`` solves
``ARL0(h) = ARL0_g`` (monotone in ``h``: bisection).  Blocks where an effect is not
identifiable do not move its CUSUM (they are not evidence), so the rate per stream
sample is at most the design rate: the target is met conservatively.
:func:`simulate_arl` checks the formula by simulation of the CUSUM itself
(``tests/test_monitor_detector.py``); the benchmark checks the whole chain on
simulated healthy rotors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

__all__ = ["CusumDesign", "chi2_sf", "cusum_arl0", "cusum_threshold", "norm_ppf", "simulate_arl"]

#: Siegmund's overshoot correction of a Gaussian random walk (2 x 0.5826)
OVERSHOOT = 1.166


def cusum_arl0(h: float, delta: float) -> float:
    """In-control ARL (steps) of the Gaussian CUSUM tuned for ``delta``, threshold ``h`` (Siegmund)."""
    k = delta / 2.0
    x = 2.0 * k * (h + OVERSHOOT)
    return (math.expm1(x) - x) / (2.0 * k * k)


def cusum_threshold(arl0_steps: float, delta: float) -> float:
    """The ``h`` whose in-control ARL is ``arl0_steps`` (bisection on :func:`cusum_arl0`)."""
    if not arl0_steps > 1.0:
        raise ValueError(f"the in-control ARL must be > 1 step, got {arl0_steps!r}")
    lo, hi = 0.0, 1.0
    while cusum_arl0(hi, delta) < arl0_steps:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if cusum_arl0(mid, delta) < arl0_steps:
            lo = mid
        else:
            hi = mid
    return hi


@dataclass(frozen=True)
class CusumDesign:
    """A CUSUM per effect for a target ARL0 in stream samples (see the module docstring).

    ``arl0``: samples between false alarms (all effects together); ``block``: samples
    per block; ``effects``: how many CUSUMs share the budget; ``delta``: the shift of
    the standardised block evidence the CUSUM is tuned for.
    """

    arl0: float
    block: int
    effects: int
    delta: float = 2.0

    @property
    def arl0_blocks_per_effect(self) -> float:
        return self.effects * self.arl0 / self.block

    @property
    def threshold(self) -> float:
        return cusum_threshold(self.arl0_blocks_per_effect, self.delta)


@njit(cache=True)
def _run_lengths(z: np.ndarray, k: float, h: float) -> np.ndarray:
    runs, steps = z.shape
    out = np.full(runs, -1.0)
    for i in range(runs):
        s = 0.0
        for j in range(steps):
            s = max(0.0, s + z[i, j] - k)
            if s > h:
                out[i] = j + 1
                break
    return out


def simulate_arl(h: float, delta: float, runs: int, max_steps: int, seed: int = 0) -> tuple[float, float]:
    """ARL of the CUSUM on i.i.d. N(0, 1) evidence by simulation: ``(mean, standard error)``.

    Runs that do not alarm within ``max_steps`` make it a lower bound; choose
    ``max_steps`` several times the ARL.
    """
    rng = np.random.default_rng(seed)
    lengths = []
    todo = runs
    while todo:
        batch = min(todo, max(1, 20_000_000 // max_steps))
        r = _run_lengths(rng.standard_normal((batch, max_steps)), delta / 2.0, h)
        r[r < 0] = max_steps
        lengths.append(r)
        todo -= batch
    n = np.concatenate(lengths)
    return float(n.mean()), float(n.std(ddof=1) / math.sqrt(len(n)))


# ----------------------------------------------------------- distributions, compiled
# Closed forms (no scipy address: the kernels that use them are cached on disk).

@njit(cache=True)
def chi2_sf(x: float, q: int) -> float:
    """``P[chi2(q) > x]`` for an integer ``q >= 1`` (closed forms of the incomplete gamma)."""
    if x <= 0.0:
        return 1.0
    h = 0.5 * x
    if q % 2 == 0:
        term = math.exp(-h)
        acc = term
        for j in range(1, q // 2):
            term *= h / j
            acc += term
        return min(acc, 1.0)
    r = math.sqrt(x)
    acc = math.erfc(r / math.sqrt(2.0))
    term = math.sqrt(2.0 * x / math.pi) * math.exp(-h)  # the odd series' first term
    for j in range(1, (q + 1) // 2):
        acc += term
        term *= h / (j + 0.5)
    return min(acc, 1.0)


@njit(cache=True)
def norm_ppf(p: float) -> float:
    """``Phi^-1(p)``: Acklam's rational approximation refined by one Halley step (to ~1e-15)."""
    if p <= 0.0:
        return -math.inf
    if p >= 1.0:
        return math.inf
    a = (-3.969683028665376e01, 2.209460984245205e02, -2.759285104469687e02,
         1.383577518672690e02, -3.066479806614716e01, 2.506628277459239e00)
    b = (-5.447609879822406e01, 1.615858368580409e02, -1.556989798598866e02,
         6.680131188771972e01, -1.328068155288572e01)
    c = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e00,
         -2.549732539343734e00, 4.374664141464968e00, 2.938163982698783e00)
    d = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e00, 3.754408661907416e00)
    if p < 0.02425:
        u = math.sqrt(-2.0 * math.log(p))
        x = ((((((c[0] * u + c[1]) * u + c[2]) * u + c[3]) * u + c[4]) * u + c[5])
             / ((((d[0] * u + d[1]) * u + d[2]) * u + d[3]) * u + 1.0))
    elif p > 1.0 - 0.02425:
        u = math.sqrt(-2.0 * math.log(1.0 - p))
        x = -((((((c[0] * u + c[1]) * u + c[2]) * u + c[3]) * u + c[4]) * u + c[5])
              / ((((d[0] * u + d[1]) * u + d[2]) * u + d[3]) * u + 1.0))
    else:
        u = p - 0.5
        r = u * u
        x = ((((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * u
             / (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0))
    # Halley refinement on Phi(x) - p
    e = 0.5 * math.erfc(-x / math.sqrt(2.0)) - p
    g = e * math.sqrt(2.0 * math.pi) * math.exp(0.5 * x * x)
    return x - g / (1.0 + 0.5 * x * g)


@njit(cache=True)
def evidence_z(chi: float, q: int) -> float:
    """Standard-normal evidence of a block: ``Phi^-1(1 - sf)`` computed from the upper tail.

    ``-Phi^-1(sf)`` keeps precision where ``sf`` is tiny (``1 - sf`` would round to 1);
    an underflowing ``sf`` is capped at 1e-300 (``Z`` about 37).
    """
    sf = chi2_sf(chi, q)
    return -norm_ppf(max(sf, 1e-300))
