"""The monitor's compiled block loop (one call per chunk; cached on disk).

Each block of ``B`` samples: noise levels from second differences, the rows of the
samples that carry information (:func:`rotor_env.online.keep_moving_rows`, the
identification core's selection), the block evidence of every effect against the
reference before the block (:mod:`rotor_env.monitor.detector`), the CUSUMs, and the
reference's time update (:func:`identifier.kernels.update_blocks`, the core's
update).  There is no second copy of the identifier's update loop here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from identifier.kernels import (
    clean_factor,
    identifiable_columns,
    nested_coefficients,
    update_blocks,
)

from ..online import keep_moving_rows
from .detector import evidence_z

# cfg entries
C_LAMBDA, C_RTOL, C_FLOOR2, C_STICK, C_STICK_SIGMAS, C_IDENT_FRAC, C_K, C_H, C_CAL_BLOCKS, C_CAL_W, \
    C_RESTART, C_BLOCK, C_LAGS, C_MIN_ROWS, C_WINDOW = range(15)
N_CFG = 15
# mon entries (scalars of the state)
M_GAMMA_N, M_SIG_TH2, M_SIG_W2, M_NOISE_N, M_BLOCKS, M_LAST_T, M_LAST_SPEED, M_ALARMS, M_HOLD, M_PENDING = range(10)
N_MON = 10
#: blocks after an alarm during which no CUSUM runs: the reference learns the changed model
HOLD_BLOCKS = 2.0
# per-effect arrays: eff[g, :]
E_KAPPA, E_KAPPA_N, E_S, E_ON_T, E_ON_SPEED, E_ON_BLOCKS, E_ON_CHI, E_COUNTED, E_CLIP, E_CWIN, E_Q = range(11)
N_EFF = 11
# event row: fixed part, then before, se_before, delta, se_delta (qmax each), then each
# effect's change alone fitted to the deciding block (G rows of 1 + 4 qmax: _isolate)
V_T, V_G, V_T_ONSET, V_S, V_CHI, V_DOF, V_BLOCKS, V_SPEED_ONSET, V_SPEED, V_KAPPA, V_LONG_RUN = range(11)
N_EV_FIXED = 11


def isolation_width(effects: int, qmax: int) -> int:
    """Entries of an event row after its fixed part and the alarm's own estimate (_isolate)."""
    return effects * (1 + 4 * qmax)


@njit(cache=True, error_model="numpy")
def _chol_solve_drop(M, idx, m, b, out, L, keep, tol):
    """Solve ``M[idx, idx] x = b`` by a Cholesky that drops (near-)dependent columns.

    ``idx[:m]`` are the columns; a pivot ``d <= tol * M_jj`` drops column ``j`` (its
    ``x`` is 0: it is explained by the ones before it in this block).  ``b`` has shape
    ``(n, r)`` (``r`` right-hand sides, rows indexed like ``M``); ``out`` ``(n, r)``.
    """
    r_cols = b.shape[1]
    for a in range(m):
        ja = idx[a]
        d = M[ja, ja]
        for c in range(a):
            d -= L[a, c] * L[a, c]
        keep[a] = d > tol * M[ja, ja] and d > 0.0
        if not keep[a]:
            for c in range(m):
                L[a, c] = 0.0
                L[c, a] = 0.0
            continue
        L[a, a] = math.sqrt(d)
        for c in range(a + 1, m):
            jc = idx[c]
            v = M[jc, ja]
            for e in range(a):
                v -= L[c, e] * L[a, e]
            L[c, a] = v / L[a, a]
    for rc in range(r_cols):
        # forward: L u = b
        for a in range(m):
            if not keep[a]:
                out[idx[a], rc] = 0.0
                continue
            v = b[idx[a], rc]
            for c in range(a):
                if keep[c]:
                    v -= L[a, c] * out[idx[c], rc]
            out[idx[a], rc] = v / L[a, a]
        # backward: L' x = u
        for a in range(m - 1, -1, -1):
            if not keep[a]:
                continue
            v = out[idx[a], rc]
            for c in range(a + 1, m):
                if keep[c]:
                    v -= L[c, a] * out[idx[c], rc]
            out[idx[a], rc] = v / L[a, a]


