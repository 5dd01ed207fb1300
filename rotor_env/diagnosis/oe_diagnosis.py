"""Which effect is missing, decided on the output-error residual (measured displacements).

Used whenever the rates and accelerations would have to be estimated from noisy
displacements (always for rig waveforms).  One round tries every candidate by an
output-error fit of the model plus the candidate (:mod:`.output_error`), and keeps it
only if every check holds:

- **significant**: the HAC Wald test of its coefficients, Bonferroni over the round's
  candidates (``log10 p < log10(alpha / n)``);
- **relevant**: it removes at least :data:`RELEVANT_SHARE` of the residual energy above
  the probes' noise floor (a significant but irrelevant effect is a statistical nicety);
- **physical**: every parameter inside its declared plausible range;
- **a crack is not a rub** (rule ``crack_amplitude_independence``): a crack's stiffness
  asymmetry is the same at every amplitude, a rub's contact acts only above the clearance
  — the crack model is refitted on the low- and on the high-amplitude half of the
  segments, and a crack that the halves fit worse at the whole record's value (a likelihood
  ratio beyond :data:`CRACK_SPLIT_Z` squared) and whose two values differ by a third is
  turned down; and a crack is
  also turned down when the rub's own model explains the data at least as well.

The best survivor (largest fall of the residual energy) is added and the next round
starts while the residual stands above :data:`SEARCH_RATIO` of the noise floor.  Below it
the residual energy alone cannot tell a small effect from the floor's own error (the
floor, read from the band above the top order, is right to about :data:`FLOOR_UNCERTAINTY`
in RMS), but a targeted test can: a weak non-linearity on a tilt rig at 1 um noise lifts
the residual by 0.7 % while its coefficients' score test stands at log10 p = -186.  So
there Rao's score test of each decidable candidate at the current fit (computed anyway
for :mod:`.detectability`) decides which candidates are tried in one more round (the rub,
where a crack is among them, only as the crack's comparison, fitted when a crack reaches
that rule); a candidate is named only by the checks above, and its relevance is measured against the
residual above the floor but never less than the floor's own uncertainty (on healthy
records the score test leans towards model-form differences, log10 p down to -21, whose
fall is a few hundredths of that).  Where the residual leans harder towards an effect the
record cannot decide (a cross-coupling: through one critical, a damping), the decidable
candidates' leaning is its projection: they are not tried, and a note says so.  The search
ends when no candidate survives.  The verdict is read off the final residual against the
floor.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..effects import EFFECTS, DerivedNames, crack_effects
from ..results import Result
from .change import ParameterChange, parameter_constancy
from .detectability import Detectability, assess_all
from .orders import OffOrderNoise, off_order_noise
from .output_error import (
    TIME_UNIT_EFFECT,
    OutputErrorFit,
    ShootingGrid,
    arguments_of,
    canonical_scale,
    equation_error_start,
    estimate_inflation,
    fit_output_error,
    library_effects,
    start_from,
)
from .parts import RecordParts, absent_on_a_side, split_at_change

__all__ = ["OutputErrorDiagnosis", "crack_fits_under_load", "diagnose_output_error", "splits", "with_parts"]

#: residual RMS within this factor of the noise floor: explained
EXPLAINED_RATIO = 1.1
#: the search goes on while the residual stands above this factor of the floor: on tens of
#: thousands of samples a 3 % excess is far outside the noise energy's own scatter
#: (sqrt(2/N) < 1 %), and a small effect (a weak non-linearity) leaves no more
SEARCH_RATIO = 1.02
#: the noise floor's relative error (RMS): the rig suite's estimated floors stand at
#: 0.98-1.02 of the probes' true noise.  A candidate's relevance is measured against the
#: residual energy above the floor, but never less than this error's share of the energy
FLOOR_UNCERTAINTY = 0.02
#: a candidate must remove this share of the residual energy above the floor
RELEVANT_SHARE = 0.1
#: the noise in the rotor's band (read between the shaft's orders) counts in the floor only off
#: a model whose residual stands within this factor of the floor it gives: a model that misses
#: the record by more leaves its misfit between the orders too -- each shooting segment's start
#: state takes the misfit's local shape, and the residual steps at every cut (a two-disk
#: rotor's record under a one-mode model, 25x its floor: steps 28x the sample-to-sample
#: change, read as 1340x "noise" at 0.1 times the natural frequency).  White records whose
#: model lacks a crack read white up to 5.6x; 1/f records' final models stand at 1.0-1.12x
COLOUR_MISFIT_RATIO = 2.0
#: crack vs rub: the asymmetry of the low- and high-amplitude halves may differ by this
#: many standard errors (and by a third) before the crack is turned down
CRACK_SPLIT_Z = 4.0
#: effects whose fit cannot start from a zero coefficient (their argument would have no
#: sensitivity): a small start value
_NONZERO_START = {"rub": {"rub_stiffness": 0.5, "rub_friction": 0.1}}
MAX_ADDED = 3
#: screening: Levenberg-Marquardt steps from each start, and how many candidates are then
#: fitted to convergence
SCREEN_ITERATIONS = 2
SCREEN_KEEP = 3
#: where a crack leads the round, the candidates screened out within this factor of its
#: screening residual energy are fitted to convergence too (:func:`_crack_lookalikes`)
LOOKALIKE_SCREEN = 1.1
#: Levenberg-Marquardt steps of a kept candidate's fit to convergence
CONVERGE_ITERATIONS = 40
#: steps from each side-load start of :func:`crack_fits_under_load` before the best goes on
LOAD_START_ITERATIONS = 8
#: a fit that gave up after this share of its steps crawled along a valley (_crack_laws_from_lead)
CRAWL_SHARE = 0.75
#: the screening reads every other shooting segment when the record has at least this many
#: (the ranking needs each candidate's fall, not its last digit; the candidates kept are
#: fitted to convergence on every segment, and every decision is made on those fits)
SCREEN_HALF_FROM = 24
#: the cracks' stiffness laws (derived from the declarations' ``crack`` flag)
CRACKS = DerivedNames(crack_effects)
#: the side load a crack is tried with (:func:`_with_side_load`)
SIDE_LOAD = "static_load"


@dataclass
class Candidate:
    """One candidate tried in one round."""

    round: int
    effect: str
    rms: float
    log10_p: float
    relevance: float
    parameters: dict
    intervals: dict
    accepted: bool
    reason: str = ""


@dataclass
class OutputErrorDiagnosis(Result):
    """The output-error diagnosis of one record (dimensionless inside; ``unit_scale`` maps a
    grid residual to the reporting unit, ``unit`` names it)."""

    model_before: tuple[str, ...]
    model_after: tuple[str, ...]
    before: OutputErrorFit
    after: OutputErrorFit
    noise_floor: float  #: per grid sample, dimensionless
    candidates: list[Candidate]
    added: list[str]
    unit_scale: float = 1.0
    unit: str = ""
    seconds: float = 0.0
    notes: list[str] = field(default_factory=list)
    #: each library effect the final model lacks: how large it would have to be to show
    #: (:mod:`.detectability`); those it cannot decide at all are in :attr:`undecidable`
    detectability: dict[str, Detectability] = field(default_factory=dict)
    #: the parameter-constancy test over the record (:mod:`.change`)
    change: ParameterChange | None = None
    #: where that test found the parameters not the same: each side diagnosed (:mod:`.parts`)
    parts: RecordParts | None = None

    @property
    def probe_factor(self) -> float:
        """Grid residual -> the probes' bandwidth (white noise): probe noise / grid noise."""
        g = self.before.grid
        return (g.probe_noise_std / g.noise_std) if g.probe_noise_std else 1.0

    @property
    def rms_ratio_before(self) -> float:
        return self.before.rms / self.noise_floor

    @property
    def rms_ratio_after(self) -> float:
        return self.after.rms / self.noise_floor

    @property
    def missing(self) -> list[str]:
        return list(self.added)

    @property
    def verdict(self) -> str:
        if self.rms_ratio_after <= EXPLAINED_RATIO:
            return "explained_after_adding" if self.added else "explained"
        return "partly_explained" if self.added else "unexplained"

    @property
    def rejected(self) -> dict[str, str]:
        """Each candidate turned down, with the last round's reason (one entry per effect)."""
        out: dict[str, str] = {}
        for c in self.candidates:
            # a side load that came in with a crack is in the model, not turned down
            if not c.accepted and c.effect not in self.added and c.effect not in self.model_after:
                out[c.effect] = f"round {c.round}: {c.reason}"
        return out

    @property
    def not_throughout(self) -> dict[str, str]:
        """Effects the one model of the whole record named for a change during it: not there on
        one side of the break (:func:`.parts.absent_on_a_side`), so not named."""
        return {e: r for e, r in self.rejected.items() if "rule present_throughout" in r}

    @property
    def undecidable(self) -> dict[str, str]:
        """Effects these data cannot decide at any size, each with the reason."""
        return {e: d.sentence() for e, d in self.detectability.items() if not d.decidable}

    def parameters(self) -> dict[str, dict]:
        """Every effect of the final model: physical values and 95 % half-widths."""
        out = {}
        for e in self.after.effects:
            out[e] = {"values": self.after.parameters(e), "ci95": _intervals(self.after, e)}
        return out

    def figures(self, speed_scale: float = 1.0, speed_unit: str = "speed (model units)") -> dict:
        return {"output_error_residual": plot_residual(self, speed_scale, speed_unit),
                "output_error_response": plot_response(self, speed_scale, speed_unit)}

    def save_figures(self, folder, *, overwrite: bool = True, speed_scale: float = 1.0,
                     speed_unit: str = "speed (model units)") -> list:
        """Each figure of :meth:`figures` as ``NAME.png`` in ``folder`` (written atomically)."""
        from pathlib import Path

        import matplotlib.pyplot as plt

        from ..outputs import atomic_write

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for name, fig in self.figures(speed_scale, speed_unit).items():
            paths.append(atomic_write(folder / f"{name}.png",
                                      lambda p, fig=fig: fig.savefig(p, format="png", dpi=110, bbox_inches="tight"),
                                      overwrite=overwrite))
            plt.close(fig)
        return paths

    def write_report(self, path, head: str, *, title: str, verdict: str | None = None, extra_text: str | None = None,
                     overwrite: bool = False, speed_scale: float = 1.0, speed_unit: str = "speed (model units)"):
        """One HTML page: the verdict, ``head`` (HTML), the summary and the figures inline."""
        from ..outputs import check_writable
        from ..pages import esc, figure_tag, write_page

        path = check_writable(path, overwrite=overwrite)  # before the figures are drawn
        imgs = "".join(f"<figure>{figure_tag(fig, name)}</figure>"
                       for name, fig in self.figures(speed_scale, speed_unit).items())
        body = (f"<h1>Diagnosis: {esc(verdict or self.verdict)}</h1>{head}"
                f"<pre>{esc(extra_text or self.summary())}</pre>{imgs}")
        return write_page(path, title, body, overwrite=overwrite)

    def to_dict(self) -> dict:
        # residual and floor as the probes see them: the analysis band's RMS scaled to the
        # probes' bandwidth (white noise), so that a model that explains the data reads ~1x
        s = self.unit_scale * self.probe_factor
        return {
            "method": "output error (multiple shooting, HAC)",
            "verdict": self.verdict,
            "missing": self.missing,
            "model_before": list(self.model_before),
            "model_after": list(self.model_after),
            "rms_before": self.before.rms * s,
            "rms_after": self.after.rms * s,
            "noise_floor": self.noise_floor * s,
            "rms_ratio_before": self.rms_ratio_before,
            "rms_ratio_after": self.rms_ratio_after,
            "unit": self.unit,
            "parameters": self.parameters(),
            "candidates": [
                {"round": c.round, "effect": c.effect, "rms": c.rms * s, "log10_p": c.log10_p,
                 "relevance": c.relevance, "accepted": c.accepted, "reason": c.reason,
                 "parameters": c.parameters, "ci95": c.intervals}
                for c in self.candidates],
            "rejected": self.rejected,
            "undecidable": self.undecidable,
            "change": self.change.to_dict() if self.change is not None else None,
            "parts": self.parts.to_dict() if self.parts is not None else None,
            "detectability": {e: d.to_dict() for e, d in self.detectability.items()},
            "seconds": self.seconds,
            "notes": list(self.notes),
        }

    def summary(self) -> str:
        s, u = self.unit_scale * self.probe_factor, self.unit
        lines = [f"verdict: {self.verdict} (output error: residual {self.after.rms * s:.4g} {u} = "
                 f"{self.rms_ratio_after:.3g}x the probes' noise floor {self.noise_floor * s:.4g} {u}; starting "
                 f"model {self.before.rms * s:.4g} {u} = {self.rms_ratio_before:.3g}x)",
                 f"model: {', '.join(self.model_before)}"
                 + (f"  + {', '.join(self.added)}" if self.added else "")]
        for e, d in self.parameters().items():
            vals = ", ".join(f"{k} = {_fmt(k, v)} +- {_fmt(k, d['ci95'].get(k, math.nan))}"
                             for k, v in d["values"].items())
            lines.append(f"  {e}: {vals}")
        if self.rejected:
            lines.append("turned down:")
            lines += [f"  {e}: {r}" for e, r in self.rejected.items()]
        if self.change is not None:
            lines.append(self.change.sentence())
        if self.parts is not None:
            lines.append(self.parts.sentence())
        if self.undecidable:
            lines.append("what these data cannot decide:")
            lines += [f"  {t}" for t in self.undecidable.values()]
        decidable = [d for d in self.detectability.values() if d.decidable]
        if decidable:
            lines.append("the smallest size each effect not named would show at (dimensionless):")
            lines += [f"  {d.sentence()}" for d in decidable]
        return "\n".join(lines)


