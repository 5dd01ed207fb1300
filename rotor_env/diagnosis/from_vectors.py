"""Diagnosis from order-tracked 1X vectors: compare, where it fails, what is missing.

The same loop as the waveform diagnosis, on the synchronous model of
:mod:`.synchronous`:

1. fit the start model (damping and unbalance; ``w_ref`` carries the stiffness);
2. the noise floor of the vectors from their row-to-row roughness: for independent
   complex noise of variance ``s^2`` per vector, the second difference across rows has
   ``E|d2|^2 = 6 s^2`` and ``median |d2|^2 = 6 s^2 ln 2``, taken band by band on the raw
   vectors and on the start model's residual (which follows the peak and the ripples
   after it), the bands where the response itself is rough left out by a robust fit of
   the noise's variance against speed (:func:`vector_noise_floor`);
3. each candidate that shows in 1X data (bow, support anisotropy, cross-coupled
   stiffness, probe runout) is fitted in turn; it is added when its parameters are
   significant by a HAC Wald test (the residuals of neighbouring rows are correlated:
   :mod:`identifier.hac`, scores summed per row), plausible (the effect's declared bounds),
   and it removes at least 10 % of the residual energy above the floor; the best one is
   added and the search repeats;
4. the verdict compares the final residual RMS with the floor (``explained`` within 1.5x).

Critical speeds (rpm) and damping ratios come from the fitted model's eigenvalues.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import nnls

from identifier.hac import hac_covariance, wald_test

from ..effects import get_effect
from ..measurements.vectors import SPEED_UNITS, VectorTable, VectorTableError, to_phase
from ..results import Result, jsonable
from .synchronous import RUNOUT, SECOND_MODE, SynchronousModel, VectorFit, fit_vectors
from .verdict import FLOOR_RATIO, verdict_of

__all__ = ["ABOVE_RUN", "VECTOR_CANDIDATES", "VECTOR_MODEL", "BackwardWhirlError", "VectorDiagnosis",
           "check_whirl_direction", "diagnose_vectors",
           "vector_noise_floor"]

VECTOR_MODEL: tuple[str, ...] = ("viscous_damping", "unbalance")
#: the candidates whose evidence is the 2X vectors (a crack turns the static deflection into a
#: 2X forcing, resonant at half the critical; a misaligned coupling forces 2X directly): tried
#: when the table has 2X columns and a time column
VECTOR_CANDIDATES_2X: tuple[str, ...] = ("asymmetry", "breathing_crack", "misalignment")
VECTOR_CANDIDATES: tuple[str, ...] = ("shaft_bow", RUNOUT, "support_anisotropy", "cross_coupled_stiffness",
                                       SECOND_MODE, *VECTOR_CANDIDATES_2X)
#: the side load a crack's 2X needs (gravity on a horizontal rotor): fitted with it
SIDE_LOAD = "static_load"
#: a candidate must remove this share of the residual energy above the floor
MIN_GAIN = 0.10
#: a crack's side load may deflect the shaft statically by at most this many times the largest 1X
#: amplitude (gravity sags of 100-620 um against 50-150 um peaks in the foreign simulator)
MAX_SAG_RATIO = 30.0
#: a crack named from a table explains 2X within this share of half its critical (the band's rows)
HALF_CRITICAL_BAND = 0.15
#: a candidate's fit gets this many evaluations of its residual at first (a true effect
#: converges within 15 on the package's tests): one that removes less than MIN_GAIN by then, or
#: cannot beat a candidate that explains the record already, is left there; another is fitted on
#: to convergence
SCREEN_ITERATIONS = 25
#: and be significant at this level (HAC Wald test), and stricter than alpha when alpha is loose
LOG10_P_MAX = -3.0
#: the effect one run's 1X vectors cannot tell from probe runout (:func:`_bow_or_runout`)
#: nor, below the critical, from a mode above the run (:func:`_bow_or_mode_above`)
BOW = "shaft_bow"
#: an added mode this far above the top speed is outside the run: only its quasi-static 1X shows
ABOVE_RUN = 1.2


def vector_noise_floor(table: VectorTable, bands: int = 8, residual: np.ndarray | None = None) -> float:
    """RMS of the noise per complex vector, from the rows' second differences (see module doc).

    The noise of a per-revolution vector grows along a run with the speed (a revolution
    holds fewer samples: with a fixed sample rate its variance is proportional to the
    speed; with a fixed number of samples a turn, constant), so its variance is taken as
    ``a + b W`` (``a, b >= 0``) fitted to robust levels of ``bands`` consecutive groups of
    rows, and the floor is the RMS of that over the rows.  A band's level is the median of
    its ``|d2|^2`` over ``6 ln 2``: it ignores what fills less than half of it.  Around a
    fast critical the response itself is rough from row to row (the peak, and the free
    whirl beating against 1X for many revolutions after it): those bands stand far above
    the others, and the band standing furthest above the fit (more than twice it) is left
    out, one at a time, while more than half are kept.  ``residual``: a fitted model's
    residual (rows, probes); its second differences carry the noise without the peak and
    the ripples the model follows, and each band's level is the lower of the two.
    """
    series = [table.vectors[1]] + ([] if residual is None else [np.asarray(residual)])
    speed = np.asarray(table.speed, dtype=float)[1:-1]
    p2s = []
    for Y in series:
        d2 = Y[2:] - 2 * Y[1:-1] + Y[:-2]
        p2s.append((np.abs(d2) ** 2).reshape(len(d2), -1))
    ok = np.logical_and.reduce([np.isfinite(p).all(axis=1) for p in p2s])
    p2s = [p[ok] for p in p2s]
    speed = speed[ok]
    if speed.size == 0:
        return float("nan")
    n_b = max(1, min(bands, len(speed) // 20))
    groups = np.array_split(np.arange(len(speed)), n_b)
    level = np.min([[np.median(p[g]) for g in groups] for p in p2s], axis=0) / (6.0 * math.log(2.0))
    if n_b < 3:
        return float(math.sqrt(np.mean(np.concatenate([np.full(len(g), lv) for g, lv in zip(groups, level, strict=True)]))))
    s_ref = float(np.max(np.abs(speed)))
    x = np.array([np.mean(np.abs(speed[g])) for g in groups]) / s_ref
    keep = np.ones(n_b, dtype=bool)
    while True:
        tiny = 1e-300 + 1e-12 * level[keep].max()
        A = np.column_stack([np.ones(keep.sum()), x[keep]]) / np.maximum(level[keep], tiny)[:, None]
        coef, _ = nnls(A, np.ones(keep.sum()))
        fit = coef[0] + coef[1] * x
        ratio = np.where(keep, level / np.maximum(fit, tiny), -np.inf)
        worst = int(np.argmax(ratio))
        if ratio[worst] <= 2.0 or keep.sum() - 1 <= n_b // 2:
            break
        keep[worst] = False
    all_speed = np.abs(np.asarray(table.speed, dtype=float)) / s_ref
    return float(math.sqrt(max(coef[0] + coef[1] * float(np.mean(all_speed)), 0.0)))


#: share of the speeds (with a clear 1X) at which a backward 1X whirl means wrong probe angles
BACKWARD_SHARE = 0.7
#: the whirl's direction is read less the slow-roll vector where the run's slowest speed is
#: at most this share of its fastest (below it the shaft's response is its runout and bow)
SLOW_ROLL_SHARE = 0.4


class BackwardWhirlError(VectorTableError):
    """The 1X whirl turns backward at most speeds (:func:`check_whirl_direction`); ``share``:
    at which share of the speeds read."""

    def __init__(self, message: str, share: float):
        super().__init__(message)
        self.share = share


def check_whirl_direction(table: VectorTable, floor: float) -> None:
    """Refuse probe angles (or a rotation direction) under which the 1X whirl turns backward.

    An unbalance drives a forward whirl; a support anisotropy turns it backward only
    between its two criticals.  With the probes' angles the 1X orbit's forward and
    backward parts are ``(Q_u + i Q_v) / 2`` and ``(conj Q_u + i conj Q_v) / 2``; when the
    backward part dominates at most speeds the angles are swapped or mirrored.

    The direction is read on the response, less the slow-roll vector (the median 1X of the
    speeds within 15 % of the slowest, where that is at most :data:`SLOW_ROLL_SHARE` of the
    fastest): each probe's track runout is a 1X vector of its own, no whirl at all, and on
    a healthy rotor with 3-8 um of it on 0.5 um probes it dominated 70 % of a foreign run's
    speeds and read as a backward whirl (the record was refused).
    """
    if table.angles is None or len(table.probes) < 2:
        return
    from .synchronous import vector_probe_matrix

    P = vector_probe_matrix(table)
    Y = table.vectors[1]
    ok = np.isfinite(Y).all(axis=1)
    speed = np.abs(np.asarray(table.speed, dtype=float))[ok]
    Y = Y[ok]
    if len(speed) and speed.min() <= SLOW_ROLL_SHARE * speed.max():
        slow = speed <= 1.15 * speed.min()
        Y = Y - (np.median(Y[slow].real, axis=0) + 1j * np.median(Y[slow].imag, axis=0))
    Q = np.linalg.lstsq(P, Y.T, rcond=None)[0]  # (2, rows): Q_u, Q_v
    fwd = np.abs(Q[0] + 1j * Q[1]) / 2
    bwd = np.abs(np.conj(Q[0]) + 1j * np.conj(Q[1])) / 2
    clear = (fwd + bwd) > 3 * max(floor, 1e-300)
    if clear.sum() < 5:
        return
    share = float(np.mean(bwd[clear] > fwd[clear]))
    if share > BACKWARD_SHARE:
        deg = ", ".join(f"{p} {math.degrees(a):g}" for p, a in zip(table.probes, table.angles, strict=True))
        raise BackwardWhirlError(
            f"{table.source}: with the probes' mounting angles ({deg} deg) the 1X whirl turns backward at "
            f"{100 * share:.0f} % of the speeds, where an unbalance drives a forward whirl: the angles (rig key "
            "'probes') are swapped or mirrored, or measured against the rotation; angles are counted from the "
            "reference in the direction of rotation.  Where the angles are right, a backward 1X forcing dominates "
            "the record, which this diagnosis does not read: a cracked shaft whose static deflection under its "
            "load is many times its unbalance drives one (a foreign coast-down, sag 276 um against 3.4 um of "
            "unbalance: backward at 87 % of the speeds)", share)


def _time_major(fit: VectorFit) -> tuple[np.ndarray, np.ndarray, int]:
    """Jacobian and residual reordered row by row (re, im of each probe), rows per speed."""
    valid = np.isfinite(fit.measured)
    n = int(valid.sum())
    r = fit.residual[valid]
    order = np.empty(2 * n, dtype=int)
    order[0::2] = np.arange(n)
    order[1::2] = np.arange(n) + n
    resid = np.concatenate([r.real, r.imag])[order]
    J = fit.jacobian[order]
    per = 2 * valid.shape[1] if valid.all() else 2
    return J, resid, per


def _wald(fit: VectorFit, effect: str) -> tuple[float, float]:
    """HAC Wald test that the effect's parameters are at their null (zero)."""
    J, resid, per = _time_major(fit)
    idx = [i for i, nm in enumerate(fit.param_names) if nm.startswith(f"{effect}[")]
    if not idx:
        return float("nan"), 0.0
    cov = hac_covariance(J, resid, rows_per_time=per)
    return wald_test(fit.params[idx], cov[np.ix_(idx, idx)])