@njit(cache=True, error_model="numpy")
def _spd_inverse(V, q, Vinv, L):
    """Inverse of the symmetric positive definite ``V[:q, :q]``; False if not positive definite."""
    for a in range(q):
        d = V[a, a]
        for c in range(a):
            d -= L[a, c] * L[a, c]
        if not d > 1e-300:
            return False
        L[a, a] = math.sqrt(d)
        for c in range(a + 1, q):
            v = V[c, a]
            for e in range(a):
                v -= L[c, e] * L[a, e]
            L[c, a] = v / L[a, a]
    # Vinv = L^-T L^-1, column by column
    for j in range(q):
        u = np.zeros(q)
        u[j] = 1.0
        for a in range(q):
            v = u[a]
            for c in range(a):
                v -= L[a, c] * u[c]
            u[a] = v / L[a, a]
        for a in range(q - 1, -1, -1):
            v = u[a]
            for c in range(a + 1, q):
                v -= L[c, a] * u[c]
            u[a] = v / L[a, a]
        for a in range(q):
            Vinv[a, j] = u[a]
    return True


@njit(cache=True, error_model="numpy")
def _reference_se(T, col, lr, c_lam, kap):
    """Standard error of the reference's coefficient ``col``: ``sqrt(lr c_lam (T T')_jj kappa)``
    (``T`` the inverse factor of the forgetting fit, ``lr`` the noise's long-run variance)."""
    tt = 0.0
    for m2 in range(T.shape[1]):
        tt += T[col, m2] * T[col, m2]
    return math.sqrt(max(lr * c_lam * tt * kap, 0.0))


@njit(cache=True, error_model="numpy")
def _isolate(Xk, e, M, cols, eff, theta, T, lr, c_lam, ev, off, A, Ainv, Lq, b):
    """Each effect's change alone, fitted to the deciding block's prediction error ``e``.

    From ``ev[off]``, ``1 + 4 qmax`` entries per effect ``h``: the energy of ``e`` it explains,
    ``e' X_h (X_h' X_h)^-1 X_h' e``, in the noise's long-run variance ``lr`` times the
    effect's calibration factor (NaN where its columns are dependent in the block),
    then the reference's coefficients and their standard errors, then the change
    ``(X_h' X_h)^-1 X_h' e`` and its standard errors.  ``M = X' X`` of the block; ``A, Ainv, Lq, b``:
    work arrays.
    """
    G, qmax = cols.shape
    for h in range(G):
        o = off + h * (1 + 4 * qmax)
        q = int(eff[h, E_Q])
        kap = max(1.0, eff[h, E_KAPPA])
        for a in range(q):
            v = 0.0
            for r in range(Xk.shape[0]):
                v += Xk[r, cols[h, a]] * e[r]
            b[a] = v
            for c in range(q):
                A[a, c] = M[cols[h, a], cols[h, c]]
            ev[o + 1 + a] = theta[cols[h, a]]
            ev[o + 1 + qmax + a] = _reference_se(T, cols[h, a], lr, c_lam, kap)
        if not _spd_inverse(A, q, Ainv, Lq):
            ev[o] = math.nan
            continue
        v = 0.0
        for a in range(q):
            d = 0.0
            for c in range(q):
                v += b[a] * Ainv[a, c] * b[c]
                d += Ainv[a, c] * b[c]
            ev[o + 1 + 2 * qmax + a] = d
            ev[o + 1 + 3 * qmax + a] = math.sqrt(max(Ainv[a, a] * lr * kap, 0.0))
        ev[o] = v / (lr * kap)


