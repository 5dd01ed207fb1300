r"""Where the linear influence model fails, with the evidence, and which physics removes it.

Two checks, per run and probe, against the scatter of the repeats:

1. **Influence** (needs more runs than planes + 1): run ``k``'s mean vectors against the
   fitted model ``X_0 + H W_k``.  The weighted residual at a speed has variance
   ``v_{k,sp} (1 - h_{k,sp})`` (``h``: the run's leverage in the weighted regression), so
   ``z = r / sqrt(v (1 - h))`` is standard circular and ``2 sum_s |z|^2 ~ chi2(2S)``; with
   the variance estimated from ``nu`` degrees of freedom of repeats, ``sum_s |z|^2 / S ~
   F(2S, nu)``.  A cell is flagged below ``alpha / cells`` (Bonferroni over the runs and
   probes: a linear rig is flagged in about ``alpha`` of campaigns).  The evidence:
   the change of vibration the run's weight caused against the change the model
   predicts (ratio of magnitudes, difference of angles) — a response not proportional
   to the weight; for several planes, whether the runs with weights on more than one
   plane contradict the single-plane runs (the planes' effects do not add).
2. **One unbalance** (needs more speeds x probes than planes): the run's vibration
   against ``H U_k`` with the unbalance ``U_k`` fitted to all its speeds and probes by
   generalized least squares, each speed and probe weighted by the variance of the run's
   response net of the influence coefficients' (the first-order propagation of
   :mod:`.influence`); the whitened residual is ``chi2(2 (N - J))``.

The physical explanations tried when a check fails (each a larger model refitted; the
first whose check passes is named):

* **speed-dependent coefficient** — a run's speed differs from the reference's (within the
  matching tolerance) and the response changes fast with speed (near a critical):
  ``X = X_0 + H W + d_k (X_0' + H' W)``, ``d_k`` the run's mean speed minus the reference's;
* **real-linear response** — ``X = X_0 + H W + A conj(W)``: vectors that are not
  steady-state (a run-up's free vibration at the natural frequency leaks into the
  per-revolution 1X vector of a real signal as ``c A + c' conj(A)``);
* **amplitude-dependent influence** — ``X = X_0 + H W + D W |W| / max|W|``: a rub or a
  clearance (the response not proportional to the weight): a non-linear rotor;
* **speed-dependent unbalance** (check 2) — one unbalance per speed: a second mode near
  the speeds, or an unbalance outside the planes weighted, makes the effective unbalance
  change with speed (one correction cannot suit every speed).

The influence coefficients are per speed and per probe: a coefficient that changes with
speed is the model, not a misfit, and so is **support anisotropy** — a linear rotor on
anisotropic supports whirls on ellipses, but each probe's 1X vector stays complex-linear
in the unbalance (the force ``Omega^2 U`` enters linearly, and so does the response of
every coordinate), so per-probe coefficients carry it exactly (tests/test_balance.py
checks it on an anisotropic rotor).  It is the isotropic model-based unbalance
(:func:`rotor_env.balance.model_based_unbalance`) that anisotropy biases.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from .influence import InfluenceFit

__all__ = ["influence_misfit", "unbalance_misfit"]

ALPHA = 0.01


def _pvalue(stat2: float, dfn: int, fit: InfluenceFit) -> float:
    """``stat2 = 2 sum |z|^2`` (chi2 with dfn under the null); F when the scale was estimated."""
    if fit.variance_source == "repeats" and fit.dof > 0:
        return float(stats.f.sf(stat2 / dfn, dfn, fit.dof))
    return float(stats.chi2.sf(stat2, dfn))


def _pvalue_f(stat2: float, dfn: float, fit: InfluenceFit) -> float:
    """:func:`_pvalue` for fractional degrees of freedom."""
    if fit.variance_source == "repeats" and fit.dof > 0:
        return float(stats.f.sf(stat2 / dfn, dfn, fit.dof))
    return float(stats.chi2.sf(stat2, dfn))


def _refit(fit: InfluenceFit, extra: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Weighted residuals z (K, S, P) of the influence model with ``extra`` columns (K, m) added."""
    K = fit.W.shape[0]
    Y, v = fit.data.Y, fit.v
    _, S, P = Y.shape
    ex = extra if extra.ndim == 3 else np.repeat(extra[:, None, :], S, axis=1)  # (K, S, m)
    if 1 + fit.W.shape[1] + ex.shape[2] >= K:
        return None
    z = np.zeros((K, S, P), dtype=complex)
    for s in range(S):
        A = np.column_stack([np.ones(K), fit.W, ex[:, s]])
        if np.linalg.matrix_rank(A) < A.shape[1]:
            return None
        for p in range(P):
            w = 1.0 / v[:, s, p]
            AhW = A.conj().T * w[None, :]
            L = np.linalg.pinv(AhW @ A) @ AhW
            hat = A @ L
            r = Y[:, s, p] - hat @ Y[:, s, p]
            lev = np.clip(np.real(np.diag(hat)), 0.0, 1.0 - 1e-12)
            z[:, s, p] = r / np.sqrt(v[:, s, p] * (1.0 - lev))
    return z, None


