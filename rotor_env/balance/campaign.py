"""The balancing campaign: read, fit, correct, check (the package's entry :func:`balance`)."""

from __future__ import annotations

import os

import numpy as np

from .influence import InfluenceFit, fit_influence, visibility
from .misfit import influence_misfit, unbalance_misfit
from .profile import joint_variances
from .result import BalanceResult
from .runs import (
    BalanceData,
    BalanceError,
    Campaign,
    load_campaign,
    read_balance_table,
    stack_tables,
)

__all__ = ["BalanceData", "BalanceError", "BalanceResult", "Campaign", "InfluenceFit", "balance", "balance_data",
           "load_campaign", "model_based_unbalance", "read_balance_table", "stack_tables"]

#: a plane whose influence is not significant at this level (Wald test) is not seen by the calibration
VISIBILITY_P = 0.05
#: below this RMS ratio of a plane's influence to its standard error the intervals are noted as optimistic
LOW_SNR = 10.0


def balance(table: str | os.PathLike, runs: str | os.PathLike | Campaign, *, amp_unit: str = "um",
            phase: str = "lag", probe_angles: dict[str, float] | None = None,
            probe_planes: dict[str, str] | None = None, model_based: bool = True) -> BalanceResult:
    """Balance from a table file and a runs file (or a :class:`Campaign`).

    ``probe_angles`` (degrees, in the direction of rotation) and ``probe_planes`` (probe ->
    plane) come from the rig file; the two-plane model-based unbalance needs both.
    """
    campaign = runs if isinstance(runs, Campaign) else load_campaign(runs)
    data = read_balance_table(table, campaign, amp_unit=amp_unit, phase=phase)
    res = balance_data(data, campaign, phase=phase)
    if model_based and campaign.disk_mass_kg:
        try:
            res.model_based = model_based_unbalance(table, campaign, amp_unit=amp_unit, phase=phase,
                                                    probe_angles=probe_angles, probe_planes=probe_planes)
        except (ValueError, np.linalg.LinAlgError) as exc:
            res.notes.append(f"model-based unbalance not computed: {exc}")
    return res


def balance_data(data: BalanceData, campaign: Campaign, *, phase: str = "lag") -> BalanceResult:
    """:func:`balance` on a table already grouped (simulations, tests)."""
    fit = fit_influence(data, campaign, phase=phase)
    notes = []
    vis = visibility(fit) if fit.variance_source != "none" else []
    unseen = [v for v in vis if v["p_value"] > VISIBILITY_P]
    if unseen:
        v = unseen[0]
        raise BalanceError(
            f"{campaign.source}: plane {v['plane']!r}: the calibration cannot see it: its trial weights changed the "
            f"vibration by no more than the repeats' scatter (Wald p = {v['p_value']:.2g}, largest change "
            f"{v['snr']:.2g} standard errors) in {data.source}; use a larger trial weight (a change of at least "
            "30 % or 30 deg)")
    weak = [v for v in vis if v["rms_snr"] < LOW_SNR]
    if weak:
        notes.append("trial weights of plane(s) " + ", ".join(f"{v['plane']} ({v['rms_snr']:.2g})" for v in weak)
                     + f" moved the vibration by fewer than {LOW_SNR:g} standard errors (RMS over speeds and probes): "
                     "the first-order intervals under-cover there (docs/BALANCING.md §4); use larger trial weights "
                     "or more repeats")
    if fit.variance_source == "none":
        notes.append("no repeats and no run beyond the planes + 1: the noise cannot be estimated, no intervals")
    elif fit.variance_source == "residuals":
        notes.append("no repeats: the noise level is estimated from the influence residuals (one level for all)")
    if fit.condition_number > 30:
        notes.append(f"condition number {fit.condition_number:.3g}: the planes act alike at these probes and speeds; "
                     "the correction splits between them poorly (add speeds or probes where they differ)")
    c0 = fit.reference_combination()
    U_two_stage, _ = fit.unbalance(c0)
    # the unbalance: maximum likelihood of every run at once (profile.py), started from the
    # two-stage estimate; its intervals are the profile likelihood's (a ratio at low SNR is far
    # from its linearisation); the first-order covariance stays for the residual and the grade
    joint = joint_variances(fit).fit(U_two_stage)
    U0 = joint.U
    cov0 = fit.unbalance_covariance(c0, U0)
    unb = {}
    for k, run in enumerate(data.runs):
        Uk = U0 + fit.W[k]
        unb[run] = (Uk, fit.unbalance_covariance(fit.run_combination(k), Uk))
    residual = fit.residual_vibration(c0, U0)
    im = influence_misfit(fit) if fit.variance_source != "none" else {"testable": False, "reason": "no noise level"}
    um = unbalance_misfit(fit) if fit.variance_source != "none" else {"testable": False, "reason": "no noise level"}
    if im.get("flagged") and um.get("flagged"):
        # the one-unbalance check rests on the influence coefficients: while they misfit, what
        # removes its misfit says nothing
        um["explained_by"] = None
        um["explanations"] = [{"explanation": e["explanation"], "testable": False,
                               "reason": "the influence coefficients it rests on misfit (above)"}
                              for e in um.get("explanations", [])]
    return BalanceResult(fit, unb, (U0, cov0), residual, im, um, vis, None, notes, joint=joint)


