"""The result of a diagnosis: the verdict, what was added, and the numbers behind it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..effects import EFFECTS
from ..results import Result
from .candidates import Candidate
from .compare import Comparison, WindowData, compare, known_values
from .figures import DiagnosisFigures
from .model import Model
from .report import DiagnosisReport, fit_cell
from .verdict import VERDICT_TEXT


@dataclass
class NotIdentifiableResult(Result):
    """A record that cannot decide anything (no excitation, too short): said, not guessed."""

    source: str | None
    reason: str
    ip: float | None = None
    notes: list[str] = field(default_factory=list)
    verdict: str = "not_identifiable"
    missing: list[str] = field(default_factory=list)
    rejected: list[dict] = field(default_factory=list)
    unexplained: dict | None = None
    noise_floor: float = math.nan
    rms_ratio_after: float = math.nan

    def to_dict(self) -> dict:
        return {"source": self.source, "verdict": self.verdict, "reason": self.reason, "ip": self.ip,
                "ip_estimate": None, "missing": [], "rejected": [], "unexplained": None,
                "noise_floor": None, "rms_ratio_after": None, "notes": self.notes}

    def summary(self) -> str:
        return (f"rotor-id diagnosis of {self.source or 'measurements'}\n"
                f"VERDICT: not_identifiable — {self.reason}\n"
                "Nothing is said about the rotor's effects: the record cannot decide them.")

    def save_figures(self, folder, *, overwrite: bool = True) -> list:
        return []

    def report(self, path, *, overwrite: bool = False):
        from ..pages import esc, write_page

        return write_page(path, "rotor-id diagnosis",
                          f"<h1>rotor-id diagnosis</h1><pre>{esc(self.summary())}</pre>", overwrite=overwrite)


# ------------------------------------------------------------------ the result
@dataclass
class Diagnosis(DiagnosisFigures, DiagnosisReport, Result):
    """Result of :func:`diagnose`: before/after comparisons, ranking, where it fails."""

    source: str | None
    ip: float
    alpha: float
    equation: str
    t_start: float
    start_model: tuple[str, ...]
    model: tuple[str, ...]
    missing: list[str]
    onset: dict[str, float | None]
    rounds: list[list[Candidate]]
    before: Comparison
    after: Comparison
    windows: list[dict]
    noise_floor: float
    data: WindowData = field(repr=False)
    steps: list[Comparison] = field(default_factory=list, repr=False)  # after each addition
    verdict: str = "explained"           # see rotor_env.diagnosis.verdict
    rms_ratio_after: float = math.nan     # final residual RMS / noise floor
    rms_ratio_before: float = math.nan
    unexplained: dict | None = None       # orders and bands of a residual above the floor
    rejected: list[dict] = field(default_factory=list)  # {effect, rule} for every candidate turned down
    ip_estimate: float = math.nan         # the inertia ratio the gyroscopic moment gives
    ip_standard_error: float = math.nan
    time_scale: float = 1.0               # t_model = time_scale * t_file
    notes: list[str] = field(default_factory=list)
    #: per added effect: the evidence that told it from its lookalikes (see verdict.lookalike_evidence)
    lookalikes: list[dict] = field(default_factory=list)
    #: the true coefficients where the data were simulated (coefficient -> a number, or an
    #: array over ``data.meas.t``): drawn dashed in the parameter tracks (docs/PLOTS.md)
    truth: dict | None = field(default=None, repr=False)

    @property
    def candidates(self) -> list[Candidate]:
        return self.rounds[0] if self.rounds else []

    def add(self, *names: str) -> Comparison:
        """The final model with more effects, compared (one call to add an effect); its
        standard errors and tests are the HAC ones, as the diagnosis reports them."""
        model = Model(self.model).add(*names).effects
        return compare(self.data, model, known_values(model), self.after.onsets, self.after.splits, robust=True,
                       alpha=self.alpha)

    # -------------------------------------------------------------- text/JSON
    def to_dict(self) -> dict:
        return {
            "source": self.source,
            "ip": self.ip,
            "alpha": self.alpha,
            "t_start": self.t_start,
            "start_model": list(self.start_model),
            "model": list(self.model),
            "missing": list(self.missing),
            "onset": dict(self.onset),
            "candidates": [c.to_dict() for c in self.candidates],
            "rounds": [[c.to_dict() for c in r] for r in self.rounds],
            "rms_before": self.before.rms,
            "rms_after": self.after.rms,
            "r2_before": self.before.r2,
            "r2_after": self.after.r2,
            "fit_percent_before": self.before.fit_percent,
            "fit_percent_after": self.after.fit_percent,
            "fit_bands_before": self.before.fit_bands,
            "fit_bands_after": self.after.fit_bands,
            "coefficients": self.after.coefficient_dict(),
            "standard_errors": dict(zip(self.after.columns, map(float, self.after.standard_errors), strict=True)),
            "physical": self.after.physical,
            "changed": list(self.after.splits),
            "physical_before": self.after.physical_before,
            "significance": self.after.significance,
            "failing_windows": self.windows,
            "noise_floor": self.noise_floor,
            "verdict": self.verdict,
            "rms_ratio_before": self.rms_ratio_before,
            "rms_ratio_after": self.rms_ratio_after,
            "unexplained": self.unexplained,
            "rejected": self.rejected,
            "ip_estimate": self.ip_estimate,
            "ip_standard_error": self.ip_standard_error,
            "time_scale": self.time_scale,
            "prefilter_cutoff": self.data.cutoff,
            "standard_errors_kind": "HAC (Newey-West, Bartlett kernel, Andrews bandwidth)",
            "errors_in_variables_bias": (None if self.after.eiv_bias is None else dict(
                zip(self.after.columns, map(float, self.after.eiv_bias), strict=True))),
            "notes": self.notes,
            "lookalikes": self.lookalikes,
        }

    def decisions(self) -> dict[str, str]:
        """Each candidate's outcome, from the same source as the turned-down list: ``"added
        in round k"`` or ``"turned down in round k: <rule, up to its colon>"``."""
        out = {}
        for k, ranked in enumerate(self.rounds, start=1):
            for c in ranked:
                if k <= len(self.missing) and c.effect == self.missing[k - 1]:
                    out[c.effect] = f"added in round {k}"
        for r in self.rejected:
            rule = r["rule"].split(":")[0]
            out[r["effect"]] = f"turned down in round {r['round']}: {rule}" if r.get("round") else f"turned down: {rule}"
        return out

    def summary(self) -> str:
        b, a = self.before, self.after
        lines = [
            f"rotor-id diagnosis of {self.source or 'measurements'} (ip = {self.ip:g}, alpha = {self.alpha:g})",
            f"informative window: t >= {self.t_start:g} ({len(self.data.meas)} samples)",
            f"starting model: {', '.join(self.start_model)}",
            f"  equation error RMS {b.rms:.4g}, R^2 {b.r2:.4f}; free-run fit {b.fit_percent:.1f} %",
            f"  residual above the noise floor ({self.noise_floor:.3g}) in {len(self.windows)} window(s)"
            + (": " + ", ".join(f"{w['t_start']:.0f}–{w['t_end']:.0f}" for w in self.windows[:6]) if self.windows else ""),
            "",
            "candidates, round 1 (HAC Wald test of each added to the starting model; last column: what the "
            "diagnosis decided, and in which round):",
            f"  {'effect':<22}{'F':>12}{'log10 p':>11}{'RMS after':>11}{'fit % after':>12}  decision",
        ]
        decided = self.decisions()
        for c in self.candidates:
            lines.append(f"  {c.effect:<22}{c.F:12.4g}{c.log10_p:11.4g}{c.rms_after:11.4g}"
                         f"{fit_cell(c):>12}  {decided.get(c.effect, 'not decided')}")
        lines.append("")
        if self.missing:
            lines.append("missing effects, in the order added:")
            for e in self.missing:
                on = self.onset.get(e)
                if e in self.after.splits:
                    change = ", ".join(
                        f"{k} {self.after.physical_before[k]:.4g} -> {self.after.physical[k]:.4g}"
                        for k in self.after.physical_before if k in EFFECTS[e].parameter_names)
                    note = f"  (changes at t ≈ {on:.0f}: {change})"
                else:
                    note = f"  (appears at t ≈ {on:.0f})" if on is not None else "  (present throughout)"
                lines.append(f"  + {e}{note}")
                lines.append(f"      {EFFECTS[e].cause}")
        for ev in self.lookalikes:
            if not ev["lookalikes"]:
                continue
            added_in = self.missing.index(ev["effect"]) + 1 if ev["effect"] in self.missing else None
            lines.append(f"  {ev['effect']} told apart from its lookalikes"
                         + (f" (round {added_in}, when it was added):" if added_in else ":"))
            if ev["residual_orders"]:
                lines.append("    the residual held " + ", ".join(
                    f"{o['order']}x {o['direction']} {100 * o['share']:.0f} %" for o in ev["residual_orders"]))
            if ev["residual_by_speed"]:
                lines.append(f"    its {ev['residual_by_speed'][0]['order']}x line by speed: " + ", ".join(
                    f"{b['speed_min']:.2g}-{b['speed_max']:.2g}: {b['amplitude']:.2g}" for b in ev["residual_by_speed"]))
            where = ev.get("acts_where")
            if where and where.get("reading"):
                scanned = ", ".join(f"{k} = {v:.4g}" for k, v in where["scanned"].items())
                lines.append(f"    {scanned} (scanned): {where['reading']}")
                lines.append(f"    where it acts the residual held -1x {100 * where['backward_1x_share']:.0f} %, "
                             f"1/2x {100 * where['half_order_share']:.0f} %; first contact at speed "
                             f"{where['first_contact']['speed']:.3g}, last at {where['last_contact']['speed']:.3g}")
            for lk in ev["lookalikes"]:
                lines.append(f"    - {lk['effect']}: {lk['status']}")
        if self.rejected:
            lines.append("candidates turned down (each by the last round that tried it):")
            lines += [f"  - {r['effect']}" + (f" (round {r['round']})" if r.get("round") else "") + f": {r['rule']}"
                      for r in self.rejected]
        lines.append("")
        lines.append(f"VERDICT: {self.verdict} — " + VERDICT_TEXT[self.verdict].format(
            ratio=self.rms_ratio_after, floor=self.noise_floor))
        if self.unexplained:
            if self.unexplained["orders"]:
                lines.append("  what is left, by rotation order (share of the energy above the noise):")
                lines += [f"    {o['order']}x {o['direction']}: {100 * o['share']:.0f} %"
                          for o in self.unexplained["orders"]]
            for w in self.unexplained["bands"][:4]:
                lines.append(f"    stands out at t {w['t_start']:.0f}–{w['t_end']:.0f}, speed "
                             f"{w.get('speed_min', math.nan):.3g}–{w.get('speed_max', math.nan):.3g} "
                             f"(up to {w['peak_rms_over_floor']:.1f}x the floor)")
        for n in self.notes:
            lines.append(f"note: {n}")
        lines += [
            "",
            f"final model: {', '.join(self.model)}",
            f"  equation error RMS {a.rms:.4g} (was {b.rms:.4g}), R^2 {a.r2:.4f} (was {b.r2:.4f})",
            f"  free-run fit {a.fit_percent:.1f} % (was {b.fit_percent:.1f} %)",
            "  coefficients:",
        ]
        bias = a.eiv_bias if a.eiv_bias is not None else np.zeros(len(a.columns))
        for c, v, s, d in zip(a.columns, a.coefficients, a.standard_errors, bias, strict=True):
            lines.append(f"    {c:<14}{v: .5g} ± {1.96 * s:.2g}"
                         + (f"   (noise bias {d:+.2g} removed)" if abs(d) >= 0.05 * s else ""))
        lines.append("  (± : 95 % intervals from HAC standard errors, valid on an autocorrelated residual;"
                     + (" values corrected for the sensor noise in the regressors by SIMEX)" if a.eiv_bias is not None
                        else ")"))
        return "\n".join(lines)