def _constancy(fit: OutputErrorFit, floor: float, alpha: float) -> ParameterChange | None:
    """The parameter-constancy test of ``fit`` (:mod:`.change`); ``None`` where it fails."""
    try:
        return parameter_constancy(fit, alpha=alpha, explained=fit.rms / floor <= EXPLAINED_RATIO)
    except FloatingPointError:
        return None


def _excess(fit: OutputErrorFit, floor: float, uncertainty: float = FLOOR_UNCERTAINTY) -> float:
    """The residual energy above the noise floor that a candidate's relevance is measured
    against: never less than the floor's own uncertainty's share (:data:`FLOOR_UNCERTAINTY`,
    more where the floor counts the noise in the rotor's band: :func:`_floor_uncertainty`)."""
    return _excess_of(fit.rss, fit.n_rows, floor, uncertainty)


def _excess_of(rss: float, n_rows: int, floor: float, uncertainty: float = FLOOR_UNCERTAINTY) -> float:
    noise = floor * floor * n_rows
    return max(rss - noise, ((1.0 + uncertainty) ** 2 - 1.0) * noise)


def _floor_uncertainty(noise: OffOrderNoise) -> float:
    """The floor's relative uncertainty (RMS): :data:`FLOOR_UNCERTAINTY` for the level read above
    the response; where the floor counts the noise in the rotor's band, two standard errors of
    its variance factor too (a few hundred periodogram bins an octave leave the low octaves'
    levels uncertain by tens of per cent: an effect that takes a share of that noise is not
    relevant for it)."""
    f = noise.floor_factor
    return max(FLOOR_UNCERTAINTY, math.sqrt(1.0 + 2.0 * noise.floor_factor_se / f) - 1.0)


def _screening_grid(fit: OutputErrorFit) -> tuple[ShootingGrid, np.ndarray, float, int]:
    """The grid the candidates are screened on (every other segment of ``fit``'s, where it has
    :data:`SCREEN_HALF_FROM` or more), ``fit``'s start states and residual energy there, and
    its rows."""
    g = fit.grid
    if len(g.segments) < SCREEN_HALF_FROM:
        return g, fit.x0, fit.rss, fit.n_rows
    sel = np.arange(0, len(g.segments), 2)
    sub = replace(g, segments=g.segments[sel])
    rows = np.concatenate([np.arange(i0, i1 + 1) for i0, i1 in sub.segments])
    return sub, fit.x0[sel], float(np.sum(fit.residual[rows] ** 2)), 2 * len(rows)


def _leaning(detect: dict[str, Detectability], level: float) -> tuple[list[str], str]:
    """The decidable candidates whose score test at the current fit rejects zero at ``level``
    and leans harder than towards any undecidable effect, strongest first; and the undecidable
    effect that leaned hardest where it outdid them (else ``""``).

    An effect the record cannot decide has most of its signature in the model's own terms;
    when the residual leans towards it more than towards any decidable candidate, what is
    left is its trace, and a decidable candidate only takes a projection of that trace (the
    rig suite: a cross-coupling at 0.1 um, score log10 p = -348, had an open crack of
    D = 4e-5 lean at -8 and named).  A small part of an undecidable signature measures
    model-form error as much as the effect (:mod:`.detectability`), so it is never tried."""
    lean = [c for c, d in detect.items() if d.decidable and d.score_log10_p < math.log10(level)]
    hidden = [c for c, d in detect.items() if not d.decidable and d.score_log10_p < math.log10(level)]
    top_hidden = min(hidden, key=lambda c: detect[c].score_log10_p, default="")
    if top_hidden:
        outdone = [c for c in lean if detect[c].score_log10_p >= detect[top_hidden].score_log10_p]
        lean = [c for c in lean if c not in outdone]
        if not outdone:
            top_hidden = ""
    return sorted(lean, key=lambda c: detect[c].score_log10_p), top_hidden


