"""Residual energies of a regression whose columns switch on or off at a change point.

For rows ``a_k = [x_k y_k]`` (the matrix ``A = [X y]``) and a cut ``c``, the split model
drops the columns ``before`` from the rows ``k < c`` and the columns ``after`` from the
rows ``k >= c`` (an effect that appears at ``c``: its columns in ``before``; a
coefficient that changes at ``c``: its columns twice, the copy in ``before`` and the
original in ``after``).  Its residual energy is

    J(c) = min_theta  sum_k (y_k - x~_k(c) theta)^2 ,

``x~_k(c)`` being ``x_k`` with those columns zeroed.  With ``R_pre(c)`` the triangular
factor of the rows before ``c`` and ``R_suf(c)`` that of the rows from ``c`` on, zeroing
a column of a factor zeroes it in the rows behind it (the factor's columns are
``Q^T A``'s), so ``J(c)`` is the last diagonal element, squared, of the factor of

    [ R_pre(c) with columns `before` zeroed ]
    [ R_suf(c) with columns `after` zeroed  ] .

One pass forward and one backward give every prefix and suffix factor
(:func:`identifier.kernels.prefix_factors`), and one batched QR the energy at every
cut: ``O(m p^2)`` for the data once and ``O(p^3)`` per cut, against ``O(m p^2)`` per cut
for a refit.  A finer scan between two cuts of a coarse one reuses the coarse scan's
factors at those cuts, so it only passes over the rows between them
(:meth:`SplitScan.refine`).  A column absent on both sides of a cut (or dependent on the
others there) is dropped at that cut, as the recursive estimator drops non-identifiable
columns: left in, its empty pivot would keep a row of ``y`` out of the energy.  The columns are scaled by powers of two (exact) so that the
squares the reflections form stay in range.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from . import kernels as K


class SplitScan:
    """Change-point energies ``J(c)`` of one ``A = [X y]`` (the last column is the response).

    ``before`` / ``after`` index the columns of ``X`` absent before / from the cut on; a
    column whose pivot is ``<= rtol`` times its norm at a cut (absent on both sides, or in
    the span of the columns before it) is dropped there, as :class:`~identifier.RecursiveQR`
    drops it.  :meth:`energies` scans a set of cuts; :meth:`refine` scans cuts between two neighbours of
    the last scan, reusing its factors.
    """

    def __init__(self, A: np.ndarray, before: Sequence[int] = (), after: Sequence[int] = (), rtol: float = 1e-10):
        self.rtol = float(rtol)
        A = np.asarray(A, dtype=float)
        if A.ndim != 2 or A.shape[1] < 2:
            raise ValueError(f"A must be [X y] with at least one regressor column, got shape {A.shape}")
        if not np.isfinite(A).all():
            r, c = np.argwhere(~np.isfinite(A))[0]
            raise ValueError(f"non-finite value at row {r}, column {c}: {A[r, c]!r}")
        p = A.shape[1]
        for name, cols in (("before", before), ("after", after)):
            bad = [c for c in cols if not 0 <= c < p - 1]
            if bad:
                raise ValueError(f"{name}: column {bad[0]} is not a regressor column (0..{p - 2})")
        top = np.maximum(A.max(axis=0), -A.min(axis=0))  # max |A| without a temporary |A|
        self._scale = np.where(top > 0, np.ldexp(1.0, -np.frexp(top)[1]), 1.0)
        self._A = np.ascontiguousarray(A * self._scale)
        self._before, self._after = list(before), list(after)
        self._cuts = np.empty(0, dtype=np.int64)
        self._pre = self._suf = np.empty((0, p, p))

    def _check(self, cuts, lo: int, hi: int) -> np.ndarray:
        cuts = np.asarray(cuts, dtype=np.int64)
        if cuts.ndim != 1 or (cuts.size and (cuts[0] < lo or cuts[-1] > hi or np.any(np.diff(cuts) < 0))):
            raise ValueError(f"cuts must be ascending row indices in {lo}..{hi}")
        return cuts

    def _energies(self, rows: np.ndarray, cuts: np.ndarray, head: np.ndarray, tail: np.ndarray) -> np.ndarray:
        """``rows``: the rows between ``head``'s and ``tail``'s; ``cuts`` relative to ``rows``."""
        p = rows.shape[1]
        pre = np.empty((cuts.size, p, p))
        K.prefix_factors(rows, cuts, head, pre)
        suf = np.empty((cuts.size, p, p))
        K.prefix_factors(np.ascontiguousarray(rows[::-1]), (len(rows) - cuts)[::-1].copy(), tail, suf)
        suf = suf[::-1]
        self._pre, self._suf = pre, suf
        if cuts.size == 0:
            return np.empty(0)
        zp, zs = pre.copy(), suf.copy()
        zp[:, :, self._before] = 0.0
        zs[:, :, self._after] = 0.0
        M = np.concatenate([zp, zs], axis=1)
        split = np.linalg.qr(M, mode="r")
        split *= np.where(np.diagonal(split, axis1=1, axis2=2) < 0, -1.0, 1.0)[:, :, None]  # pivots >= 0
        J = split[:, -1, -1] ** 2
        # a column absent on both sides of a cut, or in the span of the columns before it,
        # leaves its pivot row out of the elimination: drop it as the estimator does
        # (:func:`identifier.kernels.clean_factor`, the same ``rtol``)
        col_sq = np.einsum("kij,kij->kj", M[:, :, :-1], M[:, :, :-1])
        keep = np.empty(p - 1, dtype=np.bool_)
        work, row = np.empty((p, p)), np.empty(p)
        for i in range(cuts.size):
            if K.identifiable_columns(split[i], col_sq[i], self.rtol, keep):
                K.clean_factor(split[i], keep, work, row)
                J[i] = work[-1, -1] ** 2
        return J / self._scale[-1] ** 2

    def energies(self, cuts: Sequence[int] | np.ndarray) -> np.ndarray:
        """``J(c)`` for every cut (row indices, ascending, in ``0..len(A)``)."""
        cuts = self._check(cuts, 0, len(self._A))
        p = self._A.shape[1]
        zero = np.zeros((p, p))
        J = self._energies(self._A, cuts, zero, zero)
        self._cuts = cuts
        return J

    def refine(self, i: int, j: int, cuts: Sequence[int] | np.ndarray) -> np.ndarray:
        """``J(c)`` for cuts between the last scan's ``i``-th and ``j``-th cuts (``i <= j``):
        only the rows between those two cuts are passed over."""
        if not 0 <= i <= j < len(self._cuts):
            raise ValueError(f"refine: need 0 <= i <= j < {len(self._cuts)} (the last scan's cuts), got {i}, {j}")
        lo, hi = int(self._cuts[i]), int(self._cuts[j])
        cuts = self._check(cuts, lo, hi)
        head, tail = self._pre[i].copy(), self._suf[j].copy()
        J = self._energies(self._A[lo:hi], cuts - lo, head, tail)
        self._cuts = cuts
        return J


def split_energies(
    A: np.ndarray, cuts: Sequence[int] | np.ndarray, before: Sequence[int] = (), after: Sequence[int] = ()
) -> np.ndarray:
    """``J(c)`` for every cut ``c`` in ``cuts`` (row indices, ascending, in ``0..len(A)``):
    one :class:`SplitScan`'s :meth:`~SplitScan.energies`."""
    return SplitScan(A, before, after).energies(cuts)