@njit(cache=True, nogil=True, error_model="numpy")
def process_blocks(data, X, y, per, R, col_sq, sums, masks, cols, scales, cfg, gamma, mon, eff,
                   on_before, on_se, sumA, sum_s, sumV, events, ring_X, ring_y, ring_n):
    """Run the monitor over ``data`` (whole blocks) with its regression rows ``X, y``.

    ``cols[g, :q_g]``: the columns of effect ``g``; ``scales[g]``: the size of the effect
    its declared plausible bounds allow.  State arrays are updated in place; alarms are
    written to ``events`` (one row each).  Returns the number of events.  With a sliding
    window (``cfg[C_WINDOW] > 0`` blocks), the rows of the block leaving the window are
    taken out of the factor (``ring_*`` hold the window's rows).
    """
    B = int(cfg[C_BLOCK])
    nb = data.shape[0] // B
    G, n = masks.shape
    size = n + 1
    qmax = cols.shape[1]
    L_lags = int(cfg[C_LAGS])
    floor2 = cfg[C_FLOOR2]
    work = np.empty((size, size))
    row = np.empty(size)
    allc = np.empty((n, n))
    T = np.empty((n, n))
    invd = np.empty(n)
    ident = np.empty(n, dtype=np.bool_)
    theta = np.empty(n)
    M = np.empty((n, n))
    Lm = np.zeros((n, n))
    keep = np.empty(n, dtype=np.bool_)
    idx = np.empty(n, dtype=np.int64)
    rhs = np.empty((n, qmax + 1))
    sol = np.empty((n, qmax + 1))
    Zt = np.empty((per * B, qmax))
    e = np.empty(per * B)
    A = np.empty((qmax, qmax))
    Vh = np.empty((qmax, qmax))
    Vr = np.empty((qmax, qmax))
    V = np.empty((qmax, qmax))
    Vinv = np.empty((qmax, qmax))
    Ainv = np.empty((qmax, qmax))
    Lq = np.empty((qmax, qmax))
    s = np.empty(qmax)
    W = np.empty((n, qmax))
    U = np.empty((per * B, qmax))
    P = np.empty((qmax, qmax))
    wlag = np.zeros(L_lags + 1)
    n_ev = 0
    for b in range(nb):
        i0 = b * B
        blk = data[i0 : i0 + B]
        Xb = X[per * i0 : per * (i0 + B)]
        yb = y[per * i0 : per * (i0 + B)]
        # --- noise of the inclinations and their rates: second differences remove a smooth
        # signal (its part is theta''' dt^2) and multiply white noise's variance by 6
        acc_th = 0.0
        acc_w = 0.0
        for r in range(2, B):
            for c in (4, 5):
                d = blk[r, c] - 2.0 * blk[r - 1, c] + blk[r - 2, c]
                acc_th += d * d
            for c in (6, 7):
                d = blk[r, c] - 2.0 * blk[r - 1, c] + blk[r - 2, c]
                acc_w += d * d
        cnt = 12.0 * (B - 2)
        mon[M_NOISE_N] += 1.0
        wn = max(1.0 / mon[M_NOISE_N], cfg[C_CAL_W])
        mon[M_SIG_TH2] += wn * (acc_th / cnt - mon[M_SIG_TH2])
        mon[M_SIG_W2] += wn * (acc_w / cnt - mon[M_SIG_W2])
        speed_max = 0.0
        for r in range(B):
            speed_max = max(speed_max, abs(blk[r, 2]))
        # a disk whose relative speed S is within the noise sticks to the shaft as far as
        # the data can tell: the friction column's direction would be noise
        stick = max(cfg[C_STICK],
                    cfg[C_STICK_SIGMAS] * math.sqrt(mon[M_SIG_W2] + speed_max * speed_max * mon[M_SIG_TH2]))
        k = keep_moving_rows(blk, Xb, yb, per, stick)
        restart = False
        informative = k >= per * B // 2 and sums[0] >= cfg[C_MIN_ROWS]
        if informative:
            # --- the reference before the block
            identifiable_columns(R, col_sq, cfg[C_RTOL], ident)
            clean_factor(R, ident, work, row)
            nested_coefficients(work, ident, allc, T, invd)
            for j in range(n):
                theta[j] = allc[n - 1, j]
            c_lam = sums[2] / sums[1] if sums[1] > 0 else 1.0
            g0 = max(gamma[0], floor2)
            lr = g0
            for lag in range(1, L_lags + 1):
                lr += 2.0 * (1.0 - lag / (L_lags + 1.0)) * gamma[lag]
            lr = max(lr, g0)
            # the HAC lags' Bartlett weights times the residual autocovariance
            for lag in range(1, L_lags + 1):
                wlag[lag] = (1.0 - lag / (L_lags + 1.0)) * gamma[lag]
            Xk = Xb[:k]
            e[:k] = yb[:k] - np.dot(Xk, theta)  # BLAS: the block's rows are contiguous
            M[:, :] = np.dot(Xk.T, Xk)
            best = -1
            best_excess = 0.0
            for g in range(G):
                q = int(eff[g, E_Q])
                ok = True
                for a in range(q):
                    ok = ok and ident[cols[g, a]]
                if not ok:
                    continue
                # others, then the effect's columns regressed on them inside the block
                m_o = 0
                for j in range(n):
                    if not masks[g, j]:
                        idx[m_o] = j
                        m_o += 1
                for a in range(q):
                    for j in range(n):
                        rhs[j, a] = M[j, cols[g, a]]
                _chol_solve_drop(M, idx, m_o, rhs[:, :q], sol[:, :q], Lm, keep, 1e-10)
                # Z = X W: the effect's columns less their regression on the others
                W[:, :q] = 0.0
                for a in range(q):
                    W[cols[g, a], a] = 1.0
                    for c in range(m_o):
                        if keep[c]:
                            W[idx[c], a] = -sol[idx[c], a]
                Z = np.dot(Xk, np.ascontiguousarray(W[:, :q]))
                Zt[:k, :q] = Z
                s[:q] = np.dot(Z.T, e[:k])
                A[:q, :q] = np.dot(Z.T, Z)
                for a in range(q):
                    for c in range(q):
                        Vh[a, c] = g0 * A[a, c]
                # HAC: Bartlett-weighted lags of the pooled residual autocovariance,
                # sum_l w_l (G_l + G_l'), G_l[a, c] = sum_r Z[r, a] Z[r - l, c]: with the
                # filtered series U[r, c] = sum_l w_l Z[r - l, c], sum_l w_l G_l = Z' U
                if L_lags > 0:
                    for c in range(q):
                        for r in range(k):
                            v = 0.0
                            for lag in range(1, min(L_lags, r) + 1):
                                v += wlag[lag] * Zt[r - lag, c]
                            U[r, c] = v
                    P[:q, :q] = np.dot(Z.T, np.ascontiguousarray(U[:k, :q]))
                    for a in range(q):
                        for c in range(q):
                            Vh[a, c] += P[a, c] + P[c, a]
                # the reference's own error of the effect: A C_g A, C_g = lr c_lam (T T')_gg
                tr_h = 0.0
                tr_r = 0.0
                for a in range(q):
                    for c in range(q):
                        v = 0.0
                        for i in range(q):
                            for j in range(q):
                                ci = cols[g, i]
                                cj = cols[g, j]
                                tt = 0.0
                                for m2 in range(n):
                                    tt += T[ci, m2] * T[cj, m2]
                                v += A[a, i] * tt * A[j, c]
                        Vr[a, c] = lr * c_lam * v
                    tr_h += Vh[a, a]
                    tr_r += Vr[a, a]
                for a in range(q):
                    for c in range(q):
                        V[a, c] = Vh[a, c] + Vr[a, c]
                if not (tr_r <= tr_h and _spd_inverse(V, q, Vinv, Lq) and _spd_inverse(A, q, Ainv, Lq)):
                    continue  # the reference does not know the effect yet, or nothing to test
                chi = 0.0
                for a in range(q):
                    for c in range(q):
                        chi += s[a] * Vinv[a, c] * s[c]
                kap = max(1.0, eff[g, E_KAPPA])
                # identifiable in this block: the block alone would size a change of the
                # effect to a fraction of what its plausible bounds allow
                se_max = 0.0
                for a in range(q):
                    v = 0.0
                    for i in range(q):
                        for j in range(q):
                            v += Ainv[a, i] * V[i, j] * Ainv[j, a]
                    se_max = max(se_max, math.sqrt(max(v * kap, 0.0)))
                if not se_max <= cfg[C_IDENT_FRAC] * scales[g]:
                    continue
                calibrated = eff[g, E_KAPPA_N] >= cfg[C_CAL_BLOCKS] and mon[M_HOLD] == 0.0
                if calibrated:
                    eff[g, E_COUNTED] += 1.0
                    z = evidence_z(chi / kap, q)
                    if eff[g, E_S] == 0.0:  # a new run of evidence: its onset is this block
                        eff[g, E_ON_T] = blk[0, 0]
                        eff[g, E_ON_SPEED] = blk[0, 2]
                        eff[g, E_ON_BLOCKS] = 0.0
                        eff[g, E_ON_CHI] = 0.0
                        for a in range(q):
                            on_before[g, a] = theta[cols[g, a]]
                            on_se[g, a] = _reference_se(T, cols[g, a], lr, c_lam, kap)
                            sum_s[g, a] = 0.0
                            for c in range(q):
                                sumA[g, a, c] = 0.0
                                sumV[g, a, c] = 0.0
                    eff[g, E_S] = max(0.0, eff[g, E_S] + z - cfg[C_K])
                    eff[g, E_ON_BLOCKS] += 1.0
                    eff[g, E_ON_CHI] += chi / kap
                    for a in range(q):
                        sum_s[g, a] += s[a]
                        for c in range(q):
                            sumA[g, a, c] += A[a, c]
                            sumV[g, a, c] += V[a, c] * kap
                    if eff[g, E_S] > cfg[C_H] and eff[g, E_S] - cfg[C_H] > best_excess:
                        best = g
                        best_excess = eff[g, E_S] - cfg[C_H]
                # calibration (batch means of chi / q, winsorised, divided by its null mean)
                eff[g, E_KAPPA_N] += 1.0
                wk = max(1.0 / eff[g, E_KAPPA_N], cfg[C_CAL_W])
                eff[g, E_KAPPA] += wk * (min(chi, eff[g, E_CLIP]) / eff[g, E_CWIN] - eff[g, E_KAPPA])
            if best >= 0 and mon[M_PENDING] == 0.0:
                # a crossing: decide which effect on the next block too. The block that
                # crosses first usually straddles the change, and a step inside a block
                # projects onto other effects' columns; the next block is all after it
                mon[M_PENDING] = 1.0
                best = -1
            elif mon[M_PENDING] != 0.0:
                mon[M_PENDING] = 0.0
            if best >= 0:
                g = best
                q = int(eff[g, E_Q])
                ev = events[n_ev]
                n_ev += 1
                ev[V_T] = blk[B - 1, 0]
                ev[V_G] = g
                ev[V_T_ONSET] = eff[g, E_ON_T]
                ev[V_S] = eff[g, E_S]
                ev[V_CHI] = eff[g, E_ON_CHI]
                ev[V_DOF] = q * eff[g, E_ON_BLOCKS]
                ev[V_BLOCKS] = eff[g, E_ON_BLOCKS]
                ev[V_SPEED_ONSET] = eff[g, E_ON_SPEED]
                ev[V_SPEED] = blk[B - 1, 2]
                ev[V_KAPPA] = max(1.0, eff[g, E_KAPPA])
                # the change since the onset: delta = (sum A)^-1 sum s, its sandwich covariance
                _spd_inverse(sumA[g], q, Ainv, Lq)
                for a in range(q):
                    v = 0.0
                    for c in range(q):
                        v += Ainv[a, c] * sum_s[g, c]
                    ev[N_EV_FIXED + a] = on_before[g, a]
                    ev[N_EV_FIXED + qmax + a] = on_se[g, a]
                    ev[N_EV_FIXED + 2 * qmax + a] = v
                    v = 0.0
                    for i in range(q):
                        for j in range(q):
                            v += Ainv[a, i] * sumV[g, i, j] * Ainv[j, a]
                    ev[N_EV_FIXED + 3 * qmax + a] = math.sqrt(max(v, 0.0))
                ev[V_LONG_RUN] = lr
                # which effect's change alone makes this block's prediction error (isolation,
                # decided in Monitor._event)
                _isolate(Xk, e[:k], M, cols, eff, theta, T, lr, c_lam, ev, N_EV_FIXED + 4 * qmax, A, Ainv, Lq, s)
                mon[M_ALARMS] += 1.0
                restart = True
            # --- the pooled residual autocovariance, from the block's own full fit (a change
            # of the coefficients is fitted away; what is left is noise and misfit)
            m_all = 0
            for j in range(n):
                idx[m_all] = j
                m_all += 1
            rhs[:, 0] = np.dot(Xk.T, yb[:k])
            _chol_solve_drop(M, idx, n, rhs[:, :1], sol[:, :1], Lm, keep, 1e-10)
            p = 0
            for j in range(n):
                p += 1 if keep[j] else 0
            for r in range(k):
                v = yb[r]
                for j in range(n):
                    if keep[j]:
                        v -= Xb[r, j] * sol[j, 0]
                e[r] = v
            dof = k - p
            if dof > L_lags:
                mon[M_GAMMA_N] += 1.0
                wg = max(1.0 / mon[M_GAMMA_N], cfg[C_CAL_W])
                for lag in range(L_lags + 1):
                    v = 0.0
                    for r in range(lag, k):
                        v += e[r] * e[r - lag]
                    gamma[lag] += wg * (v / dof - gamma[lag])
        # --- the reference's time update (the identification core's)
        update_blocks(R, col_sq, sums, Xb[:k], yb[:k], cfg[C_LAMBDA])
        if cfg[C_WINDOW] > 0:
            _window_update(R, col_sq, sums, Xb[:k], yb[:k], ring_X, ring_y, ring_n, int(cfg[C_WINDOW]), per * B)
        if restart:
            # the model changed: the reference forgets the past, the alarm's block included
            # (it straddles the change), and every CUSUM starts again once the reference
            # knows the effects anew (the gates hold them until then)
            rs = cfg[C_RESTART]
            srs = math.sqrt(rs)
            for i in range(size):
                for j in range(i, size):
                    R[i, j] *= srs
            for j in range(n):
                col_sq[j] *= rs
            sums[1] *= rs
            sums[2] *= rs * rs
            for g2 in range(G):
                eff[g2, E_S] = 0.0
            ring_n[0] = 0  # a sliding window restarts with the factor (old rows keep weight rs)
            # uniform discounting leaves the reference's covariance as it was (only relative
            # weights count): hold the tests until new blocks have replaced the old model
            mon[M_HOLD] = HOLD_BLOCKS
        elif mon[M_HOLD] > 0.0 and informative:
            mon[M_HOLD] -= 1.0
        mon[M_BLOCKS] += 1.0
        mon[M_LAST_T] = blk[B - 1, 0]
        mon[M_LAST_SPEED] = blk[B - 1, 2]
    return n_ev


