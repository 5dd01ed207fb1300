"""The entry points: fit one model, or diagnose (compare, rank, add, judge)."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

from ..effects import EFFECTS, get_effect
from ..measurements import Measurements
from ..slow_roll import compensate_slow_roll
from .candidates import Candidate, appears_or_changes, change_time, rank_candidates
from .checks import check_candidate
from .compare import Comparison, WindowData, compare, known_values, make_robust
from .eiv import correct_errors_in_variables
from .model import DEFAULT_MODEL, LIBRARY_CANDIDATES, Model, as_model, validate_columns
from .orders import failing_windows, first_rows
from .result import Diagnosis, NotIdentifiableResult
from .scaling import (
    K_RANGE,
    NotIdentifiable,
    check_excitation,
    estimate_ip_and_stiffness,
    rescale_time,
)
from .verdict import describe_unexplained, estimate_noise_floor, lookalike_evidence, verdict_of

#: a given ip further than this (and 5 standard errors) from the data's estimate is contradicted
IP_TOLERANCE = 0.03


# ------------------------------------------------------------------ entry points
def fit(
    measurements: Measurements,
    model: Sequence[str] | Model | str = DEFAULT_MODEL,
    *,
    ip: float = 0.3,
    equation: str = "both",
    window_fraction: float = 0.1,
    t_start: float | None = None,
    alpha: float = 0.05,
    onsets: dict[str, float] | None = None,
) -> Comparison:
    """Fit one model and compare it with the measurements (no search).

    As :func:`diagnose` reports its final model: HAC standard errors and effect tests,
    coefficients corrected for the noise in the regressors (:mod:`.eiv`).  ``onsets``
    makes effects appear mid-run (``{"asymmetry": 250.0}``: a crack opening at t = 250).
    """
    model = as_model(model)
    onsets = dict(onsets or {})
    for e, tc in onsets.items():
        if e not in model:
            raise ValueError(f"onset given for {e!r}, which is not in the model ({', '.join(model)})")
        if not math.isfinite(tc):
            raise ValueError(f"the onset of {e!r} must be a finite time, got {tc!r}")
    data = WindowData(measurements, ip, equation, window_fraction, t_start)
    for e in model:
        validate_columns(EFFECTS[e], data.data, ip)
    comp = compare(data, model.effects, known_values(model.effects), onsets, robust=True, alpha=alpha)
    return correct_errors_in_variables(data, comp)


def diagnose(
    measurements: Measurements,
    model: Sequence[str] | Model | str = DEFAULT_MODEL,
    *,
    candidates: Sequence[str] | None = None,
    ip: float | None = None,
    alpha: float = 0.05,
    equation: str = "both",
    min_fit_gain: float = 2.0,
    min_energy_drop: float = 0.05,
    window_fraction: float = 0.1,
    t_start: float | None = None,
    max_rounds: int = 6,
    progress: bool = False,
    slow_roll: float | None = None,
) -> Diagnosis | NotIdentifiableResult:
    """Compare ``model`` with the measurements, rank and add the missing effects, judge.

    See the package docstring for the rules.  ``candidates`` defaults to every library
    effect not in the model (user effects registered with ``--effect`` are added by
    the caller).  ``ip=None`` estimates the inertia ratio from the data; a given one
    that the data contradict is kept, with a warning.  A record that cannot decide
    anything returns a :class:`NotIdentifiableResult` (verdict ``not_identifiable``).
    ``slow_roll``: a speed (the file's units) below which the 1x reading is the probe's
    runout; its pattern is subtracted first (:mod:`rotor_env.slow_roll`).
    """
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    if ip is not None and not (math.isfinite(ip) and 0 <= ip < 1):
        raise ValueError(f"ip must be a number in [0, 1), got {float(ip)!r}")
    model = as_model(model)
    from ..progress import step

    step("checking the data: excitation, time scale, ip")
    if candidates is None:
        candidates = [c for c in LIBRARY_CANDIDATES if c not in model]
    else:
        candidates = [get_effect(c).name for c in candidates if c not in model]
    if "unbalance_in_phase" in model:
        candidates = [c for c in candidates if c != "unbalance"]
    notes: list[str] = []
    if slow_roll is not None:
        measurements, runout = compensate_slow_roll(measurements, slow_roll)
        notes.append(f"slow-roll vector subtracted (speed <= {slow_roll:g}): runout {abs(runout):.4g} at "
                     f"{math.atan2(runout.imag, runout.real):.3f} rad (theta_y + i theta_x)")
    # a user effect whose columns are broken is said before anything uses them
    samples = np.ascontiguousarray(measurements.data)
    for e in (*model, *candidates):
        validate_columns(EFFECTS[e], samples, 0.3 if ip is None else float(ip))
    in_file_time = measurements  # the output-error path reads the time scale off its own fit
    try:
        check_excitation(measurements)
        k_hat = estimate_ip_and_stiffness(measurements, model.effects, widest=False).k
        time_scale = 1.0
        if math.isfinite(k_hat) and not (K_RANGE[0] <= k_hat <= K_RANGE[1]):
            if k_hat <= 0:
                raise NotIdentifiable(f"the data give a negative stiffness ({k_hat:.3g}): "
                                      "check the sign conventions of the angles and their rates")
            time_scale = math.sqrt(k_hat)
            measurements = rescale_time(measurements, k_hat)
            notes.append(f"time rescaled by {time_scale:.6g}: the data's natural frequency is "
                         f"{time_scale:.4g} per time unit of the file, the model's is 1")
        # the window and prefilter do not depend on ip: read ip on the data every fit uses
        data = WindowData(measurements, 0.3 if ip is None else float(ip), equation, window_fraction, t_start)
        check_excitation(data.raw)
        est = estimate_ip_and_stiffness(data.data, model.effects, data.raw_data, data.noise_gain, candidates)
        ip_hat, ip_se = est.ip, est.standard_error
        if not math.isfinite(ip_hat):
            raise NotIdentifiable("the gyroscopic moment is not excited (no speed or no rates)")
        ip_est = float(min(max(ip_hat, 0.0), 0.95))
        ip_note = None  # the note of an estimate the widest model could not trust (revised below)
        if ip is None:
            ip_used = ip_est
            ip_note = None if est.trusted else len(notes)
            notes.append(f"ip estimated from the data: {ip_hat:.4f} ± {1.96 * ip_se:.2g} (95 %)"
                         + ("" if est.trusted else
                            f"; uncertain: the widest library model leaves {est.rms_ratio:.1f}x the noise "
                            "floor, so something outside the library biases it"))
        else:
            ip_used = float(ip)
            contradicted = abs(ip - ip_hat) > max(IP_TOLERANCE, 5.0 * ip_se)
            if contradicted and est.trusted:
                msg = (f"the data contradict ip = {ip:g}: the gyroscopic moment gives ip = {ip_hat:.4f} "
                       f"± {1.96 * ip_se:.2g}; a wrong ip shows up as a false stiffness change")
                warnings.warn(msg, stacklevel=2)
                notes.append("WARNING: " + msg)
            elif contradicted:
                notes.append(f"ip = {ip:g} not checked: the data give {ip_hat:.4f}, but the widest library "
                             f"model leaves {est.rms_ratio:.1f}x the noise floor (a fault outside the "
                             "library biases that estimate)")
        data.ip = ip_used
        # an estimated ip is uncertain: effects it could mimic are checked against that
        data.ip_uncertainty = 1.96 * ip_se if ip is None else 0.0
    except NotIdentifiable as exc:
        return NotIdentifiableResult(source=measurements.source, reason=str(exc), ip=ip, notes=notes)
    from .from_angles import diagnose_angles, needs_output_error
    from .output_error import library_effects

    if needs_output_error(measurements) and all(e in library_effects() for e in model.effects):
        # accelerations differentiated from noisy angles: the equation error is noise, the
        # decisions are taken on the output error (from_angles' docstring)
        return diagnose_angles(in_file_time, model.effects, candidates, ip=ip, alpha=alpha,
                               notes=[n for n in notes if not n.startswith(("ip estimated from the data",
                                                                             "time rescaled by"))],
                               progress=progress)
    from ..progress import bar

    step("fitting the starting model")
    current = compare(data, model.effects, known_values(model.effects))
    before = current
    floor = estimate_noise_floor(data, before)
    rounds: list[list[Candidate]] = []
    lookalikes: list[dict] = []
    missing: list[str] = []
    steps: list[Comparison] = []
    remaining = list(candidates)
    while remaining and len(rounds) < max_rounds:
        if floor > 0 and current.rms < floor and not data.noisy:
            break  # noise-free data below the numerical floor: what is left is round-off
        pbar = bar(f"round {len(rounds) + 1}: ranking the candidates", len(remaining), "candidates",
                   enabled=progress)
        ranked = rank_candidates(data, current, remaining, known_values(current.model), alpha, min_fit_gain, min_energy_drop)
        if pbar is not None:
            pbar.close()
        rounds.append(ranked)
        step(f"round {len(rounds)}: checking the best candidates")
        chosen = _choose(data, current, ranked, floor, alpha)
        if chosen is None:
            break
        decided = lookalike_evidence(data, current, ranked, chosen)
        chosen.checks["lookalikes"] = decided
        lookalikes.append(decided)
        missing.append(chosen.effect)
        current = chosen.comparison
        if chosen.onset is not None:
            current = appears_or_changes(data, current, chosen.effect, alpha, min_energy_drop)
        steps.append(current)
        remaining.remove(chosen.effect)
    step("onsets, robust statistics and the verdict")
    onset = {
        e: current.onsets.get(e)
        if e in current.onsets
        else change_time(data, current, e, known_values(current.model), alpha, min_energy_drop)
        for e in missing
    }
    for e in missing:
        if EFFECTS[e].caveat:
            notes.append(f"{e}: {EFFECTS[e].caveat}")
    for comp in {id(c): c for c in (before, *steps, current)}.values():
        make_robust(data, comp, alpha)
    # the reported values: noise in the regressors biases c and h low (see .eiv)
    correct_errors_in_variables(data, current)
    floor = estimate_noise_floor(data, current)
    # the first equation's rows: one residual per sample, white where the model is right
    windows, _ = failing_windows(data.meas.t, first_rows(before.residual, equation), floor=floor,
                                 speed=data.meas.phi_dot)
    ratio = current.rms / floor if floor > 0 else math.inf
    verdict = verdict_of(bool(missing), ratio)
    if ip_note is not None and verdict in ("explained", "explained_after_adding"):
        # the widest model's misfit was its own (every effect at once), not a fault outside
        # the library: the final model, fitted with this ip, explains the record
        notes[ip_note] = (f"ip estimated from the data: {ip_hat:.4f} ± {1.96 * ip_se:.2g} (95 %); the widest library "
                          f"model (every effect at once) left {est.rms_ratio:.1f}x the noise floor, the final model "
                          f"fitted with this ip explains the record ({ratio:.2g}x the floor)")
    rejected: dict[str, tuple[int, str]] = {}
    for k, r in enumerate(rounds, start=1):
        for c in r:
            if c.rejected_by is not None and c.effect not in missing:
                rejected[c.effect] = (k, c.rejected_by)  # the last round that decided it
    return Diagnosis(
        source=measurements.source, ip=ip_used, alpha=alpha, equation=equation, t_start=data.t_start,
        start_model=model.effects, model=current.model, missing=missing, onset=onset, rounds=rounds,
        before=before, after=current, windows=windows, noise_floor=floor, data=data, steps=steps,
        verdict=verdict, rms_ratio_after=ratio, rms_ratio_before=before.rms / floor if floor > 0 else math.inf,
        unexplained=describe_unexplained(data, current, floor) if verdict in ("partly_explained", "unexplained")
        else None,
        rejected=[{"effect": e, "rule": rule, "round": k} for e, (k, rule) in rejected.items()],
        ip_estimate=ip_hat, ip_standard_error=ip_se, time_scale=time_scale, notes=notes,
        lookalikes=lookalikes,
    )


def _choose(data, base: Comparison, ranked: list[Candidate], floor: float, alpha: float) -> Candidate | None:
    """The best candidate that is significant, relevant and passes the physics checks."""
    n = max(1, len(ranked))
    for c in ranked:
        if c.rejected_by is not None:  # turned down while ranked (a scan that found no value)
            continue
        if not c.significant:
            c.rejected_by = (f"not significant: HAC Wald test log10 p = {c.log10_p:.3g} "
                             f"(needs < {math.log10(alpha / n):.3g})")
            continue
        if not c.relevant:
            c.rejected_by = (f"not relevant: removes {100 * c.energy_drop:.1f} % of the equation error, "
                             f"free-run fit {c.fit_gain:+.1f} points")
            continue
        rule, evidence = check_candidate(data, base, c, floor, tuple(r.effect for r in ranked))
        c.checks = evidence
        if rule is None:
            return c
        c.rejected_by = rule
    return None