def _plausible(fit: VectorFit, effect: str, before: VectorFit | None = None, *,
               above_run: bool = False) -> tuple[bool, str]:
    """Whether ``fit`` (``before`` with ``effect`` added) is physically plausible.

    ``above_run``: a second mode above the run is plausible too (:func:`_bow_or_mode_above`)."""
    if effect == RUNOUT:
        return True, ""
    if effect == SECOND_MODE:
        (w2, c2), = fit.extra_modes[-1:]
        lo, hi = float(fit.table.speed.min()), float(fit.table.speed.max())
        if not 0.5 * lo <= w2 <= (math.inf if above_run else ABOVE_RUN * hi):
            return False, f"its natural frequency {w2 / SPEED_UNITS['rpm']:.0f} rpm lies outside the run"
        if abs(w2 / fit.w_ref - 1.0) < 0.05:
            return False, "it sits on the first mode (a split or a skewed peak, not another mode)"
        if before is not None and (not 0.5 * lo <= fit.w_ref <= 1.2 * hi
                                   or abs(fit.w_ref / before.w_ref - 1.0) > 0.25):
            # the added mode took the first one's resonance and the first ran off (to a static
            # compliance far outside the run): a split or skewed peak, not another mode
            return False, (f"it takes the first mode's place (the first mode moves from "
                           f"{before.w_ref / SPEED_UNITS['rpm']:.0f} to {fit.w_ref / SPEED_UNITS['rpm']:.0f} rpm): "
                           "a split or a skewed peak, not another mode")
        if c2 > 0.6:
            return False, f"damping ratio {c2 / 2:.2f} above 0.3: not a resonance"
        return True, ""
    values = fit.values()[effect]
    if SIDE_LOAD in fit.forcing and get_effect(effect).crack and effect != SIDE_LOAD:
        # a crack's 2X is its size times the static deflection under the side load fitted with
        # it: a tiny crack under an enormous load is a 2X forcing (a misalignment's) in disguise
        sag = float(np.hypot(*fit.forcing[SIDE_LOAD][:2]))
        peak = float(np.nanmax(np.abs(fit.table.vectors[1])))
        if peak > 0 and sag > MAX_SAG_RATIO * peak:
            return False, (f"its side load's static deflection {sag:.3g} {fit.table.amp_unit} is {sag / peak:.0f}x the "
                           f"largest 1X amplitude (a rotor's sag is within {MAX_SAG_RATIO:g}x): a 2X forcing read as a "
                           "crack times an impossible load")
    for p in get_effect(effect).parameters:
        if p.name not in values or fit.model.kinds[effect] == "forcing":
            continue  # forcing amplitudes are in the table's unit: no dimensionless bound applies
        v = values[p.name]
        if not (p.lower <= v <= p.upper):
            return False, f"{p.name} = {v:.4g} outside its plausible range [{p.lower:g}, {p.upper:g}] ({p.bounds_reason})"
    return True, ""


