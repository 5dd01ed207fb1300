"""The checks a candidate must pass to be added: physics, not curve-fitting.

Significance and relevance say that adding an effect *improves the fit*; any flexible
column improves the fit of a residual it is correlated with.  A wrong effect absorbing
a misfit (a bent shaft's constant 1x forcing taken for a crack "appearing at t_c", a
2x misalignment moment taken for a huge quadratic stiffness) is told apart by four
checks, in this order; the first that fails rejects the candidate, and its rule is
reported:

1. **plausible** — every identified physical parameter lies inside the bounds the effect
   declares (:attr:`rotor_env.effects.Parameter.lower`/``upper``, with their reason);
   (with ``ip`` estimated from the data, also: the effect is larger than what the
   estimate's uncertainty makes of it through the gyroscopic moment);
2. **onset** — an effect said to *appear* at ``t_c`` must leave the data before ``t_c``
   explained: the model without it has a residual at the noise floor there (a fault
   present from the start, such as a bow, is not a crack that opened later); if only
   the model *with* it explains them, the effect *changed* at ``t_c`` (a crack that
   grows) and is checked further as such;
3. **consistent** — identified separately in three consecutive time windows (after the
   onset, if any), the effect's coefficients agree: a homogeneity test with the windows'
   HAC covariances rejects at ``1e-6`` *and* the windows differ by more than 25 % of the
   effect's size, its departure from the value the model assumed (``k - 1`` for a
   stiffness): a physical constant is constant; a wrong effect absorbing a misfit
   swings from window to window;
4. **removes what it claims** — the residual's energy at the rotation orders the effect
   declares (both whirl directions, +-0.25 order) falls by at least 10 %, and the
   free-run (output-error) fit does not get worse by more than one point (unless the
   equation error is down to the noise floor with it: then a worse free run is the
   phase drift of a long simulation, not wrong physics).
"""

from __future__ import annotations

import math

import numpy as np

from identifier.hac import chi2_log10_sf, hac_covariance

from ..effects import EFFECTS
from ..measurements.vectors import order_map
from .compare import Comparison, WindowData, compare, known_values, model_design
from .orders import complex_rows

__all__ = ["CONSISTENCY_LOG10_P", "CONSISTENCY_SPREAD", "check_candidate"]

#: a homogeneity test below this log10 p ... (the windows' HAC errors come from a third of
#: the record each and carry their own noise bias: honest effects reach 1e-5 there; the
#: wrong effects met so far swing at 1e-40 and beyond — loose pedestal, rub)
CONSISTENCY_LOG10_P = -6.0
#: ... and windows this far apart (relative to the effect's size) reject a candidate
CONSISTENCY_SPREAD = 0.25
#: the residual before an onset may stand at most this far above the noise floor
ONSET_FLOOR_RATIO = 1.5
#: an effect must remove at least this share of the residual's energy at its orders
ORDER_DROP = 0.10
#: the free-run fit may get worse by at most this many points when an effect is added
FIT_TOLERANCE = 1.0
WINDOWS = 3


def _plausible(comp: Comparison, effect: str) -> tuple[str | None, dict]:
    values = dict(comp.physical)
    before = comp.physical_before
    for p in EFFECTS[effect].parameters:
        for label, v in ((p.name, values.get(p.name)), (f"{p.name} before", before.get(p.name))):
            if v is not None and not p.contains(v):
                rule = (f"implausible: {label} = {v:.4g} outside [{p.lower:g}, {p.upper:g}]"
                        + (f" ({p.bounds_reason})" if p.bounds_reason else ""))
                return rule, {"parameter": p.name, "value": v, "lower": p.lower, "upper": p.upper}
    return None, {"parameters": {p.name: values.get(p.name) for p in EFFECTS[effect].parameters}}


def _pre_onset_ratio(data: WindowData, model, known: dict, onsets: dict, splits, onset: float,
                     floor: float) -> float | None:
    """RMS over the floor of ``model`` refitted to the rows before ``onset`` alone (fitted
    to the whole record its coefficients would be pulled by the misfit after it)."""
    _, X, y, t_rows, _, _ = model_design(data, model, known, onsets, splits)
    sel = t_rows < onset
    X = X[:, np.linalg.norm(X[sel], axis=0) > 0]
    if sel.sum() < 50 * max(1, X.shape[1]) or floor <= 0:
        return None
    Xs, ys = X[sel], y[sel]
    theta, *_ = np.linalg.lstsq(Xs, ys, rcond=None)
    pre = ys - Xs @ theta
    return float(np.sqrt(np.mean(pre * pre)) / floor)