@njit(cache=True, error_model="numpy")
def downdate_row(R, x, y):
    """Remove the row ``[x y]`` from the factor: ``R'R - [x y]'[x y]`` (LINPACK ``dchdd``).

    Solve ``R' a = [x y]``, ``alpha = sqrt(1 - a'a)``; the rotations that zero ``a``
    against ``alpha`` from the last entry up turn ``[R; 0]`` into ``[R~; [x y]]``.
    Returns False (and leaves ``R`` as it was) when the row is not in the factor.
    """
    size = R.shape[0]
    n = size - 1
    a = np.empty(size)
    for i in range(size):
        v = x[i] if i < n else y
        for j in range(i):
            v -= R[j, i] * a[j]
        if R[i, i] <= 0.0:
            a[i] = 0.0 if v == 0.0 else math.inf
        else:
            a[i] = v / R[i, i]
    nrm = 0.0
    for i in range(size):
        nrm += a[i] * a[i]
    if not nrm < 1.0:
        return False
    alpha = math.sqrt(1.0 - nrm)
    cs = np.empty(size)
    sn = np.empty(size)
    for i in range(size - 1, -1, -1):
        scale = alpha + abs(a[i])
        an = alpha / scale
        bn = a[i] / scale
        nrm2 = scale * math.sqrt(an * an + bn * bn)
        cs[i] = alpha / nrm2
        sn[i] = a[i] / nrm2
        alpha = nrm2
    for j in range(size - 1, -1, -1):
        xx = 0.0
        for i in range(j, -1, -1):
            t = cs[i] * xx + sn[i] * R[i, j]
            R[i, j] = cs[i] * R[i, j] - sn[i] * xx
            xx = t
    for i in range(size):  # keep R[i, i] >= 0 (the time update assumes it): R'R is unchanged
        if R[i, i] < 0.0:
            for j in range(i, size):
                R[i, j] = -R[i, j]
    return True


@njit(cache=True, error_model="numpy")
def _window_update(R, col_sq, sums, Xk, yk, ring_X, ring_y, ring_n, window_blocks, rows_per_block):
    """Sliding window: store the block's rows, take out the rows of the block ``window`` back.

    ``ring_n = [blocks stored, next slot, rows kept in slot 0, slot 1, ...]``; slot ``i``
    of ``ring_X, ring_y`` holds a block's kept rows.
    """
    slot = int(ring_n[1])
    if ring_n[0] >= window_blocks:
        kk = int(ring_n[2 + slot])
        for r in range(kk):
            if downdate_row(R, ring_X[slot, r], ring_y[slot, r]):
                for j in range(col_sq.shape[0]):
                    col_sq[j] = max(col_sq[j] - ring_X[slot, r, j] * ring_X[slot, r, j], 0.0)
                sums[1] -= 1.0
                sums[2] -= 1.0
    else:
        ring_n[0] += 1
    k = Xk.shape[0]
    for r in range(k):
        for j in range(Xk.shape[1]):
            ring_X[slot, r, j] = Xk[r, j]
        ring_y[slot, r] = yk[r]
    ring_n[2 + slot] = k
    ring_n[1] = (slot + 1) % window_blocks