@dataclass
class VectorDiagnosis(Result):
    """What a vector table says: the fits before and after, criticals, the verdict."""

    table: VectorTable
    before: VectorFit
    after: VectorFit
    missing: list[str]
    noise_floor: float
    tested: list[dict] = field(default_factory=list)
    rejected: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    phase: str = "lag"
    #: effects these vectors cannot tell from another term of the model (a shaft bow from
    #: probe runout: :func:`_bow_or_runout`), with the sentence that says why
    undecidable: dict[str, str] = field(default_factory=dict)

    @property
    def verdict(self) -> str:
        return verdict_of(bool(self.missing), self.after.rms / self.noise_floor if self.noise_floor > 0 else math.inf)

    def natural_frequency_se(self) -> float | None:
        """HAC standard error of the natural frequency (rpm), from the fit's sandwich covariance."""
        J, resid, per = _time_major(self.after)
        try:
            cov = hac_covariance(J, resid, rows_per_time=per)
        except (np.linalg.LinAlgError, ValueError):
            return None
        var = float(cov[0, 0])
        return float(math.sqrt(var) * self.after.w_ref / SPEED_UNITS["rpm"]) if var >= 0 else None

    def unbalance(self, mass_kg: float | None = None) -> dict | None:
        """The identified unbalance: eccentricity in the table's unit and its angle.

        In the translation (Jeffcott) model the unbalance coefficient is the mass
        eccentricity ``e`` itself (``e`` times the speed squared drives the whirl), in the
        displacement unit of the vectors; its angle is where the heavy spot sits, counted
        like a ``lag`` phase from the keyphasor.  With the disk's mass, ``U = m e`` in g·mm.
        Without the probes' angles the first probe's view is reported.
        """
        c = self.after.forcing.get("unbalance")
        if c is None:
            return None
        e = complex(c[0], c[1])
        out = {"eccentricity": abs(e), "angle_deg_lag": float(np.mod(-np.degrees(np.angle(e)), 360.0)),
               "g_mm": None}
        if mass_kg is not None and self.table.amp_unit in ("um", "mil", "mm", "m"):
            from ..measurements.vectors import AMPLITUDE_UNITS

            out["g_mm"] = mass_kg * 1e3 * abs(e) * AMPLITUDE_UNITS[self.table.amp_unit] * 1e3
        return out

    def unexplained_bands(self) -> list[dict]:
        """Speed bands (rpm) where the final residual is above 1.5x the floor."""
        mag = np.sqrt(np.nanmean(np.abs(self.after.residual) ** 2, axis=1))
        bad = mag > FLOOR_RATIO * self.noise_floor * 2.0
        rpm = self.table.rpm
        out, k = [], 0
        while k < len(bad):
            if bad[k]:
                j = k
                while j + 1 < len(bad) and bad[j + 1]:
                    j += 1
                out.append({"rpm_from": float(min(rpm[k], rpm[j])), "rpm_to": float(max(rpm[k], rpm[j])),
                            "rms": float(np.sqrt(np.mean(mag[k : j + 1] ** 2)))})
                k = j + 1
            else:
                k += 1
        return sorted(out, key=lambda d: -d["rms"])[:5]

    def to_dict(self) -> dict:
        ratio = self.after.rms / self.noise_floor if self.noise_floor > 0 else None
        return {
            "source": self.table.source,
            "kind": "vectors",
            "amplitude_unit": self.table.amp_unit,
            "probes": list(self.table.probes),
            "method": self.after.method,
            "start_model": list(self.before.model.names),
            "model": list(self.after.model.names),
            "missing": list(self.missing),
            "verdict": self.verdict,
            "criticals": [{"rpm": c["rpm"], "damping_ratio": c["damping_ratio"]} for c in self.after.criticals],
            "criticals_before": [{"rpm": c["rpm"], "damping_ratio": c["damping_ratio"]}
                                 for c in self.before.criticals],
            "rms_before": self.before.rms,
            "rms_after": self.after.rms,
            "noise_floor": self.noise_floor,
            "rms_ratio_before": self.before.rms / self.noise_floor if self.noise_floor > 0 else None,
            "rms_ratio_after": ratio,
            "natural_frequency_rpm": self.after.w_ref / SPEED_UNITS["rpm"],
            "natural_frequency_rpm_standard_error": self.natural_frequency_se(),
            "physical": jsonable(self.after.values()),
            "candidates": self.tested,
            "rejected": self.rejected,
            "unbalance": self.unbalance(),
            "unexplained": self.unexplained_bands() if self.verdict in ("partly_explained", "unexplained") else [],
            "notes": list(self.notes),
            "undecidable": dict(self.undecidable),
            "standard_errors_kind": "HAC (Newey-West, Bartlett kernel, Andrews bandwidth), scores summed per row",
        }

    def summary(self) -> str:
        d = self.to_dict()
        u = self.table.amp_unit
        lines = [f"order-tracked vectors: {self.table.source} ({len(self.table.speed)} speeds, "
                 f"{len(self.table.probes)} probe(s), {self.after.method} model)"]
        for c in d["criticals"]:
            lines.append(f"critical speed {c['rpm']:.1f} rpm, damping ratio {c['damping_ratio']:.4f}")
        lines.append(f"start model ({', '.join(self.before.model.names)}): residual RMS {self.before.rms:.4g} {u} "
                     f"({_times(d['rms_ratio_before'])} the noise floor {self.noise_floor:.3g} {u})")
        for m in self.missing:
            lines.append(f"+ {m}: {_cause(m)}")
        lines.append(f"final model ({', '.join(self.after.model.names)}): residual RMS {self.after.rms:.4g} {u} "
                     f"({_times(d['rms_ratio_after'])} the floor)")
        lines.append(f"verdict: {self.verdict}")
        for b in d["unexplained"]:
            lines.append(f"  not explained at {b['rpm_from']:.0f}-{b['rpm_to']:.0f} rpm (RMS {b['rms']:.3g} {u})")
        for r in self.rejected:
            lines.append(f"  rejected {r['effect']}: {r['rule']}")
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)

    # ---------------------------------------------------------------- figures
    def bode_data(self) -> tuple[np.ndarray, dict, dict]:
        """rpm, measured vectors per probe, model vectors (before/after) per probe."""
        meas = {p: self.table.vectors[1][:, j] for j, p in enumerate(self.table.probes)}
        models = {"before": {p: self.before.predicted[:, j] for j, p in enumerate(self.table.probes)},
                  "after": {p: self.after.predicted[:, j] for j, p in enumerate(self.table.probes)}}
        return self.table.rpm, meas, models


    def plot_bode(self, ax=None):
        """Bode plot: measured 1X vectors and the start and final models, per probe."""
        from ..plots import plot_bode

        rpm, meas, models = self.bode_data()
        return plot_bode(rpm, meas, models, speed_unit="rpm", amp_unit=_unit_label(self.table.amp_unit),
                         phase=self.phase, ax=ax)

    def plot_polar(self, ax=None):
        """Polar plot of the same vectors."""
        from ..plots import plot_polar

        rpm, meas, models = self.bode_data()
        return plot_polar(rpm, meas, models, speed_unit="rpm", amp_unit=_unit_label(self.table.amp_unit),
                          phase=self.phase, ax=ax)

    def plot_residual(self, ax=None):
        """|measured - model| against speed, before and after, with the noise floor."""
        from ..plots.diagnosis import plot_residual_by_speed

        rpm = self.table.rpm
        curves = {f"{label} ({', '.join(fit.model.names)})": (rpm, np.sqrt(np.nanmean(np.abs(fit.residual) ** 2, axis=1)))
                  for fit, label in ((self.before, "start model"), (self.after, "final model"))}
        return plot_residual_by_speed(curves, self.noise_floor, quantity="1X residual RMS",
                                      amp_unit=_unit_label(self.table.amp_unit), speed_label="speed [rpm]",
                                      floor_ratio=FLOOR_RATIO, marks=[c["rpm"] for c in self.after.criticals],
                                      title="where the model fails: 1X residual against speed (grey: criticals)",
                                      ax=ax)

    def plot_campbell(self, ax=None):
        """Whirl frequencies of the final model against speed, the 1x line and the criticals."""
        from ..plots import plot_campbell
        from .synchronous import whirl_modes

        rpm = np.linspace(0.0, float(self.table.rpm.max()) * 1.1, 120)
        coef = self.after.coef()
        w_ref = self.after.w_ref
        branches: dict[str, list[float]] = {"forward whirl": [], "backward whirl": []}
        for r in rpm:
            lam, share = whirl_modes(self.after.model, coef, r * SPEED_UNITS["rpm"] / w_ref)
            hz = np.abs(lam.imag) * w_ref / (2 * math.pi)
            branches["forward whirl"].append(float(hz[share >= 0.5].min()) if (share >= 0.5).any() else np.nan)
            # backward whirl frequencies are negative (the plot's convention)
            branches["backward whirl"].append(-float(hz[share < 0.5].min()) if (share < 0.5).any() else np.nan)
        return plot_campbell(rpm, {k: np.array(v) for k, v in branches.items()}, speed_unit="rpm", ax=ax)

    def figures(self) -> dict[str, object]:
        out = {"bode": self.plot_bode(), "polar": self.plot_polar(), "residual": self.plot_residual()}
        try:
            out["campbell"] = self.plot_campbell()
        except (ValueError, TypeError):  # a plot helper's contract changed: the report goes on without it
            pass
        return out

    def save_figures(self, folder, *, overwrite: bool = True) -> list:
        """Every figure as ``folder/<name>.png``."""
        from pathlib import Path

        import matplotlib.pyplot as plt

        from ..outputs import atomic_write

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for name, fig in self.figures().items():
            paths.append(atomic_write(folder / f"{name}.png",
                                      lambda p, fig=fig: fig.savefig(p, format="png", dpi=110, bbox_inches="tight"),
                                      overwrite=overwrite))
            plt.close(fig)
        return paths

    def report(self, path, *, overwrite: bool = False):
        """A self-contained HTML report: verdict, criticals, Bode, polar, residual, Campbell."""
        from ..outputs import check_writable
        from ..pages import write_page

        path = check_writable(path, overwrite=overwrite)
        return write_page(path, "rotor-id: 1X vectors",
                          "<h1>rotor-id diagnosis of order-tracked vectors</h1>" + self.html_section(),
                          overwrite=overwrite)

    def html_section(self, level: int = 2) -> str:
        """The vectors' verdict, criticals and figures as an HTML fragment."""
        from ..pages import esc, figure_tags

        imgs = figure_tags(self.figures(), heading=level + 1)
        d = self.to_dict()
        crit = "".join(f"<tr><td>{c['rpm']:.1f}</td><td>{c['damping_ratio']:.4f}</td></tr>" for c in d["criticals"])
        unb = d.get("unbalance")
        unb_html = ""
        if unb:
            unb_html = (f"<p>Unbalance: eccentricity {unb['eccentricity']:.4g} {esc(d['amplitude_unit'])} at "
                        f"{unb['angle_deg_lag']:.0f} deg (lag from the keyphasor)"
                        + (f", {unb['g_mm']:.4g} g·mm" if unb.get("g_mm") is not None else "") + ".</p>")
        return (f"<section class='verdict verdict-{esc(self.verdict)}'><p><b>1X vectors: "
                f"{esc(self.verdict)}</b></p><pre>{esc(self.summary())}</pre></section>"
                f"<h{level}>Critical speeds</h{level}><table><tr><th>rpm</th><th>damping ratio</th></tr>{crit}</table>"
                + unb_html + imgs)


