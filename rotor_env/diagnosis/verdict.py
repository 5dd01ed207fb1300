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

from .compare import Comparison, _Data, _design, _known
from .orders import complex_rows, failing_windows, noise_floor, order_map

__all__ = ["FLOOR_RATIO", "NUMERICAL_FLOOR", "VERDICTS", "estimate_noise_floor", "order_lines", "verdict_of"]

VERDICTS = ("explained", "explained_after_adding", "partly_explained", "unexplained", "not_identifiable")
#: a residual within this factor of the noise floor is explained
FLOOR_RATIO = 1.5
#: relative numerical floor (integration and round-off) of the equation residual
NUMERICAL_FLOOR = 1e-6


def estimate_noise_floor(data: _Data, comp: Comparison) -> float:
    """RMS the (prefiltered) equation residual would have from sensor noise alone."""
    _, X, y, _, _, _ = _design(data, comp.model, _known(comp.model), comp.onsets, comp.splits, raw=True)
    r = y - X @ comp.coefficients
    k = 2 if data.equation == "both" else 1
    levels = [noise_floor(r[j::k]) for j in range(k)]
    white = math.sqrt(sum(v * v for v in levels) / k)
    numerical = NUMERICAL_FLOOR * float(np.sqrt(np.mean(y * y)))
    return max(white * data.noise_gain, numerical)


def order_lines(data: _Data, residual: np.ndarray, max_order: float = 4.0, top: int = 6) -> list[dict]:
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


def describe_unexplained(data: _Data, comp: Comparison, floor: float) -> dict:
    """Orders and bands of a residual that stands above the noise floor."""
    k = 2 if data.equation == "both" else 1
    r = comp.residual
    per_sample = np.sqrt(sum(r[j::k] ** 2 for j in range(k)) / k)
    m = data.meas
    bands, _ = failing_windows(m.t, per_sample, floor=floor, factor=FLOOR_RATIO, speed=m.phi_dot)
    bands.sort(key=lambda w: -w["peak_rms_over_floor"])
    return {"orders": order_lines(data, r), "bands": bands[:6]}


def order_by_speed(data: _Data, residual: np.ndarray, order: float, bands: int = 3) -> list[dict]:
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


def lookalike_evidence(data: _Data, base: Comparison, ranked: list, chosen) -> dict:
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
            rows.append({"effect": name, "log10_p": c.log10_p, "energy_drop": c.energy_drop,
                         "fit_gain": c.fit_gain, "declared_orders": list(EFFECTS[name].orders), "status": status})
    main = eff.orders[0] if eff.orders else None
    return {
        "effect": chosen.effect,
        "declared_orders": list(eff.orders),
        "log10_p": chosen.log10_p, "energy_drop": chosen.energy_drop, "fit_gain": chosen.fit_gain,
        "residual_orders": order_lines(data, base.residual)[:4],
        "residual_by_speed": order_by_speed(data, base.residual, main) if main is not None else [],
        "lookalikes": rows,
    }