def _fmt(name: str, v: float) -> str:
    if name.endswith("axis") or name.endswith("phase") or name == "beta":
        return f"{math.degrees(v):.2f} deg"
    return f"{v:.4g}"


def _intervals(fit: OutputErrorFit, effect: str) -> dict[str, float]:
    """95 % half-widths of the effect's physical parameters (delta method on the mapping
    from the coefficients and the shaft stiffness they are read against,
    :meth:`~.output_error.OutputErrorFit.coefficients`; orientations directly)."""
    eff = EFFECTS[effect]
    idx = [fit.names.index(f"{effect}.{c}") for c in eff.coefficients]
    k_name = f"{TIME_UNIT_EFFECT}.k"
    with_k = effect != TIME_UNIT_EFFECT and k_name in fit.names
    if with_k:
        idx.append(fit.names.index(k_name))
    raw = fit.values[idx]
    cov = fit.covariance[np.ix_(idx, idx)]
    n_c = len(eff.coefficients)

    def physical(v: np.ndarray) -> dict:
        return eff.from_coefficients(v[:n_c] * canonical_scale(effect, float(v[n_c])) if with_k else v[:n_c])

    base = physical(raw)
    out = {}
    names = list(base)
    grads = np.zeros((len(names), len(idx)))
    for j in range(len(idx)):
        h = 1e-7 * max(1e-6, float(np.max(np.abs(raw))))
        v2 = raw.copy()
        v2[j] += h
        b2 = physical(v2)
        for i, n in enumerate(names):
            d = b2[n] - base[n]
            if "phase" in n or n == "beta":
                d = (d + math.pi) % (2 * math.pi) - math.pi
            grads[i, j] = d / h
    var = np.einsum("ij,jk,ik->i", grads, cov, grads)
    for i, n in enumerate(names):
        out[n] = 1.96 * math.sqrt(max(var[i], 0.0))
    for p in eff.argument_parameters:
        k = fit.names.index(f"{effect}.{p.name}") if f"{effect}.{p.name}" in fit.names else None
        if k is not None:
            out[p.name] = 1.96 * math.sqrt(max(fit.covariance[k, k], 0.0))
    return out


def _starts(effect: str, fit: OutputErrorFit, load_start: float | None = None) -> list[dict]:
    """Start values of a candidate: the base fit's coefficients, the candidate's small or
    zero, and several values of each argument (orientations over their period, the rub's
    clearance over the orbit's range); with ``load_start``, a crack's starts with its side
    load at that size along each axis, either way, instead (:func:`crack_fits_under_load`)."""
    eff = EFFECTS[effect]
    base: dict = {}  # the model's own effects start where ``fit`` ended (``previous``)
    phys = dict(_NONZERO_START.get(effect, {}))
    args = eff.argument_parameters
    if not args:
        # a coefficient start of zero: the first Gauss-Newton step is then the linearised
        # least-squares estimate (a default-sized start can be far off and stall)
        return [{**base, effect: np.zeros(len(eff.coefficients)) if not phys else phys}]
    r = np.hypot(fit.grid.y[:, 0], fit.grid.y[:, 1])
    grids = []
    for p in args:
        if p.orientation:
            # two orthogonal directions of a half-turn pattern (e^{2i axis}), four of a full turn
            n = 4 if p.angle_period > math.pi + 1e-9 else 2
            grids.append([p.name, [k * p.angle_period / 4 for k in range(n)]])
        else:  # the rub's clearance: where the orbit spends its time above it
            grids.append([p.name, list(np.quantile(r, [0.6, 0.8, 0.92]))])
    combos = [{}]
    for name, vals in grids:
        combos = [{**c, name: v} for c in combos for v in vals]
    small = _SMALL_START.get(effect, {})
    out = [{**base, effect: {**phys, **small, **c}} for c in combos]
    if load_start and effect in CRACKS:
        loads = [{"load_x": sx * load_start, "load_y": 0.0} for sx in (1.0, -1.0)]
        loads += [{"load_x": 0.0, "load_y": sy * load_start} for sy in (1.0, -1.0)]
        out = [{**st, SIDE_LOAD: ld} for st in out for ld in loads]
    return out


def crack_fits_under_load(grid: ShootingGrid, model: Sequence[str], candidates: Sequence[str],
                          load: float) -> dict[str, OutputErrorFit]:
    """Each crack among ``candidates`` with its side load, fitted to convergence from side-load
    starts of size ``load`` (model units) along each axis, either way, and the crack's
    orientation starts (:func:`_starts`): the best fit of each.

    A crack's moment under a side load is the product of the two, so from the search's start
    (no load) neither moves the residual; where the load is many times the response (a
    horizontal shaft's sag, 276 um under a 43 um peak) the search's few steps never reach it.
    Started near it, a foreign breathing crack under such a sag fits to 1.13x its floor with its
    axis within 0.3 deg.  For :func:`diagnose_output_error`'s ``seeds``."""
    lib = library_effects()
    model = tuple(e for e in model if e in lib)
    base = fit_output_error(grid, model, equation_error_start(grid, model))
    # every start a few steps on the screening grid (every other segment), the best of each
    # crack to convergence on the whole record
    screen_grid, screen_x0, _, _ = _screening_grid(base)
    out: dict[str, OutputErrorFit] = {}
    for c in candidates:
        if c not in CRACKS or c not in lib or SIDE_LOAD not in lib:
            continue
        effects = (*_with_side_load(model, c, lib), c)
        best = _best_of_starts(screen_grid, effects, _starts(c, base, load), base, screen_x0, LOAD_START_ITERATIONS)
        if best is None:
            continue
        try:
            out[c] = fit_output_error(grid, effects, previous=best, x0=base.x0, max_iter=CONVERGE_ITERATIONS)
        except (FloatingPointError, np.linalg.LinAlgError, ValueError):
            continue
    return out


#: start sizes of the effects whose orientation is searched from starts (at zero size the
#: orientation has no sensitivity)
_SMALL_START = {"asymmetry": {"D": 0.005}, "breathing_crack": {"dk_crack": 0.02, "breathing_depth": 0.5},
                "hinge_crack": {"dk_hinge": 0.02}, "support_anisotropy": {"support_anisotropy": 0.01}}


def _rub_against(grid, screen_grid, screen_x0, model, lib, current, converged, floor: float) -> OutputErrorFit | None:
    """The rub screened and fitted to convergence in a round that tried it only against a
    crack: given up where it cannot come within a tie of the best of the round's fits to
    convergence (``converged``), as it would have among them; ``None`` where it diverges."""
    screened = _screen(screen_grid, _with_side_load(model, "rub", lib), "rub", current, x0=screen_x0)
    if screened is None:
        return None
    done = [f.rss for f in converged if not f.gave_up]
    level = _give_up_level(min(done) if done else None, len(screened.values), floor)
    return _converge(grid, _with_side_load(model, "rub", lib), "rub", screened, current.x0, level)


def _crack_lookalikes(grid, model, lib, fits, keep, screened_rss, lead: str, current, floor: float) -> dict:
    """The candidates screened out within :data:`LOOKALIKE_SCREEN` of the leading crack's
    screening residual energy (not a crack, not the rub -- its own rule compares it), each
    fitted to convergence; those that come within a tie of the crack (they do not give up).

    The screening's two steps rank a candidate by where it stands early, and an effect whose
    signature hides mostly in the model's own terms moves slowly: a foreign 10 um bow (its 1X
    is runout plus unbalance but for the damping's share) screened at 1.07x the floor beside
    an open crack's 1.06x and was left out; the crack, with a side load at 85 % of its bound,
    removed 7 % of the excess and was named, the bow after it.  Fitted on, the bow alone
    reaches 0.99x."""
    lead_fit = fits[lead]
    level = _give_up_level(lead_fit.rss, len(lead_fit.values), floor)
    out = {}
    for c in list(fits):
        if c in keep or c in CRACKS or c == "rub" or c not in screened_rss:
            continue
        if screened_rss[c] > LOOKALIKE_SCREEN * screened_rss.get(lead, 0.0):
            continue
        full = _converge(grid, _with_side_load(model, c, lib), c, fits[c], current.x0, level)
        if full is not None and not full.gave_up:
            out[c] = full
    return out


