"""Time- and order-recursive QR least squares (Apley & Shi 1999; Zhou & Shi 2004)."""

from __future__ import annotations

import json
import math
import os
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import kernels as K
from .significance import (
    InformationCriteria,
    SignificanceTable,
    information_criteria,
    nested_tests,
    partial_f,
)

__all__ = ["History", "RecursiveQR"]

_STATE_VERSION = 1
#: rows per compiled call of a long update: Ctrl-C (SIGINT) reaches Python between calls
#: (a multiple of the block size, so chunking does not change a single bit)
CHUNK_ROWS = 1 << 16
#: a column whose values (times its scale) leave [2^-LIM, 2^LIM] is rescaled by a power of two
_SCALE_LIMIT = 32


@dataclass
class History:
    """Per-sample histories returned by :meth:`RecursiveQR.update_many`.

    ``energies[t, i]`` is ``J_i`` after sample ``t``; ``coefficients[o][t]`` the
    parameters of the order-``o`` model after sample ``t``; ``effective_samples[t]``
    the Kish effective sample size after sample ``t`` (for the F-tests).
    """

    energies: np.ndarray | None = None
    coefficients: dict[int, np.ndarray] = field(default_factory=dict)
    effective_samples: np.ndarray | None = None


class RecursiveQR:
    r"""Recursive least squares by a triangular factor, for all nested models at once.

    Model: ``y_t = x_t^T theta + e_t`` with ``n`` regressors in a fixed order.  The
    estimator keeps the upper-triangular factor ``R`` (shape ``(n+1, n+1)``) of a QR
    factorisation of the (weighted) data matrix ``A = [X y]``:

    * **time update** — each new row ``[x_t, y_t]`` is rotated into ``R`` by ``n+1``
      Givens rotations, after ``R`` is scaled by ``sqrt(lambda)`` (exponential
      forgetting).  Cost O(n^2) per sample, memory O(n^2), independent of time.  When
      no per-sample history is asked for, :meth:`update_many` reflects blocks of up to
      64 rows in at once (structured Householder, the same factor to rounding: fewer
      square roots and vectorised inner loops, ~2-3x faster).
    * **order recursion** — with ``r_{j,y} = R[j, n]`` the last column, the residual
      energy of the model with the first ``i`` regressors is
      ``J_i = R[n, n]^2 + sum_{j >= i} r_{j,y}^2`` and its parameters solve
      ``R[:i, :i] theta_i = R[:i, n]``.  ``J_0 >= J_1 >= ... >= J_n``.  This is the
      information Apley & Shi's order-downdating inverse QR provides; keeping ``R``
      itself (rather than its inverse) is numerically the more robust choice and
      gives the same nested quantities.

    Names from the math: ``R`` (:attr:`R`), ``J`` (:meth:`residual_energies`),
    ``lambda`` (``forgetting``), ``delta`` (``prior``).

    Parameters
    ----------
    n_regressors:
        Number of regressors ``n`` (or pass ``columns``).
    forgetting:
        ``lambda`` in (0, 1]; 1 is ordinary least squares.  The memory is
        ``sum w = 1/(1-lambda)`` samples in steady state; the F-tests use Kish's
        effective sample size (see :mod:`identifier.significance`).
    prior:
        ``delta >= 0``.  ``delta > 0`` starts from ``R = sqrt(delta) I``: zero
        parameters and every ``J_i = delta`` (the paper's start, ``delta = 0.01``).
        This is ridge regression: it adds ``delta * ||theta||^2`` to the cost, so it
        shrinks the parameters towards zero by about ``delta / (delta + s_j^2)`` where
        ``s_j^2`` is a column's energy, and it adds at most ``delta`` to every ``J_i``.
        Under forgetting the prior fades as ``lambda^t``.  ``delta = 0`` gives exact
        least squares as soon as the columns are identifiable.
    columns:
        Column names (default ``x1 .. xn``).
    groups:
        Named effects, each a list of column names (an effect may own several
        columns, e.g. unbalance in phase and in quadrature).  Default: one group per
        column.  Groups may not overlap.
    rtol:
        A column is *not identifiable* when its pivot ``R[j, j] <= rtol * ||x_j||``:
        it is zero (a rotor at rest), or lies in the span of the columns before it.

    Non-identifiable columns
    ------------------------
    Such a column is dropped from every model that contains it: its coefficient reads
    ``0``, it takes no share of the residual energy, its standard error reads ``0`` and
    its tests are ``testable = False``.  :meth:`identifiable` tells which columns are
    in use.  Nothing returned is ever NaN or inf; the estimator recovers by itself
    when excitation arrives.

    Scaling and exactness
    ---------------------
    Each column (and ``y``) is kept internally times a power of two, chosen when its
    values leave ``[2^-32, 2^32]`` (1 otherwise): data near 1e102 or 1e-110 are factored
    as well as data near 1 (squares would overflow or underflow), and since a power of
    two scales every rotation and reflection exactly, the results are the same bits as
    unscaled arithmetic wherever that does not overflow.  ``R`` is the factor of the
    scaled data (``scale``).  Rows are reflected in by blocks of 64 counted from the last
    reset; the rows of an unfinished block are kept (at most 63, saved with the state)
    and ``R`` holds them applied.  So the factor depends only on the rows and not on how
    they were split into calls: one call, sample by sample, or saved, restored and
    continued at any point give the same bits.  (Histories — ``return_energies``,
    ``return_coefficients`` — need the factor after every row and rotate rows in one by
    one; such a call starts the block count afresh.)  An update whose result would not
    be finite (energies beyond the double range) raises and changes nothing.
    """

    def __init__(
        self,
        n_regressors: int | None = None,
        forgetting: float = 1.0,
        prior: float = 0.0,
        *,
        columns: Sequence[str] | None = None,
        groups: Mapping[str, Sequence[str]] | None = None,
        rtol: float = 1e-10,
    ) -> None:
        if n_regressors is None and columns is None:
            raise ValueError("give n_regressors or columns")
        if columns is not None:
            columns = tuple(str(c) for c in columns)
            if n_regressors is not None and n_regressors != len(columns):
                raise ValueError(
                    f"n_regressors={n_regressors} but {len(columns)} column names were given"
                )
            if len(set(columns)) != len(columns):
                raise ValueError(f"duplicate column names: {columns}")
            n_regressors = len(columns)
        if isinstance(n_regressors, bool) or int(n_regressors) != n_regressors or n_regressors < 1:
            raise ValueError(f"n_regressors must be a positive integer, got {n_regressors!r}")
        if not (0.0 < float(forgetting) <= 1.0):
            raise ValueError(f"forgetting must be in (0, 1], got {forgetting!r}")
        if not (math.isfinite(prior) and prior >= 0.0):
            raise ValueError(f"prior must be a finite number >= 0, got {prior!r}")
        if not (math.isfinite(rtol) and 0.0 <= rtol < 1.0):
            raise ValueError(f"rtol must be in [0, 1), got {rtol!r}")
        self.n = int(n_regressors)
        self.forgetting = float(forgetting)
        self.prior = float(prior)
        self.rtol = float(rtol)
        self.columns: tuple[str, ...] = columns or tuple(f"x{i + 1}" for i in range(self.n))
        self.groups: dict[str, tuple[str, ...]] = self._check_groups(groups)
        self._masks = self._build_group_masks()
        self.reset()

    # ------------------------------------------------------------------ state
    def _check_groups(self, groups) -> dict[str, tuple[str, ...]]:
        if groups is None:
            return {c: (c,) for c in self.columns}
        out: dict[str, tuple[str, ...]] = {}
        seen: dict[str, str] = {}
        for name, cols in groups.items():
            cols = (cols,) if isinstance(cols, str) else tuple(cols)
            if not cols:
                raise ValueError(f"group {name!r} has no columns")
            for c in cols:
                if c not in self.columns:
                    raise ValueError(
                        f"group {name!r} names unknown column {c!r}; columns are {self.columns}"
                    )
                if c in seen:
                    raise ValueError(f"column {c!r} is in groups {seen[c]!r} and {name!r}")
                seen[c] = name
            out[str(name)] = cols
        return out

    def reset(self) -> RecursiveQR:
        """Forget all data: back to the prior.

        The state arrays are reset in place (a batched owner may hold them as views).
        """
        size = self.n + 1
        if getattr(self, "R", None) is None:
            self.R = np.empty((size, size))
            # Weighted squared norms of each regressor column (for the identifiability
            # test); the prior counts, so that with delta > 0 every column is
            # identifiable at once.
            self._col_sq = np.empty(self.n)
            # [samples seen, sum w, sum w^2]
            self._sums = np.empty(3)
        self.R[...] = np.sqrt(self.prior) * np.eye(size)
        self._col_sq[...] = self.prior
        self._sums[...] = 0.0
        #: the power of two each column (and y, last) is kept times, inside R
        self.scale = np.ones(size)
        self._realign()
        return self

    def _realign(self) -> None:
        """Start counting blocks here: the current state is the base, nothing pending."""
        self._base = (self.R.copy(), self._col_sq.copy(), self._sums.copy())
        self._pend_X = np.empty((0, self.n))
        self._pend_y = np.empty(0)

    def _snapshot_state(self):
        return (self.R.copy(), self._col_sq.copy(), self._sums.copy(), self.scale.copy(),
                None if self._base is None else tuple(a.copy() for a in self._base),
                self._pend_X, self._pend_y)

    def _restore_state(self, snap) -> None:
        self.R[...], self._col_sq[...], self._sums[...] = snap[0], snap[1], snap[2]
        self.scale = snap[3]
        self._base, self._pend_X, self._pend_y = snap[4], snap[5], snap[6]

    @property
    def n_samples(self) -> int:
        """Number of samples seen since the last reset."""
        return int(self._sums[0])

    @property
    def weight_sum(self) -> float:
        """``sum w_k`` — the estimator's memory in samples (``= n_samples`` if lambda = 1)."""
        return float(self._sums[1])

    @property
    def effective_samples(self) -> float:
        """Kish's effective sample size ``(sum w)^2 / sum w^2`` used by the F-tests."""
        s1, s2 = self._sums[1], self._sums[2]
        return float(s1 * s1 / s2) if s2 > 0 else 0.0

    # ------------------------------------------------------------- updating
    def _check_xy(self, X: np.ndarray, y: np.ndarray, first: int = 0) -> tuple[np.ndarray, np.ndarray]:
        X = np.asarray(X, dtype=float)
        y = np.asarray(y, dtype=float)
        if X.ndim != 2 or X.shape[1] != self.n:
            raise ValueError(
                f"X must have shape (m, {self.n}) (columns {self.columns}), got shape {X.shape}"
            )
        if y.shape != (X.shape[0],):
            raise ValueError(f"y must have shape ({X.shape[0]},) to match X, got shape {y.shape}")
        if not np.isfinite(X).all():
            r, c = np.argwhere(~np.isfinite(X))[0]
            raise ValueError(
                f"non-finite regressor at sample {first + r}, column {c} ({self.columns[c]!r}): "
                f"{X[r, c]!r}; the estimator was not changed"
            )
        if not np.isfinite(y).all():
            r = int(np.argmax(~np.isfinite(y)))
            raise ValueError(
                f"non-finite y at sample {first + r}: {y[r]!r}; the estimator was not changed"
            )
        return np.ascontiguousarray(X), np.ascontiguousarray(y)

    def update(self, x: np.ndarray, y: float) -> RecursiveQR:
        """Add one sample: ``x`` of shape ``(n,)``, scalar ``y``."""
        x = np.asarray(x, dtype=float)
        if x.shape != (self.n,):
            raise ValueError(f"x must have shape ({self.n},), got shape {x.shape}")
        y_arr = np.asarray(y, dtype=float)
        if y_arr.shape not in ((), (1,)):
            raise ValueError(f"y must be a scalar, got shape {y_arr.shape}")
        X, yv = self._check_xy(x[None, :], y_arr.reshape(1), first=self.n_samples)
        self._update(X, yv, None, None, None)
        return self

    def update_many(
        self,
        X: np.ndarray,
        y: np.ndarray,
        *,
        return_energies: bool = False,
        return_coefficients: int | Sequence[int] | str | None = None,
    ) -> History:
        """Add ``m`` samples (``X`` shape ``(m, n)``, ``y`` shape ``(m,)``).

        Histories are recorded inside the compiled loop, without Python per sample:
        ``return_energies`` gives ``J_0..J_n`` after every sample (shape ``(m, n+1)``);
        ``return_coefficients`` — an order, a list of orders or ``"all"`` — gives the
        coefficients of those nested models after every sample (``(m, order)`` each).
        All input is validated before anything changes.
        """
        X, y = self._check_xy(X, y, first=self.n_samples)
        orders = self._orders(return_coefficients)
        m = X.shape[0]
        E = np.empty((m if return_energies else 0, self.n + 1))
        C = np.empty((m if orders.size else 0, orders.size, self.n))
        n_before = self._sums.copy()
        self._update(X, y, E, C, orders)
        hist = History()
        sy = self.scale[self.n]
        if return_energies:
            hist.energies = E if sy == 1.0 else E / sy / sy
        for q, o in enumerate(orders):
            hist.coefficients[int(o)] = C[:, q, :o] * (self.scale[:o] / sy)
        if return_energies or orders.size:
            lam = self.forgetting
            k = np.arange(1, m + 1)
            s1 = lam**k * n_before[1] + (1.0 - lam**k) / (1.0 - lam) if lam < 1 else n_before[1] + k
            s2 = (
                lam ** (2 * k) * n_before[2] + (1.0 - lam ** (2 * k)) / (1.0 - lam**2)
                if lam < 1
                else n_before[2] + k
            )
            hist.effective_samples = s1 * s1 / s2
        return hist

    def fit(self, X: np.ndarray, y: np.ndarray) -> RecursiveQR:
        """Reset, then add all samples (batch use)."""
        X, y = self._check_xy(X, y)
        self.reset()
        self._update(X, y, None, None, None)
        return self

    def _orders(self, spec) -> np.ndarray:
        if spec is None:
            return np.empty(0, dtype=np.int64)
        if isinstance(spec, str):
            if spec != "all":
                raise ValueError(f"return_coefficients must be an order, a list or 'all', got {spec!r}")
            return np.arange(1, self.n + 1, dtype=np.int64)
        orders = np.atleast_1d(np.asarray(spec, dtype=np.int64))
        bad = orders[(orders < 1) | (orders > self.n)]
        if bad.size:
            raise ValueError(f"orders must be in 1..{self.n}, got {bad[0]}")
        return orders

    # ------------------------------------------------------------- the update
    def _update(self, X, y, E, C, orders) -> None:
        """Validated rows in: rescale if needed, then blocks (or rows, for histories).

        Interrupted (Ctrl-C) or not finite, the estimator is left as it was.
        """
        snap = self._snapshot_state()
        try:
            self._rescale(X, y)
            if (E is None or E.shape[0] == 0) and (C is None or C.shape[0] == 0):
                self._append_blocks(X, y)
            else:
                self._append_rows(X, y, E, C, orders)
            self._check_finite(X, y)
        except BaseException:
            self._restore_state(snap)
            raise

    def _scaled(self, X, y):
        s = self.scale
        if (s == 1.0).all():
            return X, y
        return X * s[: self.n], y * s[self.n]

    def _rescale(self, X, y) -> None:
        """Powers of two that keep every column's values near 1 (exact: see the class notes)."""
        if X.shape[0] == 0:
            return
        top = np.empty(self.n + 1)
        # max |x| as max(max x, -min x): no temporary |X| (a pass over memory saved)
        top[: self.n] = np.maximum(X.max(axis=0), -X.min(axis=0))
        top[self.n] = max(float(y.max()), -float(y.min()))
        scaled = top * self.scale
        out = (top > 0) & ((scaled > 2.0**_SCALE_LIMIT) | (scaled < 2.0**-_SCALE_LIMIT))
        if not out.any():
            return
        new = self.scale.copy()
        new[out] = np.ldexp(1.0, -np.frexp(top[out])[1])
        factor = new / self.scale
        arrays = [(self.R, self._col_sq)]
        if self._base is not None:
            arrays.append((self._base[0], self._base[1]))
        for R, col_sq in arrays:
            R *= factor[None, :]
            col_sq *= factor[: self.n]  # twice: factor**2 may overflow where col_sq is 0
            col_sq *= factor[: self.n]
        self.scale = new

    def _append_blocks(self, X, y) -> None:
        if self._base is None:  # the compiled step (wrappers) wrote R directly
            self._realign()
        lam = self.forgetting
        Rb, cb, sb = self._base
        B = K.BLOCK_ROWS
        if len(self._pend_X):
            k = min(B - len(self._pend_X), len(X))
            hx = np.concatenate([self._pend_X, X[:k]])
            hy = np.concatenate([self._pend_y, y[:k]])
            X, y = X[k:], y[k:]
            if len(hx) == B:
                K.update_block(Rb, cb, sb, *self._scaled(hx, hy), lam)
                hx, hy = hx[:0], hy[:0]
        else:
            hx, hy = self._pend_X, self._pend_y
        full = (len(X) // B) * B
        for a in range(0, full, CHUNK_ROWS):
            b = min(full, a + CHUNK_ROWS)
            K.update_blocks(Rb, cb, sb, *self._scaled(X[a:b], y[a:b]), lam)
        if full < len(X):
            hx, hy = X[full:].copy(), y[full:].copy()
        self._pend_X, self._pend_y = hx, hy
        self.R[...], self._col_sq[...], self._sums[...] = Rb, cb, sb
        if len(hx):
            K.update_block(self.R, self._col_sq, self._sums, *self._scaled(hx, hy), lam)

    def _append_rows(self, X, y, E, C, orders) -> None:
        for a in range(0, max(len(X), 1), CHUNK_ROWS):
            b = min(len(X), a + CHUNK_ROWS)
            Xs, ys = self._scaled(X[a:b], y[a:b])
            K.update_rows(self.R, self._col_sq, self._sums, np.ascontiguousarray(Xs), np.ascontiguousarray(ys),
                          self.forgetting, self.rtol, E[a:b] if E.shape[0] else E, orders,
                          C[a:b] if C.shape[0] else C)
        self._realign()

    def _check_finite(self, X, y) -> None:
        sy = self.scale[self.n]
        with np.errstate(over="ignore", invalid="ignore"):
            J0 = float(np.sum(self.R[:, self.n] ** 2)) / sy / sy
        if np.isfinite(self.R).all() and math.isfinite(J0):
            return
        raise ValueError(
            f"the update would make the estimator non-finite (largest |y| {float(np.max(np.abs(y))):.3g}, "
            f"largest |x| {float(np.max(np.abs(X))):.3g}: the residual energy leaves the double range); "
            "rescale the data; the estimator was not changed"
        )

    def _run(self, X, y, E, C, orders=None) -> None:
        """Rows straight into ``R`` by the compiled kernel (the wrappers' fused path: rows
        already in the estimator's scale, which stays 1 there); block counting restarts."""
        self._base = None
        if E is None:
            E = np.empty((0, self.n + 1))
        if C is None:
            C = np.empty((0, 0, self.n))
        if orders is None:
            orders = np.empty(0, dtype=np.int64)
        K.update_rows(
            self.R, self._col_sq, self._sums, X, y, self.forgetting, self.rtol, E, orders, C
        )
        self._pend_X, self._pend_y = self._pend_X[:0], self._pend_y[:0]

    # ------------------------------------------------------------- queries
    def identifiable(self) -> np.ndarray:
        """Boolean mask of the columns in use (see *Non-identifiable columns*)."""
        out = np.empty(self.n, dtype=np.bool_)
        K.identifiable_columns(self.R, self._col_sq, self.rtol, out)
        return out

    def _clean(self, keep: np.ndarray | None = None) -> np.ndarray:
        keep = self.identifiable() if keep is None else keep
        work = np.empty_like(self.R)
        K.clean_factor(self.R, keep, work, np.empty(self.n + 1))
        return work

    def _scaled_energies(self) -> np.ndarray:
        out = np.empty(self.n + 1)
        K.nested_energies(self._clean(), out)
        return out

    def residual_energies(self) -> np.ndarray:
        """``J_0 .. J_n`` (shape ``(n+1,)``): weighted residual sums of squares."""
        sy = self.scale[self.n]
        out = self._scaled_energies()
        return out if sy == 1.0 else out / sy / sy

    def _order(self, order: int | None) -> int:
        o = self.n if order is None else order
        if isinstance(o, bool) or int(o) != o or not 1 <= o <= self.n:
            raise ValueError(f"order must be an integer in 1..{self.n}, got {order!r}")
        return int(o)

    def all_coefficients(self) -> np.ndarray:
        """``(n, n)``: row ``i-1`` holds the order-``i`` parameters, zero-padded."""
        out = np.empty((self.n, self.n))
        K.nested_coefficients(
            self._clean(), self.identifiable(), out, np.empty((self.n, self.n)), np.empty(self.n)
        )
        if not (self.scale == 1.0).all():
            out *= self.scale[None, : self.n] / self.scale[self.n]
        return out

    def coefficients(self, order: int | None = None) -> np.ndarray:
        """Least-squares parameters of the model with the first ``order`` columns (default n)."""
        o = self._order(order)
        return self.all_coefficients()[o - 1, :o].copy()

    def standard_errors(self, order: int | None = None) -> np.ndarray:
        """Standard errors of :meth:`coefficients` (``0`` where not identifiable).

        ``se_k^2 = s^2 [(R^T R)^{-1}]_kk`` with ``s^2 = J_o / (m_eff - p)``, ``p`` the
        identifiable parameters of the model; under forgetting this is the sandwich
        variance with the Kish effective sample size (see :mod:`.significance`).
        """
        o = self._order(order)
        ident = self.identifiable()[:o]
        Rc = self._clean()
        p = int(ident.sum())
        dof = self.effective_samples - p
        if p == 0 or dof <= 0:
            return np.zeros(o)
        J = Rc[self.n, self.n] ** 2 + float(np.sum(Rc[o:self.n, self.n] ** 2))
        idx = np.flatnonzero(ident)
        T = np.linalg.inv(Rc[np.ix_(idx, idx)])  # triangular, well-posed on identifiable columns
        se = np.zeros(o)
        se[idx] = np.sqrt(J / dof * np.sum(T * T, axis=1))
        return se * (self.scale[:o] / self.scale[self.n])

    # ---------------------------------------------------------- significance
    def nested_tests(self, alpha: float = 0.05) -> SignificanceTable:
        """Each column tested as the next addition to the ones before it (the paper)."""
        return nested_tests(
            self._scaled_energies(),  # F and p do not depend on the scale of y
            self.effective_samples,
            self.columns,
            identifiable=self.identifiable(),
            alpha=alpha,
        )

    def _group_masks(self) -> np.ndarray:
        """``(groups, n)`` boolean: which columns each group owns (in :attr:`groups` order)."""
        return self._masks

    def _build_group_masks(self) -> np.ndarray:
        masks = np.zeros((len(self.groups), self.n), dtype=np.bool_)
        for g, cols in enumerate(self.groups.values()):
            masks[g, [self.columns.index(c) for c in cols]] = True
        return masks

    def effect_energies(self) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
        """One compiled pass: ``(J_without_group, J_full, coefficients, identifiable)``.

        ``J_without_group[g]`` is the residual energy of the full model without the
        columns of group ``g`` (in :attr:`groups` order).  This is the fast path used
        by :meth:`effect_tests` and by the identification wrapper at every step.
        """
        J_without, J_full, coef, ident = self._scaled_effect_energies()
        s = self.scale
        if (s == 1.0).all():
            return J_without, J_full, coef, ident
        return J_without / s[self.n] / s[self.n], J_full / s[self.n] / s[self.n], coef * s[: self.n] / s[self.n], ident

    def _scaled_effect_energies(self):
        masks = self._group_masks()
        ident = np.empty(self.n, dtype=np.bool_)
        coef = np.empty(self.n)
        J_without = np.empty(len(masks))
        J_full = K.snapshot(self.R, self._col_sq, self.rtol, masks, ident, coef, J_without)
        return J_without, float(J_full), coef, ident

    def effect_tests(self, alpha: float = 0.05) -> SignificanceTable:
        """Each named effect tested *last*: full model vs full model without its columns."""
        J_without, J_full, _, ident = self._scaled_effect_energies()  # F, p: scale-free
        masks = self._group_masks()
        d1 = (masks & ident).sum(axis=1).astype(float)
        d2 = self.effective_samples - float(ident.sum())
        F, pv, lp, ok = partial_f(J_without, J_full, d1, d2)
        names = tuple(self.groups)
        return SignificanceTable(names, F, d1, np.full(len(names), d2), pv, lp, ok, kind="last", alpha=alpha)

    def information_criteria(self) -> InformationCriteria:
        """AIC, BIC, FPE of the nested models of order ``0..n``."""
        return information_criteria(self.residual_energies(), self.effective_samples, self.weight_sum)

    # ------------------------------------------------------------ save/load
    def save(self, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
        """Write the complete state to ``.npz`` (no pickle); refuses to overwrite by default."""
        path = Path(path)
        if path.suffix != ".npz":
            raise ValueError(f"state files end in .npz, got {str(path)!r}")
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path} exists; pass overwrite=True to replace it")
        meta = {
            "version": _STATE_VERSION,
            "forgetting": self.forgetting,
            "prior": self.prior,
            "rtol": self.rtol,
            "columns": list(self.columns),
            "groups": {k: list(v) for k, v in self.groups.items()},
        }
        if self._base is None:
            self._realign()
        Rb, cb, sb = self._base
        with open(path, "wb") as fh:
            np.savez(fh, R=self.R, col_sq=self._col_sq, sums=self._sums, meta=np.array(json.dumps(meta)),
                     scale=self.scale, base_R=Rb, base_col_sq=cb, base_sums=sb,
                     pending_X=self._pend_X, pending_y=self._pend_y)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> RecursiveQR:
        """Restore a state written by :meth:`save`; continuing is bit-identical."""
        path = Path(path)
        optional = ("scale", "base_R", "base_col_sq", "base_sums", "pending_X", "pending_y")
        try:
            with np.load(path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                R, col_sq, sums = data["R"], data["col_sq"], data["sums"]
                extra = {k: data[k] for k in optional if k in data.files}
        except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile, AttributeError) as exc:
            # TypeError: np.load of a plain .npy gives an array, not an archive; EOFError: an
            # empty file; BadZipFile: a truncated one
            kind = "empty" if path.is_file() and path.stat().st_size == 0 else "not a RecursiveQR state file"
            raise ValueError(f"{path}: {kind} ({type(exc).__name__}: {exc})") from None
        if not isinstance(meta, dict) or meta.get("version") != _STATE_VERSION:
            version = meta.get("version") if isinstance(meta, dict) else None
            raise ValueError(f"{path}: unsupported state version {version!r}")
        try:
            est = cls(
                forgetting=meta["forgetting"],
                prior=meta["prior"],
                columns=meta["columns"],
                groups=meta["groups"],
                rtol=meta["rtol"],
            )
        except (KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"{path}: incomplete RecursiveQR state metadata ({exc!r})") from exc
        n = est.n
        R = _valid_array(path, "R", R, (n + 1, n + 1))
        col_sq = _valid_array(path, "col_sq", col_sq, (n,))
        sums = _valid_array(path, "sums", sums, (3,))
        _valid_factor(path, "R", R, col_sq, sums)
        est.R, est._col_sq, est._sums = R, col_sq, sums
        if "scale" in extra:
            scale = _valid_array(path, "scale", extra["scale"], (n + 1,))
            if not ((scale > 0).all() and (np.frexp(scale)[0] == 0.5).all()):
                raise ValueError(f"{path}: 'scale' must hold powers of two, got {scale.tolist()}")
            est.scale = scale
        if all(k in extra for k in optional[1:]):
            bR = _valid_array(path, "base_R", extra["base_R"], (n + 1, n + 1))
            bc = _valid_array(path, "base_col_sq", extra["base_col_sq"], (n,))
            bs = _valid_array(path, "base_sums", extra["base_sums"], (3,))
            _valid_factor(path, "base_R", bR, bc, bs)
            pX = _valid_array(path, "pending_X", extra["pending_X"], (None, n))
            py = _valid_array(path, "pending_y", extra["pending_y"], (pX.shape[0],))
            if pX.shape[0] >= K.BLOCK_ROWS or bs[0] + pX.shape[0] != sums[0]:
                raise ValueError(f"{path}: {pX.shape[0]} pending rows do not join the base state "
                                 f"({bs[0]:.0f} samples) to the state ({sums[0]:.0f} samples)")
            est._base, est._pend_X, est._pend_y = (bR, bc, bs), pX, py
        else:  # a file without the block state: continue with blocks counted from here
            est._realign()
        return est

    @property
    def state_is_aligned(self) -> bool:
        """Whether rows are being counted into blocks (False after the wrappers' fused step)."""
        return self._base is not None

    def __repr__(self) -> str:
        return (
            f"RecursiveQR(n={self.n}, forgetting={self.forgetting:g}, prior={self.prior:g}, "
            f"samples={self.n_samples}, columns={list(self.columns)})"
        )


def _valid_array(path, name: str, a: np.ndarray, shape: tuple) -> np.ndarray:
    """A real, finite float array of the expected shape (``None``: any length) from a state file."""
    if np.iscomplexobj(a) or a.dtype.kind not in "fiu":
        raise ValueError(f"{path}: {name!r} must be real numbers, got dtype {a.dtype}")
    if a.ndim != len(shape) or any(want is not None and got != want for got, want in zip(a.shape, shape, strict=False)):
        raise ValueError(f"{path}: {name!r} has shape {a.shape}, expected {tuple('m' if s is None else s for s in shape)}")
    a = np.array(a, dtype=float)
    if not np.isfinite(a).all():
        bad = np.argwhere(~np.isfinite(a))[0]
        raise ValueError(f"{path}: {name!r} holds a non-finite value at {tuple(int(i) for i in bad)}: "
                         f"{float(a[tuple(bad)])!r}")
    return a


def _valid_factor(path, name: str, R: np.ndarray, col_sq: np.ndarray, sums: np.ndarray) -> None:
    """``R`` upper triangular with a non-negative diagonal; norms and sample sums consistent."""
    below = np.tril(R, -1)
    if below.any():
        i, j = np.argwhere(below != 0)[0]
        raise ValueError(f"{path}: {name!r} is not upper triangular ({name}[{i}, {j}] = {float(R[i, j])!r})")
    if (np.diag(R) < 0).any():
        raise ValueError(f"{path}: {name!r} has a negative diagonal entry")
    if (col_sq < 0).any():
        raise ValueError(f"{path}: negative column norms")
    if sums[0] < 0 or sums[0] != int(sums[0]) or sums[1] < 0 or sums[2] < 0:
        raise ValueError(f"{path}: sample counts {sums.tolist()} are not counts")