def _check(fit: InfluenceFit, z: np.ndarray, alpha: float) -> tuple[list[dict], float]:
    K, S, P = z.shape
    cells = []
    n_cells = K * P
    for k in range(K):
        for p in range(P):
            stat2 = float(2 * np.sum(np.abs(z[k, :, p]) ** 2))
            pv = _pvalue(stat2, 2 * S, fit)
            cells.append({"run": fit.data.runs[k], "probe": fit.data.probes[p], "chi2": stat2, "dof": 2 * S,
                          "p_value": pv, "flagged": pv < alpha / n_cells,
                          "worst_rpm": float(fit.data.rpm[int(np.argmax(np.abs(z[k, :, p])))])})
    total = float(2 * np.sum(np.abs(z) ** 2))
    # the total's degrees of freedom: 2 (K - columns) per speed and probe
    return cells, total


def influence_misfit(fit: InfluenceFit, alpha: float = ALPHA) -> dict:
    """Check 1 of the module docstring, its evidence and the explanations tried."""
    K, J = fit.W.shape
    S, P = fit.H.shape[:2]
    if K <= J + 1:
        return {"testable": False, "reason": f"{K} runs for {J} plane(s): the influence model passes through every "
                "run exactly; a run more (another trial weight, of another size or angle) tests it", "cells": []}
    if fit.variance_source != "repeats":
        note = "no repeats: the noise level is taken from the same residuals, so only the spread of the misfit " \
               "across runs shows"
    else:
        note = ""
    z = fit.residual / np.sqrt(fit.v * np.clip(1.0 - fit.leverage, 1e-12, None))
    cells, _ = _check(fit, z, alpha)
    flagged = [c for c in cells if c["flagged"]]
    out = {"testable": True, "alpha": alpha, "cells": cells, "flagged": flagged, "note": note,
           "evidence": [], "explanations": [], "explained_by": None}
    if not flagged:
        return out
    # evidence: the change each flagged run's weight caused against the model's prediction
    worst: dict[str, dict] = {}
    for c in flagged:  # per run, the probe that misfits most
        if c["run"] not in worst or c["p_value"] < worst[c["run"]]["p_value"]:
            worst[c["run"]] = c
    for c in worst.values():
        k = fit.data.runs.index(c["run"])
        p = fit.data.probes.index(c["probe"])
        s = int(np.argmin(np.abs(fit.data.rpm - c["worst_rpm"])))
        pred = fit.H[s, p] @ fit.W[k]
        obs = fit.data.Y[k, s, p] - fit.X0[s, p]
        planes = [fit.campaign.plane_names[j] for j in range(J) if fit.W[k, j] != 0]
        ev = {"run": c["run"], "probe": c["probe"], "rpm": c["worst_rpm"], "planes": planes}
        if abs(pred) > 0 and k > 0:
            ratio = abs(obs) / abs(pred)
            dang = math.degrees(math.remainder(math.atan2((obs / pred).imag, (obs / pred).real), 2 * math.pi))
            ev.update({"response_ratio": ratio, "response_angle_deg": dang,
                       "text": f"run {c['run']} ({'+'.join(planes)} weighted): at {c['worst_rpm']:.0f} rpm its "
                               f"weight changed {c['probe']} by {ratio:.2f}x the linear model's change, {dang:+.0f} "
                               f"deg off (misfit p = {c['p_value']:.2g})"})
        else:
            ev["text"] = (f"run {c['run']} (reference): {c['probe']} at {c['worst_rpm']:.0f} rpm off the influence "
                          f"model fitted to all runs (p = {c['p_value']:.2g})")
        out["evidence"].append(ev)
    # the direct evidence of a response not proportional to the weight: each single-plane run's
    # apparent influence (its change over its weight) where the misfit is worst
    c0 = min(flagged, key=lambda c: c["p_value"])
    p0 = fit.data.probes.index(c0["probe"])
    s0 = int(np.argmin(np.abs(fit.data.rpm - c0["worst_rpm"])))
    unit = fit.data.amp_unit
    for j, plane in enumerate(fit.campaign.plane_names):
        ks = [k for k in range(1, K) if fit.W[k, j] != 0 and np.count_nonzero(fit.W[k]) == 1]
        if len(ks) < 2:
            continue
        app = [(fit.data.runs[k], abs(fit.W[k, j]), (fit.data.Y[k, s0, p0] - fit.X0[s0, p0]) / fit.W[k, j]) for k in ks]
        mags = np.array([abs(a[2]) for a in app])
        out["evidence"].append({
            "plane": plane, "probe": c0["probe"], "rpm": c0["worst_rpm"],
            "apparent_influence": [{"run": r, "weight_g_mm": w, "amp_per_g_mm": abs(h),
                                    "angle_deg": float(np.mod(-np.degrees(np.angle(h)), 360.0))} for r, w, h in app],
            "text": f"plane {plane}, {c0['probe']} at {c0['worst_rpm']:.0f} rpm: apparent influence "
                    + ", ".join(f"{abs(h):.3g} {unit}/(g·mm) for {w:.0f} g·mm ({r})" for r, w, h in app)
                    + f" — a spread of {100 * (mags.max() / mags.min() - 1):.0f} %"})
    multi = {r for k, r in enumerate(fit.data.runs) if np.count_nonzero(fit.W[k]) > 1}
    single = {r for k, r in enumerate(fit.data.runs) if np.count_nonzero(fit.W[k]) == 1}
    bad_runs = {c["run"] for c in flagged}
    if J > 1 and multi and bad_runs <= multi | {fit.campaign.reference} and bad_runs & multi:
        out["evidence"].append({"text": f"runs with weights on several planes ({', '.join(sorted(bad_runs & multi))}) "
                                f"contradict the single-plane runs ({', '.join(sorted(single))}): the planes' "
                                "effects do not add"})
    # explanations: larger models; the first whose check passes removes the misfit
    Wmax = np.max(np.abs(fit.W))
    trials = []
    if fit.data.run_rpm is not None:
        offset = fit.data.run_rpm - fit.data.run_rpm[:1]  # (K, S): each run's speed against the reference's
        if np.ptp(offset) > 0:
            # first order in the speed offset d: X0(rpm) + H(rpm) W ≈ X0 + H W + d (X0' + H' W)
            extra = np.concatenate([offset[:, :, None], offset[:, :, None] * fit.W[:, None, :]], axis=2)
            trials.append(("speed_dependent_coefficient", extra,
                           "the runs' speeds differ from the reference's and the response changes fast with speed "
                           "(a critical near): X0 + H W + d (X0' + H' W), d the run's speed offset; hold the speed "
                           "closer between runs, or tighten speed_tolerance_rpm"))
    trials.append(("real_linear_response", np.conj(fit.W),
                   "the response is real-linear, not complex-linear, in the weight (X0 + H W + A conj W): vectors "
                   "that are not steady-state (a run-up's free vibration leaks into the per-revolution 1X vector as "
                   "c A + c' conj A); balance from steady-speed acquisitions"))
    trials.append(("amplitude_dependent", fit.W * np.abs(fit.W) / Wmax,
               "the influence changes with the weight's size (X0 + H W + D W|W|): a non-linear rotor (rub, "
               "clearance, loose part); do not trust the linear correction: fix the cause, or balance in steps "
               "with trial weights of the correction's size"))
    for name, extra, why in trials:
        res = _refit(fit, extra)
        if res is None:
            out["explanations"].append({"explanation": name, "testable": False,
                                        "reason": f"needs more than {1 + J + extra.shape[1]} runs"})
            continue
        z2, _ = res
        cells2, _ = _check(fit, z2, alpha)
        n_bad = sum(c["flagged"] for c in cells2)
        removes = n_bad == 0
        out["explanations"].append({"explanation": name, "testable": True, "flagged_after": n_bad,
                                    "removes_misfit": removes, "meaning": why})
        if removes and out["explained_by"] is None:
            out["explained_by"] = name
    return out


