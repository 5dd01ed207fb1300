"""The result of a diagnosis: the verdict, what was added, and the numbers behind it."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from ..effects import EFFECTS
from .candidates import Candidate
from .compare import Comparison, _Data, _known, compare
from .model import Model
from .report import DiagnosisFigures


# ------------------------------------------------------------------ the result
@dataclass
class Diagnosis(DiagnosisFigures):
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
    data: _Data = field(repr=False)
    steps: list[Comparison] = field(default_factory=list, repr=False)  # after each addition

    @property
    def candidates(self) -> list[Candidate]:
        return self.rounds[0] if self.rounds else []

    def add(self, *names: str) -> Comparison:
        """The final model with more effects, compared (one call to add an effect)."""
        model = Model(self.model).add(*names).effects
        return compare(self.data, model, _known(model), self.after.onsets, self.after.splits)

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
        }

    def to_json(self, **kwargs) -> str:
        return json.dumps(_jsonable(self.to_dict()), **kwargs)

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
            "candidates (partial F of adding each to the starting model):",
            f"  {'effect':<22}{'F':>12}{'log10 p':>11}{'RMS after':>11}{'fit % after':>12}  verdict",
        ]
        for c in self.candidates:
            verdict = "MISSING" if c.effect in self.missing else (
                "significant, not relevant" if c.significant else "not significant")
            lines.append(f"  {c.effect:<22}{c.F:12.4g}{c.log10_p:11.4g}{c.rms_after:11.4g}{c.fit_percent_after:12.1f}  {verdict}")
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
        else:
            lines.append("no missing effect: the model explains the data (to the practical-relevance rule)")
        lines += [
            "",
            f"final model: {', '.join(self.model)}",
            f"  equation error RMS {a.rms:.4g} (was {b.rms:.4g}), R^2 {a.r2:.4f} (was {b.r2:.4f})",
            f"  free-run fit {a.fit_percent:.1f} % (was {b.fit_percent:.1f} %)",
            "  coefficients:",
        ]
        for c, v, s in zip(a.columns, a.coefficients, a.standard_errors, strict=True):
            lines.append(f"    {c:<14}{v: .5g} ± {s:.2g}")
        return "\n".join(lines)



def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x