def _crack_laws_from_lead(grid, screen_grid, screen_x0, model, lib, fits, keep, current,
                          best_rss: float | None = None, floor: float = 0.0) -> dict:
    """Each other crack law started from the side load and the axis the best crack of the round
    found: the best of four axes (the lead's, turned by quarter turns) after the screening's
    steps, fitted to convergence.

    A crack's law decides how it reads its side load: a cosine's breathing (Mayes) by the
    angle, Gasch's hinge by the sign of the deflection across the mouth.  From no load the
    hinge breathes with the whirl alone and its screening stalls far off (a horizontal rig's
    hinge crack under a 494 um sag: 15.5x the floor after the screening against 1.29x for the
    cosine), while from the cosine's load and axis it converges to 1.003x, its size within
    0.3 % and its axis within 0.1 deg.  Only where the lead's side load is significant (5 %):
    the laws differ in how they read it.  ``{crack: fit}`` where the crack was screened out, or
    where this fit beats the one it had."""
    leads = [c for c in keep if c in fits and c in CRACKS and SIDE_LOAD in fits[c].effects]
    if not leads:
        return {}
    lead = min(leads, key=lambda c: fits[c].rss)
    lead_fit = fits[lead]
    if lead_fit.gave_up and lead_fit.iterations >= CRAWL_SHARE * CONVERGE_ITERATIONS:
        # the best crack crawled along a valley for most of its steps and still could not come
        # within a tie of the round's best candidate, which is not a crack: a crack times an
        # ever larger side load tending to a 2X forcing (a misalignment's record: the load to
        # 11x the orbit's peak, the size to 0.002, 38 of 40 steps).  Its load and axis are no
        # start: the other laws from them crawl too (4.7 of that record's 18.8 s, both given
        # up).  A lead that gave up early stalled away from the truth instead, and the other
        # laws from its load may still win (a foreign breathing crack's lead gave up after 10
        # steps against a misalignment; the breathing law from its load beat it 3x)
        return {}
    if not lead_fit.wald(SIDE_LOAD)[2] < math.log10(0.05):
        # no side load to read: the lead's start gives the other laws nothing their own lack
        return {}
    load = start_from(lead_fit)[SIDE_LOAD]
    orient = EFFECTS[lead].orientation_parameters
    axis0 = lead_fit.value(f"{lead}.{orient[0].name}") if orient else 0.0
    out = {}
    for c in CRACKS:
        eff = EFFECTS[c]
        if c == lead or c not in fits or len(eff.orientation_parameters) != 1 or eff.scanned_parameters:
            continue
        p = eff.orientation_parameters[0]
        m = _with_side_load(model, c, lib)
        starts = [{SIDE_LOAD: load, c: {**_SMALL_START.get(c, {}), p.name: axis0 + k * math.pi / 2}} for k in range(4)]
        best = _best_of_starts(screen_grid, (*m, c), starts, current, screen_x0, SCREEN_ITERATIONS)
        if best is None:
            continue
        # like the round's candidates: a law that cannot come near the best fit of the round
        # gives up (its fit then judged at its optimum only where a decision reads it)
        level = _give_up_level(best_rss, len(best.values), floor)
        full = _converge(grid, m, c, best, current.x0, level)
        # a candidate screened out holds a fit of the screening grid's segments only
        if full is not None and (c not in keep or full.rss < fits[c].rss):
            out[c] = full
    return out


def in_band_noise(fit: OutputErrorFit) -> OffOrderNoise:
    """The probes' noise in the rotor's band, read off ``fit``'s residual away from the shaft's
    orders and the free whirl (:func:`.orders.off_order_noise`), against the grid's noise
    model (read above the response).  The free whirl at a speed ``W``: ``(+-ip W + sqrt(ip^2
    W^2 + 4 k)) / 2`` with the fitted stiffness ``k`` (the gyroscopic pair; ``sqrt(k)``
    without it)."""
    g = fit.grid
    k = _fitted_stiffness(fit)
    ip = float(g.ip)

    def whirl(w: float) -> list[float]:
        root = math.sqrt(ip * ip * w * w + 4.0 * k)
        return [0.5 * (root + ip * w), 0.5 * (root - ip * w)]

    rows = g.inside
    above = 4.0 * max(float(np.max(np.abs(g.phid))), math.sqrt(k)) / (2.0 * math.pi)
    return off_order_noise(g.t[rows], fit.residual[rows], g.phid[rows], whirl, g.noise_density, above=above)


def _floor_with_band(fit: OutputErrorFit, white: float, noise: OffOrderNoise) -> tuple[float, float, bool]:
    """The noise floor off ``fit``'s residual, its relative uncertainty, and whether the noise
    read on the residual's grid counts in it: where the band reads coloured, or the band above
    the response reads off the model's level (:attr:`.orders.OffOrderNoise.reference_level`),
    and ``fit`` stands within :data:`COLOUR_MISFIT_RATIO` of that floor; else the level read
    above the response on the raw record (``white``), :data:`FLOOR_UNCERTAINTY`."""
    if noise.floor_factor != 1.0:
        coloured = white * math.sqrt(noise.floor_factor)
        if fit.rms <= COLOUR_MISFIT_RATIO * coloured:
            return coloured, _floor_uncertainty(noise), True
    return white, FLOOR_UNCERTAINTY, False


def _misfit_between_orders_note(noise: OffOrderNoise, fit: OutputErrorFit, white: float) -> str:
    """Why the noise read on the residual's grid was not counted in the floor."""
    coloured = white * math.sqrt(noise.floor_factor)
    return (f"the residual's noise between the shaft's orders reads off the level read above the response (the floor "
            f"would be {math.sqrt(noise.floor_factor):.4g}x it), but the model misses the record by "
            f"{fit.rms / coloured:.3g}x even that floor (more than {COLOUR_MISFIT_RATIO:g}x): its shooting segments' "
            "start states take the misfit's local shape and the residual steps at every cut, which reads as noise "
            "between the orders -- not counted: the floor is the level read above the response")


def _fitted_stiffness(fit: OutputErrorFit) -> float:
    """The fitted shaft stiffness ``k`` (the natural frequency is ``sqrt(k)`` in model time);
    1 where the fit holds it, or where it is not a positive number."""
    k_name = f"{TIME_UNIT_EFFECT}.k"
    k = fit.value(k_name) if k_name in fit.names else 1.0
    return k if math.isfinite(k) and k > 0 else 1.0


def _coloured_note(noise: OffOrderNoise, fit: OutputErrorFit) -> str:
    """What the noise read on the residual's grid did to the floor, the bands named in the
    natural frequency."""
    said = []
    if noise.reference_level != 1.0:
        said.append(f"on the residual's grid the band above the response reads {noise.reference:.3g} +- "
                    f"{1.96 * noise.reference_se:.2g} times the noise model read off the record's band above the "
                    "response up to its Nyquist frequency: the noise is not of one first-order shape (white noise "
                    "with a coloured part, a filter's slope), and the level where the fit reads counts")
    if noise.variance_factor > 1.0:
        per = 2.0 * math.pi / math.sqrt(_fitted_stiffness(fit))  # cycles per unit time -> per natural frequency
        bands = ", ".join(f"{r:.3g}x at {lo * per:.2g}-{hi * per:.2g}"
                          for (lo, hi), r, up in zip(noise.bands, noise.ratio, noise.raised, strict=True) if up)
        said.append(f"the probes' noise is coloured in the rotor's band (log10 p = {noise.log10_p:.3g} that it is at "
                    "the level read above the response): away from the shaft's orders and the free whirl the "
                    f"residual's density is {bands or 'within two standard errors in each band, above it together'} "
                    "times that level (bands in multiples of the natural frequency)")
    return (f"{'; '.join(said)}; the floor counts it: {math.sqrt(noise.floor_factor):.4g}x the level read above the "
            "response")


def _half_turn_orientation(effect: str):
    """The effect's one orientation when its moment turns as ``e^{-2i axis}`` (period pi) and it
    has one coefficient and no other argument: then ``D e^{-2i axis}`` is linear in
    ``(D cos 2 axis, D sin 2 axis)``."""
    eff = EFFECTS[effect]
    args = eff.argument_parameters
    if len(eff.coefficients) == 1 and len(args) == 1 and args[0].orientation \
            and abs(args[0].angle_period - math.pi) < 1e-9:
        return args[0]
    return None


def _screen(grid, model, effect, base_fit, x0=None):
    """The candidate from each of its starts, a few Levenberg-Marquardt steps each: the best.

    A half-turn orientation (a crack's axis, the supports' axis) is not searched from
    starts: the moment is linear in ``D cos 2a`` and ``D sin 2a``, whose columns (the axis at
    0 and at 45 deg) are in quadrature over the record — one step from zero at each gives
    both components, hence the start ``D, a``."""
    p = _half_turn_orientation(effect)
    starts = _starts(effect, base_fit)
    if p is not None:
        base = {}
        comps = []
        for axis in (0.0, math.pi / 4):
            try:
                f = fit_output_error(grid, (*model, effect), {**base, effect: np.zeros(1)}, previous=base_fit,
                                     fixed_args={effect: {p.name: axis}}, x0=x0, max_iter=SCREEN_ITERATIONS)
            except (FloatingPointError, np.linalg.LinAlgError, ValueError):
                comps = []
                break
            comps.append(f.value(f"{effect}.{EFFECTS[effect].coefficients[0]}"))
        if comps:
            D = math.hypot(*comps)
            axis = 0.5 * math.atan2(comps[1], comps[0])
            name = EFFECTS[effect].parameters[0].name
            starts = [{**base, effect: {name: D, p.name: axis}}]
    return _best_of_starts(grid, (*model, effect), starts, base_fit, x0, SCREEN_ITERATIONS)


