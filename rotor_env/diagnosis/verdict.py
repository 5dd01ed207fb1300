"""The verdict: is the data explained, and if not, what is left.

After the selection the final residual is held against the **noise floor** — the
level the residual would have if the model were exactly right.  The floor is read
from the data, never from the misfit: the white-noise level of the *unfiltered*
equation residual from the median absolute first difference (a smooth misfit hardly
moves first differences), scaled by the prefilter's gain for white noise, and never
below a numerical floor (``NUMERICAL_FLOOR`` x the RMS of the regression's output, so
that a noise-free record is not judged by round-off).

Verdicts:

* ``explained`` — the starting model leaves a residual within ``FLOOR_RATIO`` (1.5) x
  the floor;
* ``explained_after_adding`` — effects were added and the residual is within it;
* ``partly_explained`` — effects were added, the residual still stands above it;
* ``unexplained`` — a residual above it that no library effect explains (every
  candidate failed a rule: :attr:`Diagnosis.rejected` says which);
* ``not_identifiable`` — the data cannot decide (no excitation, too few samples).

For the last two the remaining residual is described as an engineer reads it: its
**order lines** (rotation order, whirl direction, share of the residual's energy above
the noise) and the **bands** of time and speed where it stands out.
"""

from __future__ import annotations

import math

import numpy as np

from ..measurements.vectors import order_map
from .compare import Comparison, WindowData, known_values, model_design
from .orders import complex_rows, failing_windows, noise_floor

__all__ = ["FLOOR_RATIO", "NUMERICAL_FLOOR", "VERDICTS", "VERDICT_TEXT", "estimate_noise_floor", "order_lines", "verdict_of"]

VERDICTS = ("explained", "explained_after_adding", "partly_explained", "unexplained", "not_identifiable")
#: The sentence of each verdict (``ratio``: the residual over the noise floor ``floor``).
VERDICT_TEXT = {
    "explained": "the starting model explains the data: residual {ratio:.2g}x the noise floor ({floor:.3g})",
    "explained_after_adding": "explained after adding the missing effects: residual {ratio:.2g}x the noise "
    "floor ({floor:.3g})",
    "partly_explained": "effects were added, but the residual still stands at {ratio:.2g}x the noise floor "
    "({floor:.3g}): something the library does not hold is left",
    "unexplained": "the residual stands at {ratio:.2g}x the noise floor ({floor:.3g}) and no library effect "
    "explains it (see the candidates turned down)",
}

#: a residual within this factor of the noise floor is explained
FLOOR_RATIO = 1.5
#: relative numerical floor (integration and round-off) of the equation residual
NUMERICAL_FLOOR = 1e-6


def estimate_noise_floor(data: WindowData, comp: Comparison) -> float:
    """RMS the (prefiltered) equation residual would have from sensor noise alone."""
    _, X, y, _, _, _ = model_design(data, comp.model, known_values(comp.model), comp.onsets, comp.splits, raw=True)
    r = y - X @ comp.coefficients
    k = 2 if data.equation == "both" else 1
    levels = [noise_floor(r[j::k]) for j in range(k)]
    white = math.sqrt(sum(v * v for v in levels) / k)
    numerical = NUMERICAL_FLOOR * float(np.sqrt(np.mean(y * y)))
    return max(white * data.noise_gain, numerical)


def order_lines(data: WindowData, residual: np.ndarray, max_order: float = 4.0, top: int = 6) -> list[dict]:
    """The residual's rotation-order lines: order, whirl direction, share of the excess energy.

    The order-tracked power (mean over windows of a few revolutions) is summed over
    the bins within 0.25 of every integer order up to ``max_order`` and over those
    between them (half orders: sub- and inter-harmonics), each bin counted once; the
    noise's share is the median power per bin (white noise is flat in order), and what
    stands above it is shared among the lines.
    """
    m = data.meas
    _, ords, amp = order_map(m.t, m.phi, m.phi_dot, complex_rows(residual, data.equation), max_order=max_order)
    if not amp.size:
        return []
    power = (amp * amp).mean(axis=0)
    excess = np.maximum(power - np.median(power), 0.0)
    total = float(excess.sum())
    if total <= 0:
        return []
    lines = []
    # every bin belongs to one order: within 0.25 of an integer order to it, else to the
    # half order between (each bin counted once, so the shares add up to at most 1)
    whole = np.round(ords)
    nearest = np.where(np.abs(ords - whole) <= 0.25, whole, np.floor(ords) + 0.5)
    for o in np.arange(-max_order, max_order + 0.25, 0.5):
        share = float(excess[nearest == o].sum()) / total
        if share >= 0.05:
            order = int(abs(o)) if float(o).is_integer() else float(abs(o))
            direction = "static" if o == 0 else ("forward" if o > 0 else "backward")
            lines.append({"order": order, "direction": direction, "share": share})
    lines.sort(key=lambda d: -d["share"])
    return lines[:top]


