"""The record in two parts: where the parameters changed, each side diagnosed on its own.

One model for the whole record cannot hold a rotor that changed during it.  When that model
does not explain the record and the parameter-constancy test (:mod:`.change`) finds its
parameters not the same over it, the record is cut at the break it dates -- between two shooting segments, leaving
out the segment either side of the cut (the break is dated to a block), so that each side is
an ordinary record of its own -- and each side goes through the same
output-error diagnosis (same starting model, same candidates, same checks, the same noise
floor).  What the two sides name differently is what appeared (or went); a parameter both
sides fit whose 95 % intervals do not overlap is what moved.

Two readings follow:

- **the rotor changed**: both sides are explained on their own, and a side names what the
  other lacks or parameters moved beyond their intervals (a crack that opened: ``asymmetry`` after the
  break, nothing before);
- **the drift is not a change**: each side needs what the whole needed, and nothing moved
  beyond its intervals -- a parameter that depends on speed (a cross-coupling reads as a
  damping ``c - q/w``) or the instrument's drift, which no cut removes; or the sides are not
  both explained either, and the model misses something all through (whatever they name).

What it does not do: split a record that one model explains.  There the change test's drift
may be an instrument's (a keyphasor sampled at 2.5 kHz puts milliradians of error into the
spin angle at top speed), and each side would name what its own small misfit makes of it
(a rig test's breathing crack got a support anisotropy "appeared" so); the drift is reported
and the record stays one rotor.  A crack that opens above the critical changes the small
response there by a fraction of a micrometre and leaves the record explained: its change is
dated, not named.  Each side holds fewer samples than the record, so its detectability is
lower.

**Present on both sides** (:func:`absent_on_a_side`).  An effect the whole record's model
names must be there on each side of a break the change test found.  Where one side's own fit
(the whole model, its arguments held, started from the whole fit) finds the effect's
coefficients consistent with zero (HAC Wald, 5 %) and rejects the whole record's values
(Bonferroni over the effects and sides), the effect is the trace of the change, not a
property of the rotor: a crack that opens above the critical moves the 1X there by 0.1-0.2 um,
and a shaft bow of constant size over the whole record took that move (before the break the
record's own bow coefficients were 0.0009 in size, the whole record's 0.0084: log10 p = -0.6
that the side's are zero, -52.7 that they are the whole record's).  Both conditions are needed: a true effect on a rotor whose 1X drifts
(keyphasor, runout) is significant on each side, and an effect the side cannot see is not
rejected there.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from .change import ParameterChange
    from .output_error import OutputErrorFit, ShootingGrid


class SideDiagnosis(Protocol):
    """What a side's diagnosis offers (an :class:`~.oe_diagnosis.SideDiagnosis`; named
    by what it does, so that this module need not import the diagnosis that calls it)."""

    verdict: str
    added: list[str]
    model_after: tuple[str, ...]
    after: OutputErrorFit
    change: ParameterChange | None

    @property
    def rms_ratio_after(self) -> float: ...

    def parameters(self) -> dict: ...

    def to_dict(self) -> dict: ...

__all__ = ["MIN_PART_SEGMENTS", "RecordParts", "absent_on_a_side", "split_at_change"]

#: each side needs at least this many shooting segments to be diagnosed on its own
MIN_PART_SEGMENTS = 8
#: Levenberg-Marquardt steps of each refit that dates the break (:func:`_refit_date`)
REFIT_ITERATIONS = 10
#: the largest change of the shaft's stiffness a fault makes (a crack through half the shaft
#: lowers one bending stiffness by about 30 %): two sides whose fitted stiffness ``k`` differs
#: by more are two modes of the rotor, not one rotor before and after a change
MAX_STIFFNESS_CHANGE = 0.3
_EXPLAINED = ("explained", "explained_after_adding")


@dataclass(frozen=True)
class RecordParts:
    """The record cut at its change, each side diagnosed on its own (module docstring)."""

    t_break: float  #: model time of the cut (the end of the last segment before it)
    before: SideDiagnosis
    after: SideDiagnosis

    @property
    def explained(self) -> bool:
        """Each side explained by its own model."""
        return self.before.verdict in _EXPLAINED and self.after.verdict in _EXPLAINED

    @property
    def appeared(self) -> list[str]:
        """Effects named after the break and not before."""
        return [e for e in self.after.added if e not in self.before.model_after]

    @property
    def gone(self) -> list[str]:
        """Effects named before the break and not after."""
        return [e for e in self.before.added if e not in self.after.model_after]

    def moved(self) -> dict[str, dict[str, tuple[float, float]]]:
        """Parameters both sides fit whose 95 % intervals do not overlap: effect -> name ->
        (before, after)."""
        pb, pa = self.before.parameters(), self.after.parameters()
        out: dict[str, dict[str, tuple[float, float]]] = {}
        for e in pb:
            if e not in pa:
                continue
            for name, vb in pb[e]["values"].items():
                va = pa[e]["values"].get(name)
                hb, ha = pb[e]["ci95"].get(name, math.nan), pa[e]["ci95"].get(name, math.nan)
                if va is None or not (math.isfinite(hb) and math.isfinite(ha)):
                    continue
                gap = abs(va - vb)
                if name.endswith(("axis", "phase")) or name == "beta":
                    gap = abs((va - vb + math.pi) % (2 * math.pi) - math.pi)
                if gap > hb + ha:
                    out.setdefault(e, {})[name] = (float(vb), float(va))
        return out

    @property
    def other_mode(self) -> tuple[float, float] | None:
        """The two sides' fitted shaft stiffness ``(before, after)`` where it differs by more
        than :data:`MAX_STIFFNESS_CHANGE` (relative): the sides' models hold two different
        modes of the rotor; ``None`` otherwise.  A foreign two-disk rotor with a crack, its
        second mode 5 % above the run, was read as changing at 2124 rpm -- before, k 1.68
        (the model's mode 30 % above its own critical, between the two); after, 1.04 with a
        hinge crack and a bow "appeared"."""
        kb = self.before.parameters().get("stiffness", {}).get("values", {}).get("k")
        ka = self.after.parameters().get("stiffness", {}).get("values", {}).get("k")
        if kb is None or ka is None or not (kb > 0 and ka > 0):
            return None
        return (float(kb), float(ka)) if abs(math.log(ka / kb)) > math.log1p(MAX_STIFFNESS_CHANGE) else None

    @property
    def changed(self) -> bool:
        """The two sides are two rotors: each is explained on its own (the whole record was not:
        :func:`split_at_change` is asked only then), and something appeared, went or moved.
        Sides that are not both explained show no change: the model misses something on both
        (a record from another code, a crack under a sag eight times its response: the sides
        named different things, each side's fit far off); nor do sides whose shaft stiffness
        differs by more than a fault changes it (:attr:`other_mode`)."""
        return bool(self.explained and self.other_mode is None and (self.appeared or self.gone or self.moved()))

    def sentence(self, when: str = "") -> str:
        when = when or "at the break"
        sides = (f"diagnosed apart {when}: before, {self.before.verdict} ({self.before.rms_ratio_after:.3g}x the "
                 f"floor{', named ' + ', '.join(self.before.added) if self.before.added else ''}); after, "
                 f"{self.after.verdict} ({self.after.rms_ratio_after:.3g}x"
                 f"{', named ' + ', '.join(self.after.added) if self.after.added else ''})")
        moved = self.moved()
        what = "; ".join(f"{e} {name} {v0:.4g} -> {v1:.4g}" for e, d in moved.items() for name, (v0, v1) in d.items())
        if not self.explained:
            head = (f"no change of the rotor {when} that the two sides show: they are not both explained either, "
                    "so the model misses something all through")
        elif self.other_mode is not None:
            kb, ka = self.other_mode
            head = (f"no change of the rotor {when}: the two sides' shafts differ by {100 * (ka / kb - 1):+.0f} % in "
                    f"stiffness (natural frequency x{math.sqrt(ka / kb):.3g}), more than any fault changes it "
                    f"({100 * MAX_STIFFNESS_CHANGE:.0f} %): each side's model holds another mode of the rotor, which "
                    "the one-mode model lacks")
        elif self.appeared or self.gone:
            head = "the rotor changed " + when + ": " + ", ".join(
                [f"{e} appeared" for e in self.appeared] + [f"{e} went" for e in self.gone])
        elif self.changed:
            head = f"the rotor changed {when}: no effect named differently, but the parameters moved"
        else:
            head = (f"no change of the rotor {when} that the two sides tell: each side needs what the whole "
                    "record needed (a parameter that depends on speed, or the instrument's drift, is no change)")
        return f"{head} -- {sides}" + (f"; moved beyond their 95 % intervals: {what}" if what else "")

    def to_dict(self) -> dict:
        keys = ("verdict", "missing", "rms_ratio_after", "parameters", "rejected", "undecidable")
        b, a = self.before.to_dict(), self.after.to_dict()
        return {"t_break": self.t_break, "changed": self.changed, "appeared": self.appeared, "gone": self.gone,
                "explained": self.explained,
                "moved": {e: {k: list(v) for k, v in d.items()} for e, d in self.moved().items()},
                "before": {k: b[k] for k in keys}, "after": {k: a[k] for k in keys}, "sentence": self.sentence()}


def _refit_date(grid: ShootingGrid, whole: OutputErrorFit, sides: RecordParts) -> float | None:
    """The least-squares date of the break, by refits: the sides' joint model (every effect
    either side named, at the sides' values) fitted on each side of every candidate cut, the
    cut where the two sums of squares together are least (a coarse grid over the middle of
    the record, then finer around its best).  ``None`` where no cut could be fitted."""
    from .output_error import arguments_of, fit_output_error, start_from

    fits = (sides.after.after, sides.before.after)
    effects = tuple(dict.fromkeys(e for f in fits for e in f.effects))
    start = {e: v for f in reversed(fits) for e, v in start_from(f).items()}
    args = arguments_of(*fits)
    S = len(grid.segments)
    lo, hi = max(MIN_PART_SEGMENTS, int(0.15 * S)), min(S - MIN_PART_SEGMENTS, int(0.85 * S))
    cost: dict[int, float] = {}

    def rss(n_first: int) -> float:
        if n_first not in cost:
            total = 0.0
            for idx in (np.arange(0, n_first), np.arange(n_first, S)):
                try:
                    f = fit_output_error(replace(grid, segments=grid.segments[idx]), effects, start, x0=whole.x0[idx],
                                         fixed_args=args, max_iter=REFIT_ITERATIONS)
                except (FloatingPointError, np.linalg.LinAlgError, ValueError):
                    total = math.inf
                    break
                total += f.rss
            cost[n_first] = total
        return cost[n_first]

    if hi <= lo:
        return None
    step = max(1, (hi - lo) // 12)
    best = min(range(lo, hi + 1, step), key=rss)
    while step > 1:
        span, step = step, max(1, step // 4)
        best = min(range(max(lo, best - span), min(hi, best + span) + 1, step), key=rss)
    if not math.isfinite(cost[best]):
        return None
    return float(grid.t[grid.segments[best - 1, 1]])


def _sides(grid: ShootingGrid, t_break: float) -> tuple[int, np.ndarray, np.ndarray] | None:
    """The segments before and after a break at model time ``t_break`` (the number of
    segments up to it, then each side's segment indices): the break is dated to a block, so
    the segment either side of the cut may hold it, and one segment of a changed rotor lifts
    its side's residual -- both left out.  ``None`` where a side would hold fewer than
    :data:`MIN_PART_SEGMENTS` segments."""
    ends = grid.t[grid.segments[:, 1]]
    n_first = int(np.sum(ends <= t_break))
    before, after = np.arange(0, max(n_first - 1, 0)), np.arange(n_first + 1, len(grid.segments))
    if n_first < 1 or min(len(before), len(after)) < MIN_PART_SEGMENTS:
        return None
    return n_first, before, after


def absent_on_a_side(grid: ShootingGrid, change: ParameterChange, whole: OutputErrorFit,
                     effects: Sequence[str], *, alpha: float = 0.05) -> dict[str, str]:
    """Each of ``effects`` (named on the whole record) that one side of ``change``'s break
    does not hold (module docstring: present on both sides), with the reason; ``{}`` where
    every one is on both sides, or the sides are too short to fit."""
    from .output_error import arguments_of, fit_output_error, start_from

    cut = _sides(grid, change.t_break)
    if cut is None or not effects:
        return {}
    _, before, after = cut
    level = math.log10(alpha / (2 * len(effects)))
    out: dict[str, str] = {}
    for side, idx in (("before", before), ("after", after)):
        try:
            f = fit_output_error(replace(grid, segments=grid.segments[idx]), whole.effects, start_from(whole),
                                 x0=whole.x0[idx], fixed_args=arguments_of(whole), max_iter=REFIT_ITERATIONS)
        except (FloatingPointError, np.linalg.LinAlgError, ValueError):
            continue
        for e in effects:
            if e in out:
                continue
            _, q, lp_zero = f.wald(e)
            if q == 0:
                continue
            _, _, lp_same = f.wald(e, null={nm: whole.value(nm) for nm, o in zip(f.names, f.owners, strict=True)
                                            if o == e})
            if lp_zero > math.log10(0.05) and lp_same < level:
                out[e] = (f"rule present_throughout: not there {side} the break the change test dates -- that "
                          f"side's own fit finds it absent (log10 p = {lp_zero:.3g} that it is zero) and not the "
                          f"whole record's value (log10 p = {lp_same:.3g}): the one model of the whole record "
                          "named it for the change")
    return out


def split_at_change(grid: ShootingGrid, change: ParameterChange, whole: OutputErrorFit,
                    diagnose: Callable[[ShootingGrid], SideDiagnosis]) -> RecordParts | None:
    """Cut ``grid`` between the shooting segments at ``change``'s break and ``diagnose`` each
    side; ``None`` where a side would hold fewer than :data:`MIN_PART_SEGMENTS` segments.

    The change test dates the break by its linearisation at the whole record's fit, which a
    model far from the data (no crack, or one constant crack, fitted to a record where a crack
    opened) misplaces -- towards the critical, where the information is.  Where the sides name
    different effects, or one of them is not explained, the break is dated again by refits of
    their joint model (:func:`_refit_date`, Bai's least-squares date itself) and the record
    is cut there."""
    ends = grid.t[grid.segments[:, 1]]

    def cut(t_break: float) -> RecordParts | None:
        sides = _sides(grid, t_break)
        if sides is None:
            return None
        n_first, before, after = sides
        return RecordParts(float(ends[n_first - 1]), diagnose(replace(grid, segments=grid.segments[before])),
                           diagnose(replace(grid, segments=grid.segments[after])))

    parts = cut(change.t_break)
    if parts is None:
        return None
    if set(parts.before.model_after) != set(parts.after.model_after) or not parts.explained:
        t_new = _refit_date(grid, whole, parts)
        if t_new is not None and int(np.sum(ends <= t_new)) != int(np.sum(ends <= parts.t_break)):
            parts = cut(t_new) or parts
    return parts
