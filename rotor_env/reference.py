"""A tight, independent reference solution of the rotor equations (for validation).

The equations of docs/PHYSICS.md section 1 written out by hand (deliberately *not* from
the effect declarations, so that comparing with the simulator checks both), with the
friction regularised as ``S -> sqrt(S^2 + eps^2)`` and integrated by
``scipy.integrate.solve_ivp(method="LSODA", rtol=1e-9, atol=1e-12)``, split at a crack.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from .params import RotorParams


def reference_solution(
    params: RotorParams,
    t_eval: np.ndarray,
    run_up: float = 0.01,
    eps: float = 1e-6,
    rtol: float = 1e-9,
    atol: float = 1e-12,
) -> np.ndarray:
    """States ``[th_x, th_y, w_x, w_y]`` at ``t_eval`` (shape ``(len(t_eval), 4)``)."""
    ip = params.ip
    v = params.values
    a = run_up

    def rhs_for(D):
        tau, beta, c, h, k = v["tau"], v["beta"], v["c"], v["h"], v["k"]
        k30, k21, k12, k03 = v["k30"], v["k21"], v["k12"], v["k03"]

        def rhs(t, s):
            thx, thy, wx, wy = s
            phid = a * t
            phi = 0.5 * a * t * t
            s2, c2 = math.sin(2 * phi), math.cos(2 * phi)
            Mky = -k * thy - D * (thy * c2 + thx * s2)
            Mkx = -k * thx - D * (thy * s2 - thx * c2)
            Ny = -(k03 * thy**2 + 2 * k12 * thx * thy + k21 * thx**2)
            Nx = -(k30 * thx**2 + 2 * k21 * thx * thy + k12 * thy**2)
            S = math.sqrt(wx**2 + wy**2 + 2 * phid * (wy * thx - wx * thy) + phid**2 * (thx**2 + thy**2) + eps**2)
            Mdy = -h * (wy + phid * thx) / S
            Mdx = -h * (wx - phid * thy) / S
            fy = (1 - ip) * tau * (a * math.cos(phi + beta) - phid**2 * math.sin(phi + beta))
            fx = (1 - ip) * tau * (a * math.sin(phi + beta) + phid**2 * math.cos(phi + beta))
            ay = fy - ip * phid * wx - c * wy + Mdy + Ny + Mky
            ax = fx + ip * phid * wy - c * wx + Mdx + Nx + Mkx
            return [wx, wy, ax, ay]

        return rhs

    t_eval = np.asarray(t_eval, dtype=float)
    segments = [(0.0, float(t_eval[-1]), v["D"])]
    crack = params.crack
    if crack is not None and 0 < crack.time < t_eval[-1]:
        segments = [(0.0, crack.time, v["D"]), (crack.time, float(t_eval[-1]), crack.D)]
    out = np.empty((len(t_eval), 4))
    state = np.zeros(4)
    for t0, t1, D in segments:
        mask = (t_eval >= t0) & (t_eval <= t1)
        # one pass per segment: evaluate at the samples and at the segment's end
        te = np.append(t_eval[mask], t1) if t_eval[mask][-1] < t1 else t_eval[mask]
        sol = solve_ivp(rhs_for(D), (t0, t1), state, method="LSODA", rtol=rtol, atol=atol, t_eval=te)
        if not sol.success:
            raise RuntimeError(f"reference integration failed: {sol.message}")
        out[mask] = sol.y.T[: mask.sum()]
        state = sol.y[:, -1]
    return out