def _unit_label(unit: str) -> str:
    return "µm" if unit == "um" else unit


def _times(ratio: float | None) -> str:
    """``3.2x`` of a ratio to the noise floor; a floor of zero (noise-free data) has none."""
    return f"{ratio:.3g}x" if ratio is not None else "no ratio to"


def _cause(name: str) -> str:
    if name == SECOND_MODE:
        return ("a second mode of the rotor and its supports (another critical speed) in the run: the rotor "
                "model's single mode cannot carry it")
    if name == RUNOUT:
        return "probe runout: a constant 1X vector (mechanical/electrical runout of the probe track), seen at slow roll"
    return get_effect(name).cause


def diagnose_vectors(
    table: VectorTable,
    *,
    ip: float = 0.0,
    model: Sequence[str] = VECTOR_MODEL,
    candidates: Sequence[str] = VECTOR_CANDIDATES,
    alpha: float = 0.05,
    method: str = "auto",
    max_added: int = 3,
    phase: str = "lag",
    check_direction: bool = True,
) -> VectorDiagnosis:
    """Fit ``model`` to the table's 1X vectors and add the missing effects one by one;
    ``check_direction``: refuse a backward whirl first (:func:`check_whirl_direction`)."""
    if check_direction:
        check_whirl_direction(table, vector_noise_floor(table))
    base_effects = tuple(e for e in model if e != RUNOUT)
    start_model = SynchronousModel(base_effects, ip=ip, runout=RUNOUT in model)
    before = fit_vectors(table, start_model, method=method)
    # the start model follows the peak and the ripples: its residual's roughness is the noise's
    floor = vector_noise_floor(table, residual=before.residual)
    probe_floor = floor
    if table.phase_error_rad > 0:
        # the tracker's angle error moves every vector by |X| times it, smoothly from row to row
        # (the roughness misses it): a floor of its own, in quadrature
        Y = table.vectors[1]
        floor = math.hypot(floor, table.phase_error_rad * float(np.sqrt(np.nanmean(np.abs(Y) ** 2))))
    notes = list(table.notes)
    if before.method == "transient":
        notes.append("transient model: the run simulated along the table's speed profile and order-tracked per "
                     "revolution (the quasi-steady response differs by more than 1 % of the peak at this sweep rate)")
    elif table.t is not None:
        notes.append("quasi-steady model: within 1 % of the transient one at this sweep rate")
    current, missing, tested, rejected = before, [], [], []
    log10_alpha = min(math.log10(alpha), LOG10_P_MAX)
    remaining = [c for c in candidates if c not in current.model.names]
    if 2 not in before.orders:
        skip = [c for c in remaining if c in VECTOR_CANDIDATES_2X]
        if skip:
            notes.append(f"no 2X vectors (or no time column, or several probes without their angles): "
                         f"{', '.join(skip)} not tested")
            remaining = [c for c in remaining if c not in skip]
    if table.angles is None and len(table.probes) > 1:
        # runout and a second mode are the vector model's own terms, not registered effects
        skip = [c for c in remaining if c not in (RUNOUT, SECOND_MODE) and get_effect(c).name in ("support_anisotropy",)]
        if skip:
            notes.append(f"probe angles unknown (no rig description): {', '.join(skip)} not tested; give --rig")
            remaining = [c for c in remaining if c not in skip]
    undecidable: dict[str, str] = {}
    while remaining and len(missing) < max_added:
        if current.rms <= FLOOR_RATIO * floor:
            break
        excess = current.rms ** 2 - floor ** 2
        best = None
        round_fits: dict[str, VectorFit] = {}
        accepted: dict[str, VectorFit] = {}
        mode_above: VectorFit | None = None
        best_misfit = math.inf
        for cand in remaining:
            trial = current.model.with_effect(cand)
            if cand != RUNOUT and cand != SECOND_MODE and trial.kinds.get(cand) == "rotating" \
                    and SIDE_LOAD not in trial.effects:
                trial = trial.with_effect(SIDE_LOAD)  # its 2X is the side load's static deflection, turned
            is_crack = cand not in (RUNOUT, SECOND_MODE) and get_effect(cand).crack
            screen_rule = None  # the 2X rule read on the screened fit, where it was
            try:
                fit = fit_vectors(table, trial, method=current.method, start=current,
                                  max_iterations=SCREEN_ITERATIONS)
                gain = (current.rms ** 2 - fit.rms ** 2) / excess if excess > 0 else 0.0
                # it could still matter if it removes enough and could beat the best so far: that
                # one is above the floor, or this one is the simpler (a tie goes to the simpler)
                could_matter = gain >= MIN_GAIN and (
                    best is None or best[1].rms > FLOOR_RATIO * floor
                    or len(fit.param_names) < len(best[1].param_names))
                if could_matter and not fit.success and is_crack:
                    # a crack that does not take the 2X at half its critical after the first
                    # iterations is not fitted on (it wanders over a rub's table for minutes)
                    screen_rule = _crack_without_its_2x(fit, current, cand, floor)
                    could_matter = screen_rule is None
                stopped = not fit.success and not could_matter
                if not fit.success and not stopped:
                    # promising but not converged: fitted on to convergence from where it stopped
                    fit = fit_vectors(table, trial, method=current.method, start=fit)
            except (ValueError, FloatingPointError) as exc:
                rejected.append({"effect": cand, "rule": f"cannot be fitted: {exc}"})
                continue
            round_fits[cand] = fit
            F, log10_p = _wald(fit, cand)
            gain = (current.rms ** 2 - fit.rms ** 2) / excess if excess > 0 else 0.0
            if stopped:
                # a candidate that, in the many iterations a true effect converges within,
                # removes less than the share asked of it: its fit is left there (a breathing
                # crack wandering over a bow's table for 160 s before; the waveforms decide)
                tested.append({"effect": cand, "F": F, "log10_p": log10_p, "rms": fit.rms, "gain": gain,
                               "plausible": False})
                explained_by = best is not None and best[1].rms <= FLOOR_RATIO * floor
                why = (f"removes only {100 * gain:.1f} % of the residual energy above the floor" if gain < MIN_GAIN
                       else f"cannot come near {best[0]}, which explains the record" if explained_by
                       else screen_rule)
                if is_crack and gain >= MIN_GAIN and not explained_by:
                    undecidable[cand] = f"{cand}: {why}"
                rejected.append({"effect": cand, "rule": f"{why} after {SCREEN_ITERATIONS} iterations (not converged)"})
                continue
            ok, why = _plausible(fit, cand, current)
            if (cand == SECOND_MODE and not ok and log10_p <= log10_alpha
                    and _plausible(fit, cand, current, above_run=True)[0]):
                mode_above = fit  # what a bow is weighed against (:func:`_bow_or_mode_above`)
            entry = {"effect": cand, "F": F, "log10_p": log10_p, "rms": fit.rms, "gain": gain,
                     "plausible": ok}
            tested.append(entry)
            if log10_p > log10_alpha:
                rule = f"not significant (HAC Wald log10 p = {log10_p:.3g})"
            elif gain < MIN_GAIN:
                rule = f"removes only {100 * gain:.1f} % of the residual energy above the floor"
            elif not ok:
                rule = f"implausible: {why}"
            else:
                rule = None
            if rule is None and is_crack:
                rule = _crack_without_its_2x(fit, current, cand, floor)
                if rule is not None:
                    undecidable[cand] = f"{cand}: {rule}"
            if rule is not None:
                rejected.append({"effect": cand, "rule": rule})
                continue
            accepted[cand] = fit
            # ranked by the misfit with the keyphasor angle's smooth error as what it is (_misfit)
            misfit = _misfit(fit, floor, probe_floor)
            if best is None or misfit < best_misfit:
                best, best_misfit = (cand, fit), misfit
        if best is None:
            break
        best = _simplest_within_noise(best, accepted, floor, probe_floor)
        best, why = _bow_or_runout(best, round_fits, floor, table.amp_unit, probe_floor)
        if best[0] in (BOW, RUNOUT) and mode_above is not None:
            named = best[0]
            best, said = _bow_or_mode_above(best, mode_above, floor, probe_floor)
            if said:
                notes.append(said)
                if named == BOW:
                    why = said
                    remaining = [c for c in remaining if c != BOW]
                else:
                    why = ""  # the bow-or-runout sentence was about a runout no longer read
        if why:
            undecidable[BOW] = why
            if why not in notes:
                notes.append(why)
        missing.append(best[0])
        current = best[1]
        remaining = [c for c in remaining if c != best[0]]
        # every remaining effect is tried again in the next round: only the last round's
        # reasons stand (they were listed once per round before)
        rejected = []
    if not current.criticals:
        notes.append(f"no critical speed within the run ({table.rpm.min():.0f}-{table.rpm.max():.0f} rpm): the "
                     f"natural frequency ({current.w_ref / SPEED_UNITS['rpm']:.0f} rpm) is extrapolated; see its "
                     "standard error")
    if current.rms > FLOOR_RATIO * floor:
        notes.append("what is left may act in the rotating frame (a crack: asymmetry, breathing) or be non-linear "
                     "(a rub, dry friction): the 1X vectors cannot carry those; diagnose the waveforms (--rig)")
    amp, _ = to_phase(table.vectors[1], phase)
    if floor > 0 and np.nanmax(amp) < 3 * floor:
        notes.append("the 1X amplitude hardly rises above the noise: the critical is not excited in this run")
    if floor > probe_floor * 1.01:
        notes.append(f"noise floor {floor:.3g} {table.amp_unit}: the probes' {probe_floor:.3g} and the keyphasor "
                     f"angle's error ({math.degrees(table.phase_error_rad):.2g} deg RMS, from the pulses' timing "
                     "jitter) times the 1X amplitude")
    return VectorDiagnosis(table, before, current, missing, floor, tested, rejected, notes, phase,
                           {e: t for e, t in undecidable.items() if e not in missing})


