"""What a record cannot decide: the smallest size of each effect it would show.

A diagnosis that names nothing has said little until it says how large a fault could be
and still hide in the data.  For every library effect the final model lacks, the
output-error fit is asked (:func:`~rotor_env.diagnosis.output_error.added_effect_information`)
how much of the effect's output signature the model, the probes' offsets and runout and
the segments' free start states already take, and what the rest is worth against the
noise:

- ``visible``: the share of the signature's energy left (least and most visible
  direction of its coefficients).  A static load on a linear rotor only moves the static
  position, which the probes' offsets take (visible share ~0): no displacement record can
  show it.  Through one critical a cross-coupled stiffness ``q`` acts as the damping
  ``-q/w`` at the whirl frequency ``w ~ 1``: the damping takes nearly all of it.
- the **minimum detectable size**: the size at which the HAC Wald test of the effect's
  coefficients (the test the diagnosis uses, at the diagnosis's Bonferroni level) would
  reject zero with probability ``power``.  With ``C`` the covariance of the coefficients'
  estimate at zero size and ``lambda`` the non-centrality at which a chi-square test with
  ``q`` degrees of freedom has that power, the smallest detectable coefficient vector
  along a unit direction ``u`` has length ``sqrt(lambda u'C u)``; we report it along the
  most visible direction (``smallest``) and the least visible one (``smallest_any``: in
  any direction, e.g. with the fault's axis anywhere), in the effect's physical
  parameters.
- a **score test** (Rao's Lagrange multiplier) of each effect at the final model: does the
  residual lean towards it, and towards what size (the Gauss-Newton step from zero)?  It is
  kept in the JSON for inspection and never decides: for an effect of which a few
  millionths of the signature stay visible it measures the smallest model-form differences
  as well.  On the rig suite at 0.1 um (``benchmarks/rig_suite.py``) a cross-coupling of
  0.0166 gave a one-step estimate of 0.0167 (log10 p = -154), but healthy records and
  records with a static load leaned towards 0.007-0.015 with log10 p = -11 to -21 too.
- ``decidable``: ``False`` when less than :data:`UNDECIDABLE_SHARE` of the signature is
  left in its most visible direction: at any size the effect reads as its lookalike
  (``absorbed_by`` names it), and the report says so instead of calling the record healthy.

Effects with an argument that is not an orientation (the rub's clearance) are assessed at
their declared default; orientations at two settings a quarter period apart, the worse
one kept (a fault with its axis anywhere).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..effects import EFFECTS
from .output_error import OutputErrorFit, added_effect_information

__all__ = ["UNDECIDABLE_SHARE", "Detectability", "assess", "assess_all", "required_noncentrality"]

#: less than this share of an effect's output signature left visible by the model and the
#: nuisance terms, in its most visible direction: the record cannot decide it at any size
UNDECIDABLE_SHARE = 1e-3
#: power of the test at the minimum detectable size
POWER = 0.8


def required_noncentrality(q: int, alpha: float, power: float = POWER) -> float:
    """The non-centrality ``lambda`` at which a chi-square test with ``q`` degrees of freedom at
    level ``alpha`` rejects with probability ``power``."""
    from scipy.optimize import brentq
    from scipy.stats import chi2, ncx2

    crit = chi2.isf(alpha, q)
    return float(brentq(lambda lam: ncx2.sf(crit, q, lam) - power, 1e-9, 1e4))


@dataclass(frozen=True)
class Detectability:
    """One effect's detectability in one record (see the module docstring)."""

    effect: str
    visible: tuple[float, float]  #: least, most visible share of its signature
    absorbed_by: dict[str, float]
    smallest: dict[str, float]  #: physical parameters at the minimum detectable size, best direction
    smallest_any: dict[str, float]  #: ... least visible direction (inf where nothing is visible)
    coefficients: tuple[str, ...]
    covariance: np.ndarray  #: the coefficients' estimate's covariance at zero size (long-run variance x G^-1)
    noncentrality: float  #: the Wald statistic's non-centrality needed (level and power)
    alpha: float
    arguments: dict[str, float]
    #: Rao's score test at the final model: statistic, log10 p, and the physical values of
    #: the one-step estimate (what the residual leans towards)
    score: float = 0.0
    score_log10_p: float = 0.0
    leaning: dict[str, float] | None = None
    #: the Wald test's own non-centrality and smallest size, where the diagnosis's relevance
    #: rule asks for more (``noncentrality`` and ``smallest`` are then the rule's)
    wald_noncentrality: float = 0.0
    smallest_wald: dict[str, float] | None = None

    @property
    def decidable(self) -> bool:
        return self.visible[1] >= UNDECIDABLE_SHARE

    @property
    def lookalike(self) -> str:
        """The group of the fit that takes most of its signature."""
        return next(iter(self.absorbed_by), "")

    def noncentrality_of(self, values: dict[str, float]) -> float:
        """The Wald statistic's non-centrality an effect of these physical ``values`` would give
        in this record (``inf`` where its coefficients leave the estimable space)."""
        eff = EFFECTS[self.effect]
        theta = np.asarray(eff.to_coefficients({p.name: p.default for p in eff.parameters} | dict(values)), float)
        w, V = np.linalg.eigh(self.covariance)
        z = V.T @ theta
        ok = w > 1e-300
        return float(np.sum(z[ok] ** 2 / w[ok])) if not np.any(np.abs(z[~ok]) > 0) else math.inf

    def sentence(self) -> str:
        look = self.lookalike
        share = self.absorbed_by.get(look, 0.0)
        small = ", ".join(f"{k} = {_fmt(v)}" for k, v in _sizes(self.effect, self.smallest).items())
        if not self.decidable:
            hidden = 100 * (1 - self.visible[1])
            text = (f"{self.effect}: these data cannot decide it: {hidden:.{2 if hidden < 99.99 else 4}f} % of its "
                    f"signature is taken by the fit's other terms, most by {look}")
            finite = all(math.isfinite(v) for v in _sizes(self.effect, self.smallest).values())
            # the Wald test's threshold on so small a visible part holds only for a model exact
            # to that level, which no model of a rig is: the record does not try the effect, and a
            # larger one has gone unseen (the rig suite's cross-couplings, 10x their threshold)
            text += (f"; what is left would reach the Wald test from {small} if the model were exact to "
                     f"{_fmt(100 * self.visible[1])} % of the signature, which no model of a rig is: not tried"
                     if finite else "; it would not show at any size")
            # no word of the score test here: on a part this small of the signature it measures
            # model-form error as much as the effect (module docstring)
            return text
        if self.noncentrality > self.wald_noncentrality > 0 and self.smallest_wald:
            wald = ", ".join(f"{k} = {_fmt(v)}" for k, v in _sizes(self.effect, self.smallest_wald).items())
            text = (f"{self.effect}: would be named from {small}, where it removes the share of the residual above "
                    f"the floor the diagnosis asks of an effect (the Wald test alone, {100 * POWER:.0f} % power: "
                    f"from {wald})")
        else:
            text = f"{self.effect}: would show from {small} (Wald test, {100 * POWER:.0f} % power)"
        if share > 0.5:
            text += f"; below that it reads as {look} ({100 * share:.0f} % of its signature)"
        return text

    def to_dict(self) -> dict:
        return {"decidable": self.decidable, "visible_share": list(self.visible),
                "absorbed_by": self.absorbed_by, "smallest": self.smallest, "smallest_any": self.smallest_any,
                "coefficients": list(self.coefficients), "covariance": self.covariance.tolist(),
                "noncentrality": self.noncentrality, "alpha": self.alpha, "arguments": self.arguments,
                "score": self.score, "score_log10_p": self.score_log10_p, "leaning": self.leaning,
                "wald_noncentrality": self.wald_noncentrality, "smallest_wald": self.smallest_wald,
                "sentence": self.sentence()}


