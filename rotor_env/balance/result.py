"""The balancing result: JSON (stable keys), a text summary, figures and an HTML report."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..measurements.vectors import to_phase
from ..results import Result
from .correction import iso_grade, split_to_holes, weight_of
from .influence import InfluenceFit, t_quantile
from .profile import JointUnbalance

__all__ = ["BalanceResult"]

ANGLE_CONVENTION = {
    "lag": "degrees against the rotation from the keyphasor mark, like the phase lag (weights, unbalance, "
           "correction and phases alike)",
    "lead": "degrees in the direction of rotation from the keyphasor mark, like the phase lead (weights, "
            "unbalance, correction and phases alike)",
}
COVERS = ("95 % intervals (Student t, Welch-Satterthwaite degrees of freedom of the repeats' scatter) of the "
          "measurement noise shown by the "
          "repeats, propagated to first order; they do not cover a model that does not hold (see misfit), the "
          "placement of the weights, or a drift between runs that the repeats do not see")


def _amp_unit(unit: str) -> str:
    """The amplitude unit as the figures write it (``um`` -> ``µm``)."""
    return "µm" if unit == "um" else unit


def polar_ci(U: complex, var: float, tq: float, phase: str) -> tuple[float, float, float, float]:
    """Magnitude, angle (phase convention), and their 95 % half-widths for a circular complex estimate."""
    amp, ang = to_phase(np.array([U]), phase)
    se = math.sqrt(max(var, 0.0) / 2.0)  # circular: each component carries half the variance
    ci_amp = tq * se
    ci_deg = 180.0 if amp[0] <= ci_amp else math.degrees(math.asin(min(1.0, ci_amp / amp[0])))
    return float(amp[0]), float(np.mod(ang[0], 360.0)), ci_amp, ci_deg


def _interval_keys(amp: float, ang: float, iv: dict | None) -> dict:
    """The JSON keys of a profile interval: ranges, and symmetric half-widths that enclose them."""
    if iv is None:
        return {"ci95_g_mm": None, "ci95_deg": None, "ci95_g_mm_range": None, "ci95_deg_range": None}
    lo, hi = iv["g_mm"]
    below, above = iv["deg"]
    bounded = math.isfinite(hi)
    return {"ci95_g_mm": max(hi - amp, amp - lo) if bounded else None,
            "ci95_deg": min(180.0, max(below, above)),
            "ci95_g_mm_range": [lo, hi if bounded else None],
            "ci95_deg_range": [ang - below, ang + above]}


@dataclass
class BalanceResult(Result):
    """Everything a balancing campaign says (see :func:`rotor_env.balance.balance`)."""

    fit: InfluenceFit
    unbalance: dict[str, tuple[np.ndarray, np.ndarray]]  #: run -> (U (J,), complex covariance (J, J)), g·mm
    reference_unbalance: tuple[np.ndarray, np.ndarray]  #: from the fitted reference response
    residual: tuple[np.ndarray, np.ndarray]  #: predicted vibration after correction (S, P) and its variance
    influence_misfit: dict
    unbalance_misfit: dict
    visibility: list[dict]
    model_based: dict | None = None
    notes: list[str] = field(default_factory=list)
    joint: JointUnbalance | None = None  #: the joint likelihood whose maximum gave ``unbalance`` (profile.py)
    _profiles: dict = field(default_factory=dict, repr=False)

    @property
    def phase(self) -> str:
        return self.fit.phase

    @property
    def tq(self) -> float:
        return t_quantile(self.fit.dof)

    @property
    def intervals(self) -> bool:
        return self.fit.variance_source != "none"

    def correction_vectors(self) -> np.ndarray:
        return -self.reference_unbalance[0]

    def _t(self, dof) -> np.ndarray:
        """Student-t quantiles for degrees of freedom (array); the fit's own without repeats."""
        if self.fit.variance_source != "repeats":
            return np.full(np.shape(dof), self.tq)
        return np.vectorize(t_quantile)(np.asarray(dof, dtype=float))

    def profile_dof(self) -> np.ndarray:
        """Degrees of freedom (J,) of the reference unbalance's noise level (Welch-Satterthwaite).

        The joint likelihood weighs each probe by its noise level pooled over speeds and runs
        (``probe_dof`` each); the shares are the probes' first-order contributions to the
        unbalance's variance.
        """
        fit, joint = self.fit, self.joint
        if fit.variance_source != "repeats" or joint is None or joint.probe_dof is None:
            return np.full(len(fit.campaign.planes), float(fit.dof))
        S, P, J = fit.H.shape
        U0 = self.reference_unbalance[0]
        q = fit.noise_terms(fit.reference_combination(), U0)
        share = (np.abs(fit.G) ** 2 * q[None, :]).reshape(J, S, P).sum(axis=1)  # (J, P)
        den = np.sum(share ** 2 / joint.probe_dof[None, :], axis=1)
        return np.where(den > 0, share.sum(axis=1) ** 2 / np.where(den > 0, den, 1.0), float(fit.dof))

    def profile_interval(self, run: str, j: int) -> dict:
        """95 % profile-likelihood intervals of run ``run``'s total unbalance on plane ``j``.

        ``g_mm`` (lo, hi) and the angle's offsets below and above the estimate in the phase
        convention's degrees (180 where the angle is not bounded); ``None`` without intervals.
        """
        key = (run, j)
        if key not in self._profiles:
            if not self.intervals or self.joint is None:
                self._profiles[key] = None
            else:
                k = self.fit.data.runs.index(run)
                shift = complex(self.fit.W[k, j])
                crit = t_quantile(float(self.profile_dof()[j])) ** 2 / 2.0  # F(1, nu) on the deviance 2 dR
                # the first-order half-widths start the search (the profile is near them at high SNR)
                U, cov = self.unbalance[run]
                half = math.sqrt(2 * crit) * math.sqrt(max(float(np.real(cov[j, j])), 0.0) / 2)
                lo, hi = self.joint.magnitude_interval(j, shift, crit, guess=half)
                below, above = self.joint.angle_interval(j, shift, crit,
                                                         guess=min(math.pi / 2, half / max(abs(U[j]), 1e-300)))
                if self.phase == "lag":  # the lag angle runs the other way
                    below, above = above, below
                self._profiles[key] = {"g_mm": (lo, hi), "deg": (math.degrees(below), math.degrees(above))}
        return self._profiles[key]

    def _unb_dict(self, run: str, U) -> tuple[dict, dict]:
        """``unbalance`` (symmetric half-widths that enclose the intervals) and ``unbalance_ci95`` (the ranges)."""
        out, ranges = {}, {}
        for j, name in enumerate(self.fit.campaign.plane_names):
            amp, ang = to_phase(np.array([U[j]]), self.phase)
            a, g = float(amp[0]), float(np.mod(ang[0], 360.0))
            iv = _interval_keys(a, g, self.profile_interval(run, j))
            out[name] = {"g_mm": a, "angle_deg": g, "ci95_g_mm": iv["ci95_g_mm"], "ci95_deg": iv["ci95_deg"]}
            ranges[name] = {"g_mm": iv["ci95_g_mm_range"], "angle_deg": iv["ci95_deg_range"]}
        return out, ranges

    def to_dict(self) -> dict:
        fit, camp, data = self.fit, self.fit.campaign, self.fit.data
        S, P, J = fit.H.shape
        unit = data.amp_unit
        influence = []
        t_cell = self._t(fit.cell_dof) if fit.cell_dof is not None else np.full((S, P), self.tq)
        for s in range(S):
            for p in range(P):
                for j, plane in enumerate(camp.plane_names):
                    a, ang, ca, cd = polar_ci(fit.H[s, p, j], float(np.real(fit.cov_theta[s, p, 1 + j, 1 + j])),
                                               float(t_cell[s, p]), self.phase)
                    influence.append({"rpm": float(data.rpm[s]), "probe": data.probes[p], "plane": plane,
                                      "amp_per_g_mm": a, "angle_deg": ang,
                                      "ci95_amp_per_g_mm": ca if self.intervals else None,
                                      "ci95_deg": cd if self.intervals else None})
        runs = {}
        for run in data.runs:
            U, _ = self.unbalance[run]
            cells = [c for c in self.influence_misfit.get("cells", []) if c["run"] == run]
            one = self.unbalance_misfit.get("runs", {}).get(run, {})
            unbalance, ranges = self._unb_dict(run, U)
            runs[run] = {
                "reference": run == camp.reference,
                "trial": {pl: {"mass_g": m, "angle_deg": a} for pl, (m, a) in camp.weights.get(run, {}).items()},
                "unbalance": unbalance,
                "unbalance_ci95": ranges if self.intervals else None,
                "misfit": {"influence": cells, "one_unbalance": one,
                           "flagged": any(c["flagged"] for c in cells) or any(v["flagged"] for v in one.values())},
            }
        C = self.correction_vectors()
        Uref, covref = self.reference_unbalance
        correction = {}
        c0 = fit.reference_combination()
        t_ref = self._t(fit.unbalance_dof(c0, Uref))
        for j, pl in enumerate(camp.planes):
            m, ang = weight_of(C[j], pl.radius_mm, self.phase)
            # the correction is minus the reference's unbalance: the same intervals, turned by 180 deg
            iv = _interval_keys(abs(C[j]), ang, self.profile_interval(camp.reference, j))
            ci_mass = None if iv["ci95_g_mm"] is None else iv["ci95_g_mm"] / pl.radius_mm
            rng = iv["ci95_g_mm_range"]
            correction[pl.name] = {"mass_g": m, "angle_deg": ang, "g_mm": abs(C[j]),
                                   "ci95_mass_g": ci_mass,
                                   "ci95_mass_g_range": None if rng is None else
                                   [rng[0] / pl.radius_mm, None if rng[1] is None else rng[1] / pl.radius_mm],
                                   "ci95_deg": iv["ci95_deg"], "ci95_deg_range": iv["ci95_deg_range"],
                                   "radius_mm": pl.radius_mm,
                                   "holes": split_to_holes(m, ang, pl.holes, pl.first_hole_deg) if pl.holes else None}
        R, Rvar = self.residual
        X0 = fit.X0
        predicted = []
        t_res = self._t(fit.residual_dof(c0, Uref))
        for s in range(S):
            for p in range(P):
                a, ang, ca, _ = polar_ci(R[s, p], float(Rvar[s, p]), float(t_res[s, p]), self.phase)
                b, bang = to_phase(np.array([X0[s, p]]), self.phase)
                predicted.append({"rpm": float(data.rpm[s]), "probe": data.probes[p], "amp": a, "phase_deg": ang,
                                  "ci95_amp": ca if self.intervals else None, "before_amp": float(b[0]),
                                  "before_phase_deg": float(bang[0])})
        iso = None
        if camp.rotor_mass_kg is not None and camp.service_rpm is not None:
            before = float(np.sum(np.abs(Uref)))
            after = float(np.sum(t_ref * np.sqrt(np.real(np.diag(covref)) / 2))) if self.intervals else None
            iso = {"rotor_mass_kg": camp.rotor_mass_kg, "service_rpm": camp.service_rpm,
                   "before": iso_grade(before, camp.rotor_mass_kg, camp.service_rpm),
                   "after_ci95": iso_grade(after, camp.rotor_mass_kg, camp.service_rpm) if after is not None else None,
                   "note": "before: the reference's unbalance (sum over planes); after: the 95 % bound of what the "
                           "correction leaves (its uncertainty), if the model holds"}
        im, um = self.influence_misfit, self.unbalance_misfit
        trusted = not (im.get("flagged") or um.get("flagged"))
        return {
            "source": data.source,
            "runs_file": camp.source,
            "amplitude_unit": unit,
            "phase_convention": self.phase,
            "angle_convention": ANGLE_CONVENTION[self.phase],
            "planes": {p.name: {"radius_mm": p.radius_mm, "holes": p.holes, "first_hole_deg": p.first_hole_deg}
                       for p in camp.planes},
            "probes": list(data.probes),
            "speeds_rpm": [float(v) for v in data.rpm],
            "reference": camp.reference,
            "condition_number": fit.condition_number,
            "calibration_condition_number": fit.calibration_condition_number,
            "variance": {"source": fit.variance_source, "dof": fit.dof,
                         "reference_unbalance_dof": [float(v) for v in np.atleast_1d(fit.unbalance_dof(c0, Uref))]
                         if fit.variance_source == "repeats" else None},
            "intervals_cover": COVERS,
            "visibility": self.visibility,
            "influence": influence,
            "runs": runs,
            "correction": correction,
            "predicted_residual": predicted,
            "misfit": {"linear_model_trusted": trusted,
                       "influence": {k: v for k, v in im.items() if k != "cells"},
                       "one_unbalance": {k: v for k, v in um.items() if k != "runs"}},
            "iso_21940_11": iso,
            "model_based": self.model_based,
            "notes": list(self.notes) + list(data.notes),
        }

    def summary(self) -> str:
        d = self.to_dict()
        u = d["amplitude_unit"]
        lines = [f"balancing: {d['source']} ({len(d['speeds_rpm'])} speed(s), {len(d['probes'])} probe(s), "
                 f"{len(d['runs'])} runs, planes {', '.join(d['planes'])})",
                 f"condition number {d['condition_number']:.3g} (calibration design {d['calibration_condition_number']:.3g});"
                 f" scatter from {d['variance']['source']} ({d['variance']['dof']} dof)",
                 f"angles: {d['angle_convention']}"]
        for run, r in d["runs"].items():
            parts = []
            for pl, v in r["unbalance"].items():
                ci = f" ± {v['ci95_g_mm']:.3g} g·mm / ± {v['ci95_deg']:.2g} deg" if v["ci95_g_mm"] is not None else ""
                parts.append(f"{pl} {v['g_mm']:.4g} g·mm at {v['angle_deg']:.0f} deg{ci}")
            flag = "  << misfit" if r["misfit"]["flagged"] else ""
            lines.append(f"run {run}{' (reference)' if r['reference'] else ''}: unbalance " + "; ".join(parts) + flag)
        for pl, c in d["correction"].items():
            ci = f" (± {c['ci95_mass_g']:.3g} g, ± {c['ci95_deg']:.2g} deg)" if c["ci95_mass_g"] is not None else ""
            lines.append(f"correction {pl}: {c['mass_g']:.4g} g at {c['angle_deg']:.1f} deg, radius "
                         f"{c['radius_mm']:g} mm{ci}")
            for h in c["holes"] or []:
                lines.append(f"    hole {h['hole']} ({h['angle_deg']:.1f} deg): {h['mass_g']:.4g} g")
        before = max(p["before_amp"] for p in d["predicted_residual"])
        after = max(p["amp"] for p in d["predicted_residual"])
        lines.append(f"vibration: largest 1X {before:.4g} {u} before, {after:.4g} {u} predicted after correction")
        if d["iso_21940_11"]:
            iso = d["iso_21940_11"]
            after_txt = (f", after (95 % bound) {iso['after_ci95']['grade']} (G = {iso['after_ci95']['G_mm_per_s']:.3g})"
                         if iso["after_ci95"] else "")
            lines.append(f"ISO 21940-11: before {iso['before']['grade']} (G = {iso['before']['G_mm_per_s']:.3g} "
                         f"mm/s){after_txt}")
        m = d["misfit"]
        if m["linear_model_trusted"]:
            lines.append("misfit: none beyond the scatter (the linear influence model holds"
                         + ("" if m["influence"].get("testable") else "; " + m["influence"].get("reason", "")) + ")")
        else:
            lines.append("misfit: the linear influence model does NOT hold (do not trust the correction as it is)")
            for title, part, bad in (
                    ("runs the influence model X0 + H W does not explain (the response not proportional to the weight)", m["influence"],
                     m["influence"].get("flagged")),
                    ("no single unbalance explains every speed and probe of run(s) "
                     + ", ".join(m["one_unbalance"].get("flagged", [])), m["one_unbalance"],
                     m["one_unbalance"].get("flagged"))):
                if not bad:
                    continue
                lines.append(f"  {title}:")
                for ev in part.get("evidence", []):
                    lines.append(f"    - {ev['text']}")
                for e in part.get("explanations", []):
                    if e.get("testable"):
                        lines.append(f"    tried {e['explanation']}: "
                                     + ("removes it: " + e["meaning"] if e["removes_misfit"] else "does not remove it"))
                    else:
                        lines.append(f"    {e['explanation']}: not testable ({e['reason']})")
                if not part.get("explained_by"):
                    tried = [e for e in part.get("explanations", []) if e.get("testable")]
                    if not tried and part.get("explanations"):
                        lines.append("    no explanation could be tested (reasons above)")
                    else:
                        lines.append("    no explanation tried removes it" + (
                            ": a non-linear rotor (rub, clearance, loose part) is left" if part is m["influence"]
                            else ""))
        if d["model_based"] and "planes" in d["model_based"]:
            mb = d["model_based"]
            parts = "; ".join(f"{pl} {v['g_mm']:.4g} g·mm at {v['angle_deg']:.0f} deg (± {v['ci95_g_mm']:.3g} g·mm)"
                              for pl, v in mb["planes"].items())
            lines.append(f"model-based (one run-up of {mb['run']}, two disks, no trial weight): {parts}")
            if not mb["planes_separated"]:
                lines.append(f"  the run-up cannot decide {mb['cannot_decide']}")
        elif d["model_based"]:
            mb = d["model_based"]
            lines.append(f"model-based (one run-up of {mb['run']}, no trial weight): {mb['g_mm']:.4g} g·mm at "
                         f"{mb['angle_deg']:.0f} deg")
        lines += [f"note: {n}" for n in d["notes"]]
        return "\n".join(lines)

    # ---------------------------------------------------------------- figures
    def plot_polar(self, ax=None):
        """Polar plot: every run's mean vector per probe (first speed ... last), the influence
        of each plane's trial weight, and the predicted vibration after correction
        (:func:`rotor_env.plots.balance.plot_correction_polar`; ``ax``: one polar axes per probe)."""
        from ..plots.balance import plot_correction_polar

        fit, data = self.fit, self.fit.data
        s = int(np.argmax(np.abs(fit.X0).max(axis=1)))  # the speed of the largest reference vector
        arrows = {}
        for j, plane in enumerate(fit.campaign.plane_names):
            kk = int(np.argmax(np.abs(fit.W[:, j])))  # the run that carries this plane's trial weight
            arrows[plane] = (fit.X0[s], fit.X0[s] + fit.H[s, :, j] * fit.W[kk, j])
        return plot_correction_polar(data.probes, dict(zip(data.runs, data.Y, strict=True)), self.residual[0],
                                     arrows, arrow_rpm=float(data.rpm[s]), phase=self.phase,
                                     amp_unit=_amp_unit(data.amp_unit), ax=ax)

    def plot_bode(self, ax=None):
        """Bode-style: 1X amplitude and phase against speed, before and predicted after correction
        (:func:`rotor_env.plots.balance.plot_correction_bode`; ``ax``: a pair of axes)."""
        from ..plots.balance import plot_correction_bode

        fit, data = self.fit, self.fit.data
        R, Rvar = self.residual
        half = self.tq * np.sqrt(Rvar / 2) if self.intervals else None
        return plot_correction_bode(data.rpm, data.probes, fit.X0, R, half, phase=self.phase,
                                    amp_unit=_amp_unit(data.amp_unit), ax=ax)

    def figures(self) -> dict:
        return {"polar": self.plot_polar(), "bode": self.plot_bode()}

    def report(self, path, *, overwrite: bool = False):
        """A self-contained HTML report: summary, correction, misfit, figures."""
        from ..outputs import check_writable
        from ..pages import esc, figure_tags, write_page

        path = check_writable(path, overwrite=overwrite)  # before the figures are drawn
        imgs = figure_tags(self.figures(), heading=2)
        d = self.to_dict()
        def ci(c: dict) -> str:
            return "" if c["ci95_mass_g"] is None else f"± {c['ci95_mass_g']:.3g} g, ± {c['ci95_deg']:.0f} deg"

        rows = "".join(f"<tr><td>{esc(pl)}</td><td>{c['mass_g']:.4g}</td><td>{c['angle_deg']:.1f}</td>"
                       f"<td>{ci(c)}</td></tr>" for pl, c in d["correction"].items())
        trusted = d["misfit"]["linear_model_trusted"]
        verdict = "linear model holds" if trusted else "linear model does NOT hold: see the misfit"
        body = ("<h1>rotor-id balancing (influence coefficients)</h1>"
                f"<section class='verdict verdict-{'explained' if trusted else 'unexplained'}'><p><b>"
                f"{esc(verdict)}</b></p></section>"
                "<h2>Correction</h2><table><tr><th>plane</th><th>mass [g]</th>"
                f"<th>angle [deg, {esc(d['phase_convention'])}]</th><th>95 %</th></tr>{rows}</table>"
                f"<p>{esc(d['angle_convention'])}. {esc(COVERS)}.</p>"
                f"<h2>Summary</h2><pre>{esc(self.summary())}</pre>" + imgs)
        return write_page(path, "rotor-id: balancing", body, overwrite=overwrite)