def _crack_without_its_2x(fit: VectorFit, without: VectorFit, crack: str, floor: float) -> str | None:
    """The crack-or-rub rule of a table: ``None`` where a crack fitted to it explains 2X at
    half its critical, else why it is not named.

    A shaft whose stiffness turns with it makes the static deflection under a side load a 2X
    forcing, which resonates where twice the speed meets the critical: the field engineer's
    crack test, and what nothing else in the library does (a misalignment's 2X is its own
    forcing, tried beside it; a rub's harmonics come with the large orbit at the critical, where
    its contact acts).  Elsewhere a crack on a table has only the 1X at the critical, which a
    rub's contact changes too: there, with its axis and breathing free, a breathing crack took
    each of the rig suite's rubs on 1X/2X tables (and none of the waveforms' rubs, whose own
    model is tried).  So a crack is named from a table only where its 2X in the band of rows
    within 15 % of half its critical takes more residual energy than noise would, by a
    likelihood ratio beyond the 99 % point of a chi-square with the crack's coefficients.
    Otherwise the table cannot decide; the waveforms can."""
    from scipy.stats import chi2

    crits = fit.criticals
    if 2 not in fit.orders or 2 not in without.orders or not crits or not floor > 0:
        return "no 2X vectors to read a crack's 2X from (the waveforms decide)"
    half = 0.5 * crits[0]["rpm"] * SPEED_UNITS["rpm"]
    rows = np.abs(fit.table.speed - half) <= HALF_CRITICAL_BAND * half
    if rows.sum() < 3:
        return (f"the run does not pass half its critical ({half / SPEED_UNITS['rpm']:.0f} rpm), where a crack's 2X "
                "resonates: these vectors cannot tell a crack from a rub's contact at the critical (the waveforms decide)")
    n_p = len(fit.table.probes)
    k = fit.orders.index(2)
    cols = slice(k * n_p, (k + 1) * n_p)
    rss = [float(np.nansum(np.abs(f.residual[rows][:, cols]) ** 2)) for f in (without, fit)]
    lr = 2.0 * (rss[0] - rss[1]) / floor ** 2
    n_coef = sum(1 for nm in fit.param_names if nm.startswith(f"{crack}["))
    if lr > chi2.ppf(0.99, max(n_coef, 1)):
        return None
    return (f"no 2X resonance at half its critical ({half / SPEED_UNITS['rpm']:.0f} rpm: the crack takes "
            f"{max(lr, 0.0):.3g} noise variances of the 2X there, under the 99 % point "
            f"{chi2.ppf(0.99, max(n_coef, 1)):.3g}): its 1X at the critical alone is what a rub's contact also makes; "
            "these vectors cannot decide it (the waveforms can)")


