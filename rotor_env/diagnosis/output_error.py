"""Output-error identification: the model fitted where the data were measured.

Why
---
The equation error (PHYSICS.md section 3) needs the second derivative of the measured
displacements.  A rig records displacements with noise; differentiating twice multiplies
the noise at frequency ``f`` by ``(2 pi f)^2``, so at 0.5 um probe noise the equation error
is noise at every speed and its energy no longer moves when an effect is added.  The
output error ``e = y - y_hat(theta)`` compares the *measured displacements* with the
model's predicted response: its noise is the probes' own, and what is left above it is
the model's misfit.  This is the prediction-error method (Ljung, *System Identification*,
2nd ed., ch. 7; MATLAB's ``pem``/``oe``) for the rotor's equations.

What we chose: multiple shooting with the start states projected out
--------------------------------------------------------------------
A free run of a lightly damped rotor through its critical from one start state is a
badly conditioned, multi-modal problem (a 0.5 % error of the natural frequency turns the
phase of the free whirl by half a turn over a few hundred periods).  Multiple shooting
(Bock 1983; Voss, Timmer & Kurths 2004) cuts the record into ``S`` segments of a few
natural periods, each starting from its own state ``x0_s = (th_x, th_y, th_x', th_y')``:

    min over theta, x0_1..x0_S   sum_s sum_{k in s} |y_k - C x(t_k; theta, x0_s)|^2

We do not enforce continuity between segments: every segment's start state is a free
nuisance parameter (4 per segment), eliminated at every Gauss-Newton step by variable
projection (Golub & Pereyra 1973): the segment's rows of the Jacobian and residual are
projected on the orthogonal complement of its start-state columns, and the reduced
problem in ``theta`` alone is solved with Levenberg-Marquardt damping.  What this gives
up is the information in the free whirl's continuity across a cut (little, when a
segment holds a few periods); what it buys is a fit that is stable through the
critical from an equation-error start, with no divergence of a long free run.

Why not a Kalman predictor: a one-step predictor with process noise would fit the
model's misfit into its state and leave white innovations even for a wrong model — the
diagnosis needs the misfit to *stay* in the residual, where the missing effect's orders
can be read; the segments' free start states absorb only the transient.

Sensitivities
-------------
The model is ``x' = f(x, t; theta, a)`` with the effects' coefficients ``theta`` (linear in
``f``) and argument parameters ``a`` (orientations, the rub's clearance).  The forward
sensitivities ``S = dx/d(theta, a, x0)`` obey ``S' = A S + B`` with ``A = df/dx`` and
``B = df/d(theta, a)``; the compiled kernel integrates them with the state by the same
RK4 steps (one per sample, the spin between samples at constant acceleration, as the
simulator follows a measured profile).  ``B`` for a coefficient is the effect's column
itself; ``A`` and ``B`` for an argument are forward differences of the *column functions*
at the current state (exact for the linear effects, whose columns are linear in ``x``),
never differences of whole runs.

A second mode
-------------
Where the grid holds one (:attr:`ShootingGrid.second_mode`, :mod:`.second_mode`) every fit on it
predicts the first mode's orbit plus a second isotropic oscillator's, forced by the unbalance
through its own modal unbalance: four more parameters (its stiffness, damping and the modal
unbalance's two parts, after the output terms) and four more start-state columns per segment
(before the first mode's, projected out with them).

Uncertainty
-----------
``Cov(theta) = (J'J)^-1 S (J'J)^-1`` with ``J`` the projected Jacobian and ``S`` the
Bartlett (Newey-West) long-run covariance of the scores ``J_k' e_k`` per time sample
(:mod:`identifier.hac`): the prediction errors of a decimated, filtered probe signal are
coloured, and a misfit leaves them slowly varying.  The intervals cover the parameters
of the best model in the class the fit is given: their coverage on noisy probes is
measured by simulation in the tests.

Relation to the equation-error method
-------------------------------------
The paper's equation-error regression (and its recursive QR) stays the fast start and
the on-line core of the wrapper and the monitor: it is linear, needs no simulation and
is exact on clean or finely sampled angles.  Its estimates are biased by the noise of
estimated rates (errors in variables); the output-error fit starts from them and removes
that bias, at the cost of a simulation per iteration.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cache, cached_property, lru_cache
from pathlib import Path

import numpy as np
from numba import njit, prange

from identifier.hac import andrews_bandwidth, chi2_log10_sf, long_run_covariance

from ..effects import EFFECTS, Effect
from .second_mode import (
    MODE_PARAMETERS,
    N_MODE_PARAMETERS,
    N_MODE_STATES,
    SecondMode,
    shoot_second_mode,
    substeps,
)

__all__ = [
    "AddedEffectInformation",
    "OutputErrorFit",
    "ShootingGrid",
    "added_effect_information",
    "arguments_of",
    "canonical_scale",
    "coefficient_slice",
    "colour_inflation",
    "equation_error_start",
    "estimate_inflation",
    "fit_output_error",
    "library_effects",
    "noise_ar1_high_band",
    "noise_ar1_two_channels",
    "noise_std_high_band",
    "sample_scores",
    "start_from",
]

#: segment length of the multiple shooting, in the model's time unit (about two natural
#: periods: the free whirl from the start state is a small part of the prediction)
SEGMENT_LENGTH = 12.0
#: model time step of the shooting grid aimed at (RK4 per sample; the record is low-pass
#: decimated to it when finer)
GRID_DT = 0.12
#: at least this many samples per revolution at the top speed on the shooting grid
GRID_PER_TURN = 24
#: output terms fitted with every model (nuisance parameters, in the reading, not in the
#: rotor: no dynamics): the probes' static offsets (the gap removed by the mean leaves one);
#: a probe track's runout, a pattern fixed to the shaft angle -- its 1X (an eccentric track
#: seen by two orthogonal probes on one track is a forward circle; probes on tracks a little
#: apart, or a scratch under one of them, give each its own 1X, as a field engineer's
#: per-probe slow-roll vectors have: any 1X pattern of the two axes, forward and backward,
#: four terms) and its 2X (an oval track: each probe sees it at twice its own angle, so any
#: 2X pattern of the two axes, four terms).  Subtracting the slow-roll revolutions instead would take a cracked shaft's own
#: slow-roll 1X and 2X under its static load with it; fitted with the model, only what is
#: the same at every speed is taken, and the crack's 2X resonance at half the critical stays.
#: The last two are the probes' **calibration**: two probes of a plane whose sensitivities
#: differ by ``2 d`` (API 670 allows 5 % each) or whose angles are off by ``g1``, ``g2`` read the
#: orbit ``z`` as ``z (1 + ...) + eps conj(z)`` with ``eps = (d + i (g1 - g2) / 2) e^{2 i a1}``: a
#: backward whirl that follows the forward one at every speed (a support anisotropy's changes
#: through the critical), and ``z + eps conj(z)`` is fitted with every model (a 4 % sensitivity
#: difference read as ``support_anisotropy``).
OUTPUT_TERMS = ("offset_x", "offset_y", "runout_cos", "runout_sin",
                "runout2_x_cos", "runout2_x_sin", "runout2_y_cos", "runout2_y_sin",
                "runout_back_cos", "runout_back_sin", "calibration_re", "calibration_im")
N_OFFSETS = len(OUTPUT_TERMS)
#: the probes' calibration among the output terms (real and imaginary part of ``eps``)
CALIBRATION_TERMS = ("calibration_re", "calibration_im")
_CAL = OUTPUT_TERMS.index(CALIBRATION_TERMS[0])
#: a fit with a ``give_up_above`` stops where, at its last step's fall, it would need this
#: many times the steps left to come down to that level (the steps of a Levenberg-Marquardt
#: fit that crawls along a valley fall less and less, never more by ten)
GIVE_UP_MARGIN = 10.0
#: forward-difference step for A = df/dx (relative to 1 + |x|) and for the arguments
_FD_STATE = 1e-7
_FD_ARG = 1e-6


def library_effects() -> tuple[str, ...]:
    """The smooth library effects the output-error kernel is compiled for (set-valued dry
    friction is not: its stick phases make the sensitivities meaningless)."""
    from .. import effects as effects_module

    out = []
    for name, eff in EFFECTS.items():
        col = eff.columns
        if eff.dry_friction:
            continue
        if getattr(effects_module, getattr(col, "__name__", ""), None) is not col:
            continue  # a user effect: its source may change under the same name
        out.append(name)
    return tuple(out)


# ------------------------------------------------------------------ the compiled kernel
_KERNEL_TEMPLATE = '''
@njit(cache=True)
def rhs(ph, pd, pdd, x, S, theta, arg, active, actx, acta, pidx, midx, qidx, qlo, qhi, ip, cy, cx, cy2, cx2, xp, argp,
        fx, fS):
    # the moment of every coefficient of the model (midx); sensitivities of the free ones (pidx)
    columns(ph, pd, pdd, x[0], x[1], x[2], x[3], ip, arg, active, cy, cx)
    ay = -ip * pd * x[2]
    ax = ip * pd * x[3]
    for j in midx:
        ay += theta[j] * cy[j]
        ax += theta[j] * cx[j]
    fx[0] = x[2]
    fx[1] = x[3]
    fx[2] = ax
    fx[3] = ay
    nf = S.shape[1]
    for c in range(nf):
        fS[0, c] = S[2, c]
        fS[1, c] = S[3, c]
        fS[2, c] = 0.0
        fS[3, c] = 0.0
    # the state's differences evaluate only the effects that read the state (actx): the
    # others' columns are the same at the shifted state, copied (the same numbers, less work)
    for j in range(cy.shape[0]):
        cy2[j] = cy[j]
        cx2[j] = cx[j]
    for m in range(4):
        for q in range(4):
            xp[q] = x[q]
        h = FD_STATE * (1.0 + abs(x[m]))
        xp[m] += h
        columns(ph, pd, pdd, xp[0], xp[1], xp[2], xp[3], ip, arg, actx, cy2, cx2)
        ay2 = -ip * pd * xp[2]
        ax2 = ip * pd * xp[3]
        for j in midx:
            ay2 += theta[j] * cy2[j]
            ax2 += theta[j] * cx2[j]
        dax = (ax2 - ax) / h
        day = (ay2 - ay) / h
        for c in range(nf):
            fS[2, c] += dax * S[m, c]
            fS[3, c] += day * S[m, c]
    npar = pidx.shape[0]
    for i in range(npar):
        j = pidx[i]
        fS[2, i] += cx[j]
        fS[3, i] += cy[j]
    for i in range(qidx.shape[0]):
        for q in range(arg.shape[0]):
            argp[q] = arg[q]
        argp[qidx[i]] += FD_ARG
        # an argument's difference reads its own effect's columns only (acta: that effect)
        owner = ARG_OWNER[qidx[i]]
        acta[owner] = True
        columns(ph, pd, pdd, x[0], x[1], x[2], x[3], ip, argp, acta, cy2, cx2)
        acta[owner] = False
        gy = 0.0
        gx = 0.0
        for j in range(qlo[i], qhi[i]):
            gy += theta[j] * (cy2[j] - cy[j])
            gx += theta[j] * (cx2[j] - cx[j])
        fS[2, npar + i] += gx / FD_ARG
        fS[3, npar + i] += gy / FD_ARG


@njit(cache=True, parallel=True)
def shoot(t, phi, phid, seg, x0, theta, arg, active, pidx, midx, qidx, qlo, qhi, ip, nsub, pred, jac):
    # the segments are independent (each from its own start state): chunks of them in parallel,
    # each writing its own rows of pred and jac
    nseg = seg.shape[0]
    nchunk = min(nseg, 16)
    status = np.zeros(nchunk, np.int64)
    for ch in prange(nchunk):
        status[ch] = shoot_range(ch * nseg // nchunk, (ch + 1) * nseg // nchunk, t, phi, phid, seg, x0, theta,
                                 arg, active, pidx, midx, qidx, qlo, qhi, ip, nsub, pred, jac)
    for ch in range(nchunk):
        if status[ch] != 0:
            return status[ch]
    return 0


@njit(cache=True)
def shoot_range(s0, s1, t, phi, phid, seg, x0, theta, arg, active, pidx, midx, qidx, qlo, qhi, ip, nsub, pred, jac):
    ncol = theta.shape[0]
    cy = np.zeros(ncol)
    cx = np.zeros(ncol)
    cy2 = np.zeros(ncol)
    cx2 = np.zeros(ncol)
    xp = np.zeros(4)
    argp = arg.copy()
    actx = np.zeros(active.shape[0], np.bool_)
    for e in range(active.shape[0]):
        actx[e] = active[e] and STATE_DEP[e]
    acta = np.zeros(active.shape[0], np.bool_)
    # the sensitivities carried: the parameters' (coefficients, then arguments) and the start
    # state's; jac's output-term columns between them stay zero (no state depends on them),
    # and leaving them out of the integration saves almost half its work
    nf = jac.shape[2]
    nx0 = nf - 4
    nq = pidx.shape[0] + qidx.shape[0]
    ns = nq + 4
    S = np.zeros((4, ns))
    x = np.zeros(4)
    xs = np.zeros(4)
    Ss = np.zeros((4, ns))
    k1 = np.zeros(4)
    k2 = np.zeros(4)
    k3 = np.zeros(4)
    k4 = np.zeros(4)
    K1 = np.zeros((4, ns))
    K2 = np.zeros((4, ns))
    K3 = np.zeros((4, ns))
    K4 = np.zeros((4, ns))
    for s in range(s0, s1):
        i0 = seg[s, 0]
        i1 = seg[s, 1]
        for q in range(4):
            x[q] = x0[s, q]
        S[:, :] = 0.0
        for q in range(4):
            S[q, nq + q] = 1.0
        pred[i0, 0] = x[0]
        pred[i0, 1] = x[1]
        for c in range(nq):
            jac[i0, 0, c] = S[0, c]
            jac[i0, 1, c] = S[1, c]
        for q in range(4):
            jac[i0, 0, nx0 + q] = S[0, nq + q]
            jac[i0, 1, nx0 + q] = S[1, nq + q]
        for k in range(i0, i1):
            dts = t[k + 1] - t[k]
            a = (phid[k + 1] - phid[k]) / dts
            dt = dts / nsub
            for m in range(nsub):
                p0, w0 = spin_between(phi[k], phid[k], a, m * dt)
                rhs(p0, w0, a, x, S, theta, arg, active, actx, acta, pidx, midx, qidx, qlo, qhi, ip, cy, cx, cy2, cx2, xp,
                    argp, k1, K1)
                hh = 0.5 * dt
                for q in range(4):
                    xs[q] = x[q] + hh * k1[q]
                for q in range(4):
                    for c in range(ns):
                        Ss[q, c] = S[q, c] + hh * K1[q, c]
                pm, wm = spin_between(p0, w0, a, hh)
                rhs(pm, wm, a, xs, Ss, theta, arg, active, actx, acta, pidx, midx, qidx, qlo, qhi, ip, cy, cx, cy2, cx2, xp,
                    argp, k2, K2)
                for q in range(4):
                    xs[q] = x[q] + hh * k2[q]
                for q in range(4):
                    for c in range(ns):
                        Ss[q, c] = S[q, c] + hh * K2[q, c]
                rhs(pm, wm, a, xs, Ss, theta, arg, active, actx, acta, pidx, midx, qidx, qlo, qhi, ip, cy, cx, cy2, cx2, xp,
                    argp, k3, K3)
                for q in range(4):
                    xs[q] = x[q] + dt * k3[q]
                for q in range(4):
                    for c in range(ns):
                        Ss[q, c] = S[q, c] + dt * K3[q, c]
                pe, we = spin_between(p0, w0, a, dt)
                rhs(pe, we, a, xs, Ss, theta, arg, active, actx, acta, pidx, midx, qidx, qlo, qhi, ip, cy, cx, cy2, cx2, xp,
                    argp, k4, K4)
                for q in range(4):
                    x[q] += dt / 6.0 * (k1[q] + 2.0 * k2[q] + 2.0 * k3[q] + k4[q])
                for q in range(4):
                    for c in range(ns):
                        S[q, c] += dt / 6.0 * (K1[q, c] + 2.0 * K2[q, c] + 2.0 * K3[q, c] + K4[q, c])
            if not (abs(x[0]) < DIVERGED and abs(x[1]) < DIVERGED and abs(x[2]) < DIVERGED
                    and abs(x[3]) < DIVERGED):
                return k + 1
            pred[k + 1, 0] = x[0]
            pred[k + 1, 1] = x[1]
            for c in range(nq):
                jac[k + 1, 0, c] = S[0, c]
                jac[k + 1, 1, c] = S[1, c]
            for q in range(4):
                jac[k + 1, 0, nx0 + q] = S[0, nq + q]
                jac[k + 1, 1, nx0 + q] = S[1, nq + q]
    return 0
'''


@dataclass(frozen=True)
class _Kernel:
    module: object
    effects: tuple[str, ...]
    coef_slots: dict  #: effect -> (lo, hi) in theta
    arg_slots: dict  #: effect -> (lo, hi) in arg
    n_coef: int
    n_arg: int


_KERNELS: dict[tuple[str, ...], _Kernel] = {}


def _reads_state(columns) -> bool:
    """Whether an effect's column function reads the state (``th_x, th_y, w_x, w_y``, its
    arguments 4-7) anywhere in its code: one that never loads them (an unbalance, a load, a
    bow) has the same columns at every state, and the kernel's state differences skip it."""
    import dis

    code = columns.__code__
    state = set(code.co_varnames[3:7])
    for ins in dis.get_instructions(columns):
        if ins.opname.startswith("LOAD") or ins.opname.startswith("STORE") or ins.opname.startswith("DELETE"):
            val = ins.argval if isinstance(ins.argval, tuple) else (ins.argval,)
            if state & set(val):
                return True
    # a closure or a nested function over the state: read as reading it
    return bool(state & set(code.co_cellvars))


