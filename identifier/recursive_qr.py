"""Time- and order-recursive QR least squares (Apley & Shi 1999; Zhou & Shi 2004)."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import _kernels as K
from .significance import (
    InformationCriteria,
    SignificanceTable,
    information_criteria,
    nested_tests,
    partial_f,
)

__all__ = ["History", "RecursiveQR"]

_STATE_VERSION = 1


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
        return self

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
        self._run(X, yv, None, None)
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
        self._run(X, y, E, C, orders)
        hist = History()
        if return_energies:
            hist.energies = E
        for q, o in enumerate(orders):
            hist.coefficients[int(o)] = C[:, q, :o]
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
        self._run(X, y, None, None)
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

    def _run(self, X, y, E, C, orders=None) -> None:
        if E is None:
            E = np.empty((0, self.n + 1))
        if C is None:
            C = np.empty((0, 0, self.n))
        if orders is None:
            orders = np.empty(0, dtype=np.int64)
        K.update_rows(
            self.R, self._col_sq, self._sums, X, y, self.forgetting, self.rtol, E, orders, C
        )

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

    def residual_energies(self) -> np.ndarray:
        """``J_0 .. J_n`` (shape ``(n+1,)``): weighted residual sums of squares."""
        out = np.empty(self.n + 1)
        K.nested_energies(self._clean(), out)
        return out

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
        return se

    # ---------------------------------------------------------- significance
    def nested_tests(self, alpha: float = 0.05) -> SignificanceTable:
        """Each column tested as the next addition to the ones before it (the paper)."""
        return nested_tests(
            self.residual_energies(),
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
        masks = self._group_masks()
        ident = np.empty(self.n, dtype=np.bool_)
        coef = np.empty(self.n)
        J_without = np.empty(len(masks))
        J_full = K.snapshot(self.R, self._col_sq, self.rtol, masks, ident, coef, J_without)
        return J_without, float(J_full), coef, ident

    def effect_tests(self, alpha: float = 0.05) -> SignificanceTable:
        """Each named effect tested *last*: full model vs full model without its columns."""
        J_without, J_full, _, ident = self.effect_energies()
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
        with open(path, "wb") as fh:
            np.savez(fh, R=self.R, col_sq=self._col_sq, sums=self._sums, meta=np.array(json.dumps(meta)))
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> RecursiveQR:
        """Restore a state written by :meth:`save`; continuing is bit-identical."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                R, col_sq, sums = data["R"], data["col_sq"], data["sums"]
        except (OSError, KeyError, ValueError, TypeError) as exc:
            # TypeError: np.load of a plain .npy gives an array, not an archive
            raise ValueError(f"{path}: not a RecursiveQR state file ({exc})") from exc
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
        if R.shape != (n + 1, n + 1) or col_sq.shape != (n,) or sums.shape != (3,):
            raise ValueError(f"{path}: arrays do not match {n} columns")
        est.R = np.array(R, dtype=float)
        est._col_sq = np.array(col_sq, dtype=float)
        est._sums = np.array(sums, dtype=float)
        return est

    def __repr__(self) -> str:
        return (
            f"RecursiveQR(n={self.n}, forgetting={self.forgetting:g}, prior={self.prior:g}, "
            f"samples={self.n_samples}, columns={list(self.columns)})"
        )