def _simplest_within_noise(best: tuple[str, VectorFit], accepted: dict[str, VectorFit],
                           floor: float, probe_floor: float | None = None) -> tuple[str, VectorFit]:
    """Of the candidates that passed every rule, the one with fewest parameters whose fit the
    best one's does not beat by more than noise: a likelihood-ratio test at 1 % with the extra
    parameters' degrees of freedom, the residual in noise variances per real component (:func:`_misfit`).
    An open crack is a breathing crack that does not breathe (depth 0, its isotropic part in
    the stiffness): both fit its table to the floor, and the open crack is the reading."""
    from scipy.stats import chi2

    if not floor > 0:
        return best
    misfit_best = _misfit(best[1], floor, probe_floor)
    simpler = None
    for cand, fit in accepted.items():
        extra = len(best[1].param_names) - len(fit.param_names)
        if cand == best[0] or extra <= 0:
            continue
        gap = _misfit(fit, floor, probe_floor) - misfit_best
        if gap <= chi2.ppf(0.99, extra) and (simpler is None or len(fit.param_names) < len(simpler[1].param_names)):
            simpler = (cand, fit)
    return simpler or best


def _bow_or_mode_above(best: tuple[str, VectorFit], mode: VectorFit, floor: float,
                       probe_floor: float | None = None) -> tuple[tuple[str, VectorFit], str]:
    """A shaft bow (or probe runout), or another mode of the rotor above the run, as one run's
    1X vectors tell them.

    Below its critical a bow ``b`` responds as ``b / (1 - W^2 + i c W) = b (1 + W^2 + ...)``:
    a 1X that grows as ``W^2`` from the slow-roll vector.  A mode above the run (natural
    frequency ``w2`` beyond the top speed, which every shaft has: a finite-element code's
    rotor run below its second critical) adds its quasi-static response ``u2 W^2 / (w2^2 -
    W^2)``, which grows the same way; past the first critical the bow's response falls as
    ``1/W^2`` and the mode's keeps growing, so a run far above the critical can tell them.
    Where the bow's fit does not beat the mode's by more than the 99 % point of a chi-square
    with the bow's two parameters (in the noise's variance per real component), the run
    cannot decide: the mode is kept (it is there on every rotor; a bow is a fault, named
    only on evidence), and the bow is said undecidable.  A foreign two-disk rotor whose second
    mode lay 31 % above its top speed was read as a bow before (1.27x the floor; the mode
    0.85x)."""
    from scipy.stats import chi2

    if not floor > 0:
        return best, ""
    gap = _misfit(mode, floor, probe_floor) - _misfit(best[1], floor, probe_floor)
    if gap > chi2.ppf(0.99, 2):
        return best, ""
    (w2, _), = mode.extra_modes[-1:]
    top = float(mode.table.speed.max())
    if best[0] == RUNOUT:
        # a runout is the reading's own term and no fault: the better fit is kept, said in a note
        return (SECOND_MODE, mode), (
            f"{RUNOUT}: another mode of the rotor above the run (natural frequency {w2 / SPEED_UNITS['rpm']:.0f} rpm, "
            f"{w2 / top:.2f}x the top speed) fits these 1X vectors as well or better (the runout's fit "
            + (f"{gap:.2g} noise variances worse" if gap > 0 else f"{-gap:.2g} noise variances better")
            + "): the mode's quasi-static response is read, not a runout") if gap <= 0 else (best, "")
    return (SECOND_MODE, mode), (
        f"{BOW}: these 1X vectors cannot tell it from another mode of the rotor above the run (natural frequency "
        f"{w2 / SPEED_UNITS['rpm']:.0f} rpm, {w2 / top:.2f}x the top speed; the bow's fit "
        + (f"{gap:.2g} noise variances worse" if gap > 0 else f"{-gap:.2g} noise variances better")
        + "): below the critical a bow's 1X grows as W^2 from its slow-roll vector, as a higher mode's quasi-static "
        "response does; the mode, which every shaft has, is kept; a run well past the critical (where a bow's 1X "
        "falls and the mode's grows) or slow-roll vectors before and after would decide")