def _kernel(effects: tuple[str, ...]) -> _Kernel:
    """The compiled shooting kernel for these effects (all of them can be switched on or off
    per call: one compilation, cached on disk, serves every candidate model)."""
    if effects in _KERNELS:
        return _KERNELS[effects]
    from .. import effects as effects_module
    from ..simulator import load_generated

    head = ["import math", "", "import numpy as np", "from numba import njit, prange", "",
            "from rotor_env.diagnosis.spin import spin_between", "",
            f"FD_STATE = {_FD_STATE!r}", f"FD_ARG = {_FD_ARG!r}", "DIVERGED = 1e3", ""]
    body = ["@njit(cache=True)",
            "def columns(phi, phid, phidd, thx, thy, wx, wy, ip, arg, active, cy, cx):"]
    coef_slots, arg_slots = {}, {}
    state_dep, arg_owner = [], []
    j = a = 0
    for i, name in enumerate(effects):
        eff: Effect = EFFECTS[name]
        fn = eff.columns.__name__
        head.append(f"from rotor_env.effects import {fn} as _c{i}")
        head.append(f"f{i} = njit(inline='always')(_c{i})")
        nc, na = len(eff.coefficients), len(eff.argument_parameters)
        extra = "".join(f", arg[{a + q}]" for q in range(na))
        body.append(f"    if active[{i}]:")
        body.append(f"        ry, rx = f{i}(phi, phid, phidd, thx, thy, wx, wy, ip{extra})")
        for q in range(nc):
            body.append(f"        cy[{j + q}] = ry[{q}]")
            body.append(f"        cx[{j + q}] = rx[{q}]")
        coef_slots[name] = (j, j + nc)
        arg_slots[name] = (a, a + na)
        state_dep.append(_reads_state(eff.columns))
        arg_owner += [i] * na
        j += nc
        a += na
    head += [f"STATE_DEP = np.array({state_dep!r}, dtype=np.bool_)",
             f"ARG_OWNER = np.array({(arg_owner or [0])!r}, dtype=np.int64)", ""]
    text = ("# generated by rotor_env.diagnosis.output_error; safe to delete\n" + "\n".join(head) + "\n\n"
            + "\n".join(body) + "\n\n" + _KERNEL_TEMPLATE)
    module = load_generated("rotor_id_oe", text, (Path(__file__), Path(effects_module.__file__),
                                                  Path(__file__).with_name("spin.py")))
    if module is None:  # pragma: no cover - unwritable cache folder: compile in memory
        namespace: dict = {}
        exec(compile(text, "<rotor_id_oe>", "exec"), namespace)
        module = type("M", (), namespace)
    k = _Kernel(module, effects, coef_slots, arg_slots, j, a)
    _KERNELS[effects] = k
    return k