def _onset(data: WindowData, base: Comparison, cand, floor: float, library: tuple[str, ...]) -> tuple[str | None, dict]:
    """An effect *appearing* at ``t_c`` leaves the data before ``t_c`` explainable without it.

    The rows before ``t_c`` are refitted with the widest model the library offers
    (``base`` plus every candidate of the round: another missing effect must not count
    against this one), without the effect and with it present throughout:

    * explained without it — it may appear at ``t_c``;
    * explained only with it — it was there all along and its value *changed* (a crack
      that grows): the candidate becomes the split model (own coefficients before
      ``t_c``) and goes on to the next checks;
    * explained by neither — a misfit before ``t_c`` that this effect does not remove:
      a fault present from the start (a bow), whose misfit after ``t_c`` the effect's
      flexible columns absorb.  Rejected.
    """
    onset = cand.onset
    if onset is None:
        return None, {}
    name = cand.effect
    widest = tuple(dict.fromkeys(e for e in (*base.model, *library) if e != name))
    if "unbalance_in_phase" in widest:
        widest = tuple(e for e in widest if e != "unbalance")
    known = {k: v for k, v in known_values(widest).items() if k != name}
    without = _pre_onset_ratio(data, widest, known, base.onsets, base.splits, onset, floor)
    if without is None:
        return None, {}
    info: dict = {"widest_model_before_onset_over_floor": without}
    if without <= ONSET_FLOOR_RATIO:
        return None, info
    with_it = _pre_onset_ratio(data, (*widest, name), known, base.onsets, base.splits, onset, floor)
    info["with_the_effect_before_onset_over_floor"] = with_it
    if with_it is not None and with_it <= ONSET_FLOOR_RATIO:
        kn = {k: v for k, v in known_values(base.model).items() if k != name}
        cand.comparison = compare(data, (*base.model, name), kn, {**base.onsets, name: onset},
                                  (*base.splits, name))
        cand.fit_gain = cand.comparison.fit_percent - base.fit_percent
        info["changes"] = True
        return None, info
    return (f"misfit before the onset: before t = {onset:.0f} the library leaves {without:.1f}x the noise floor "
            f"without the effect and {with_it if with_it is not None else math.nan:.1f}x with it, so it neither "
            "appears nor changes there (a fault present from the start)"), info


def _window_estimates(data: WindowData, comp: Comparison, effect: str, start: float | None):
    """Per time window: the effect's coefficients and their HAC covariance."""
    spec, X, y, t_rows, columns, _ = model_design(data, comp.model, known_values(comp.model), comp.onsets, comp.splits)
    idx = [columns.index(c) for c in spec.groups[effect]]
    lo = data.meas.t[0] if start is None else start
    edges = np.linspace(lo, data.meas.t[-1], WINDOWS + 1)
    out = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        sel = (t_rows >= a) & (t_rows <= b)
        Xw, yw = X[sel], y[sel]
        keep = np.flatnonzero(np.linalg.norm(Xw, axis=0) > 0)
        if len(yw) < 10 * len(keep) or not set(idx) <= set(keep.tolist()):
            continue
        Xk = Xw[:, keep]
        theta, *_ = np.linalg.lstsq(Xk, yw, rcond=None)
        cov = hac_covariance(Xk, yw - Xk @ theta, rows_per_time=spec.rows_per_sample)
        pos = [keep.tolist().index(i) for i in idx]
        out.append((float(a), float(b), theta[pos], cov[np.ix_(pos, pos)]))
    return out


def _consistent(data: WindowData, comp: Comparison, effect: str, onset: float | None,
                null: np.ndarray | None) -> tuple[str | None, dict]:
    est = _window_estimates(data, comp, effect, onset)
    if len(est) < 2:
        return None, {}
    thetas = [e[2] for e in est]
    infos = [np.linalg.pinv(e[3]) for e in est]
    pooled = np.linalg.pinv(sum(infos)) @ sum(i @ th for i, th in zip(infos, thetas, strict=True))
    Q = float(sum((th - pooled) @ i @ (th - pooled) for i, th in zip(infos, thetas, strict=True)))
    df = (len(est) - 1) * len(pooled)
    log10_p = chi2_log10_sf(Q, df)
    # the effect's size is its departure from what the model without it assumed (a
    # stiffness change is k - 1, not k)
    size = float(np.linalg.norm(pooled - (0.0 if null is None else null)))
    spread = max(float(np.linalg.norm(th - pooled)) for th in thetas) / size if size > 0 else math.inf
    info = {"windows": [{"t_start": a, "t_end": b, "coefficients": th.tolist(),
                         "standard_errors": np.sqrt(np.maximum(np.diag(c), 0)).tolist()}
                        for a, b, th, c in est],
            "homogeneity_log10_p": log10_p, "relative_spread": spread}
    if log10_p < CONSISTENCY_LOG10_P and spread > CONSISTENCY_SPREAD:
        return (f"inconsistent: identified in {len(est)} time windows its coefficients differ by "
                f"{100 * spread:.0f} % (homogeneity log10 p = {log10_p:.3g}): a physical constant does not swing"), info
    return None, info