def _best_of_starts(grid, effects, starts, previous, x0, max_iter: int) -> OutputErrorFit | None:
    """``effects`` fitted ``max_iter`` steps from each of ``starts`` (the rest from ``previous``):
    the fit with the least residual energy; ``None`` where every one diverged."""
    best = None
    for st in starts:
        try:
            f = fit_output_error(grid, effects, st, previous=previous, x0=x0, max_iter=max_iter)
        except (FloatingPointError, np.linalg.LinAlgError, ValueError):
            continue
        if best is None or f.rss < best.rss:
            best = f
    return best


def _converge(grid, model, effect, screened, x0, give_up_above=None):
    """The screened fit to convergence on every segment of ``grid`` (start states ``x0``: the
    model's fit's), its argument values (orientation, clearance) with it; ``None`` where it
    fails.  ``give_up_above``: the residual energy of the best candidate fitted so far -- a
    fit that cannot come down to it stops (:func:`~.output_error.fit_output_error`), and is
    fitted on only where a decision reads it (:func:`_to_convergence`)."""
    try:
        return fit_output_error(grid, (*model, effect), {}, previous=screened, x0=x0, max_iter=CONVERGE_ITERATIONS,
                                give_up_above=give_up_above)
    except (FloatingPointError, np.linalg.LinAlgError, ValueError):
        return None


def _fit_on(fit: OutputErrorFit, steps: int) -> OutputErrorFit | None:
    """``fit``'s model fitted on from where it stopped, for at most ``steps`` steps; ``None``
    where that fails."""
    try:
        return fit_output_error(fit.grid, fit.effects, {}, previous=fit, x0=fit.x0, max_iter=max(steps, 1))
    except (FloatingPointError, np.linalg.LinAlgError, ValueError):
        return None


def _run_on(fit: OutputErrorFit, floor: float, notes: list[str]) -> OutputErrorFit:
    """``fit`` (not converged) fitted on for :data:`CONVERGE_ITERATIONS` more steps; where it
    still has not converged, a note says so."""
    more = _fit_on(fit, CONVERGE_ITERATIONS)
    if more is not None and more.rss <= fit.rss:
        fit = more
    if not fit.converged:
        model = ", ".join(e for e in fit.effects if e != "stiffness")
        notes.append(f"the final model's fit ({model}) did not converge in its step limit: its residual "
                     f"({fit.rms / floor:.4g}x the floor) still falls and its parameters still move -- they are "
                     "given where the fit stopped, and their intervals (from the curvature there) do not hold: "
                     "this record does not determine them (a run that does not pass through a critical speed, or "
                     "barely changes speed, holds too few numbers for the model)")
    return fit


def _to_convergence(fit: OutputErrorFit) -> OutputErrorFit:
    """A fit that gave up (:attr:`~.output_error.OutputErrorFit.gave_up`) run on to
    convergence, in the steps it had left; the fit itself otherwise or where that fails."""
    if not fit.gave_up:
        return fit
    return _fit_on(fit, CONVERGE_ITERATIONS - fit.iterations) or fit


def _physical_problem(fit: OutputErrorFit, effect: str, base: OutputErrorFit | None = None) -> str:
    """Why ``effect``'s fit is not physical (``""`` when it is): a parameter of the candidate
    outside its declared range, or one of the model's own that the candidate pushed out of it
    (``base``: the fit without the candidate).  A cross-coupling and a damping are degenerate
    through one critical (``c - q/w``): a bow's small trace at 0.1 um was once fitted by a
    cross-coupling of -0.055 with the damping driven to -0.007."""
    # the record's peak amplitude (model units): a moment polynomial's bounds scale with it
    peak = float(np.max(np.hypot(fit.grid.y[:, 0], fit.grid.y[:, 1]))) if fit.grid.n else None

    def outside(e: str, vals: dict) -> tuple[str, str] | None:
        for p in EFFECTS[e].parameters:
            lo, hi = p.bounds_at(peak)
            if p.name in vals and not p.orientation and not lo <= vals[p.name] <= hi:
                where = f" at this record's peak amplitude {peak:.3g}" if p.amplitude_reference > 0 else ""
                return p.name, (f"{p.name} = {vals[p.name]:.4g} outside [{lo:.4g}, {hi:.4g}]{where} "
                                f"({p.bounds_reason})")
        return None

    bad = outside(effect, fit.parameters(effect))
    if bad:
        return f"not physical: {bad[1]}"
    for e in fit.effects:
        if e == effect or base is None or e not in base.effects:
            continue
        bad = outside(e, fit.parameters(e))
        if bad and not outside(e, {bad[0]: base.parameters(e)[bad[0]]}):
            return f"not physical: with it the model's {bad[1]}"
    return ""


def _comparison_note(rnd: int, row: Candidate, fit: OutputErrorFit, chosen: str, chosen_fit: OutputErrorFit,
                     floor: float) -> str:
    """A round's note on a fitted candidate beside the one named: it fits the data as well
    (its residual energy within the 99 % point of a chi-square with its parameter count, in
    units of the noise variance: both fits see the same noise, so it cancels) -- the data
    cannot tell them apart; or it fits them better by more than that and a rule turned it
    down -- said with the rule, not as a tie.  ``""`` otherwise."""
    gap, level = _gap(fit, chosen_fit, floor)
    residuals = f"residual {fit.rms / floor:.4g}x vs {chosen_fit.rms / floor:.4g}x the floor"
    if gap < -level:
        return (f"round {rnd}: {row.effect} fits these data better than {chosen} ({residuals}) but is not named: "
                f"{row.reason}")
    if gap <= level:
        return (f"round {rnd}: {row.effect} fits these data as well as {chosen} ({residuals}): the data cannot "
                f"tell them apart; {chosen} is named "
                + ("as the simpler (fewer parameters)" if len(fit.values) > len(chosen_fit.values)
                   else "as the simpler crack law" if _simpler_crack_law(chosen, row.effect)
                   else "by the information criterion"))
    return ""


def _gap(fit: OutputErrorFit, other: OutputErrorFit, floor: float) -> tuple[float, float]:
    """How much more residual energy ``fit`` leaves than ``other``, in units of the noise
    variance (both fits see the same noise, so it cancels), and the level within which the two
    tie: the 99 % point of a chi-square with ``fit``'s parameter count."""
    return (fit.rss - other.rss) / (floor * floor), _tie_level(len(fit.values))


def _give_up_level(best_rss: float | None, n_parameters: int, floor: float) -> float | None:
    """The residual energy a fit of ``n_parameters`` gives up above (``give_up_above``):
    beyond a tie with the best fit so far -- the 99 % chi-square point of its parameters,
    twice, and a thousandth of the best residual, the crack_not_rub rule's margin; ``None``
    where there is no best yet."""
    return None if best_rss is None else best_rss * 1.001 + 2.0 * _tie_level(n_parameters) * floor * floor


def _tie_level(n_parameters: int) -> float:
    """Two fits of the same data tie within this much residual energy, in units of the noise
    variance: the 99 % point of a chi-square with the fit's parameter count."""
    from scipy.stats import chi2

    return float(chi2.ppf(0.99, n_parameters))


def _simpler_crack_law_first(accepted: list[Candidate], fits: dict, floor: float) -> list[Candidate]:
    """``accepted`` (best first) with a simpler crack law moved ahead of the crack law ranked
    first where it ties with it and has no more parameters (with fewer, the information
    criterion already prefers it): a law that assumes more is named only where it fits
    better.  An open crack whose weak axis lies along the unbalance is, to a run-up, a hinge
    open below the critical and shut above it, where the response hardly sees the stiffness
    (rig suite seed 7: both 0.9918x the floor)."""
    if not accepted or accepted[0].effect not in CRACKS:
        return accepted
    first = fits[accepted[0].effect]
    simpler = []
    for r in accepted[1:]:
        f = fits[r.effect]
        gap, level = _gap(f, first, floor)
        if _simpler_crack_law(r.effect, accepted[0].effect) and len(f.values) <= len(first.values) and gap <= level:
            simpler.append(r)
    if not simpler:
        return accepted
    pick = min(simpler, key=lambda r: CRACKS.index(r.effect))
    return [pick, *[r for r in accepted if r is not pick]]


def _simpler_crack_law(a: str, b: str) -> bool:
    """Is ``a`` a crack law that assumes less than the crack law ``b``?  The laws are declared
    from the simplest (an open crack: linear, always there) to the most particular (Gasch's
    hinge, switched by the state)."""
    return a in CRACKS and b in CRACKS and CRACKS.index(a) < CRACKS.index(b)