@lru_cache(maxsize=16)
def _decimated_noise_shape(q: int, rho: float) -> tuple[np.ndarray, np.ndarray, float]:
    """AR(1) noise's density shape ``1 / |1 - rho e^{-iw}|^2`` through the decimating FIR's
    ``|H(w)|^2`` on a dense grid of input-rate frequencies ``w`` in ``[0, pi / q]``, and its
    mean there (the grid's band)."""
    n = 1 << 17
    w = np.linspace(0.0, math.pi, n // 2 + 1)
    shape = 1.0 / (1.0 - 2.0 * rho * np.cos(w) + rho * rho)
    if q > 1:
        shape = shape * np.abs(np.fft.rfft(decimation_filter(q), n)) ** 2
    band = w <= math.pi / q
    w, shape = w[band], shape[band]
    mean = float(np.sum(0.5 * (shape[1:] + shape[:-1]) * np.diff(w)) / (w[-1] - w[0]))
    return w, shape, mean


def decimation_filter(q: int) -> np.ndarray:
    """The low-pass FIR of the decimation by ``q``: Kaiser window (beta 12, about 1e-6 ripple
    and -100 dB), cut at 0.8 of the new Nyquist, 64 q + 1 taps, unit gain at DC.  A record
    whose response is thousands of times its noise needs a pass band flat to 1e-5 (scipy's
    default Hamming FIR ripples by 1e-3 near its cut)."""
    from scipy.signal import firwin

    return firwin(64 * q + 1, 0.8 / q, window=("kaiser", 12.0))


def coefficient_slice(effect: str) -> slice:
    """Where ``effect``'s coefficients sit in a fit's :attr:`OutputErrorFit.theta_full`."""
    return slice(*_kernel(library_effects()).coef_slots[effect])


#: the effect whose coefficient sets the model's time unit (its natural frequency sqrt(k))
TIME_UNIT_EFFECT = "stiffness"


@cache
def time_degrees(effect: str) -> tuple[int, ...]:
    """Each coefficient's degree in the time derivatives (``phid`` and the tilt rates count
    once, ``phidd`` twice): a stiffness-like column 0, a damping 1, an unbalance 2.

    The output-error fit frees the shaft stiffness ``k`` because the time unit ``w_ref`` is
    itself an estimate; a coefficient ``theta`` of degree ``n`` then reads
    ``theta k^((n - 2) / 2)`` in the units where the fitted shaft has ``k = 1`` (time
    rescaled by ``sqrt(k)``, the equation divided by ``k``) -- the paper's units, where
    the declared plausible ranges hold and a crack's size is relative to its shaft's
    stiffness.  Read off the declared column function by doubling every time derivative."""
    eff = EFFECTS[effect]
    args = [p.default for p in eff.argument_parameters]
    # a state beyond any default clearance (a rub's contact acts), rates and spin generic
    state = (0.7, 1.3, 0.2, 0.061, -0.047, 0.013, 0.029)
    fast = (state[0], 2 * state[1], 4 * state[2], state[3], state[4], 2 * state[5], 2 * state[6])
    ry, rx = eff.columns(*state, 0.0, *args)
    fy, fx = eff.columns(*fast, 0.0, *args)
    out = []
    for j in range(len(eff.coefficients)):
        a = float(ry[j]) if abs(float(ry[j])) >= abs(float(rx[j])) else float(rx[j])
        b = float(fy[j]) if abs(float(ry[j])) >= abs(float(rx[j])) else float(fx[j])
        n = math.log2(b / a) if a != 0.0 and b / a > 0 else math.nan
        if not (math.isfinite(n) and abs(n - round(n)) < 1e-6):
            raise ValueError(f"effect {effect!r}: coefficient {eff.coefficients[j]!r}'s column is not homogeneous "
                             "in the time derivatives")
        out.append(int(round(n)))
    return tuple(out)


def canonical_scale(effect: str, k: float) -> np.ndarray:
    """The factors ``k^((n - 2) / 2)`` that turn ``effect``'s coefficients fitted with the
    stiffness ``k`` into the units where the shaft has ``k = 1`` (:func:`time_degrees`)."""
    if effect == TIME_UNIT_EFFECT or not k > 0:
        return np.ones(len(EFFECTS[effect].coefficients))
    return np.array([k ** ((n - 2) / 2) for n in time_degrees(effect)])


def start_from(fit: OutputErrorFit) -> dict[str, np.ndarray]:
    """A fit's coefficients as the start of another fit (``start`` of :func:`fit_output_error`)."""
    return {e: fit.theta_full[coefficient_slice(e)].copy() for e in fit.effects}


def arguments_of(*fits: OutputErrorFit) -> dict[str, dict[str, float]]:
    """The argument parameters (a rub's clearance, a crack's breathing) of the fits' effects at
    their fitted values, to hold in a refit (``fixed_args`` of :func:`fit_output_error`): a
    refit on part of the record then moves the coefficients only, whose sensitivities are
    linear.  An effect in several fits takes the first fit's values."""
    args: dict[str, dict[str, float]] = {}
    for fit in reversed(fits):
        for e in fit.effects:
            if EFFECTS[e].argument_parameters:
                args[e] = {p.name: fit.value(f"{e}.{p.name}") for p in EFFECTS[e].argument_parameters}
    return args


# ------------------------------------------------------------------ the data
@dataclass(frozen=True)
class ShootingGrid:
    """The record on the shooting grid (dimensionless): time, spin, measured tilts, the
    segments and the start states' first guesses.

    ``y`` holds ``(th_x, th_y)``; ``noise_std`` the probes' noise per grid sample (same
    unit), when known; ``segments`` ``(S, 2)`` first and last sample of each segment.
    """

    t: np.ndarray
    phi: np.ndarray
    phid: np.ndarray
    y: np.ndarray
    rates: np.ndarray  #: (N, 2) estimated (th_x', th_y'): start states only
    segments: np.ndarray
    ip: float
    noise_std: float | None = None
    decimation: int = 1
    #: the probes' noise per sample of the record the grid was decimated from
    probe_noise_std: float | None = None
    #: RK4 steps per grid sample (more where the response is many times the noise)
    substeps: int = 1
    #: the noise's integrated correlation time on the grid, in grid samples (sum over every lag
    #: of its autocorrelation: 1 for white, (1 + rho) / (1 - rho) for AR(1) at its own rate)
    noise_correlation: float = 1.0
    #: knot spacing (model time) of the probes' slowly moving mean fitted with every model
    #: (:func:`_baseline_fit`); ``None``: only the static offsets
    baseline_spacing: float | None = None
    #: the noise's lag-one correlation at the rate of the record the grid was decimated from
    #: (AR(1); 0: white): the shape of :meth:`noise_density`
    noise_rho: float = 0.0
    #: a second mode of the rotor every fit on this grid holds (:mod:`.second_mode`), started
    #: here where the fit has no ``previous`` with one; ``None``: the one-mode model
    second_mode: SecondMode | None = None

    @classmethod
    def from_arrays(cls, t, phi, phid, th_x, th_y, ip: float, *, noise_std: float | None = None,
                    noise_rho: float = 0.0, segment_length: float = SEGMENT_LENGTH,
                    grid_dt: float | None = None, baseline_spacing: float | None = None) -> ShootingGrid:
        """Decimate (zero-phase FIR) to the grid step and cut the segments.  ``noise_std``: the
        noise's standard deviation per sample of the input, ``noise_rho`` its lag-one
        correlation (AR(1); 0: white); ``baseline_spacing``: knot spacing (same time unit as
        ``t``) of the probes' slowly moving mean fitted with every model (``None``: none)."""
        from scipy.signal import resample_poly, savgol_filter

        t = np.asarray(t, float)
        dt0 = float(np.median(np.diff(t)))
        top = float(np.max(np.abs(phid)))
        target = grid_dt if grid_dt is not None else min(GRID_DT, 2 * math.pi / (GRID_PER_TURN * max(top, 1e-9)))
        q = max(1, int(target // dt0))
        taps = None
        if q > 1:
            taps = decimation_filter(q)
            thx = resample_poly(np.asarray(th_x, float), 1, q, window=taps)
            thy = resample_poly(np.asarray(th_y, float), 1, q, window=taps)
            sel = slice(None, None, q)
            t, phi, phid = t[sel], np.asarray(phi, float)[sel], np.asarray(phid, float)[sel]
            n = min(len(t), len(thx))
            t, phi, phid, thx, thy = t[:n], phi[:n], phid[:n], thx[:n], thy[:n]
            # the filter rings at the ends: its half length (and at least half a segment) off each end
            cut = max(len(taps) // (2 * q) + 1, int(round(0.5 * segment_length / (dt0 * q))))
            if n > 6 * cut:
                keep = slice(cut, n - cut)
                t, phi, phid, thx, thy = t[keep], phi[keep], phid[keep], thx[keep], thy[keep]
        else:
            thx, thy = np.asarray(th_x, float), np.asarray(th_y, float)
        dt = float(np.median(np.diff(t)))
        y = np.column_stack([thx, thy])
        win = max(5, int(round(1.0 / dt)) | 1)
        win = min(win, (len(t) - 1) | 1 if len(t) % 2 == 0 else len(t))
        rates = np.column_stack([savgol_filter(y[:, c], win, 3, deriv=1, delta=dt) for c in range(2)])
        per = max(8, int(round(segment_length / dt)))
        starts = np.arange(0, len(t) - 1, per)
        if len(starts) > 1 and len(t) - 1 - starts[-1] < per // 2:  # a stub at the end joins its neighbour
            starts = starts[:-1]
        # each sample in one segment: a segment ends one sample before the next one starts
        ends = np.append(starts[1:] - 1, len(t) - 1)
        seg = np.column_stack([starts, ends]).astype(np.int64)
        # AR(1) noise through the decimating FIR: its variance times sum_ij h_i h_j rho^|i-j|
        # (white: the sum of squared taps)
        if taps is None:
            gain = 1.0
        elif noise_rho == 0.0:
            gain = float(np.sum(taps * taps))
        else:
            acf = np.correlate(taps, taps, mode="full")
            lags = np.abs(np.arange(-(len(taps) - 1), len(taps)))
            gain = float(np.sum(acf * float(noise_rho) ** lags))
        sigma = None if noise_std is None else float(noise_std) * math.sqrt(gain)
        tau = _noise_correlation_time(taps, q, float(noise_rho))
        # RK4's phase error over a segment, omega T (omega dt)^4 / 120 relative at the top
        # speed's 1X, kept below a third of the noise-to-response ratio
        amp = float(np.max(np.hypot(y[:, 0], y[:, 1]))) if len(y) else 0.0
        omega = max(top, 1.2)
        nsub = 1
        if sigma is not None and amp > 0:
            # an error of a third of the noise adds 5 % to the residual's variance
            want = 0.3 * sigma / amp
            while nsub < 8 and omega * segment_length * (omega * dt / nsub) ** 4 / 120.0 > want:
                nsub += 1
        if baseline_spacing is not None and not (math.isfinite(baseline_spacing) and baseline_spacing > 0):
            raise ValueError(f"baseline_spacing must be a positive number, got {baseline_spacing!r}")
        return cls(t, np.asarray(phi, float), np.asarray(phid, float), y, rates, seg, float(ip), sigma, q,
                   None if noise_std is None else float(noise_std), nsub, tau,
                   None if baseline_spacing is None else float(baseline_spacing), float(noise_rho))

    @property
    def n(self) -> int:
        return len(self.t)

    @cached_property
    def inside(self) -> np.ndarray:
        """The samples in a segment (the rows a fit on this grid reads)."""
        mask = np.zeros(self.n, dtype=bool)
        for i0, i1 in self.segments:
            mask[i0:i1 + 1] = True
        return mask

    @cached_property
    def output_basis(self) -> tuple[np.ndarray, ...]:
        """``sin phi, cos phi, cos 2 phi, sin 2 phi`` at the samples in a segment: the output
        terms' columns (:data:`OUTPUT_TERMS`), the same at every shot of a fit."""
        phi = self.phi[self.inside]
        return np.sin(phi), np.cos(phi), np.cos(2 * phi), np.sin(2 * phi)

    @cached_property
    def rows(self):
        """The samples in a segment as an index: every sample (a slice: views, no copies) or
        their positions."""
        return slice(None) if bool(self.inside.all()) else np.flatnonzero(self.inside)

    @cached_property
    def output_columns(self) -> np.ndarray:
        """``(samples in a segment, 2, 10)``: the Jacobian columns of the output terms before
        the calibration (:data:`OUTPUT_TERMS`): static offsets (x, y); a probe track's 1X runout
        ``R e^{i phi} + R_b e^{-i phi}`` in ``z = th_y + i th_x`` (any 1X pattern on each axis,
        columns 2, 3, 8, 9); its 2X, any pattern of ``2 phi`` on each axis (4-7)."""
        s, c, c2, s2 = self.output_basis
        block = np.zeros((len(s), 2, _CAL))
        block[:, 0, 0] = 1.0
        block[:, 1, 1] = 1.0
        block[:, 0, 2], block[:, 1, 2] = s, c
        block[:, 0, 3], block[:, 1, 3] = c, -s
        block[:, 0, 4], block[:, 0, 5] = c2, s2
        block[:, 1, 6], block[:, 1, 7] = c2, s2
        block[:, 0, 8], block[:, 1, 8] = -s, c
        block[:, 0, 9], block[:, 1, 9] = c, s
        return block

    @cached_property
    def baseline_basis(self):
        """``(B, G)``: the cubic B-splines of the slowly moving mean at the samples in a segment
        (sparse, knots :attr:`baseline_spacing` apart, the last interval stretched to the
        end) and the Cholesky factor of their Gram matrix ``B'B``; ``None`` without a baseline."""
        if self.baseline_spacing is None:
            return None
        from scipy.interpolate import BSpline
        from scipy.linalg import cho_factor

        from ..measurements.drift import spline_knots

        t = self.t[self.inside]
        B = BSpline.design_matrix(t, spline_knots(float(t[0]), float(t[-1]), self.baseline_spacing), 3).tocsr()
        G = (B.T @ B).toarray()
        return B, cho_factor(G + 1e-12 * np.trace(G) / len(G) * np.eye(len(G)))

    def noise_density(self, nu: np.ndarray) -> np.ndarray:
        """The one-sided spectral density of the grid's noise model at ``nu`` (cycles per unit of
        model time): AR(1) noise of lag-one correlation :attr:`noise_rho` at the input rate,
        through the decimating FIR, scaled so that it integrates to ``noise_std^2`` over the
        grid's band (white noise on an undecimated grid: flat)."""
        dt = float(np.median(np.diff(self.t)))
        q = max(int(self.decimation), 1)
        w, shape, mean = _decimated_noise_shape(q, float(self.noise_rho))
        w_in = 2.0 * math.pi * np.asarray(nu, dtype=float) * dt / q  # radians per input sample
        var = float(self.noise_std) ** 2 if self.noise_std else 0.0
        # the grid's band (0, 1 / (2 dt)) is (0, pi / q) at the input rate: mean density there
        return var * 2.0 * dt * np.interp(w_in, w, shape) / mean

    def start_states(self) -> np.ndarray:
        """The segments' first start states: the first mode's from the measured tilts and their
        estimated rates; with a second mode its steady 1X state first (``(S, 8)``)."""
        i = self.segments[:, 0]
        own = np.column_stack([self.y[i, 0], self.y[i, 1], self.rates[i, 0], self.rates[i, 1]])
        if self.second_mode is None:
            return own
        return np.column_stack([self.second_mode.steady_states(self.phi[i], self.phid[i]), own])

    @property
    def n_states(self) -> int:
        """Start-state parameters per segment: the first mode's four, and the second mode's."""
        return 4 + (N_MODE_STATES if self.second_mode is not None else 0)


# ------------------------------------------------------------------ the fit
@dataclass
class OutputErrorFit:
    """An output-error fit: parameters, their HAC covariance, residuals, the start states."""

    effects: tuple[str, ...]
    names: tuple[str, ...]  #: free parameters: coefficients, then arguments
    owners: tuple[str, ...]  #: the effect of each free parameter
    values: np.ndarray
    covariance: np.ndarray
    rss: float
    residual: np.ndarray  #: (N, 2) measured - predicted on the grid
    prediction: np.ndarray
    x0: np.ndarray
    iterations: int
    converged: bool
    bandwidth: int
    grid: ShootingGrid = field(repr=False)
    theta_full: np.ndarray = field(repr=False, default=None)
    arg_full: np.ndarray = field(repr=False, default=None)
    #: the output terms (:data:`OUTPUT_TERMS`): the probes' static offsets (the gap voltage's
    #: mean removed from a signal whose response has a mean of its own leaves one), the track's
    #: 1X and 2X runout
    offset: np.ndarray = field(repr=False, default=None)
    #: where the fit gave up (``give_up_above``): the least residual energy it could still have
    #: reached in the steps left (its last step's fall for each, :data:`GIVE_UP_MARGIN` times);
    #: ``None`` where it ran to convergence or to ``max_iter``
    reachable: float | None = None
    #: the second mode's parameters (:data:`~.second_mode.MODE_PARAMETERS`) where the grid holds
    #: one (:attr:`ShootingGrid.second_mode`)
    mode2: np.ndarray | None = field(repr=False, default=None)

    @property
    def second_mode(self) -> SecondMode | None:
        """The fitted second mode, ``None`` in a one-mode model."""
        return None if self.mode2 is None else SecondMode.from_array(self.mode2)

    @property
    def gave_up(self) -> bool:
        return self.reachable is not None

    @property
    def n_rows(self) -> int:
        """Rows fitted: two channels of every sample in a segment."""
        return int(2 * sum(i1 - i0 + 1 for i0, i1 in self.grid.segments))

    @property
    def rms(self) -> float:
        return math.sqrt(self.rss / self.n_rows)

    @property
    def std_errors(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    def value(self, name: str) -> float:
        """A free parameter's fitted value, or a held effect's coefficient (``held`` of
        :func:`fit_output_error`) at the value it was held at."""
        if name not in self.names:
            effect, _, coef = name.partition(".")
            eff = EFFECTS.get(effect)
            if eff is not None and effect in self.effects and coef in eff.coefficients:
                return float(self.theta_full[coefficient_slice(effect)][eff.coefficients.index(coef)])
            args = [p.name for p in eff.argument_parameters] if eff is not None and effect in self.effects else []
            if coef in args:  # an argument held at a value (``fixed_args``): where it was held
                lo, _ = _kernel(library_effects()).arg_slots[effect]
                return float(self.arg_full[lo + args.index(coef)])
        return float(self.values[self.names.index(name)])

    def coefficients(self, effect: str, k: float | None = None) -> np.ndarray:
        """``effect``'s coefficients in the units where the fitted shaft has ``k = 1``
        (:func:`time_degrees`; the stiffness itself as fitted); ``k``: another value of the
        stiffness to convert with (the delta method's step)."""
        eff = EFFECTS[effect]
        coef = np.array([self.value(f"{effect}.{c}") for c in eff.coefficients])
        if TIME_UNIT_EFFECT not in self.effects:
            return coef
        k = self.value(f"{TIME_UNIT_EFFECT}.k") if k is None else k
        return coef * canonical_scale(effect, k)

    def parameters(self, effect: str) -> dict[str, float]:
        """Physical parameters of ``effect`` (its declaration's mapping) in the units where
        the fitted shaft has ``k = 1`` (:meth:`coefficients`), orientations in ``[0, period)``."""
        eff = EFFECTS[effect]
        out = dict(eff.from_coefficients(self.coefficients(effect)))
        for p in eff.argument_parameters:
            v = self.value(f"{effect}.{p.name}")
            out[p.name] = float(v % p.angle_period) if p.orientation else float(v)
        if effect == "breathing_crack" and out.get("crack_axis", 0.0) >= math.pi:
            # the crack turned by half a turn with its opening phase turned by half a turn is
            # the same moment: reported with the axis in [0, pi)
            out["crack_axis"] -= math.pi
            out["breathing_phase"] = float((out["breathing_phase"] + 2 * math.pi) % (2 * math.pi) - math.pi)
        return out

    def wald(self, effect: str, null: Mapping[str, float] | None = None) -> tuple[float, int, float]:
        """HAC Wald test that the effect's coefficients equal ``null`` (by full name,
        ``"effect.coefficient"``; zero where ``None``): ``(W, q, log10 p)``."""
        names = [nm for o, nm in zip(self.owners, self.names, strict=True)
                 if o == effect and nm.split(".", 1)[1] in EFFECTS[effect].coefficients]
        return self.wald_of(names, null)

    def wald_of(self, names: Sequence[str], null: Mapping[str, float] | None = None) -> tuple[float, int, float]:
        """HAC Wald test that the free parameters ``names`` equal ``null`` (zero where ``None``):
        ``(W, q, log10 p)``; ``W`` infinite where their covariance is singular."""
        idx = [self.names.index(nm) for nm in names]
        th = self.values[idx]
        if null is not None:
            th = th - np.array([null[self.names[i]] for i in idx])
        cov = self.covariance[np.ix_(idx, idx)]
        try:
            w = float(th @ np.linalg.solve(cov, th))
        except np.linalg.LinAlgError:
            w = math.inf
        return w, len(idx), chi2_log10_sf(w, len(idx)) if math.isfinite(w) else -math.inf


def _free_layout(kernel: _Kernel, effects: Sequence[str], fixed_args: Mapping[str, Mapping[str, float]],
                 held: Sequence[str] = ()):
    pidx, qidx, qlo, qhi, names, owners = [], [], [], [], [], []
    for e in effects:
        if e in held:
            continue
        lo, hi = kernel.coef_slots[e]
        for j, c in zip(range(lo, hi), EFFECTS[e].coefficients, strict=True):
            pidx.append(j)
            names.append(f"{e}.{c}")
            owners.append(e)
    for e in effects:
        alo, _ = kernel.arg_slots[e]
        for q, p in enumerate(EFFECTS[e].argument_parameters):
            if p.name in fixed_args.get(e, {}):
                continue
            qidx.append(alo + q)
            lo, hi = kernel.coef_slots[e]
            qlo.append(lo)
            qhi.append(hi)
            names.append(f"{e}.{p.name}")
            owners.append(e)
    as_int = lambda v: np.asarray(v, dtype=np.int64)  # noqa: E731
    return as_int(pidx), as_int(qidx), as_int(qlo), as_int(qhi), tuple(names), tuple(owners)


def _moment_layout(kernel: _Kernel, effects: Sequence[str]) -> np.ndarray:
    """Every coefficient slot of the model's effects (the moment sums them, free or held)."""
    return np.asarray([j for e in effects for j in range(*kernel.coef_slots[e])], dtype=np.int64)


def _baseline_fit(grid, r: np.ndarray) -> np.ndarray:
    """The least-squares fit of the slowly moving mean (:attr:`ShootingGrid.baseline_basis`)
    to ``r``, rows of the samples in a segment (any number of columns, one channel's
    samples each)."""
    from scipy.linalg import cho_solve

    B, G = grid.baseline_basis
    return B @ cho_solve(G, B.T @ r)


def _shoot(kernel, grid, x0, theta, arg, active, pidx, qidx, qlo, qhi, offset, midx=None, mode2=None):
    """Predictions and Jacobian columns: the free coefficients (``pidx``), arguments, the
    output terms (:data:`OUTPUT_TERMS`), with a second mode (``mode2``) its parameters and
    start state, then the segment's start state; the moment is that of the coefficients
    ``midx`` (default: the free ones).  ``x0``: the segments' start states (the second mode's
    first where there is one)."""
    midx = pidx if midx is None else midx
    npar = len(pidx) + len(qidx)
    n2 = N_MODE_PARAMETERS + N_MODE_STATES if mode2 is not None else 0
    nf = npar + N_OFFSETS + n2 + 4
    # rows outside the segments (a fit on a subset of them) predict the measurement itself:
    # no residual, no gradient
    pred = grid.y.copy()
    jac = np.zeros((grid.n, 2, nf))
    # the kernel leaves the offsets' columns at zero (no state depends on them)
    status = kernel.module.shoot(grid.t, grid.phi, grid.phid, grid.segments, np.ascontiguousarray(x0[:, -4:]), theta,
                                 arg, active, pidx, midx, qidx, qlo, qhi, grid.ip, grid.substeps, pred, jac)
    rows = grid.rows
    if mode2 is not None and status == 0:
        # the second mode's orbit adds to the first's (both are what the probes read)
        other = np.zeros((grid.n, 2))
        dt = float(np.max(np.diff(grid.t))) if grid.n > 1 else 1.0
        nsub = substeps(SecondMode.from_array(mode2), dt, grid.substeps)
        shoot_second_mode(grid.t, grid.phi, grid.phid, grid.segments, x0[:, :N_MODE_STATES], mode2, nsub, other, jac,
                          npar + N_OFFSETS)
        pred[rows] += other[rows]
    # the probes' calibration first (it acts on the rotor's orbit, not on the track's runout):
    # z + eps conj(z) with z = th_y + i th_x, eps = a + i b -- th_y += a th_y + b th_x,
    # th_x += b th_y - a th_x; every column of the orbit's Jacobian the same way
    a, b = float(offset[_CAL]), float(offset[_CAL + 1])
    xm, ym = pred[rows, 0].copy(), pred[rows, 1].copy()
    if a or b:
        jx, jy = jac[rows, 0, :], jac[rows, 1, :]
        new_x, new_y = (1.0 - a) * jx + b * jy, (1.0 + a) * jy + b * jx
        jac[rows, 0, :] = new_x
        jac[rows, 1, :] = new_y
        pred[rows, 0] = (1.0 - a) * xm + b * ym
        pred[rows, 1] = (1.0 + a) * ym + b * xm
    jac[rows, 0, npar + _CAL] = -xm
    jac[rows, 1, npar + _CAL] = ym
    jac[rows, 0, npar + _CAL + 1] = ym
    jac[rows, 1, npar + _CAL + 1] = xm
    # the other output terms (static offsets, the track's 1X and 2X runout): columns the same
    # at every shot (:attr:`ShootingGrid.output_columns`)
    block = grid.output_columns
    pred[rows] += block @ offset[:_CAL]
    jac[rows, :, npar:npar + _CAL] = block
    if grid.baseline_spacing is not None and status == 0:
        # the probes' slowly moving mean (the shaft's centreline, thermal drift), projected
        # out: the prediction takes the least-squares baseline of what it leaves, so the
        # residual is orthogonal to the baseline's splines (variable projection).  The
        # Jacobian stays the model's: with a projected residual its product J'r is the exact
        # gradient; the covariance projects it (:func:`_project`)
        pred[rows] += _baseline_fit(grid, grid.y[rows] - pred[rows])
    return status, pred, jac


@njit(cache=True)
def _segment_rows(r, jac, i0, i1):
    """One segment's rows ``[J r]``: two channels per sample, the Jacobian's columns then the
    residual."""
    nf = jac.shape[2]
    m = 2 * (i1 - i0)
    A = np.empty((m, nf + 1))
    A[:, :nf] = jac[i0:i1].reshape(m, nf)
    A[:, nf] = r[i0:i1].reshape(m)
    return A


@njit(cache=True, parallel=True)
def _reduced_normal_equations(r, jac, seg, npq):
    """Variable projection in normal-equation form: per segment ``G = Jx'Jx``,
    ``C = Jx'Jp``, ``c = Jx'r``; the reduced ``H = sum Jp'Jp - C'G^-1 C`` and
    ``g = sum Jp'r - C'G^-1 c``; ``Gi_C``, ``Gi_c`` give the start states' step
    ``dx0_s = Gi_c - Gi_C d`` for a parameter step ``d``.  The segments in parallel
    (independent), each adding its own part, summed after; each segment's products are one
    matrix product ``[J r]'[J r]`` (BLAS: twice as fast as the sums written out)."""
    ns = seg.shape[0]
    nf = jac.shape[2]
    nx = nf - npq
    Hs = np.zeros((ns, npq, npq))
    gs = np.zeros((ns, npq))
    GiC = np.zeros((ns, nx, npq))
    Gic = np.zeros((ns, nx))
    for s in prange(ns):
        A = _segment_rows(r, jac, seg[s, 0], seg[s, 1] + 1)
        M = A.T @ A
        G = M[npq:nf, npq:nf].copy()
        C = M[npq:nf, :npq].copy()
        c = M[npq:nf, nf].copy()
        Gi = np.linalg.pinv(G)
        GiC[s] = Gi @ C
        Gic[s] = Gi @ c
        Hs[s] = M[:npq, :npq] - C.T @ GiC[s]
        gs[s] = M[:npq, nf] - C.T @ Gic[s]
    H = np.zeros((npq, npq))
    g = np.zeros(npq)
    for s in range(ns):
        H += Hs[s]
        g += gs[s]
    return H, g, GiC, Gic, nf


@njit(cache=True, parallel=True)
def _project_rows(r, jac, seg, npq):
    """Variable projection: each segment's rows (two channels per sample, in time order) of
    the residual and the parameters' Jacobian on the complement of its start-state columns
    ``Jx``, ``A - Jx (Jx'Jx)^+ Jx' A``."""
    ns = seg.shape[0]
    nf = jac.shape[2]
    start = np.zeros(ns + 1, dtype=np.int64)
    for s in range(ns):
        start[s + 1] = start[s] + 2 * (seg[s, 1] + 1 - seg[s, 0])
    rt = np.empty(start[ns])
    Jt = np.empty((start[ns], npq))
    for s in prange(ns):
        A = _segment_rows(r, jac, seg[s, 0], seg[s, 1] + 1)
        Jx = A[:, npq:nf].copy()
        P = A - Jx @ (np.linalg.pinv(Jx.T @ Jx) @ (Jx.T @ A))
        Jt[start[s]:start[s + 1]] = P[:, :npq]
        rt[start[s]:start[s + 1]] = P[:, nf]
    return rt, Jt


def _project(grid, r, jac, npq):
    """Variable projection: the residual's and the parameters' rows of every segment of
    ``grid`` on the complement of its start-state columns (:func:`_project_rows`), then, on
    a grid with a slowly moving mean, on the complement of its splines (each channel)."""
    rt, Jt = _project_rows(np.ascontiguousarray(r), np.ascontiguousarray(jac), np.ascontiguousarray(grid.segments),
                           npq)
    if grid.baseline_spacing is not None:
        # the segments' rows are the samples in a segment, in time order, two channels each
        for ch in range(2):
            both = np.column_stack([rt[ch::2], Jt[ch::2]])
            both -= _baseline_fit(grid, both)
            rt[ch::2], Jt[ch::2] = both[:, 0], both[:, 1:]
    return rt, Jt


def colour_inflation(w: np.ndarray, dt: float, density, reference) -> float:
    """How much more a weighted sum ``sum_t w_t' e_t`` of the noise varies under the density
    ``density(nu)`` than under ``reference(nu)`` (one-sided densities of stationary noise,
    the channels of ``w`` ``(N, channels)`` independent and alike): ``int |W|^2 density /
    int |W|^2 reference``, ``W`` the rows' transform (zero-padded to twice their length:
    ``int |W(nu)|^2 S(nu) d nu`` is the sum's variance).  With ``w = J (J'J)^-1 e_i`` it is how
    much wider the least-squares estimate of parameter ``i`` is under ``density`` than the
    reference model -- and so by how much a change of the residual energy counted in the
    reference's noise variances overstates the evidence (a likelihood ratio ``dRSS /
    sigma^2`` is that factor times a chi-square)."""
    w = np.asarray(w, dtype=float)
    if w.ndim == 1:
        w = w[:, None]
    n = w.shape[0]
    size = 1 << int(math.ceil(math.log2(2 * max(n, 1))))
    power = np.sum(np.abs(np.fft.rfft(w, size, axis=0)) ** 2, axis=1)
    nu = np.fft.rfftfreq(size, dt)
    ref = float(np.sum(power * reference(nu)))
    return float(np.sum(power * density(nu))) / ref if ref > 0 else 1.0


def estimate_inflation(fit: OutputErrorFit, name: str, band_ratio=None) -> float:
    """:func:`colour_inflation` of the free parameter ``name`` of ``fit``: the noise its grid
    models (:meth:`ShootingGrid.noise_density`: AR(1) at the input rate through the
    decimating filter), times ``band_ratio(nu)`` (what the residual read between the shaft's
    orders says of the noise in the rotor's band against that model; 1 where ``None``),
    against the white noise of the same level through the same filter.  1 for white noise
    read at its level.  The Jacobian is the fit's own (every free parameter and each
    segment's start state partialled out, as the estimate has them).  A fit on part of the
    segments (one half of the record) joins segments that are not neighbours in time: the
    noise's correlation across such a join (a few grid samples, against a segment's hundreds)
    is read as if they were."""
    grid = fit.grid
    if grid.noise_rho == 0.0 and band_ratio is None:
        return 1.0
    _, _, J3, names = sample_scores(fit, with_jacobian=True)
    J = J3.reshape(-1, J3.shape[2])
    a = np.linalg.pinv(J.T @ J)[:, list(names).index(name)]
    white = replace(grid, noise_rho=0.0)
    coloured = grid.noise_density if band_ratio is None else (lambda nu: grid.noise_density(nu) * band_ratio(nu))
    # the rows are the segments' samples in time order: one series per channel
    return colour_inflation(J3 @ a, float(np.median(np.diff(grid.t))), coloured, white.noise_density)


def _noise_correlation_time(taps: np.ndarray | None, q: int, rho: float) -> float:
    """The integrated correlation time, in grid samples, of AR(1) noise (lag-one correlation
    ``rho`` at the input rate) after the decimating FIR ``taps`` and keeping every ``q``-th
    sample: ``sum_m r(m q)`` over every grid lag ``m``, ``r`` the filtered noise's
    autocorrelation."""
    if taps is None:
        return (1.0 + rho) / (1.0 - rho)
    acf = np.correlate(taps, taps, mode="full")
    half = len(taps) - 1
    if rho != 0.0:
        # the filter's autocorrelation convolved with rho^|l|, over lags where rho^|l| matters
        reach = int(min(50_000, math.ceil(math.log(1e-9) / math.log(min(abs(rho), 0.999999)))))
        kern = rho ** np.abs(np.arange(-reach, reach + 1))
        acf = np.convolve(acf, kern)
        half += reach
    lags = np.arange(-half, half + 1)
    on_grid = lags % q == 0
    return float(np.sum(acf[on_grid]) / acf[half])


def fit_output_error(
    grid: ShootingGrid,
    effects: Sequence[str],
    start: Mapping[str, Mapping[str, float]] | None = None,
    *,
    fixed_args: Mapping[str, Mapping[str, float]] | None = None,
    x0: np.ndarray | None = None,
    start_args: Mapping[str, Mapping[str, float]] | None = None,
    previous: OutputErrorFit | None = None,
    held: Sequence[str] = (),
    max_iter: int = 40,
    tol: float = 1e-8,
    give_up_above: float | None = None,
) -> OutputErrorFit:
    """Levenberg-Marquardt on the multiple-shooting output error (module docstring).

    ``effects``: the model (``stiffness`` is added when absent: the time scale of measured
    data is itself an estimate); ``start``: physical parameter values per effect (the
    declaration's defaults where absent, 0 for a coefficient whose effect has no start);
    ``fixed_args``: argument parameters held at a value (not fitted); ``start_args``:
    argument start values (with ``start`` given as coefficient arrays); ``previous``: a fit
    whose effects' coefficients, arguments and start states seed this one (a model grown
    by one effect starts where the smaller one ended); ``held``: effects of the model whose
    coefficients stay at their start values (their moment acts, nothing of them is fitted:
    a refit on part of the record keeps what that part alone cannot tell, a side load whose
    product with a crack is all a record's low-amplitude half sees).
    ``give_up_above``: a residual energy another model of the same data reached; the fit
    stops where it could not come down to it in the steps left (:data:`GIVE_UP_MARGIN`) and
    says so (:attr:`OutputErrorFit.reachable`): a candidate six times the residual of the
    best crawls through all its steps (a hinge crack on an open crack's record: 40 steps,
    1.9 s of a 15 s record's diagnosis) to a value no decision reads.
    """
    effects = tuple(dict.fromkeys(("stiffness", *effects)))
    lib = library_effects()
    for e in effects:
        if e not in lib:
            raise ValueError(f"effect {e!r} cannot be fitted by output error (set-valued or a user effect)")
    kernel = _kernel(lib)
    start = dict(start or {})
    fixed_args = dict(fixed_args or {})
    theta = np.zeros(kernel.n_coef)
    arg = np.zeros(max(kernel.n_arg, 1))
    active = np.zeros(len(lib), dtype=np.bool_)
    for e in effects:
        eff = EFFECTS[e]
        active[lib.index(e)] = True
        lo, hi = kernel.coef_slots[e]
        if e in start and isinstance(start[e], np.ndarray):
            theta[lo:hi] = start[e]  # coefficients themselves (an equation-error start)
        elif e in start:
            vals = {p.name: p.default for p in eff.parameters} | dict(start[e])
            theta[lo:hi] = eff.to_coefficients(vals)
        elif e == "stiffness":
            theta[lo:hi] = 1.0
        alo, ahi = kernel.arg_slots[e]
        given = {**(start.get(e, {}) if not isinstance(start.get(e), np.ndarray) else {}),
                 **(start_args or {}).get(e, {}), **fixed_args.get(e, {})}
        arg[alo:ahi] = [float(given.get(p.name, p.default)) for p in eff.argument_parameters]
    if previous is not None:
        for e in previous.effects:
            if e in effects and e not in start:
                theta[slice(*kernel.coef_slots[e])] = previous.theta_full[slice(*kernel.coef_slots[e])]
                lo, hi = kernel.arg_slots[e]
                for q, p in enumerate(EFFECTS[e].argument_parameters):
                    if p.name not in fixed_args.get(e, {}) and p.name not in (start_args or {}).get(e, {}):
                        arg[lo + q] = previous.arg_full[lo + q]
        if x0 is None and len(previous.x0) == len(grid.segments):
            x0 = previous.x0
    unknown = [e for e in held if e not in effects]
    if unknown:
        raise ValueError(f"held effects {unknown} are not in the model {effects}")
    pidx, qidx, qlo, qhi, names, owners = _free_layout(kernel, effects, fixed_args, held)
    midx = _moment_layout(kernel, effects)
    # the second mode where the grid holds one: from a previous fit that has it, else the grid's start
    mode2 = None
    if grid.second_mode is not None:
        mode2 = (previous.mode2.copy() if previous is not None and previous.mode2 is not None
                 else grid.second_mode.as_array())
    n_mode = N_MODE_PARAMETERS if mode2 is not None else 0
    npq = len(pidx) + len(qidx) + N_OFFSETS + n_mode
    names = (*names, *(f"output.{n}" for n in OUTPUT_TERMS), *(f"second_mode.{n}" for n in MODE_PARAMETERS[:n_mode]))
    owners = (*owners, *("output",) * N_OFFSETS, *("second_mode",) * n_mode)
    x0 = _start_states_for(grid, x0)
    offset = previous.offset.copy() if previous is not None else np.zeros(N_OFFSETS)
    n_free = len(pidx) + len(qidx)

    def pack():
        return np.concatenate([theta[pidx], arg[qidx], offset, *(() if mode2 is None else (mode2,))])

    def unpack(v):
        th, ar = theta.copy(), arg.copy()
        th[pidx] = v[:len(pidx)]
        ar[qidx] = v[len(pidx):n_free]
        m2 = None if mode2 is None else v[n_free + N_OFFSETS:].copy()
        return th, ar, v[n_free:n_free + N_OFFSETS].copy(), m2

    status, pred, jac = _shoot(kernel, grid, x0, theta, arg, active, pidx, qidx, qlo, qhi, offset, midx, mode2)
    if status:
        raise FloatingPointError("the model diverged from its start values")
    r = grid.y - pred
    rss = float(np.sum(r * r))
    lam = 1e-3
    it = 0
    converged = False
    reachable = None
    v = pack()
    while it < max_iter:
        it += 1
        H, gr, GiC, Gic, _ = _reduced_normal_equations(r, jac, grid.segments, npq)
        scale = np.sqrt(np.maximum(np.diag(H), 0.0))
        scale[scale == 0] = 1.0
        JtJ = H / np.outer(scale, scale)
        g = gr / scale
        improved = False
        for _ in range(12):
            try:
                d = np.linalg.solve(JtJ + lam * np.diag(np.diag(JtJ) + 1e-12), g) / scale
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            v_new = v + d
            th_new, ar_new, off_new, m2_new = unpack(v_new)
            x0_new = x0 + Gic - GiC @ d
            if m2_new is not None and not (m2_new[0] > 0 and m2_new[1] >= 0):
                lam *= 8.0  # a second mode with no stiffness or negative damping is no mode
                continue
            st, p_new, j_new = _shoot(kernel, grid, x0_new, th_new, ar_new, active, pidx, qidx, qlo, qhi, off_new,
                                      midx, m2_new)
            r_new = grid.y - p_new
            with np.errstate(over="ignore", invalid="ignore"):  # a trial step that blew up is refused
                rss_new = float(np.sum(r_new * r_new)) if st == 0 else math.inf
            if not math.isfinite(rss_new):
                rss_new = math.inf
            if rss_new < rss:
                improved = True
                fall = rss - rss_new
                drop = fall / max(rss, 1e-300)
                v, theta, arg, offset, x0, mode2 = v_new, th_new, ar_new, off_new, x0_new, m2_new
                pred, jac, r, rss = p_new, j_new, r_new, rss_new
                lam = max(lam / 5.0, 1e-9)
                break
            lam *= 8.0
        if not improved or drop < tol:
            converged = True
            break
        if give_up_above is not None and it >= 2 and it < max_iter:
            lowest = rss - GIVE_UP_MARGIN * (max_iter - it) * fall
            if lowest > give_up_above:
                reachable = lowest
                break
    # the covariance at the optimum: projected Jacobian, HAC of the per-sample scores
    rt, Jt = _project(grid, r, jac, npq)
    bread = np.linalg.pinv(Jt.T @ Jt)
    # the scores per time sample of the segments' rows (two channels each), in time order
    scores = (Jt * rt[:, None]).reshape(-1, 2, npq).sum(axis=1)
    bw = andrews_bandwidth(scores)
    S = long_run_covariance(scores, bw)
    cov = bread @ S @ bread
    return OutputErrorFit(effects, names, owners, v.copy(), cov, rss, r, pred, x0, it, converged, bw, grid,
                          theta, arg, offset, reachable, mode2)


def _start_states_for(grid: ShootingGrid, x0: np.ndarray | None) -> np.ndarray:
    """``x0`` (a previous fit's, or ``None``: the grid's first guesses) with the columns the
    grid's model has: the second mode's steady state put first where ``x0`` lacks it, dropped
    where the grid has none."""
    if x0 is None:
        return grid.start_states()
    x0 = np.array(x0, float)
    if x0.shape[1] == grid.n_states:
        return x0
    own = x0[:, -4:]
    if grid.second_mode is None:
        return own
    i = grid.segments[:, 0]
    return np.column_stack([grid.second_mode.steady_states(grid.phi[i], grid.phid[i]), own])


@dataclass(frozen=True)
class AddedEffectInformation:
    """What a fitted record knows about an effect *not* in its model, at zero size.

    With ``A`` the prediction's sensitivity to the effect's coefficients (forward
    sensitivities along the fitted model's trajectory) and ``B`` every column the fit
    already has (the model's parameters, the probes' offsets and runout, each segment's
    free start state), ``signature = A'A`` is the effect's own output energy per unit
    coefficient and ``information = A'(I - P_B)A`` what is left of it once ``B`` has taken
    its share: the Fisher information of a test that adds the effect, up to the noise
    variance.  ``covariance`` is the estimate's covariance at zero size,
    ``s^2 information^-1`` with ``s^2`` the Bartlett long-run variance of the fit's residual
    per row (white noise: its variance).  ``absorbed_by`` gives, for each group of ``B`` (the
    start states, the offsets, each effect of the model), how much more of the signature
    would stay visible without that group: the lookalike that hides it.  ``score`` is
    Rao's score test of the effect at the fitted model (``g' information^-1 g / s^2`` with
    ``g = A'(I - P_B) r``): the evidence in the residual, without a refit.
    """

    effect: str
    coefficients: tuple[str, ...]
    arguments: dict[str, float]
    signature: np.ndarray
    information: np.ndarray
    covariance: np.ndarray
    absorbed_by: dict[str, float]
    #: Rao's score (Lagrange multiplier) statistic for the effect at zero size, chi-square
    #: with one degree of freedom per coefficient when the effect is absent
    score: float = 0.0
    #: the Gauss-Newton step from zero: the coefficients the residual leans towards
    one_step: np.ndarray | None = None

    @property
    def visible_share(self) -> tuple[float, float]:
        """The share of the signature's energy left visible, least and most visible direction
        in coefficient space (generalized eigenvalues of ``information`` on ``signature``)."""
        mu = _visible_shares(self.signature, self.information)
        return float(mu[0]), float(mu[-1])


def _visible_shares(G0: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Eigenvalues of ``G`` relative to ``G0`` (ascending, in [0, 1]); directions with no
    signature at all (a zero column) count as invisible."""
    d = np.sqrt(np.maximum(np.diag(G0), 0.0))
    ok = d > 1e-300
    if not ok.any():
        return np.zeros(len(d))
    Gn0 = G0[np.ix_(ok, ok)] / np.outer(d[ok], d[ok])
    Gn = G[np.ix_(ok, ok)] / np.outer(d[ok], d[ok])
    w0, V0 = np.linalg.eigh(Gn0)
    keep = w0 > 1e-12 * w0.max()
    W = V0[:, keep] / np.sqrt(w0[keep])
    mu = np.clip(np.linalg.eigvalsh(W.T @ Gn @ W), 0.0, 1.0)
    return np.concatenate([np.zeros(int((~ok).sum()) + int((~keep).sum())), mu])


def _residual_part(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A`` minus its least-squares projection on the columns of ``B`` (scaled, rank-safe)."""
    if B.shape[1] == 0:
        return A
    sc = np.linalg.norm(B, axis=0)
    sc[sc == 0] = 1.0
    coef, *_ = np.linalg.lstsq(B / sc, A, rcond=1e-10)
    return A - (B / sc) @ coef


def _held_arguments(fit: OutputErrorFit) -> dict[str, dict[str, float]]:
    """The model's argument parameters the fit held (not among its free names)."""
    return {e: {p.name: 0.0 for p in EFFECTS[e].argument_parameters if f"{e}.{p.name}" not in fit.names}
            for e in fit.effects}


def _jacobian_along(fit: OutputErrorFit, effects: Sequence[str], theta: np.ndarray, arg: np.ndarray,
                    fixed: Mapping[str, Mapping[str, float]]):
    """One simulation with sensitivities of ``effects`` (coefficients ``theta``, arguments
    ``arg``) from ``fit``'s start states and offsets: ``(names, owners, npar, npq, pred, jac)``,
    the names and owners of the free parameters and of the output terms, ``npar`` the
    model's free parameters, ``npq`` with the output terms."""
    lib = library_effects()
    kernel = _kernel(lib)
    active = np.zeros(len(lib), dtype=np.bool_)
    for e in effects:
        active[lib.index(e)] = True
    pidx, qidx, qlo, qhi, names, owners = _free_layout(kernel, effects, fixed)
    npar = len(pidx) + len(qidx)
    status, pred, jac = _shoot(kernel, fit.grid, fit.x0, theta, arg, active, pidx, qidx, qlo, qhi, fit.offset,
                               mode2=fit.mode2)
    if status:
        raise FloatingPointError("the fitted model diverged on its own record")
    n_mode = 0 if fit.mode2 is None else N_MODE_PARAMETERS
    names = (*names, *(f"output.{n}" for n in OUTPUT_TERMS), *(f"second_mode.{n}" for n in MODE_PARAMETERS[:n_mode]))
    owners = (*owners, *("output",) * N_OFFSETS, *("second_mode",) * n_mode)
    return names, owners, npar, npar + N_OFFSETS + n_mode, pred, jac


def added_effect_information(fit: OutputErrorFit, effect: str,
                             arguments: Mapping[str, float] | None = None) -> AddedEffectInformation:
    """The information the record ``fit`` was fitted to holds about ``effect`` at zero size
    (:class:`AddedEffectInformation`); ``arguments``: the effect's argument parameters
    (orientations, a clearance), their declared defaults where absent.  One simulation with
    sensitivities along the fitted trajectory; nothing is refitted."""
    lib = library_effects()
    if effect not in lib:
        raise ValueError(f"effect {effect!r} cannot be assessed by output error (set-valued or a user effect)")
    if effect in fit.effects:
        raise ValueError(f"effect {effect!r} is already in the model")
    kernel = _kernel(lib)
    eff = EFFECTS[effect]
    grid = fit.grid
    effects = (*fit.effects, effect)
    theta, arg = fit.theta_full.copy(), fit.arg_full.copy()
    theta[slice(*kernel.coef_slots[effect])] = 0.0
    given = {p.name: float((arguments or {}).get(p.name, p.default)) for p in eff.argument_parameters}
    alo, _ = kernel.arg_slots[effect]
    for q, p in enumerate(eff.argument_parameters):
        arg[alo + q] = given[p.name]
    # the model's arguments stay free as they were fitted; the new effect's are held (at
    # zero size they have no sensitivity)
    fixed = {**_held_arguments(fit), effect: dict(given)}
    names, owners, npar, npq, pred, jac = _jacobian_along(fit, effects, theta, arg, fixed)
    r = grid.y - pred
    mine = [i for i, o in enumerate(owners) if o == effect]
    groups: dict[str, list[int]] = {}
    for i, o in enumerate(owners[:npar]):
        if o != effect:
            groups.setdefault(o, []).append(i)
    groups["the probes' offsets and runout"] = list(range(npar, npar + N_OFFSETS))
    if npq > npar + N_OFFSETS:
        groups["the second mode"] = list(range(npar + N_OFFSETS, npq))
    rest = [i for i in range(npq) if i not in mine]
    raw = np.vstack([jac[i0:i1 + 1, :, :npq].reshape(-1, npq) for i0, i1 in grid.segments])
    rt, Jt = _project(grid, r, jac, npq)
    # every projection below is a least-squares fit among the columns of one tall matrix:
    # with M = Q R (thin QR, once), min |M_B c - M_A| = min |R_B c - R_A| and M_A' M_B = R_A' R_B,
    # so they are done on the small R (the residual as M's last column gives the score)
    R = np.linalg.qr(np.column_stack([Jt, rt]), mode="r")
    R_raw = np.linalg.qr(raw, mode="r")
    A = R[:, mine]
    A_perp = _residual_part(A, R[:, rest])
    G0 = R_raw[:, mine].T @ R_raw[:, mine]
    G = A_perp.T @ A_perp
    top = _visible_shares(G0, G)[-1]
    absorbed = {}
    # without the segments' start states (the raw rows), then without each group in turn
    A_raw_perp = _residual_part(R_raw[:, mine], R_raw[:, rest])
    absorbed["the segments' start states"] = float(_visible_shares(G0, A_raw_perp.T @ A_raw_perp)[-1] - top)
    for g, cols in groups.items():
        others = [i for i in rest if i not in cols]
        P = _residual_part(A, R[:, others])
        absorbed[g] = float(_visible_shares(G0, P.T @ P)[-1] - top)
    absorbed = dict(sorted(absorbed.items(), key=lambda kv: -kv[1]))
    # the estimate's covariance at zero size: the residual's long-run variance per row times
    # G^-1 -- the residual has tens of thousands of samples, so its long-run variance is
    # well estimated, where a HAC of the few slow scores of one effect scatters by tens of
    # per cent from record to record (coloured noise is still covered: its spectrum near the
    # effect's frequencies, approximated by the long-run variance, sets the variance)
    r2 = rt.reshape(-1, 2)
    lrv = float(np.trace(long_run_covariance(r2, andrews_bandwidth(r2)))) / (2 * len(r2))
    Gi = np.linalg.pinv(G, rcond=1e-13)
    cov = lrv * Gi
    # Rao's score test at zero size: the residual's projection on the effect's visible part
    g = A_perp.T @ R[:, npq]
    score = float(g @ Gi @ g) / lrv if lrv > 0 else 0.0
    return AddedEffectInformation(effect, tuple(eff.coefficients), given, G0, G, cov, absorbed, score, Gi @ g)


def sample_scores(fit: OutputErrorFit, *, with_jacobian: bool = False):
    """The fit's scores per grid sample: ``J_k' e_k`` summed over the two channels, with ``J``
    the Jacobian of every free parameter (the model's, then the probes' offsets and runout)
    projected on the complement of each segment's start state, ``e`` the residual.  At the
    optimum they sum to zero; their partial sums are the path of a parameter-constancy test
    (:mod:`rotor_env.diagnosis.change`).  Returns the samples' times, the scores ``(N, p)``
    and the parameters' names; ``with_jacobian``: also the projected Jacobian rows
    ``(N, 2, p)`` (the test's information per sample), before the names."""
    names, _, _, npq, pred, jac = _jacobian_along(fit, fit.effects, fit.theta_full, fit.arg_full,
                                                  _held_arguments(fit))
    grid = fit.grid
    rt, Jt = _project(grid, grid.y - pred, jac, npq)
    J3 = Jt.reshape(-1, 2, npq)
    scores = (J3 * rt.reshape(-1, 2)[:, :, None]).sum(axis=1)
    t = np.concatenate([grid.t[i0:i1 + 1] for i0, i1 in grid.segments])
    return (t, scores, J3, names) if with_jacobian else (t, scores, names)


def equation_error_start(grid: ShootingGrid, effects: Sequence[str]) -> dict[str, np.ndarray]:
    """Coefficients from the equation error on the grid (Savitzky-Golay rates and
    accelerations over about a sixth of a natural period): the output-error fit's start.
    Biased by the noise of the estimated derivatives, which the output-error fit removes."""
    from scipy.signal import savgol_filter

    effects = tuple(dict.fromkeys(("stiffness", *effects)))
    dt = float(np.median(np.diff(grid.t)))
    win = max(7, int(round(1.0 / dt)) | 1)
    y = grid.y
    w = np.column_stack([savgol_filter(y[:, c], win, 3, deriv=1, delta=dt) for c in range(2)])
    acc = np.column_stack([savgol_filter(y[:, c], win, 3, deriv=2, delta=dt) for c in range(2)])
    phidd = np.gradient(grid.phid, grid.t)
    ip = grid.ip
    # th_y'' + ip phid th_x' = sum theta cy;  th_x'' - ip phid th_y' = sum theta cx
    out_y = acc[:, 1] + ip * grid.phid * w[:, 0]
    out_x = acc[:, 0] - ip * grid.phid * w[:, 1]
    blocks_y, blocks_x, sizes = [], [], []
    for e in effects:
        Xy, Xx = EFFECTS[e].regressors(grid.phi, grid.phid, phidd, y[:, 0], y[:, 1], w[:, 0], w[:, 1], ip)
        blocks_y.append(Xy)
        blocks_x.append(Xx)
        sizes.append(Xy.shape[1])
    X = np.vstack([np.hstack(blocks_y), np.hstack(blocks_x)])
    b = np.concatenate([out_y, out_x])
    scale = np.sqrt(np.sum(X * X, axis=0))
    scale[scale == 0] = 1.0
    theta = np.linalg.lstsq(X / scale, b, rcond=None)[0] / scale
    out, j = {}, 0
    for e, n in zip(effects, sizes, strict=True):
        out[e] = theta[j:j + n].copy()
        j += n
    return out


# ------------------------------------------------------------------ the probes' noise
def _high_band(x: np.ndarray, dt: float, f_signal: float):
    """Welch's periodogram of ``x`` (mean removed) and the band ``(1.5 f_signal, 0.9 Nyquist)``
    above the signal: ``(f, p, band, nyquist)``; ``f`` is ``None`` where the record is too
    short or sampled too close to its content for a band to exist."""
    from scipy.signal import welch

    x = np.asarray(x, float)
    x = x - np.mean(x)
    nyq = 0.5 / dt
    lo = 1.5 * f_signal
    if not (lo < 0.6 * nyq and len(x) >= 512):
        return None, None, None, nyq
    nper = int(min(4096, 2 ** math.floor(math.log2(len(x) / 8))))
    f, p = welch(x, fs=1.0 / dt, nperseg=nper, detrend="linear")
    return f, p, (f > lo) & (f < 0.9 * nyq), nyq


def noise_ar1_high_band(x: np.ndarray, dt: float, f_signal: float) -> tuple[float, float]:
    """``(std, rho)`` of first-order autoregressive sensor noise from the band above the signal.

    Coloured noise (an integrating sensor, a filtered channel, a random walk of the
    quantiser) is an AR(1) process ``n_k = rho n_{k-1} + e_k``: its one-sided density is
    ``2 dt var(e) / |1 - rho exp(-i w)|^2`` with ``w = 2 pi f dt``, so the shape of Welch's
    periodogram over ``(1.5 f_signal, 0.9 Nyquist)`` gives ``rho`` (least squares of the log
    density over a grid of ``rho``, the level by the median ratio: a few spikes do not lift
    it) and its level ``var(e)``.  Returned: the noise's marginal standard deviation
    ``sqrt(var(e) / (1 - rho^2))`` and ``rho``.  White noise gives ``rho`` near 0 and the
    level of :func:`noise_std_high_band`; where the band is too narrow to read a shape, that
    function's white estimate with ``rho = 0``.
    """
    f, p, band, nyq = _high_band(x, dt, f_signal)
    if f is not None:
        band = band & (p > 0)
        if band.sum() >= 16:
            w = 2 * math.pi * f[band] * dt
            lp = np.log(p[band])
            best = (math.inf, 0.0, 0.0)
            for rho in np.linspace(-0.9, 0.98, 189):
                lg = -np.log(1.0 - 2.0 * rho * np.cos(w) + rho * rho)
                level = float(np.median(lp - lg))
                loss = float(np.sum((lp - lg - level) ** 2))
                if loss < best[0]:
                    best = (loss, float(rho), level)
            _, rho, level = best
            # Welch's averaged periodogram: its median is ~its mean (chi^2 of many degrees of freedom)
            var_e = math.exp(level) * nyq
            return math.sqrt(var_e / (1.0 - rho * rho)), rho
    return noise_std_high_band(x, dt, f_signal), 0.0


def noise_ar1_two_channels(x: np.ndarray, y: np.ndarray, dt: float, f_signal: float) -> tuple[float, float]:
    """:func:`noise_ar1_high_band` of two channels measured alike (the two axes of an orbit):
    their variances and lag-one correlations averaged."""
    (sx, rx), (sy, ry) = (noise_ar1_high_band(c, dt, f_signal) for c in (x, y))
    return math.sqrt(0.5 * (sx * sx + sy * sy)), 0.5 * (rx + ry)


def noise_std_high_band(x: np.ndarray, dt: float, f_signal: float) -> float:
    """Standard deviation of white sensor noise from the band above the signal.

    ``x`` sampled every ``dt``; ``f_signal``: the highest frequency the rotor's response
    holds (cycles per unit of ``dt``).  Welch's periodogram's median level over
    ``(1.5 f_signal, 0.9 Nyquist)`` times the full band; where that band is too narrow
    (a record sampled barely above its content), the third difference's variance
    (20 sigma^2 for white noise; a smooth signal's third difference is small).
    """
    f, p, band, nyq = _high_band(x, dt, f_signal)
    if f is not None and band.sum() >= 8:
        # the median of an averaged periodogram is ~the mean for white noise (chi^2 with
        # many degrees of freedom), and a few spikes (a rub's impacts) do not lift it
        level = float(np.median(p[band]))
        return math.sqrt(level * nyq)
    d3 = np.diff(np.asarray(x, float), 3)
    return float(math.sqrt(np.median(d3 * d3) / 0.4549364231195724 / 20.0))