def _misfit(fit: VectorFit, floor: float, probe_floor: float | None = None) -> float:
    """The fit's residual energy in noise variances (per real component): ``2 rss / floor^2``
    where the vectors' noise is white.  Where the keyphasor angle's error is known as a smooth
    curve (``table.phase_error_basis``: the spin spline's error, :class:`~.keyphasor.SpinFit`),
    ``r' (s^2 I + G G')^-1 r``: ``s^2`` the probes' own noise variance, ``G`` the vectors'
    response to that angle error (``-i n X`` at order ``n`` times its basis).  One smooth angle
    error moves every large vector alike; counted as white noise in the floor, a difference it
    makes between two fits would be taken for evidence many times over (a foreign rotor's 9 um
    bow at 2.5 kHz, a pulse timed to 0.4 ms: runout preferred by 21 noise variances; with the
    bow's angle from a 20 kHz keyphasor, the bow)."""
    r = fit.residual
    basis = fit.table.phase_error_basis
    if basis is None or probe_floor is None or not probe_floor > 0 or basis.shape[0] != r.shape[0]:
        return 2.0 * float(np.nansum(np.abs(r) ** 2)) / floor ** 2
    n_p = len(fit.table.probes)
    order = np.repeat(np.asarray(fit.orders, dtype=float), n_p)
    ok = np.isfinite(r)
    s2 = 0.5 * probe_floor ** 2
    rv = np.concatenate([r[ok].real, r[ok].imag])
    turned = -1j * order[None, :] * fit.predicted  # d(vector) / d(angle error), per row and column
    G = np.stack([np.concatenate([(turned * L[:, None])[ok].real, (turned * L[:, None])[ok].imag])
                  for L in basis.T], axis=1)
    Gr = G.T @ rv
    A = s2 * np.eye(G.shape[1]) + G.T @ G
    return float(rv @ rv - Gr @ np.linalg.solve(A, Gr)) / s2


