"""Which effect is missing: candidates ranked, onsets scanned, each checked."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from identifier import partial_f
from identifier.hac import wald_group_test
from identifier.segments import SplitScan

from ..effects import EFFECTS
from ..measurements.vectors import order_map
from ..regression import RegressionSpec, regression_columns
from .compare import Comparison, WindowData, compare, known_values, model_design
from .orders import complex_rows


# ------------------------------------------------------------------ candidates
@dataclass
class Candidate:
    effect: str
    F: float
    log10_p: float
    rms_after: float
    fit_percent_after: float
    energy_drop: float           # fraction of the equation-error energy removed
    fit_gain: float              # free-run fit % gained
    significant: bool
    relevant: bool
    correlation: float           # multiple correlation of the residual with its columns
    order_overlap: float         # cosine similarity of order spectra (residual vs columns)
    onset: float | None          # the effect appears at this time (None: present throughout)
    story: str
    comparison: Comparison = field(repr=False)
    rejected_by: str | None = None   # the rule that rejected it (None: not rejected / not reached)
    checks: dict = field(default_factory=dict)  # the physics checks' numbers
    #: the scan of its non-linear parameters (the rub's clearance; None: it has none)
    scan: dict | None = None

    def to_dict(self) -> dict:
        return {
            "effect": self.effect, "F": self.F, "log10_p": self.log10_p, "rms_after": self.rms_after,
            "fit_percent_after": self.fit_percent_after, "energy_drop": self.energy_drop,
            "fit_gain": self.fit_gain, "significant": self.significant, "relevant": self.relevant,
            "correlation": self.correlation, "order_overlap": self.order_overlap, "onset": self.onset,
            "declared_orders": list(EFFECTS[self.effect].orders), "story": self.story,
            "rejected_by": self.rejected_by, "evidence": self.checks, "scan": self.scan,
        }




def _order_profile(data: WindowData, values: np.ndarray) -> np.ndarray:
    m = data.meas
    z = complex_rows(values, data.equation)
    _, _, amp = order_map(m.t, m.phi, m.phi_dot, z)
    return amp.mean(axis=0) if amp.size else np.zeros(1)


GRID = 160  # change-point candidates per scan (the Bonferroni factor of the scan)
#: an onset or change must remove at least this share of the energy the effect explains
ONSET_SHARE = 0.01


def _grid(data: WindowData) -> np.ndarray:
    t = data.meas.t
    return np.linspace(t[0], t[-1], GRID + 2)[1:-1]


#: points of the fine scan between the coarse grid's neighbours of the best t_c
FINE = 41


def _best_time(A: np.ndarray, t_rows: np.ndarray, t_grid: np.ndarray, zero_pre, zero_suf) -> tuple[float, float]:
    """The ``t_c`` of least residual energy of ``A = [X y]`` with columns ``zero_pre`` absent
    before ``t_c`` and ``zero_suf`` absent after it (:class:`identifier.segments.SplitScan`):
    the coarse grid, then a fine one around its best point (a change placed a coarse step off
    leaves a burst of misfit there), over the rows between the coarse neighbours only."""
    scan = SplitScan(A, zero_pre, zero_suf)
    J = scan.energies(np.searchsorted(t_rows, t_grid))
    k = int(np.argmin(J))
    i, j = max(k - 1, 0), min(k + 1, len(t_grid) - 1)
    lo, hi = t_grid[i], t_grid[j]
    if hi > lo:
        fine = np.linspace(lo, hi, FINE)
        Jf = scan.refine(i, j, np.searchsorted(t_rows, fine))
        f = int(np.argmin(Jf))
        if Jf[f] < J[k]:
            return float(fine[f]), float(Jf[f])
    return float(t_grid[k]), float(J[k])


def _appear_scan(data: WindowData, base: Comparison, name: str, known: dict) -> tuple[float, float]:
    """Best onset ``t_c`` for ``name`` appearing mid-run, and the energy with it."""
    spec, X, y, t_rows, _, _ = model_design(data, (*base.model, name), known, base.onsets, base.splits)
    cols = [spec.columns.index(c) for c in spec.groups[name]]
    return _best_time(np.column_stack([X, y]), t_rows, _grid(data), cols, [])


#: points of the fine scan of a scanned parameter between the grid's neighbours of the best value
FINE_SCAN = 21
#: a scanned effect (the rub) is tried only at values where it acts on at most this share of
#: the window's samples: a contact that holds all along is a stiffness change (plus a
#: cross-coupling) to these data, not a rub that comes and goes ...
MAX_ACTIVE_SHARE = 0.9
#: ... and on at least this many samples (fewer cannot be told from noise)
MIN_ACTIVE_SAMPLES = 50


def _active(Z: np.ndarray, per: int) -> np.ndarray:
    """Per sample: does the effect act (any of its columns non-zero)?"""
    Zs = Z.reshape(-1, per * Z.shape[1])
    act = Zs[:, 0] != 0.0
    for j in range(1, Zs.shape[1]):  # column by column: numpy's any(axis=1) over a few columns is slow
        act |= Zs[:, j] != 0.0
    return act


def _scan_parameters(data: WindowData, base: Comparison, name: str, known: dict) -> dict | None:
    """Scan ``name``'s non-linear parameters (the rub's clearance) over their grids.

    Every grid value (geometric over the parameter's plausible bounds, :meth:`Parameter.scan_grid`)
    where the effect acts on some but not all of the window (:data:`MAX_ACTIVE_SHARE`,
    :data:`MIN_ACTIVE_SAMPLES`) is fitted in the model ``base + name`` (equation error); the
    least energy wins, then a fine scan between its neighbours.  The value is set in
    ``data.scanned`` (every later fit of the effect uses it); the caller pays a Bonferroni
    factor of the number of values tried, as for the onset.  None: the effect has no
    scanned parameter; ``{"values": {}}``: no value where it comes and goes.
    """
    eff = EFFECTS[name]
    params = eff.scanned_parameters
    if not params:
        return None
    if len(params) > 1:  # pragma: no cover - no library effect scans two (a product grid would)
        raise NotImplementedError(f"{name}: one scanned parameter per effect is supported")
    p = params[0]
    per = 2 if data.equation == "both" else 1
    # the base model's columns once (the same rows as the design of base + name); the
    # effect's own columns at each value
    _, Xb, y, _, _, _ = model_design(data, base.model, known, base.onsets, base.splits)
    Xb = Xb[:, np.linalg.norm(Xb, axis=0) > 0]
    # the base model's fit once: its orthonormal basis Q and residual; each value then only
    # fits the effect's columns with Q's span projected out (the same least squares as
    # [Xb Z] at a fraction of the price: the scan tries ~60 values per round)
    Q = np.linalg.qr(Xb, mode="reduced")[0] if Xb.shape[1] else np.zeros((len(y), 0))
    r_base = y - Q @ (Q.T @ y)

    def energy(v: float) -> tuple[float, float]:
        data.scanned[name] = {p.name: float(v)}
        share = data.active_share.get((name, float(v)))
        if share is None or _tried(share):
            Z = _candidate_columns(data, name, None)
            share = data.active_share[(name, float(v))] = float(_active(Z, per).mean())
        if not _tried(share):
            return math.inf, share
        # the columns less their part in the base model's span; the energy left is the last
        # diagonal element of the factor of [Zp r_base] (r_base is orthogonal to that span)
        Zp = Z - Q @ (Q.T @ Z)
        return float(np.linalg.qr(np.column_stack([Zp, r_base]), mode="r")[-1, -1] ** 2), share

    def _tried(share: float) -> bool:
        return share <= MAX_ACTIVE_SHARE and share * len(y) / per >= MIN_ACTIVE_SAMPLES

    grid = p.scan_grid()
    J = np.empty(len(grid))
    shares = np.empty(len(grid))
    for i, v in enumerate(grid):
        J[i], shares[i] = energy(v)
    tried = int(np.isfinite(J).sum())
    out = {"parameter": p.name, "grid": [float(grid[0]), float(grid[-1]), len(grid)], "tried": tried,
           "active_share_limits": [MIN_ACTIVE_SAMPLES, MAX_ACTIVE_SHARE]}
    if tried == 0:
        data.scanned.pop(name, None)
        out["values"] = {}
        return out
    k = int(np.argmin(J))
    best, J_best, share_best = float(grid[k]), float(J[k]), float(shares[k])
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    for v in np.linspace(lo, hi, FINE_SCAN):
        Jv, sv = energy(v)
        if Jv < J_best:
            best, J_best, share_best = float(v), Jv, sv
    data.scanned[name] = {p.name: best}
    out.update({"values": {p.name: best}, "energy": J_best, "active_share": share_best,
                # the scan's energy profile (grid value, energy relative to the best; inf: not tried)
                "profile": [[float(v), float(j / J_best) if J_best > 0 and math.isfinite(j) else None]
                            for v, j in zip(grid, J, strict=True)]})
    return out


def _candidate_columns(data: WindowData, name: str, onset: float | None) -> np.ndarray:
    """The candidate's regressor columns on the window's rows (zero before an onset)."""
    spec = RegressionSpec(effects=(name,), equation=data.equation, known={}, scanned=data.scanned)
    Z = regression_columns(spec, data.data, data.ip, data.columns)
    if onset is not None:
        Z[np.repeat(data.meas.t, spec.rows_per_sample) < onset] = 0.0
    return Z


def _wald(data: WindowData, comp: Comparison, name: str, known: dict, null=None) -> tuple[float, float]:
    """HAC Wald test of ``name``'s coefficients in the fitted model ``comp`` against ``null``
    (0, or the value the base model assumed for it — the stiffness scale 1)."""
    spec, X, _, _, columns, groups = model_design(data, comp.model, known, comp.onsets, comp.splits)
    keep = np.flatnonzero(np.linalg.norm(X, axis=0) > 0)
    group = [c for c in (columns.index(c) for c in groups[name]) if c in set(keep.tolist())]
    if not group:
        return 0.0, 0.0
    pos = [keep.tolist().index(g) for g in group]
    theta = comp.coefficients[group] - (0.0 if null is None else np.asarray(null, dtype=float)[:len(group)])
    return wald_group_test(X[:, keep], comp.residual, theta, pos, rows_per_time=spec.rows_per_sample)


def rank_candidates(data: WindowData, base: Comparison, candidates: Sequence[str], known: dict, alpha: float,
          min_fit_gain: float, min_energy_drop: float) -> list[Candidate]:
    """Every candidate's evidence for being added to ``base`` (best first).

    The test of adding an effect is the HAC Wald test of its coefficients in the
    augmented model (:func:`identifier.hac.wald_group_test`), valid when the residual is
    autocorrelated; the change-point scan finds the onset by least residual energy and
    pays a Bonferroni factor of ``GRID`` for having searched.
    """
    out = []
    n_cand = max(1, len(candidates))
    res_profile = _order_profile(data, base.residual)
    from ..progress import advance

    for i, name in enumerate(candidates):
        advance(1 if i else 0)  # the one before is done (the step's rate: candidates per second)
        kn = {k: v for k, v in known.items() if k != name}
        null = EFFECTS[name].to_coefficients(known[name]) if name in known else None
        # a non-linear parameter (the rub's clearance) is scanned first, and the scan paid for
        scan = _scan_parameters(data, base, name, kn)
        if scan is not None and not scan["values"]:
            out.append(_not_scanned(name, base, scan))
            continue
        comp = compare(data, (*base.model, name), kn, base.onsets, base.splits)
        q = comp.n_params - base.n_params
        F, lp = _wald(data, comp, name, kn, null) if q > 0 else (0.0, 0.0)
        if scan is not None:
            lp = min(0.0, lp + math.log10(max(scan["tried"], 1)))
        onset = None
        # the same effect appearing mid-run (a crack): scan its onset, pay for the scan
        if q > 0:
            tc, J_app = _appear_scan(data, base, name, kn)
            gain = comp.energy - J_app
            # the onset must matter twice: against what is left, and against what the
            # effect explains (on noise-free data what is left is rounding, see change_time)
            if (comp.energy > 0 and gain >= min_energy_drop * comp.energy
                    and gain >= ONSET_SHARE * (base.energy - comp.energy)):
                at = compare(data, (*base.model, name), kn, {**base.onsets, name: tc}, base.splits,
                             simulate=False)
                Fa, lpa = _wald(data, at, name, kn, null)
                lpa = min(0.0, lpa + math.log10(GRID))
                if lpa < lp:
                    onset = tc
                    F, lp = Fa, lpa
                    comp = compare(data, (*base.model, name), kn, {**base.onsets, name: tc}, base.splits)
        # evidence: correlation of the residual with the candidate's columns, and order overlap
        Xc = _candidate_columns(data, name, onset)
        rr = base.residual @ base.residual
        # the residual's energy left after its regression on the columns (last diagonal of R)
        left = np.linalg.qr(np.column_stack([Xc, base.residual]), mode="r")[-1, -1] ** 2
        corr = math.sqrt(max(0.0, 1.0 - left / rr)) if rr > 0 else 0.0
        # the columns' order spectrum depends on the data alone: each round reuses it
        key = repr((name, onset, data.scanned.get(name)))
        prof = data.order_profiles.get(key)
        if prof is None:
            prof = data.order_profiles[key] = _order_profile(data, Xc @ np.ones(Xc.shape[1]))
        overlap = float(prof @ res_profile / (np.linalg.norm(prof) * np.linalg.norm(res_profile) + 1e-300))
        drop = (base.energy - comp.energy) / base.energy if base.energy > 0 else 0.0
        gain = comp.fit_percent - base.fit_percent
        eff = EFFECTS[name]
        out.append(Candidate(
            effect=name, F=float(F), log10_p=float(lp), rms_after=comp.rms, fit_percent_after=comp.fit_percent,
            energy_drop=float(drop), fit_gain=float(gain),
            significant=bool(q > 0 and lp < math.log10(alpha / n_cand)),
            # an equation-error gain that makes the output error clearly worse explains the
            # residual with the wrong physics (e.g. quadratic stiffness for a side load)
            relevant=bool(gain >= min_fit_gain or (drop >= min_energy_drop and gain > -min_fit_gain)),
            correlation=float(corr), order_overlap=overlap, onset=onset,
            story=f"{eff.cause}. Signature: {eff.signature}.", comparison=comp, scan=scan,
        ))
    advance(1 if candidates else 0)
    out.sort(key=lambda c: (c.log10_p, -c.F))
    return out


def _not_scanned(name: str, base: Comparison, scan: dict) -> Candidate:
    """A scanned effect with no value where it comes and goes: not a candidate this round."""
    eff = EFFECTS[name]
    return Candidate(
        effect=name, F=0.0, log10_p=0.0, rms_after=base.rms, fit_percent_after=base.fit_percent,
        energy_drop=0.0, fit_gain=0.0, significant=False, relevant=False, correlation=0.0, order_overlap=0.0,
        onset=None, story=f"{eff.cause}. Signature: {eff.signature}.", comparison=base, scan=scan,
        rejected_by=(f"no {scan['parameter']} in [{scan['grid'][0]:g}, {scan['grid'][1]:g}] where it comes and "
                     f"goes: at every value it acts on fewer than {MIN_ACTIVE_SAMPLES} samples or on more than "
                     f"{100 * MAX_ACTIVE_SHARE:.0f} % of the record"),
    )


def appears_or_changes(data: WindowData, comp: Comparison, effect: str, alpha: float,
                        min_energy_drop: float) -> Comparison:
    """An effect found appearing at ``t_c``: was it there before with another value?

    The split model (own coefficients before ``t_c``) replaces the appearing one when
    the extra coefficients are significant and remove at least ``min_energy_drop`` of
    the energy left (a crack that *grows*, D 0.03 -> 0.08, rather than one that opens).
    """
    split = compare(data, comp.model, known_values(comp.model), comp.onsets, (*comp.splits, effect))
    q = split.n_params - comp.n_params
    if q <= 0:
        return comp
    _, _, lp, _ = partial_f(comp.energy, split.energy, q, split.n_rows - split.n_params)
    if float(lp) < math.log10(alpha) and comp.energy - split.energy >= min_energy_drop * comp.energy:
        return split
    return comp


def change_time(data: WindowData, comp: Comparison, effect: str, known: dict, alpha: float,
                 min_energy_drop: float) -> float | None:
    """When an effect in the model changes mid-run: split its coefficient at ``t_c``."""
    spec, X, y, t_rows, _, _ = model_design(data, comp.model, known, comp.onsets, comp.splits)
    cols = [spec.columns.index(c) for c in spec.groups[effect]]
    n = X.shape[1]
    A = np.column_stack([X, X[:, cols], y])  # the effect's columns twice: before | after
    after = list(range(n, n + len(cols)))
    t_c, J_c = _best_time(A, t_rows, _grid(data), after, cols)
    q = len(cols)
    dof = len(y) - comp.n_params - q
    _, _, lp, _ = partial_f(comp.energy, J_c, q, dof)
    drop = comp.energy - J_c
    # energy the effect explains in the model: from its test (F of removing it, tested last)
    sig = comp.significance.get(effect, {})
    explained = sig.get("F", 0.0) * q * comp.energy / max(len(y) - comp.n_params, 1)
    # a change must matter against what is left AND against the effect itself: on
    # noise-free data what is left is integration error, and splitting any coefficient
    # "removes" a large share of it while changing the value by 1e-5
    if (float(lp) + math.log10(GRID) < math.log10(alpha) and drop >= min_energy_drop * comp.energy
            and drop >= ONSET_SHARE * explained):
        return t_c
    return None