def model_based_unbalance(table: str | os.PathLike, campaign: Campaign, *, run: str | None = None,
                          amp_unit: str = "um", phase: str = "lag",
                          probe_angles: dict[str, float] | None = None,
                          probe_planes: dict[str, str] | None = None) -> dict:
    """The unbalance from one run-up of ``run`` (default the reference), no trial weight.

    Two planes: :func:`_model_based_two_planes` (two disks on a shaft, :mod:`.model_based`).

    The 1X transient fit of :func:`rotor_env.diagnosis.from_vectors.diagnose_vectors`
    (damping, natural frequency, unbalance) on the run's rows; its eccentricity times the
    disk mass (``disk_mass_kg`` of the runs file) is the unbalance in g·mm.  One plane only
    (the translation model); the angle is counted from the probes' reference direction
    (``probe_angles``, the rig's), which is the keyphasor's when the keyphasor sits there;
    without the probe angles, as the first probe sees it.
    """
    from ..diagnosis.from_vectors import diagnose_vectors
    from ..measurements.vectors import VectorTable, load_vector_table

    if len(campaign.planes) == 2:
        return _model_based_two_planes(table, campaign, run=run, amp_unit=amp_unit, phase=phase,
                                       probe_angles=probe_angles, probe_planes=probe_planes)
    if len(campaign.planes) != 1:
        raise BalanceError("the model-based unbalance models one or two planes (one disk, or two disks on a "
                           f"shaft): this campaign has {len(campaign.planes)}")
    plane = campaign.planes[0].name
    if plane not in campaign.disk_mass_kg:
        raise BalanceError(f"{campaign.source}: disk_mass_kg.{plane} is missing")
    run = run or campaign.reference
    full = load_vector_table(table, amp_unit=amp_unit, phase=phase, run_column="run", angles=probe_angles)
    rows = np.array([r == run for r in full.runs])
    if rows.sum() < 8:
        raise BalanceError(f"{full.source}: run {run!r} has {int(rows.sum())} rows; the model-based unbalance needs a "
                           "run-up or coast-down (at least 8 speeds)")
    order = np.argsort(full.speed[rows], kind="stable")
    t = None if full.t is None else full.t[rows][order]
    if t is not None and not np.all(np.diff(t) > 0):
        t = None
    sub = VectorTable(speed=full.speed[rows][order], t=t, probes=full.probes,
                      vectors={n: v[rows][order] for n, v in full.vectors.items()}, amp_unit=full.amp_unit,
                      angles=full.angles, source=f"{full.source} (run {run})")
    diag = diagnose_vectors(sub, candidates=(), phase=phase)
    u = diag.unbalance(campaign.disk_mass_kg[plane])
    if u is None or u["g_mm"] is None:
        raise BalanceError("the 1X fit found no unbalance in the table's unit")
    ang = u["angle_deg_lag"] if phase == "lag" else float(np.mod(-u["angle_deg_lag"], 360.0))
    return {"run": run, "plane": plane, "g_mm": u["g_mm"], "angle_deg": ang,
            "eccentricity": u["eccentricity"], "disk_mass_kg": campaign.disk_mass_kg[plane],
            "natural_frequency_rpm": float(diag.after.w_ref * 60 / (2 * np.pi)),
            "frame": "probe reference direction" if probe_angles else "as the first probe sees it (no probe angles)"}


def _model_based_two_planes(table: str | os.PathLike, campaign: Campaign, *, run: str | None, amp_unit: str,
                            phase: str, probe_angles: dict[str, float] | None,
                            probe_planes: dict[str, str] | None) -> dict:
    """Two planes: the two-disk model fitted to one run-up (:func:`.model_based.fit_run_up`).

    Needs ``disk_mass_kg`` for both planes and, from the rig file, every probe's plane and
    angle.  Says what the run-up cannot decide (the split between the planes).
    """
    from ..measurements.vectors import AMPLITUDE_UNITS, load_vector_table
    from .model_based import fit_run_up

    names = campaign.plane_names
    missing = [nm for nm in names if nm not in campaign.disk_mass_kg]
    if missing:
        raise BalanceError(f"{campaign.source}: disk_mass_kg.{missing[0]} is missing (the two-plane model-based "
                           "unbalance needs the mass of each plane's disk)")
    run = run or campaign.reference
    full = load_vector_table(table, amp_unit=amp_unit, phase=phase, run_column="run")
    if not probe_planes or not probe_angles:
        raise BalanceError(f"{full.source}: the two-plane model-based unbalance needs each probe's plane and angle "
                           "(--rig with probes: [{name, angle_deg, plane}])")
    probes = []
    for nm in full.probes:
        if nm not in probe_planes or nm not in probe_angles:
            raise BalanceError(f"{full.source}, column {nm + '_amp'!r}: probe {nm!r} is not in the rig file "
                               "(its plane and angle are needed)")
        if probe_planes[nm] not in names:
            raise BalanceError(f"{full.source}, column {nm + '_amp'!r}: the rig puts probe {nm!r} on plane "
                               f"{probe_planes[nm]!r}, not one of the runs file's planes {list(names)}")
        probes.append((names.index(probe_planes[nm]), float(probe_angles[nm])))
    rows = np.array([r == run for r in full.runs])
    order = np.argsort(full.speed[rows], kind="stable")
    rpm = full.rpm[rows][order]
    Y = full.vectors[1][rows][order]
    try:
        fit = fit_run_up(rpm, Y, probes, [campaign.disk_mass_kg[nm] for nm in names],
                         amp_scale=AMPLITUDE_UNITS[full.amp_unit])
    except ValueError as exc:
        raise BalanceError(f"{full.source} (run {run}): {exc}") from exc
    out = {"run": run, "model": "two disks on a shaft, isotropic supports (docs/BALANCING.md §3)",
           "disk_mass_kg": {nm: campaign.disk_mass_kg[nm] for nm in names},
           "frame": "probe reference direction", **fit.to_dict(names, phase)}
    return out