def _with_side_load(model: tuple[str, ...], effect: str, lib: Sequence[str]) -> tuple[str, ...]:
    """The model a candidate is tried in: a crack with the side load (gravity, a misaligned
    bearing).  A cracked shaft under a static deflection sees its stiffness turn against it:
    a 2X forcing whose size is the crack's times the deflection, resonant at half the
    critical -- the field engineer's crack test.  Without the load in the model the crack's
    fit takes that 2X on its asymmetry, which then differs between slow roll and the
    critical and fails the amplitude rule for a crack that is there.  Alone, a static load
    is a static offset the probes' gap removal takes away; beside a crack it is seen.

    A crack also *replaces* the other crack of the model: a breathing crack contains the open
    one (its mean stiffness loss), and fitted on top of it the two are degenerate -- its
    breathing depth runs off to a value no crack has."""
    if effect in CRACKS:
        model = tuple(e for e in model if e not in CRACKS)
    if effect in CRACKS and SIDE_LOAD in lib and SIDE_LOAD not in model:
        return (*model, SIDE_LOAD)
    return model


def _crack_split(grid: ShootingGrid, fit: OutputErrorFit, effect: str, noise: OffOrderNoise | None = None) -> str:
    """The crack's asymmetry on the low- and the high-amplitude half of the segments.

    Each half is fitted twice: with the crack free, and with it held at the whole record's
    value.  The halves disagree where the residual energy that holding it costs, summed over
    both, exceeds :data:`CRACK_SPLIT_Z` squared noise variances (a likelihood ratio: one
    parameter, the same crack, tested at ``z = 4``) and the free values differ by a third.
    A likelihood ratio, not the Wald distance of the free values: on a half that hardly
    determines the crack, the free fit can run far along a flat valley where its curvature
    promises a small interval (rig suite seed 1: an open crack at 3 um and 2.5 kHz read
    0.263 +- 0.039 on its low-amplitude half, outside any crack's range, against 0.0397 on the
    high one -- 5.5 standard errors apart, yet held at the record's 0.0396 that half's fit
    rose by only 12 noise variances).

    The side load stays at the whole record's value in both halves: away from the critical a
    crack under a static deflection shows only as the product of the two (its 1X, 2X and 3X
    forcing), and refitted freely there the load takes the crack's size with it -- a horizontal
    rig's breathing crack under a 500 um gravity sag, which explained its record to 1.003x the
    floor, had 0.024 on the low half against 0.014 on the high one and was turned down."""
    amp = np.array([np.max(np.hypot(grid.y[i0:i1 + 1, 0], grid.y[i0:i1 + 1, 1])) for i0, i1 in grid.segments])
    order = np.argsort(amp)
    half = len(order) // 2
    if half < 3:
        return ""
    coef_name = f"{effect}.{EFFECTS[effect].coefficients[0]}"
    floor2 = float(grid.noise_std) ** 2
    res, cost = [], 0.0
    for part in (order[:half], order[half:]):
        part = np.sort(part)
        sub = replace(grid, segments=grid.segments[part])
        kw = dict(x0=fit.x0[part], fixed_args=arguments_of(fit), max_iter=CONVERGE_ITERATIONS)
        try:
            f = fit_output_error(sub, fit.effects, start_from(fit), **kw,
                                 held=tuple(e for e in fit.effects if e == SIDE_LOAD))
            at_whole = fit_output_error(sub, fit.effects, start_from(fit), **kw,
                                        held=tuple(e for e in fit.effects if e in (SIDE_LOAD, effect)))
        except (FloatingPointError, np.linalg.LinAlgError, ValueError):
            return ""
        # counted in noise variances of the crack's own estimate: under coloured noise (an
        # integrating sensor, a filtered channel) the residual energy one parameter moves is
        # kappa times a chi-square (estimate_inflation, with the in-band reading ``noise``
        # where the floor counts it; 1 for white noise).  A foreign open crack under AR(1)
        # noise (rho 0.9 at 2.5 kHz, the band 5-18x the level above the response) cost 64
        # white variances and was turned down as a rub
        kappa = estimate_inflation(f, coef_name, None if noise is None else noise.level_at)
        cost += max(at_whole.rss - f.rss, 0.0) / (floor2 * kappa)
        i = f.names.index(coef_name)
        # in the units of each half's own fitted shaft (k = 1): the halves' time units differ
        scale = float(canonical_scale(effect, f.value(f"{TIME_UNIT_EFFECT}.k"))[0])
        res.append((scale * f.values[i], abs(scale) * math.sqrt(max(f.covariance[i, i], 0.0))))
    (lo, se_lo), (hi, se_hi) = res
    if cost > CRACK_SPLIT_Z ** 2 and abs(hi - lo) > abs(hi + lo) / 6.0:
        return (f"rule crack_amplitude_independence: its stiffness asymmetry is {lo:.3g} +- {1.96 * se_lo:.2g} "
                f"on the low-amplitude half of the record and {hi:.3g} +- {1.96 * se_hi:.2g} on the high-amplitude "
                f"half; held at the whole record's value the halves' residual rises by {cost:.3g} noise variances "
                f"(more than {CRACK_SPLIT_Z ** 2:.3g}): a crack's asymmetry does not depend on the amplitude, a "
                f"rub's contact does")
    return ""