def order_energy(data: WindowData, residual: np.ndarray, orders, width: float = 0.25) -> float:
    """Residual energy at the given rotation orders, both whirl directions (order tracked)."""
    m = data.meas
    _, ords, amp = order_map(m.t, m.phi, m.phi_dot, complex_rows(residual, data.equation))
    if not amp.size:
        return 0.0
    power = (amp * amp).mean(axis=0)
    sel = np.zeros(len(ords), dtype=bool)
    for o in orders:
        sel |= np.abs(np.abs(ords) - abs(o)) <= width
    return float(power[sel].sum())


def _removes_its_orders(data: WindowData, base: Comparison, comp: Comparison, effect: str,
                        fit_gain: float, floor: float) -> tuple[str | None, dict]:
    info: dict = {"fit_gain": fit_gain}
    # a model whose equation error is down to the noise floor is not the wrong physics: a
    # slightly worse free run is then the phase drift of a long simulation (a lightly
    # damped transient after a crack opens drifts with a 1e-4 error in ip)
    at_floor = floor > 0 and comp.rms <= ONSET_FLOOR_RATIO * floor
    if fit_gain < -FIT_TOLERANCE and not at_floor:
        return f"worse free run: adding it makes the free-run fit {-fit_gain:.1f} points worse", info
    orders = EFFECTS[effect].orders
    if not orders:
        return None, info
    e0 = order_energy(data, base.residual, orders)
    e1 = order_energy(data, comp.residual, orders)
    drop = (e0 - e1) / e0 if e0 > 0 else 0.0
    info["order_energy_drop"] = drop
    if drop < ORDER_DROP:
        return (f"does not remove its signature: the residual at its orders {list(orders)} falls by "
                f"{100 * drop:.0f} % only"), info
    return None, info


def _gyro_rows(data: WindowData) -> np.ndarray:
    """``d y / d ip`` per regression row: the gyroscopic moment moved to the output side."""
    d = data.data
    first, second = d[:, 2] * d[:, 6], -d[:, 2] * d[:, 7]  # phid th_x',  -phid th_y'
    if data.equation == "first":
        return first.copy()
    if data.equation == "second":
        return second.copy()
    g = np.empty(2 * len(d))
    g[0::2], g[1::2] = first, second
    return g


def _not_the_ip(data: WindowData, comp: Comparison, effect: str, null: np.ndarray | None) -> tuple[str | None, dict]:
    """With ``ip`` estimated from the data, an effect that the estimate's own uncertainty
    moves by as much as its size is not told apart from an error in ``ip`` (a 0.002 error
    in ip reads as a 0.3 % stiffness change through the gyroscopic moment)."""
    delta = data.ip_uncertainty
    if not delta:
        return None, {}
    spec, X, _, _, columns, _ = model_design(data, comp.model, known_values(comp.model), comp.onsets, comp.splits)
    keep = np.flatnonzero(np.linalg.norm(X, axis=0) > 0)
    idx = [columns.index(c) for c in spec.groups[effect]]
    if not set(idx) <= set(keep.tolist()):
        return None, {}
    shift, *_ = np.linalg.lstsq(X[:, keep], _gyro_rows(data) * delta, rcond=None)
    moved = float(np.linalg.norm(shift[[keep.tolist().index(i) for i in idx]]))
    size = float(np.linalg.norm(comp.coefficients[idx] - (0.0 if null is None else null)))
    info = {"ip_uncertainty": delta, "moved_by_the_ip_uncertainty": moved, "size": size}
    if size <= moved:
        return (f"confounded with ip: the estimated ip's uncertainty (± {delta:.2g}) moves it by {moved:.3g}, "
                f"as much as its size {size:.3g}; give --ip to decide"), info
    return None, info


def check_candidate(data: WindowData, base: Comparison, cand, floor: float,
                    library: tuple[str, ...] = ()) -> tuple[str | None, dict]:
    """The first rule that rejects ``cand`` (None: it passes), and the numbers of every check run.

    ``library``: the other candidates of the round (the onset check refits with them).
    """
    evidence: dict = {}
    if getattr(cand, "scan", None) is not None:
        evidence["scan"] = cand.scan  # the non-linear parameter's scan (the rub's clearance)
    known = known_values(base.model)
    null = (np.asarray(EFFECTS[cand.effect].to_coefficients(known[cand.effect]), dtype=float)
            if cand.effect in known else None)
    for name, run in (
        ("plausible", lambda: _plausible(cand.comparison, cand.effect)),
        ("not the ip", lambda: _not_the_ip(data, cand.comparison, cand.effect, null)),
        ("onset", lambda: _onset(data, base, cand, floor, library)),
        ("consistent", lambda: _consistent(data, cand.comparison, cand.effect, cand.onset, null)),
        ("signature", lambda: _removes_its_orders(data, base, cand.comparison, cand.effect, cand.fit_gain, floor)),
    ):
        rule, info = run()
        evidence[name] = info
        if rule is not None:
            return rule, evidence
    return None, evidence