def verdict_of(added: bool, ratio: float) -> str:
    """The verdict from whether effects were added and the final residual over the floor."""
    if ratio <= FLOOR_RATIO:
        return "explained_after_adding" if added else "explained"
    return "partly_explained" if added else "unexplained"


def describe_unexplained(data: WindowData, comp: Comparison, floor: float) -> dict:
    """Orders and bands of a residual that stands above the noise floor."""
    k = 2 if data.equation == "both" else 1
    r = comp.residual
    per_sample = np.sqrt(sum(r[j::k] ** 2 for j in range(k)) / k)
    m = data.meas
    bands, _ = failing_windows(m.t, per_sample, floor=floor, factor=FLOOR_RATIO, speed=m.phi_dot)
    bands.sort(key=lambda w: -w["peak_rms_over_floor"])
    return {"orders": order_lines(data, r), "bands": bands[:6]}


def order_by_speed(data: WindowData, residual: np.ndarray, order: float, bands: int = 3) -> list[dict]:
    """Amplitude of the residual's line at ``order`` (signed: negative is backward) in
    ``bands`` speed bands — how a missing effect scales with speed (a bow's 1x forcing is
    constant, an unbalance's grows with speed squared)."""
    m = data.meas
    speeds, ords, amp = order_map(m.t, m.phi, m.phi_dot, complex_rows(residual, data.equation))
    if not amp.size:
        return []
    col = int(np.argmin(np.abs(ords - order)))
    lo, hi = float(np.min(speeds)), float(np.max(speeds))
    edges = np.linspace(lo, hi, bands + 1)
    out = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        sel = (speeds >= a) & (speeds <= b)
        if sel.any():
            out.append({"speed_min": float(a), "speed_max": float(b), "order": order,
                        "amplitude": float(np.sqrt(np.mean(amp[sel, col] ** 2)))})
    return out


def lookalike_evidence(data: WindowData, base: Comparison, ranked: list, chosen) -> dict:
    """Why ``chosen`` and not its lookalikes: the residual's order lines before adding it,
    how its main order scales with speed, and each lookalike's test and rule."""
    from ..effects import EFFECTS

    eff = EFFECTS[chosen.effect]
    by_name = {c.effect: c for c in ranked}
    rows = []
    for name in eff.lookalikes:
        if name in base.model:
            rows.append({"effect": name, "status": "in the model already: it leaves the misfit that "
                         f"{chosen.effect} removes"})
        elif name in by_name:
            c = by_name[name]
            status = c.rejected_by or (f"ranked below {chosen.effect} (log10 p {c.log10_p:.3g} vs "
                                       f"{chosen.log10_p:.3g})")
            row = {"effect": name, "log10_p": c.log10_p, "energy_drop": c.energy_drop,
                   "fit_gain": c.fit_gain, "declared_orders": list(EFFECTS[name].orders), "status": status}
            if getattr(c, "scan", None):
                row["scan"] = {k: c.scan.get(k) for k in ("values", "active_share", "tried")}
            rows.append(row)
    main = eff.orders[0] if eff.orders else None
    out = {
        "effect": chosen.effect,
        "declared_orders": list(eff.orders),
        "log10_p": chosen.log10_p, "energy_drop": chosen.energy_drop, "fit_gain": chosen.fit_gain,
        "residual_orders": order_lines(data, base.residual)[:4],
        "residual_by_speed": order_by_speed(data, base.residual, main) if main is not None else [],
        "lookalikes": rows,
    }
    if getattr(chosen, "scan", None) and chosen.scan.get("values"):
        out["acts_where"] = acts_where(data, base, chosen)
    return out