def unbalance_misfit(fit: InfluenceFit, alpha: float = ALPHA) -> dict:
    """Check 2 of the module docstring: does one unbalance explain every speed and probe of a run?

    The run's unbalance is refitted by generalized least squares with the weights
    ``1/q_sp`` (the variance of its response net of the influence coefficients'
    uncertainty, :meth:`InfluenceFit._q`); the whitened residual ``sum |e|^2 / q`` is then
    ``chi2(2 (N - J)) / 2`` for a linear rotor, and a probe's share has ``2 sum (1 - h)``
    degrees of freedom (``h``: the weighted leverage of its speeds).  Linear in ``N``: a
    sweep of thousands of revolutions costs no ``N x N`` matrix.
    """
    S, P, J = fit.H.shape
    N = S * P
    if N <= J:
        return {"testable": False, "reason": f"{N} speed-probe pairs for {J} plane(s): no redundancy", "runs": {}}
    H = fit.Hmat
    runs = {}
    n_tests = len(fit.data.runs) * (P + 1)
    probe_of = np.tile(np.arange(P), S)
    for k, run in enumerate(fit.data.runs):
        c = fit.run_combination(k)
        U, _ = fit.unbalance(c)
        q = fit.noise_terms(c, U)
        X = fit.data.Y[k].reshape(-1)
        sw = 1.0 / np.sqrt(q)
        Hw = H * sw[:, None]
        Uq = np.linalg.lstsq(Hw, X * sw, rcond=None)[0]
        z = (X - H @ Uq) * sw
        Q, _ = np.linalg.qr(Hw)
        lev = np.sum(np.abs(Q) ** 2, axis=1)
        entry = {}
        for label, idx in [("all", np.arange(N))] + [(fit.data.probes[p], np.flatnonzero(probe_of == p))
                                                      for p in range(P)]:
            dof = float(2 * np.sum(1.0 - lev[idx]))
            if dof < 0.5:
                continue
            stat2 = float(2 * np.sum(np.abs(z[idx]) ** 2))
            pv = _pvalue_f(stat2, dof, fit)
            entry[label] = {"chi2": stat2, "dof": dof, "p_value": pv, "flagged": pv < alpha / n_tests}
        runs[run] = entry
    flagged = [r for r, e in runs.items() if any(v["flagged"] for v in e.values())]
    out = {"testable": True, "alpha": alpha, "runs": runs, "flagged": flagged, "explained_by": None,
           "explanations": []}
    if flagged:
        if P > J:
            # one unbalance per speed (a second mode near the speeds, an unbalance outside the planes)
            bad = 0
            for k in range(len(fit.data.runs)):
                for s in range(S):
                    Hs = fit.H[s]
                    ws = 1.0 / fit.v[k, s]
                    Us = np.linalg.lstsq(Hs * np.sqrt(ws)[:, None], fit.data.Y[k, s] * np.sqrt(ws), rcond=None)[0]
                    r = (fit.data.Y[k, s] - Hs @ Us) * np.sqrt(ws)
                    stat2 = float(2 * np.sum(np.abs(r) ** 2))
                    bad += _pvalue(stat2, 2 * (P - J), fit) < alpha / (len(fit.data.runs) * S)
            removes = bad == 0
            out["explanations"].append({"explanation": "speed_dependent_unbalance", "testable": True,
                                        "removes_misfit": removes,
                                        "meaning": "the unbalance the probes see changes with speed: a second mode "
                                        "near the speeds, or an unbalance outside the planes weighted; one "
                                        "correction cannot suit every speed: balance for the service speed, or add "
                                        "a plane"})
            if removes:
                out["explained_by"] = "speed_dependent_unbalance"
        else:
            out["explanations"].append({"explanation": "speed_dependent_unbalance", "testable": False,
                                        "reason": "as many probes as planes at each speed: an unbalance per speed "
                                        "fits every speed exactly (consistent with a second mode near the "
                                        "speeds or an unbalance outside the planes, not a test of it)"})
    return out