def diagnose_output_error(
    grid: ShootingGrid,
    model: Sequence[str],
    candidates: Sequence[str],
    *,
    alpha: float = 0.05,
    unit_scale: float = 1.0,
    unit: str = "",
    progress: bool = False,
    split: bool = True,
    seeds: Mapping[str, OutputErrorFit] | None = None,
) -> OutputErrorDiagnosis:
    """Forward selection on the output error (module docstring); ``split``: where the
    parameters are found not the same over the record, diagnose each side of the break on
    its own (:mod:`.parts`); ``seeds``: fits of candidates found apart (each the starting
    model with that candidate, :func:`crack_fits_under_load`), which the first round's
    screening of that candidate starts from too, the better taken."""
    t_start = time.perf_counter()
    lib = library_effects()
    notes = []
    model = tuple(e for e in model if e in lib)
    skipped = [c for c in candidates if c not in lib]
    if skipped:
        notes.append(f"not tried by the output-error fit (set-valued friction or a user effect): {', '.join(skipped)}")
    cands = [c for c in dict.fromkeys(candidates) if c in lib and c not in model and c != "stiffness"]
    if grid.noise_std is None or not grid.noise_std > 0:
        raise ValueError("the output-error diagnosis needs the probes' noise level (grid.noise_std)")
    floor = float(grid.noise_std)

    from ..progress import advance, step

    def say(msg: str) -> None:
        if progress:
            print(f"[{time.perf_counter() - t_start:6.1f} s] {msg}", file=sys.stderr, flush=True)

    step("waveforms: output-error fit of the starting model")

    start = equation_error_start(grid, model)
    if grid.second_mode is not None and TIME_UNIT_EFFECT in start:
        # with a second mode the model's own is started at the time scale: the equation error
        # of one mode on two modes' record puts its stiffness anywhere between the two
        start[TIME_UNIT_EFFECT] = np.ones_like(start[TIME_UNIT_EFFECT])
    base = fit_output_error(grid, model, start)
    # the probes' noise in the rotor's band, read off the starting model's residual between
    # the shaft's orders (a misfit at them stays out of the bins read): 1/f noise lifts it
    # above the level read above the response, and the search's relevance rule measures what
    # an effect removes against the residual above the floor (read again from the final model)
    white = floor
    in_band = in_band_noise(base)
    floor, unc, band_counted = _floor_with_band(base, white, in_band)
    say(f"starting model fitted: residual {base.rms / floor:.3g}x the noise floor")
    current, cur_model, added = base, tuple(model), []
    tried: list[Candidate] = []
    crack_amp_cache: dict = {}
    n_lib = max(len(cands), 1)

    def undetermined(cur_model):
        # the candidates the detectability is asked about (a scanned argument -- the rub's
        # clearance -- has no single setting to assess at)
        return [c for c in cands if c not in cur_model and not any(p.scanned for p in EFFECTS[c].argument_parameters)]

    detect, detect_of = None, None
    for rnd in range(1, MAX_ADDED + 1):
        todo = [c for c in cands if c not in cur_model]
        # a round the score tests chose: the rub is tried only against a crack (crack_not_rub),
        # and fitted only when a crack reaches that rule (a misalignment record's round of a
        # leaning crack spent 1.4 s of its 15 s on a rub no rule read)
        rub_against_cracks = False
        if current.rms / floor <= SEARCH_RATIO:
            # the residual energy cannot tell; the score tests can (module docstring)
            detect, detect_of = assess_all(current, undetermined(cur_model), alpha=alpha / n_lib,
                                           min_fall=RELEVANT_SHARE * _excess(current, floor, unc)), current
            todo, trace = _leaning(detect, alpha / n_lib)
            if trace:
                notes.append(f"round {rnd}: the residual ({current.rms / floor:.4g}x the floor) leans most towards "
                             f"{trace} (score test log10 p = {detect[trace].score_log10_p:.3g}), which these data "
                             f"cannot decide: what is left is read as its trace, not as a decidable effect")
            if not todo:
                break
            rub_against_cracks = (any(c in CRACKS for c in todo) and "rub" in cands and "rub" not in cur_model
                                  and "rub" not in todo)
            notes.append(f"round {rnd}: the residual stands within {SEARCH_RATIO} of the floor "
                         f"({current.rms / floor:.4g}x) but leans towards "
                         + ", ".join(f"{c} (score test log10 p = {detect[c].score_log10_p:.3g})"
                                     for c in todo if c in detect)
                         + ": tried" + (" (and the rub, against the crack)" if rub_against_cracks else ""))
        excess = _excess(current, floor, unc)
        screen_grid, screen_x0, screen_rss, screen_rows = _screening_grid(current)
        screen_excess = _excess_of(screen_rss, screen_rows, floor, unc)
        fits = {}
        step(f"waveforms, round {rnd}: output-error screening of each candidate", total=len(todo), unit="candidates")
        for c in todo:
            f = _screen(screen_grid, _with_side_load(cur_model, c, lib), c, current, x0=screen_x0)
            if rnd == 1 and seeds and c in seeds:
                try:
                    g = fit_output_error(screen_grid, (*_with_side_load(cur_model, c, lib), c), previous=seeds[c],
                                         x0=screen_x0, max_iter=SCREEN_ITERATIONS)
                except (FloatingPointError, np.linalg.LinAlgError, ValueError):
                    g = None
                if g is not None and (f is None or g.rss < f.rss):
                    f = g
            advance()
            say(f"round {rnd}: {c} screened" + (f" (residual {f.rms / floor:.3g}x the floor)" if f else " (diverged)"))
            if f is not None:
                fits[c] = f
        # every candidate screened by a few steps from each start; the best few (by the
        # information criterion below) fitted to convergence, the rub always when a crack is
        # among them (the crack_not_rub rule compares the two)
        screened_rss = {c: f.rss for c, f in fits.items()}
        ranked = sorted(fits, key=lambda c: fits[c].rss / (floor * floor) + len(fits[c].values)
                        * math.log(fits[c].n_rows))
        keep = ranked[:SCREEN_KEEP]
        if any(c in CRACKS for c in keep) and "rub" in fits and "rub" not in keep:
            keep.append("rub")
        step(f"waveforms, round {rnd}: the best candidates fitted to convergence", total=len(keep),
             unit="candidates")
        best_rss = None
        for c in list(keep):
            advance()
            # best first (ranked): one that cannot come near the best so far gives up
            level = _give_up_level(best_rss, len(fits[c].values), floor)
            full = _converge(grid, _with_side_load(cur_model, c, lib), c, fits[c], current.x0, level)
            if full is None:
                del fits[c]
                keep.remove(c)
                say(f"round {rnd}: {c} diverged when fitted to convergence")
                continue
            fits[c] = full
            if not full.gave_up:
                best_rss = full.rss if best_rss is None else min(best_rss, full.rss)
            say(f"round {rnd}: {c} fitted (residual {fits[c].rms / floor:.3g}x the floor)"
                + (" -- gave up: it cannot come down to the best" if full.gave_up else ""))
        for c, full in _crack_laws_from_lead(grid, screen_grid, screen_x0, cur_model, lib, fits, keep,
                                             current, best_rss, floor).items():
            fits[c] = full
            if c not in keep:
                keep.append(c)
            say(f"round {rnd}: {c} started from the best crack's side load and axis (residual "
                f"{full.rms / floor:.3g}x the floor)")
        # the rub kept for the crack rule counts in the round's Bonferroni level
        n = max(len(fits) + int(rub_against_cracks), 1)

        def row_of(c, f, rnd=rnd, keep=keep, excess=excess, screen_rss=screen_rss, screen_excess=screen_excess,
                   n=n, current=current):
            _, _, lp = f.wald(c)
            # a candidate screened out was fitted on the screening grid only: its fall there
            relevance = ((current.rss - f.rss) / excess if c in keep
                         else (screen_rss - f.rss) / screen_excess)
            reason = ""
            if c not in keep:
                reason = (f"screened out: after {SCREEN_ITERATIONS} steps from each start it removes "
                          f"{100 * relevance:.1f} % of the residual above the floor, less than the "
                          f"{SCREEN_KEEP} best of the round")
            elif not lp < math.log10(alpha / n):
                reason = f"not significant (log10 p = {lp:.3g}, Bonferroni level {math.log10(alpha / n):.3g})"
            elif relevance < RELEVANT_SHARE:
                reason = f"significant, not relevant: removes {100 * relevance:.1f} % of the residual above the floor"
            else:
                reason = _physical_problem(f, c, current)
            return Candidate(rnd, c, f.rms, lp, relevance, f.parameters(c), _intervals(f, c), not reason, reason)

        round_rows = [row_of(c, f) for c, f in fits.items()]
        # the best survivor by the Bayesian information criterion with the known noise level
        # (rss / sigma^2 + free parameters * ln N): a breathing crack that fits no better
        # than the open one it contains is not chosen over it
        def bic(r, fits=fits):
            f = fits[r.effect]
            return f.rss / (floor * floor) + len(f.values) * math.log(f.n_rows)

        # a crack must beat the rub and hold at every amplitude
        accepted = sorted((r for r in round_rows if r.accepted), key=bic)
        if accepted and accepted[0].effect in CRACKS:
            # a crack leads: the candidates screened out near it are fitted to convergence and
            # ranked with it, so that a crack is named against every alternative at its optimum
            lookalikes = _crack_lookalikes(grid, cur_model, lib, fits, keep, screened_rss, accepted[0].effect,
                                           current, floor)
            for c, full in lookalikes.items():
                fits[c] = full
                keep.append(c)
                say(f"round {rnd}: {c} (screened out near the leading crack) fitted (residual "
                    f"{full.rms / floor:.3g}x the floor)")
            if lookalikes:
                round_rows = [row_of(c, f) for c, f in fits.items()]
                accepted = sorted((r for r in round_rows if r.accepted), key=bic)
        # an open crack is a breathing crack that does not breathe: when the breathing depth's
        # interval reaches zero and the open crack fits, the open crack (fewer parameters) is named
        names = [r.effect for r in accepted]
        if names and names[0] == "breathing_crack" and "asymmetry" in fits:
            depth = accepted[0].parameters.get("breathing_depth", math.nan)
            half = accepted[0].intervals.get("breathing_depth", math.nan)
            asym = next((r for r in round_rows if r.effect == "asymmetry"), None)
            if asym is not None and asym.accepted and abs(depth) <= half:
                accepted = [asym, *[r for r in accepted if r is not asym]]
        accepted = _simpler_crack_law_first(accepted, fits, floor)
        chosen = None
        for r in accepted:
            if fits[r.effect].gave_up:
                # the better candidates were turned down: this one is judged at its own optimum
                fits[r.effect] = _to_convergence(fits[r.effect])
                r2 = row_of(r.effect, fits[r.effect])
                round_rows[round_rows.index(r)] = r2
                if not r2.accepted:
                    continue
                r = r2
            if r.effect in CRACKS:
                if rub_against_cracks and "rub" not in fits:
                    rub = _rub_against(grid, screen_grid, screen_x0, cur_model, lib, current,
                                       [fits[c] for c in keep], floor)
                    if rub is not None:
                        fits["rub"] = rub
                        keep.append("rub")
                        row = row_of("rub", rub)
                        row.accepted, row.reason = False, ("tried in this round only against the crack "
                                                           "(rule crack_not_rub), not for its own score test")
                        round_rows.append(row)
                        say(f"round {rnd}: rub fitted against the crack (residual {rub.rms / floor:.3g}x the floor)")
                rub = fits.get("rub")
                if rub is not None and rub.gave_up and rub.reachable <= fits[r.effect].rss * 1.001:
                    rub = fits["rub"] = _to_convergence(rub)  # it might reach the crack: the rule reads it
                if rub is not None and rub.rss <= fits[r.effect].rss * 1.001:
                    r.accepted, r.reason = False, ("rule crack_not_rub: the rub's own model explains the data at least "
                                                   f"as well (residual {rub.rms / floor:.3g}x vs "
                                                   f"{fits[r.effect].rms / floor:.3g}x the floor)")
                    continue
                key = (rnd, r.effect)
                msg = crack_amp_cache.get(key)
                if msg is None:
                    msg = _crack_split(grid, fits[r.effect], r.effect, in_band if band_counted else None)
                    crack_amp_cache[key] = msg
                if msg:
                    r.accepted, r.reason = False, msg
                    continue
            chosen = r
            break
        for r in round_rows:
            if chosen is not None and r is not chosen and r.accepted:
                r.accepted, r.reason = False, f"a better candidate in this round: {chosen.effect}"
            f = fits.get(r.effect)
            if f is not None and f.gave_up and r.effect in keep:
                r.reason += (f" (its fit stopped after {f.iterations} steps: at its rate it could not come within a "
                             "tie of the best candidate's residual; the figures are where it stopped)")
        tried.extend(round_rows)
        if chosen is None:
            break
        # what these data cannot decide (and what fits better but a rule turned down)
        for r in round_rows:
            if r is chosen or r.effect not in keep or r.reason.startswith("not significant"):
                continue
            note = _comparison_note(rnd, r, fits[r.effect], chosen.effect, fits[chosen.effect], floor)
            if note:
                notes.append(note)
        # the chosen fit's model: a crack comes with the side load it was fitted with, and
        # replaces the other crack (_with_side_load)
        new_model = tuple(e for e in fits[chosen.effect].effects if e != "stiffness")
        dropped = [e for e in cur_model if e not in new_model]
        if dropped:
            notes.append(f"round {rnd}: {chosen.effect} replaces {', '.join(dropped)} (a breathing crack contains "
                         "the open one)")
        added = [e for e in added if e not in dropped] + [chosen.effect]
        cur_model = (*[e for e in cur_model if e in new_model], *[e for e in new_model if e not in cur_model])
        current = fits[chosen.effect]
        say(f"round {rnd}: {chosen.effect} added: residual {current.rms / floor:.3g}x the noise floor")
    if not current.converged:
        # the final model stopped at its step limit: run on once, and where it still moves
        # say so -- its estimates are where it stopped, and intervals from the curvature there
        # hold only near an optimum (a record at one speed, 1200-1210 rpm, crawls along a
        # valley of stiffness, damping and unbalance: 1X at one speed holds two numbers)
        current = _run_on(current, floor, notes)
    # the in-band noise again, from the model the search ended with (the one the verdict is on)
    in_band = in_band_noise(current)
    floor, unc, counted = _floor_with_band(current, white, in_band)
    if counted:
        notes.append(_coloured_note(in_band, current))
        say(f"the probes' noise in the rotor's band counted: the floor {math.sqrt(in_band.floor_factor):.4g}x "
            "the level above the response")
    elif in_band.floor_factor != 1.0:
        notes.append(_misfit_between_orders_note(in_band, current, white))
    # one model for the whole record: is it the same rotor all through? (a crack that opens
    # above the critical barely lifts the residual, but the fit's scores drift at its onset)
    change = _constancy(current, floor, alpha)
    if change is not None and change.significant and added:
        # what the one model named must be there on both sides of the break (parts module)
        absent = absent_on_a_side(grid, change, current, added, alpha=alpha)
        if absent:
            kept = [e for e in added if e not in absent]
            drop = set(absent)
            if (SIDE_LOAD in cur_model and SIDE_LOAD not in model and SIDE_LOAD not in kept
                    and not any(e in CRACKS for e in kept)):
                drop.add(SIDE_LOAD)  # it came with a crack that goes
            new_model = tuple(e for e in cur_model if e not in drop)
            try:
                refit = fit_output_error(grid, new_model, previous=current, x0=current.x0)
            except (FloatingPointError, np.linalg.LinAlgError, ValueError):
                refit = None
            if refit is not None:
                for r in tried:
                    if r.effect in absent and r.accepted:
                        r.accepted, r.reason = False, absent[r.effect]
                notes.append(f"{', '.join(absent)}: named by the one model of the whole record for its change "
                             f"(not there on one side of the break); refitted without: residual "
                             f"{refit.rms / floor:.3g}x the floor (was {current.rms / floor:.3g}x)")
                say(f"{', '.join(absent)} not there on one side of the break: not named")
                current, cur_model, added = refit, new_model, kept
                change = _constancy(current, floor, alpha)
    # what the data cannot decide: each candidate the final model lacks, asked how much of
    # its signature the model and the nuisance terms take and how large it would have to be
    # to show (a static load in the probes' offsets, a cross-coupling in the damping)
    step("waveforms: what the record cannot decide (detectability of the effects not named)")
    if detect_of is not current:
        detect = assess_all(current, undetermined(cur_model), alpha=alpha / n_lib,
                            min_fall=RELEVANT_SHARE * _excess(current, floor, unc))
    say(f"detectability of {len(detect)} effects not named: "
        f"{sum(not d.decidable for d in detect.values())} cannot be decided")
    diag = OutputErrorDiagnosis(tuple(model), cur_model, base, current, floor, tried, added, unit_scale, unit,
                                time.perf_counter() - t_start, notes, detect, change, None)
    if split and splits(diag):
        say(f"parameters not the same over the record (break at model time {change.t_break:.4g}): each side diagnosed")
        diag = with_parts(diag, candidates, alpha=alpha)
    return diag