def acts_where(data: WindowData, base: Comparison, cand) -> dict:
    """Where an effect with a scanned threshold (the rub's clearance) acts, and what the
    misfit it removes looked like there and elsewhere — the evidence against a stiffness
    change (acts at every amplitude) and a quadratic stiffness (grows smoothly with it).

    Per sample of the window: does the effect act (its columns non-zero at the scanned
    value)?  Reported: the scanned value, the smallest and largest inclination where it
    acts (its amplitude threshold), the first and last time and speed of contact in the
    sweep (run-up or coast-down: a rub's contact band differs between them), the base
    model's residual RMS over the noise floor where it acts and elsewhere, the residual's
    order lines where it acts (the backward -1x and the 1/2x sub-harmonic among them),
    and how sharply the scan's energy rises away from the value found.
    """
    from ..regression import RegressionSpec, regression_arrays

    name = cand.effect
    m = data.meas
    spec = RegressionSpec(effects=(name,), equation=data.equation, known={}, scanned=data.scanned)
    Z, _ = regression_arrays(spec, data.data, data.ip)
    k = spec.rows_per_sample
    on = np.any(Z != 0.0, axis=1).reshape(-1, k).any(axis=1)
    amp = np.hypot(m.theta_x, m.theta_y)
    floor = estimate_noise_floor(data, base)
    r = base.residual
    per_sample = np.sqrt(sum(r[j::k] ** 2 for j in range(k)) / k)

    def over(sel) -> float | None:
        return float(np.sqrt(np.mean(per_sample[sel] ** 2)) / floor) if sel.any() and floor > 0 else None

    _, Xb, yb, _, _, _ = model_design(data, base.model, known_values(base.model), base.onsets, base.splits)

    def refit(sel) -> float | None:
        """The starting model refitted to these samples alone: its RMS over the floor."""
        rows = np.repeat(sel, k)
        X, y = Xb[rows], yb[rows]
        X = X[:, np.linalg.norm(X, axis=0) > 0]
        if sel.sum() < 50 * max(1, X.shape[1]) or floor <= 0:
            return None
        theta, *_ = np.linalg.lstsq(X, y, rcond=None)
        e = y - X @ theta
        return float(np.sqrt(np.mean(e * e)) / floor)

    masked = r.copy()
    masked.reshape(-1, k)[~on] = 0.0
    lines = order_lines(data, masked)
    share = {}
    for o in lines:
        signed = -o["order"] if o["direction"] == "backward" else o["order"]
        share[float(signed)] = share.get(float(signed), 0.0) + o["share"]
    scan = cand.scan or {}
    prof = [(v, j) for v, j in scan.get("profile", []) if j is not None]
    value = next(iter(scan.get("values", {}).values()), None)
    contrast = {}
    if prof and value:
        for label, f in (("at_half", 0.5), ("at_double", 2.0)):
            v, j = min(prof, key=lambda pj, f=f: abs(math.log(pj[0] / (f * value))))
            if abs(math.log(v / (f * value))) < 0.15:
                contrast[label] = j
    sweep = "run-up" if m.phi_dot[-1] >= m.phi_dot[0] else "coast-down"
    idx = np.flatnonzero(on)
    out = {
        "scanned": dict(scan.get("values", {})),
        "active_share": float(on.mean()),
        "acts_above_amplitude": float(amp[on].min()) if on.any() else None,
        "peak_amplitude": float(amp.max()),
        "sweep": sweep,
        "first_contact": {"t": float(m.t[idx[0]]), "speed": float(m.phi_dot[idx[0]])} if idx.size else None,
        "last_contact": {"t": float(m.t[idx[-1]]), "speed": float(m.phi_dot[idx[-1]])} if idx.size else None,
        "residual_over_floor": {"where_it_acts": over(on), "elsewhere": over(~on)},
        # the starting model refitted to each part alone (the misfit of one part cannot pull it)
        "starting_model_refitted_over_floor": {"where_it_acts": refit(on), "elsewhere": refit(~on)},
        "residual_orders_where_it_acts": lines[:4],
        "backward_1x_share": share.get(-1.0, 0.0),
        "half_order_share": share.get(0.5, 0.0) + share.get(-0.5, 0.0),
        # the scan's energy at half and at twice the value found, over its least energy
        "scan_energy_ratio": contrast,
    }
    refitted = out["starting_model_refitted_over_floor"]
    ins, outs = refitted["where_it_acts"], refitted["elsewhere"]
    if ins is not None and outs is not None:
        out["reading"] = (
            f"refitted to the samples where |theta| exceeds {out['acts_above_amplitude']:.3g} "
            f"({100 * out['active_share']:.0f} % of the {sweep}) the starting model leaves {ins:.1f}x the noise "
            f"floor, refitted to the others {outs:.1f}x: the misfit sits above a threshold amplitude, where a "
            "stiffness change would act at every amplitude and a quadratic stiffness grow smoothly with it")
    return out
