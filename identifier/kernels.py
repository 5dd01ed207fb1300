"""Compiled per-sample kernels of the recursive QR estimator (a public module).

Used by :class:`identifier.RecursiveQR`, :mod:`identifier.segments`, the on-line
identification engine (:mod:`rotor_env.online`, behind the Gymnasium wrappers) and the
monitor's block loop (:mod:`rotor_env.monitor.kernel`): one update, one set of tests.

Everything here works on the augmented upper-triangular factor ``R`` of ``[X y]``
(shape ``(n+1, n+1)``; the last column holds ``R[:, y]``).  The kernels are written
for numba; with ``NUMBA_DISABLE_JIT=1`` they run (slowly) as plain Python, which is
how the tests exercise the same code path without compilation.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def rotate_in(R: np.ndarray, row: np.ndarray, start: int, scale: float = 1.0) -> None:
    """Rotate ``row`` into the triangular factor ``R`` (Givens), from column ``start``.

    Each row ``j`` of ``R`` is first multiplied by ``scale`` (``sqrt(lambda)`` for
    forgetting; folding it in here saves a pass over ``R``).  On return ``row[start:]``
    has been annihilated; ``R[j, j] >= 0`` is kept.
    """
    size = R.shape[0]
    for j in range(start, size):
        if scale != 1.0:
            for k in range(j, size):
                R[j, k] *= scale
        a = row[j]
        if a == 0.0:
            continue
        r_jj = R[j, j]
        # sqrt instead of hypot: 3x faster, and overflow would need |entries| > 1e150.
        r = math.sqrt(r_jj * r_jj + a * a)
        inv = 1.0 / r
        c = r_jj * inv
        s = a * inv
        R[j, j] = r
        for k in range(j + 1, size):
            rk = R[j, k]
            ak = row[k]
            R[j, k] = c * rk + s * ak
            row[k] = c * ak - s * rk
        row[j] = 0.0


@njit(cache=True, nogil=True, error_model="numpy")
def identifiable_columns(R: np.ndarray, col_sq: np.ndarray, rtol: float, out: np.ndarray) -> int:
    """Flag columns whose pivot is not negligible against the column's own norm.

    ``col_sq[j]`` is the (weighted) squared norm of regressor ``j``; rotations keep it
    equal to ``sum_k R[k, j]**2``.  A pivot ``R[j, j] <= rtol * norm_j`` means the column
    lies (numerically) in the span of the columns before it — or is all zero.  The test
    is per column, so it is invariant to the scale of each regressor.  Returns the
    number of columns that are *not* identifiable.
    """
    n = col_sq.shape[0]
    bad = 0
    rtol2 = rtol * rtol
    for j in range(n):
        r = R[j, j]  # >= 0 by construction
        ok = r * r > rtol2 * col_sq[j]
        out[j] = ok
        if not ok:
            bad += 1
    return bad


@njit(cache=True, nogil=True, error_model="numpy")
def clean_factor(R: np.ndarray, ident: np.ndarray, work: np.ndarray, row: np.ndarray) -> None:
    """Copy ``R`` into ``work`` with every non-identifiable column removed.

    Removing column ``j`` means treating the regressor as zero: since ``A = Q R``,
    zeroing ``R[:, j]`` gives a valid factor of ``A`` with that column zeroed; row ``j``
    is then rotated back into the rows below it so that ``work`` is triangular again.
    Every nested model built from ``work`` is the exact least-squares model without
    the dropped columns (coefficient 0, no share of the residual energy).
    """
    size = R.shape[0]
    for i in range(size):
        for k in range(size):
            work[i, k] = R[i, k]
    n = size - 1
    for j in range(n):
        if ident[j]:
            continue
        for i in range(size):
            work[i, j] = 0.0
        for k in range(size):
            row[k] = work[j, k]
            work[j, k] = 0.0
        rotate_in(work, row, j + 1)


@njit(cache=True, nogil=True, error_model="numpy")
def nested_energies(R: np.ndarray, out: np.ndarray) -> None:
    """``out[i] = J_i = R[y,y]**2 + sum_{j >= i} R[j,y]**2`` for ``i = 0..n``."""
    n = R.shape[0] - 1
    acc = R[n, n] * R[n, n]
    out[n] = acc
    for i in range(n - 1, -1, -1):
        acc += R[i, n] * R[i, n]
        out[i] = acc


@njit(cache=True, nogil=True, error_model="numpy")
def nested_coefficients(
    R: np.ndarray, ident: np.ndarray, out: np.ndarray, T: np.ndarray, inv_diag: np.ndarray
) -> None:
    """All nested least-squares solutions at once, O(n^2) after one O(n^3/6) inversion.

    With ``T = R_xx^{-1}`` (upper triangular) the inverse of a leading block is the
    leading block of the inverse, so ``theta_i = T[:i, :i] @ R[:i, y]`` and
    ``theta_{i+1} = theta_i + T[:i+1, i] * R[i, y]`` (Apley & Shi's order recursion).
    ``out[i-1, :i]`` receives ``theta_i``; entries above the order are zero.  ``R`` must
    be a clean factor (see :func:`clean_factor`): non-identifiable pivots are skipped.
    ``T`` (``(n, n)``) and ``inv_diag`` (``(n,)``) are scratch space.
    """
    n = R.shape[0] - 1
    for i in range(n):
        inv_diag[i] = 1.0 / R[i, i] if ident[i] else 0.0
    # Columns of T = R^{-1}, built one at a time (column i depends on columns < i).
    for i in range(n):
        for k in range(n):
            T[k, i] = 0.0
        if not ident[i]:
            continue
        T[i, i] = inv_diag[i]
        for k in range(i - 1, -1, -1):
            acc = 0.0
            for m in range(k + 1, i + 1):
                acc += R[k, m] * T[m, i]
            T[k, i] = -acc * inv_diag[k]
    for k in range(n):
        out[0, k] = 0.0
    if ident[0]:
        out[0, 0] = T[0, 0] * R[0, n]
    for i in range(1, n):
        for k in range(n):
            out[i, k] = out[i - 1, k]
        if ident[i]:
            ry = R[i, n]
            for k in range(i + 1):
                out[i, k] += T[k, i] * ry


#: Rows per block of :func:`update_block` (its work array is ``(n+1) x BLOCK_ROWS``).
BLOCK_ROWS = 64


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract"})
def update_block(
    R: np.ndarray, col_sq: np.ndarray, sums: np.ndarray, X: np.ndarray, y: np.ndarray, forgetting: float
) -> None:
    """Time update with a block of ``m`` rows by structured Householder reflections.

    The same factor as ``m`` calls of :func:`rotate_in` (to rounding): with forgetting
    the block's row ``t`` carries the weight ``lambda^(m-1-t)`` and ``R`` the weight
    ``lambda^m``, so ``[lambda^(m/2) R; W^(1/2) [X y]]`` is re-triangularised.  Column
    ``j``'s reflection only touches row ``j`` of ``R`` and the block (``R`` is already
    triangular), so a block costs ``~2 m (n+1)^2`` flops and ``n+1`` square roots
    against ``3 m (n+1)^2`` flops and ``m (n+1)`` square roots and divisions for the
    rotations; its inner loops run over contiguous block columns (vectorised — hence
    ``reassoc``: sums may be added in another order, a rounding-level difference).
    ``R[j, j] >= 0`` is kept.
    """
    m, n = X.shape
    size = n + 1
    if m == 0:
        return
    sqrt_lam = math.sqrt(forgetting)
    # B[k, i]: column k of the weighted block, contiguous in i
    B = np.empty((size, m))
    w = 1.0
    for i in range(m - 1, -1, -1):
        for k in range(n):
            B[k, i] = w * X[i, k]
        B[n, i] = w * y[i]
        w *= sqrt_lam
    for i in range(m):
        for k in range(n):
            col_sq[k] = forgetting * col_sq[k] + X[i, k] * X[i, k]
        sums[0] += 1.0
        sums[1] = forgetting * sums[1] + 1.0
        sums[2] = forgetting * forgetting * sums[2] + 1.0
    if w != 1.0:  # w = lambda^(m/2) here
        for j in range(size):
            for k in range(j, size):
                R[j, k] *= w
    for j in range(size):
        sigma = 0.0
        for i in range(m):
            sigma += B[j, i] * B[j, i]
        if sigma == 0.0:
            continue
        alpha = R[j, j]  # >= 0
        beta = math.sqrt(alpha * alpha + sigma)
        # v = [v0; B[j]] with v0 = alpha - beta, written without cancellation (alpha >= 0)
        v0 = -sigma / (alpha + beta)
        tau = 2.0 * v0 * v0 / (sigma + v0 * v0)
        inv_v0 = 1.0 / v0
        for i in range(m):
            B[j, i] *= inv_v0  # u = v / v0, so that v = [1; u]
        R[j, j] = beta
        for k in range(j + 1, size):
            acc = R[j, k]
            for i in range(m):
                acc += B[j, i] * B[k, i]
            acc *= tau
            R[j, k] -= acc
            for i in range(m):
                B[k, i] -= acc * B[j, i]


@njit(cache=True, nogil=True, error_model="numpy")
def update_blocks(
    R: np.ndarray, col_sq: np.ndarray, sums: np.ndarray, X: np.ndarray, y: np.ndarray, forgetting: float
) -> None:
    """Time update with ``m`` rows, ``BLOCK_ROWS`` at a time (:func:`update_block`)."""
    for b0 in range(0, X.shape[0], BLOCK_ROWS):
        update_block(R, col_sq, sums, X[b0 : b0 + BLOCK_ROWS], y[b0 : b0 + BLOCK_ROWS], forgetting)


@njit(cache=True, nogil=True, error_model="numpy")
def update_rows(
    R: np.ndarray,
    col_sq: np.ndarray,
    sums: np.ndarray,
    X: np.ndarray,
    y: np.ndarray,
    forgetting: float,
    rtol: float,
    energies_out: np.ndarray,
    orders: np.ndarray,
    coef_out: np.ndarray,
) -> None:
    """Time update with ``m`` rows, optionally recording per-sample histories.

    ``sums`` holds ``[n_samples, sum w, sum w^2]``.  ``energies_out`` has shape
    ``(m, n+1)`` or ``(0, n+1)`` (not recorded); ``coef_out`` has shape
    ``(m, len(orders), n)`` or ``(0, ...)``.
    """
    m, n = X.shape
    size = n + 1
    sqrt_lam = math.sqrt(forgetting)
    if energies_out.shape[0] == 0 and coef_out.shape[0] == 0:
        # nothing recorded per sample: reflect the rows in by blocks (same factor, less work)
        update_blocks(R, col_sq, sums, X, y, forgetting)
        return
    row = np.empty(size)
    scratch_row = np.empty(size)
    work = np.empty((size, size))
    ident = np.empty(n, dtype=np.bool_)
    all_coef = np.empty((n, n))
    T = np.empty((n, n))
    inv_diag = np.empty(n)
    record_e = energies_out.shape[0] > 0
    record_c = coef_out.shape[0] > 0
    n_orders = orders.shape[0]
    for t in range(m):
        for j in range(n):
            v = X[t, j]
            row[j] = v
            col_sq[j] = forgetting * col_sq[j] + v * v
        row[n] = y[t]
        rotate_in(R, row, 0, sqrt_lam)
        sums[0] += 1.0
        sums[1] = forgetting * sums[1] + 1.0
        sums[2] = forgetting * forgetting * sums[2] + 1.0
        if record_e or record_c:
            bad = identifiable_columns(R, col_sq, rtol, ident)
            F = R
            if bad > 0:
                clean_factor(R, ident, work, scratch_row)
                F = work
            if record_e:
                # J_i = R[y,y]^2 + sum_{j >= i} R[j,y]^2, inlined (hot path)
                acc = F[n, n] * F[n, n]
                energies_out[t, n] = acc
                for i in range(n - 1, -1, -1):
                    acc += F[i, n] * F[i, n]
                    energies_out[t, i] = acc
            if record_c:
                nested_coefficients(F, ident, all_coef, T, inv_diag)
                for q in range(n_orders):
                    o = orders[q]
                    for k in range(n):
                        coef_out[t, q, k] = all_coef[o - 1, k]


@njit(cache=True, nogil=True, error_model="numpy")
def betainc_cf(a: np.ndarray, b: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """Lentz's continued fraction of the regularised incomplete beta, element by element.

    ``out[i]`` receives the *log* of the fraction's value ``h`` so that
    ``log I_x(a, b) = a log x + b log(1-x) - log B(a, b) - log a + log h``;
    converges for ``x < (a+1)/(a+b+2)`` (the lower tail, where ``I`` is tiny).
    """
    tiny = 1e-300
    for i in range(x.shape[0]):
        ai, bi, xi = a[i], b[i], x[i]
        qab, qap, qam = ai + bi, ai + 1.0, ai - 1.0
        c = 1.0
        d = 1.0 - qab * xi / qap
        if abs(d) < tiny:
            d = tiny
        d = 1.0 / d
        h = d
        for m in range(1, 1_000_000):
            m2 = 2.0 * m
            aa = m * (bi - m) * xi / ((qam + m2) * (ai + m2))
            d = 1.0 + aa * d
            if abs(d) < tiny:
                d = tiny
            c = 1.0 + aa / c
            if abs(c) < tiny:
                c = tiny
            d = 1.0 / d
            h *= d * c
            aa = -(ai + m) * (qab + m) * xi / ((ai + m2) * (qap + m2))
            d = 1.0 + aa * d
            if abs(d) < tiny:
                d = tiny
            c = 1.0 + aa / c
            if abs(c) < tiny:
                c = tiny
            d = 1.0 / d
            delta = d * c
            h *= delta
            if abs(delta - 1.0) < 1e-15:
                break
        out[i] = math.log(h)


@njit(cache=True, nogil=True, error_model="numpy")
def snapshot(
    R: np.ndarray,
    col_sq: np.ndarray,
    rtol: float,
    group_masks: np.ndarray,
    ident: np.ndarray,
    coef: np.ndarray,
    J_without: np.ndarray,
) -> float:
    """Everything the tests of effects need, in one compiled call.

    Fills ``ident`` (columns in use), ``coef`` (full-model parameters) and
    ``J_without[g]`` (residual energy of the full model without group ``g``, whose
    columns are ``group_masks[g]``); returns the full model's residual energy.

    Dropping a group ``g`` raises the energy by ``theta_g^T (S_gg)^-1 theta_g`` with
    ``S = (X^T X)^-1 = T T^T``, ``T = R^-1`` (the Wald form of the extra sum of squares,
    exact in exact arithmetic).  With ``T_g`` the group's rows of ``T``, a QR
    factorisation ``T_g^T = Q U`` gives ``S_gg = U^T U`` without squaring ``T``'s
    condition, and the increase is ``||U^-T theta_g||^2``: O(n q^2) per group instead
    of re-triangularising ``R`` without the group's columns.
    """
    size = R.shape[0]
    n = size - 1
    # one scratch block, cut into views (this runs at every step of an env: allocations count)
    scratch = np.empty(size * size + size + 3 * n * n + 2 * n)
    work = scratch[: size * size].reshape((size, size))
    at = size * size
    row = scratch[at : at + size]
    at += size
    T = scratch[at : at + n * n].reshape((n, n))
    at += n * n
    all_coef = scratch[at : at + n * n].reshape((n, n))
    at += n * n
    M = scratch[at : at + n * n].reshape((n, n))  # T_g^T, column by column
    at += n * n
    inv_diag = scratch[at : at + n]
    z = scratch[at + n : at + 2 * n]
    identifiable_columns(R, col_sq, rtol, ident)
    clean_factor(R, ident, work, row)
    nested_coefficients(work, ident, all_coef, T, inv_diag)
    for k in range(n):
        coef[k] = all_coef[n - 1, k]
    J_full = work[n, n] * work[n, n]
    for g in range(group_masks.shape[0]):
        q = 0
        for c in range(n):
            if group_masks[g, c] and ident[c]:
                for k in range(n):
                    M[k, q] = T[c, k]
                z[q] = coef[c]
                q += 1
        # Householder QR of M[:, :q] in place: U in the upper triangle
        for j in range(q):
            sigma = 0.0
            for k in range(j + 1, n):
                sigma += M[k, j] * M[k, j]
            alpha = M[j, j]
            if sigma == 0.0:
                continue
            beta = math.sqrt(alpha * alpha + sigma)
            if alpha > 0.0:
                beta = -beta
            v0 = alpha - beta
            tau = (beta - alpha) / beta
            for k in range(j + 1, n):
                M[k, j] /= v0
            M[j, j] = beta
            for i in range(j + 1, q):
                acc = M[j, i]
                for k in range(j + 1, n):
                    acc += M[k, j] * M[k, i]
                acc *= tau
                M[j, i] -= acc
                for k in range(j + 1, n):
                    M[k, i] -= acc * M[k, j]
        # U^T w = theta_g (forward substitution); the increase is ||w||^2
        extra = 0.0
        for i in range(q):
            acc = z[i]
            for k in range(i):
                acc -= M[k, i] * z[k]
            z[i] = acc / M[i, i]
            extra += z[i] * z[i]
        J_without[g] = J_full + extra
    return J_full


@njit(cache=True, nogil=True, error_model="numpy")
def prefix_factors(A: np.ndarray, cuts: np.ndarray, head: np.ndarray, out: np.ndarray) -> None:
    """``out[i]`` = the triangular factor of ``head``'s rows and the rows ``A[:cuts[i]]``
    (``cuts`` ascending; ``head``: a factor of rows before ``A``'s, zeros for none).

    One pass over the rows by :func:`update_block` (no forgetting), the factor copied at
    every cut: the factors of all prefixes for the price of one factorisation.
    """
    p = A.shape[1]
    n = p - 1
    R = head.copy()
    col_sq = np.zeros(n)
    sums = np.zeros(3)
    last = 0
    for i in range(cuts.shape[0]):
        c = cuts[i]
        for b0 in range(last, c, BLOCK_ROWS):
            b1 = min(c, b0 + BLOCK_ROWS)
            update_block(R, col_sq, sums, A[b0:b1, :n], A[b0:b1, n], 1.0)
        out[i] = R
        last = max(last, c)