def _bow_or_runout(best: tuple[str, VectorFit], fits: dict[str, VectorFit], floor: float,
                   unit: str, probe_floor: float | None = None) -> tuple[tuple[str, VectorFit], str]:
    """A shaft bow or probe runout, as the 1X vectors of one run can tell them.

    A bow ``b`` responds as ``b / (1 - W^2 + i c W)``; a runout ``R`` is read as it is.  With
    ``R = b`` and the unbalance shifted by ``b (1 - i c)`` the runout model differs from the
    bow's by ``i c b W (W - 1) / (1 - W^2 + i c W)``, less than ``c b`` at any speed: a few
    per cent of the bow.  So when the one fits within the 99 % point of a chi-square with the
    bow's two parameters of the other (in the noise's variance per real component), the run
    cannot decide; the reading's own term, runout, is kept (naming a bow for a track's runout
    would be a false alarm, and the slow-roll vector is the same either way), and the bow is
    said undecidable.  Slow-roll vectors at different times (a thermal bow changes) or a track
    runout measured on a straight shaft decide."""
    from scipy.stats import chi2

    other = {BOW: RUNOUT, RUNOUT: BOW}.get(best[0])
    if other is None or other not in fits or not floor > 0:
        return best, ""
    misfit = {k: _misfit(f, floor, probe_floor) for k, f in ((best[0], best[1]), (other, fits[other]))}
    gap = abs(misfit[other] - misfit[best[0]])
    if gap > chi2.ppf(0.99, 2):
        return best, ""
    kept = (RUNOUT, fits[RUNOUT]) if best[0] == BOW else best
    r = kept[1].runout
    size = float(np.max(np.abs(r))) if r is not None and np.size(r) else math.nan
    return kept, (f"{BOW}: these 1X vectors cannot tell it from probe runout (the two fits {gap:.2g} noise "
                  f"variances apart; a bow adds to a runout of its size only a term below c b (c = 2 zeta) beside a "
                  f"shifted unbalance): the constant 1X vector ({size:.3g} {unit}) is read as runout; slow-roll "
                  "vectors at different times or a track runout measured on a straight shaft would decide")