def splits(diag: OutputErrorDiagnosis) -> bool:
    """Whether ``diag`` reads as two rotors in one record, each side to be diagnosed on its own
    (:func:`with_parts`): the one model does not explain it and its parameters drift.  A record
    one model explains is one rotor as far as its residual can tell: there the drift is
    reported, not diagnosed apart (each side would name what its own small misfit makes of an
    instrument's drift: a 2.5 kHz keyphasor's, say)."""
    change = diag.change
    return change is not None and change.significant and diag.rms_ratio_after > EXPLAINED_RATIO


def with_parts(diag: OutputErrorDiagnosis, candidates: Sequence[str], *, alpha: float = 0.05) -> OutputErrorDiagnosis:
    """``diag`` with each side of its break diagnosed on its own (:mod:`.parts`), the same model
    and ``candidates``; ``diag`` itself where it does not split (:func:`splits`).  Apart from
    :func:`diagnose_output_error` so that a caller with a simpler reading to try first (one
    rotor with two modes, :mod:`.from_rig`) pays for the two sides only where it needs them."""
    from ..progress import step

    if diag.parts is not None or not splits(diag):
        return diag
    step("waveforms: the record changed -- each side of the break diagnosed on its own")
    t0 = time.perf_counter()
    model = list(diag.model_before)
    parts = split_at_change(diag.after.grid, diag.change, diag.after,
                            lambda sub: diagnose_output_error(sub, model, list(candidates), alpha=alpha,
                                                              unit_scale=diag.unit_scale, unit=diag.unit,
                                                              split=False))
    return replace(diag, parts=parts, seconds=diag.seconds + time.perf_counter() - t0)


# ------------------------------------------------------------------ figures and report
def _segment_speed_and_rms(fit: OutputErrorFit) -> tuple[np.ndarray, np.ndarray]:
    g = fit.grid
    speed = np.array([np.mean(g.phid[i0:i1 + 1]) for i0, i1 in g.segments])
    rms = np.array([math.sqrt(np.mean(fit.residual[i0:i1 + 1] ** 2)) for i0, i1 in g.segments])
    return speed, rms


def plot_residual(diag: OutputErrorDiagnosis, speed_scale: float = 1.0, speed_unit: str = "speed (model units)"):
    """Output-error residual RMS per segment against speed, before and after, with the
    probes' noise floor: where the starting model fails, and that the added effects close it.
    ``speed_unit``: the speed axis's whole label (``"speed [rpm]"``)."""
    from ..plots.diagnosis import plot_residual_by_speed

    s = diag.unit_scale * diag.probe_factor
    curves = {}
    for fit, label in ((diag.before, "starting model"), (diag.after, "final model")):
        sp, rms = _segment_speed_and_rms(fit)
        curves[label] = (sp * speed_scale, rms * s)
    return plot_residual_by_speed(curves, diag.noise_floor * s, quantity="output-error RMS",
                                  amp_unit=diag.unit or "model units", speed_label=speed_unit,
                                  floor_label="probes' noise floor", log=True,
                                  title="Where the model fails: measured minus predicted displacement")


def plot_response(diag: OutputErrorDiagnosis, speed_scale: float = 1.0, speed_unit: str = "speed (model units)"):
    """Measured and predicted orbit radius against speed (final model)."""
    from ..plots.diagnosis import plot_orbit_radius

    g = diag.after.grid
    s = diag.unit_scale
    pred = diag.after.prediction
    return plot_orbit_radius(g.phid * speed_scale, np.hypot(g.y[:, 0], g.y[:, 1]) * s,
                             np.hypot(pred[:, 0], pred[:, 1]) * s, amp_unit=diag.unit or "model units",
                             speed_label=speed_unit)
