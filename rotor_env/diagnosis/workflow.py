"""The entry points: fit one model, or diagnose (compare, rank, add, judge)."""

from __future__ import annotations

from collections.abc import Sequence

from ..effects import EFFECTS, get_effect
from ..measurements import Measurements
from .candidates import Candidate, _appears_or_changes, _change_time, _rank
from .compare import Comparison, _Data, _known, compare
from .model import DEFAULT_MODEL, LIBRARY_CANDIDATES, Model, _as_model, _validate_columns
from .orders import _first_rows, failing_windows
from .result import Diagnosis


# ------------------------------------------------------------------ entry points
def fit(
    measurements: Measurements,
    model: Sequence[str] | Model | str = DEFAULT_MODEL,
    *,
    ip: float = 0.3,
    equation: str = "both",
    window_fraction: float = 0.1,
    t_start: float | None = None,
) -> Comparison:
    """Fit one model and compare it with the measurements (no search)."""
    model = _as_model(model)
    data = _Data(measurements, ip, equation, window_fraction, t_start)
    for e in model:
        _validate_columns(EFFECTS[e], data.data, ip)
    return compare(data, model.effects, _known(model.effects))


def diagnose(
    measurements: Measurements,
    model: Sequence[str] | Model | str = DEFAULT_MODEL,
    *,
    candidates: Sequence[str] | None = None,
    ip: float = 0.3,
    alpha: float = 0.05,
    equation: str = "both",
    min_fit_gain: float = 2.0,
    min_energy_drop: float = 0.05,
    window_fraction: float = 0.1,
    t_start: float | None = None,
    max_rounds: int = 6,
    progress: bool = False,
) -> Diagnosis:
    """Compare ``model`` with the measurements, rank and add the missing effects.

    See the module docstring for the rules.  ``candidates`` defaults to every library
    effect not in the model (user effects registered with ``--effect`` are added by
    the caller).
    """
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    model = _as_model(model)
    if candidates is None:
        candidates = [c for c in LIBRARY_CANDIDATES if c not in model]
    else:
        candidates = [get_effect(c).name for c in candidates if c not in model]
    if "unbalance_in_phase" in model:
        candidates = [c for c in candidates if c != "unbalance"]
    data = _Data(measurements, ip, equation, window_fraction, t_start)
    for e in (*model, *candidates):
        _validate_columns(EFFECTS[e], data.data, ip)
    pbar = None
    if progress:
        from tqdm.auto import tqdm

        pbar = tqdm(total=max_rounds, desc="diagnosing", unit="round", leave=False)
    current = compare(data, model.effects, _known(model.effects))
    before = current
    # the first equation's rows: one residual per sample, white where the model is right
    windows, floor = failing_windows(data.meas.t, _first_rows(before.residual, equation))
    rounds: list[list[Candidate]] = []
    missing: list[str] = []
    steps: list[Comparison] = []
    remaining = list(candidates)
    while remaining and len(rounds) < max_rounds:
        ranked = _rank(data, current, remaining, _known(current.model), alpha, min_fit_gain, min_energy_drop)
        rounds.append(ranked)
        if pbar is not None:
            pbar.update(1)
        chosen = next((c for c in ranked if c.significant and c.relevant), None)
        if chosen is None or not ranked[0].significant:
            break
        missing.append(chosen.effect)
        current = chosen.comparison
        if chosen.onset is not None:
            current = _appears_or_changes(data, current, chosen.effect, alpha, min_energy_drop)
        steps.append(current)
        remaining.remove(chosen.effect)
    if pbar is not None:
        pbar.close()
    onset = {
        e: current.onsets.get(e)
        if e in current.onsets
        else _change_time(data, current, e, _known(current.model), alpha, min_energy_drop)
        for e in missing
    }
    diag = Diagnosis(
        source=measurements.source, ip=ip, alpha=alpha, equation=equation, t_start=data.t_start,
        start_model=model.effects, model=current.model, missing=missing, onset=onset, rounds=rounds,
        before=before, after=current, windows=windows, noise_floor=floor, data=data, steps=steps,
    )
    return diag