def _fmt(v: float) -> str:
    return "inf" if not math.isfinite(v) else f"{v:.3g}"


def _sizes(effect: str, values: dict[str, float]) -> dict[str, float]:
    """The magnitudes among an effect's physical parameters (its phases and axes say where,
    not how large)."""
    eff = EFFECTS[effect]
    angles = {p.name for p in eff.parameters if p.orientation or p.name.endswith("phase")}
    return {k: abs(v) for k, v in values.items() if k not in angles} or dict(values)


def _direction_size(eff, cov: np.ndarray, lam: float, which: int, visible: float) -> dict[str, float]:
    if visible < 1e-9:
        return {p.name: math.inf for p in eff.parameters if not p.orientation}
    w, V = np.linalg.eigh(cov)
    a = math.sqrt(lam * max(w[which], 0.0))
    return {k: float(v) for k, v in eff.from_coefficients(a * V[:, which]).items()}


def assess(fit: OutputErrorFit, effect: str, *, alpha: float = 0.05, power: float = POWER,
           min_fall: float = 0.0) -> Detectability:
    """The detectability of ``effect`` (not in ``fit``'s model) in ``fit``'s record.

    ``min_fall``: the fall of the residual energy (sum of squares, the fit's units) the
    diagnosis asks of an effect before naming it (its relevance rule).  An effect of
    coefficients ``theta`` lowers the residual energy by ``theta' information theta``, which
    is its Wald non-centrality times the long-run variance ``s^2``: so the size it must have
    is the Wald test's with the non-centrality ``max(lambda, min_fall / s^2)``.  On a long
    record the relevance rule binds (the rig suite's weak non-linearities were significant
    at log10 p = -19 to -28 and removed 6-7 % where 10 % is asked)."""
    eff = EFFECTS[effect]
    settings = [{}]
    orient = [p for p in eff.argument_parameters if p.orientation]
    if orient:
        settings = [{p.name: k * p.angle_period / 4 for p in orient} for k in (0, 1)]
    best = None
    for args in settings:
        info = added_effect_information(fit, effect, args)
        if best is None or info.visible_share[1] < best.visible_share[1]:
            best = info
    from identifier.hac import chi2_log10_sf

    q = len(best.coefficients)
    lam_wald = required_noncentrality(q, alpha, power)
    # the long-run variance: covariance = s^2 information^-1
    s2 = float(np.trace(best.covariance @ best.information)) / q
    lam = max(lam_wald, min_fall / s2) if s2 > 0 else lam_wald
    lo, hi = best.visible_share
    leaning = ({k: float(v) for k, v in eff.from_coefficients(best.one_step).items()}
               if best.one_step is not None and hi >= 1e-9 else None)
    return Detectability(
        effect, (lo, hi), best.absorbed_by,
        _direction_size(eff, best.covariance, lam, 0, hi),
        _direction_size(eff, best.covariance, lam, q - 1, lo),
        best.coefficients, best.covariance, lam, alpha, best.arguments,
        best.score, chi2_log10_sf(best.score, q), leaning,
        lam_wald, _direction_size(eff, best.covariance, lam_wald, 0, hi))


def assess_all(fit: OutputErrorFit, effects: Sequence[str], *, alpha: float = 0.05,
               min_fall: float = 0.0) -> dict[str, Detectability]:
    """:func:`assess` for each of ``effects`` outside the model (those with a non-orientation
    argument, whose visibility hangs on it, at its default); one that cannot be simulated
    along the fit (diverges) is left out."""
    out = {}
    for e in effects:
        if e in fit.effects:
            continue
        try:
            out[e] = assess(fit, e, alpha=alpha, min_fall=min_fall)
        except FloatingPointError:
            continue
    return out
