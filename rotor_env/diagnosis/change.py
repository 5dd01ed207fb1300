"""Did the rotor change during the record?  A parameter-constancy test on the output error.

The output-error fit holds one set of parameters for the whole record.  A crack that opens,
a balance weight that flies off or a rub that starts halfway through breaks that
assumption, and the fit then averages two rotors.  A crack appearing above the critical
speed changes the small response there by a fraction of a micrometre: the whole record's
residual barely rises above the noise floor, yet the fit's own scores show it.

The test (Andrews 1993, the sup-LM test for a structural break at an unknown time): with
``s_k = J_k' e_k`` the fit's score of sample ``k``
(:func:`~rotor_env.diagnosis.output_error.sample_scores`: every free parameter, projected on
the complement of the segments' start states) and ``S_k`` their partial sums (zero at the end:
the fit's normal equations), ``LM_k = S_k' W_k^-1 S_k`` is the Lagrange-multiplier statistic
of "every parameter changes at ``k``", ``W_k`` the variance of ``S_k`` under a constant rotor.

A run-up gathers most of its information in the seconds at the critical speed, so ``W_k`` is
built from the fit's own information and scores as they accumulate, summed over blocks of
whole shooting segments (the scores are exact over whole segments), each at least five
correlation times of the probes' noise -- measured above the signal band, not read off the
residual, whose slow misfit under a change would hide it -- and the supremum's null is drawn
by a block multiplier bootstrap (:func:`identifier.breaks.sup_lm_test`, which says why the
textbook null would be wrong here).  A record with too few blocks for that (fewer than
eight per parameter: a short angle record) gets the textbook form: ``W_k = n lambda
(1 - lambda) V`` with ``V`` the scores' long-run covariance per sample (Bartlett, Andrews'
bandwidth), ``lambda = k / n``, whose supremum converges to that of a squared ``p``-dimensional
Brownian bridge over ``lambda (1 - lambda)`` (critical values simulated here, seeded and
cached per ``p``; Andrews' Table 1 gives 8.68 at 5 % for ``p = 1``, reproduced by the tests).
The break is dated by least squares (Bai 1997) with the blocks, at the supremum with the
textbook form; what moved is read off the partial sums there, effect by effect (the same
statistic on each effect's parameters).

It is information, not a verdict.  In a sweep time and speed go together, so a parameter that
depends on speed (a cross-coupling reads as a damping ``c - q/w``) is a "change" too, and the 1X
terms carry the instrument's spin-angle and runout errors: on the rig suite's constant rotors
(``benchmarks/rig_suite.py``) most "not the same" are cross-couplings, bows the waveforms
cannot tell from runout (their trace drifts) and records at 2.5-5 kHz, where the keyphasor's
sampled edges put milliradians of error into the spin angle at top speed and the 1X terms
drift with it.  A bow the 1X vectors name is tested with the bow in the model
(``from_rig._constancy_of_the_verdict``): the model the record's verdict stands on.

What it assumes: the model is right on each side of the break.  A model that misses an
effect everywhere (a residual well above the floor) also makes the scores drift, so a
"change" is only reported as one when the record is otherwise explained; otherwise it is
said to be the missing effect's trace.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from identifier.breaks import MAX_BLOCKS, MIN_BLOCKS_PER_PARAMETER, sup_lm_test
from identifier.hac import andrews_bandwidth, long_run_covariance

from .output_error import CALIBRATION_TERMS, OutputErrorFit, sample_scores

__all__ = ["TRIM", "ParameterChange", "parameter_constancy", "sup_lm_distribution"]

#: the share of the record at each end where no break is looked for (Andrews' pi_0)
TRIM = 0.15
#: Monte Carlo size and grid of the null distribution
_PATHS = 4000
_GRID = 1000
_NULL: dict[tuple[int, float], np.ndarray] = {}
#: bootstrap draws of the blocks' null (seeded: the same answer every run)
DRAWS = 999
#: a block holds at least this many correlation times of the probes' noise: batch means of
#: AR(1) noise then miss its long-run variance by about 2 rho / ((1 - rho^2) L) < 10 %
BLOCK_CORRELATIONS = 5


def sup_lm_distribution(p: int, trim: float = TRIM) -> np.ndarray:
    """Simulated null draws (sorted) of ``sup |B(l)|^2 / (l (1 - l))`` over ``[trim, 1 - trim]``,
    ``B`` a ``p``-dimensional Brownian bridge (seed fixed: the same answer every run)."""
    key = (int(p), float(trim))
    if key in _NULL:
        return _NULL[key]
    # simulated once per machine (about 0.08 s a dimension), then read from the kernel cache
    # folder: a plain .npy of the sorted draws, named by everything that makes them
    from ..simulator import kernel_cache_dir

    path = kernel_cache_dir() / "null" / f"sup_lm_p{p}_trim{trim:g}_{_PATHS}x{_GRID}_v1.npy"
    try:
        draws = np.load(path, allow_pickle=False)
        if draws.shape == (_PATHS,) and np.all(np.isfinite(draws)):
            _NULL[key] = draws
            return draws
    except (OSError, ValueError):
        pass
    rng = np.random.default_rng(1993 + 97 * p)
    lam = (np.arange(1, _GRID + 1) / _GRID).astype(np.float32)
    sel = (lam >= trim) & (lam <= 1 - trim)
    acc = np.zeros((_PATHS, int(sel.sum())), dtype=np.float32)
    for _ in range(p):
        # single precision: a third less time, far below the Monte Carlo error
        w = np.cumsum(rng.standard_normal((_PATHS, _GRID), dtype=np.float32), axis=1) / np.float32(math.sqrt(_GRID))
        b = w - lam * w[:, -1:]
        acc += b[:, sel] ** 2
    _NULL[key] = np.sort(np.max(acc / (lam[sel] * (1 - lam[sel])), axis=1).astype(float))
    try:  # a read-only home: simulated again next time
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")
        np.save(tmp, _NULL[key], allow_pickle=False)
        os.replace(tmp, path)
    except OSError:
        pass
    return _NULL[key]


@dataclass(frozen=True)
class ParameterChange:
    """The record's parameter-constancy test (module docstring)."""

    statistic: float  #: sup-LM
    p_value: float  #: from the simulated null (at least 1 / paths)
    dof: int
    t_break: float  #: model time of the break
    fraction: float  #: its place in the record (0..1)
    moved: dict[str, float]  #: effect -> its own sup-LM share at the break (largest first)
    alpha: float
    explained: bool  #: the record is otherwise explained (residual at the floor)
    #: "blocks" (the information's own path, bootstrap) or "bridge" (the textbook form)
    method: str = "blocks"

    @property
    def significant(self) -> bool:
        return self.p_value < self.alpha

    @property
    def changed(self) -> bool:
        """Not the same parameters over the record, on an otherwise explained record: a change
        of the rotor, a parameter that depends on speed, or an instrument's drift (information,
        not a verdict: on the rig suite's constant rotors 46 of 220 records said so)."""
        return self.significant and self.explained

    def sentence(self, when: str = "") -> str:
        when = when or f"at {100 * self.fraction:.0f} % of the record"
        least = 1 / (DRAWS + 1) if self.method == "blocks" else 1 / _PATHS
        p = f"p <= {least:g}" if self.p_value <= least else f"p = {self.p_value:.3g}"
        top = ", ".join(f"{e} ({v:.0f})" for e, v in list(self.moved.items())[:3])
        if not self.significant:
            return f"no change of the rotor during the record (sup-LM {self.statistic:.1f}, {p})"
        if not self.explained:
            return (f"the fitted parameters drift along the record (sup-LM {self.statistic:.1f}, {p}, most {when}): "
                    "the trace of what the model still misses, not a proven change of the rotor")
        return (f"the fitted parameters are not the same over the record, most {when} (sup-LM "
                f"{self.statistic:.1f}, {p}; what moved: {top}): the rotor changed then, or a parameter depends on "
                "speed (in a sweep time and speed go together; a cross-coupling reads as a damping c - q/w), or the "
                "1X carries an instrument's drift -- diagnose the parts before and after separately to tell")

    def to_dict(self) -> dict:
        return {"statistic": self.statistic, "p_value": self.p_value, "dof": self.dof, "t_break": self.t_break,
                "fraction": self.fraction, "moved": self.moved, "significant": self.significant,
                "changed": self.changed, "method": self.method, "sentence": self.sentence()}


def _blocks(fit: OutputErrorFit, n: int) -> np.ndarray:
    """The last sample of each block: whole shooting segments, together at least five noise
    correlation times and at most MAX_BLOCKS blocks."""
    ends = np.cumsum([i1 - i0 + 1 for i0, i1 in fit.grid.segments]) - 1
    least = max(BLOCK_CORRELATIONS * fit.grid.noise_correlation, n / MAX_BLOCKS)
    keep, last = [], -1
    for e in ends:
        if e - last >= least:
            keep.append(e)
            last = e
    if keep and keep[-1] != ends[-1]:
        keep[-1] = ends[-1]  # a short tail joins the last block
    return np.asarray(keep, dtype=int)


def parameter_constancy(fit: OutputErrorFit, *, alpha: float = 0.05, explained: bool = True,
                        trim: float = TRIM, method: str = "auto") -> ParameterChange:
    """The sup-LM test of ``fit``'s parameters being the same over the whole record;
    ``explained``: the record's residual is at the noise floor; ``method``: "blocks", "bridge"
    (the textbook form) or "auto" (blocks where the record has enough; module docstring)."""
    if method not in ("auto", "blocks", "bridge"):
        raise ValueError(f"method must be 'auto', 'blocks' or 'bridge', got {method!r}")
    t, sc, J, names = sample_scores(fit, with_jacobian=True)
    # parameters without a score (held, or absent from the record) carry no test
    ss = np.sum(sc * sc, axis=0)
    # nor the probes' calibration: a sensitivity does not change within a run, and its two
    # scores share the orbit's backward 1X with a crack that opens (tested with them, a crack
    # appearing at 45 % of a record was dated at 54 %)
    calibration = {f"output.{n}" for n in CALIBRATION_TERMS}
    keep = (ss > 1e-300 * max(float(np.max(ss)), 1e-300)) & np.array([nm not in calibration for nm in names])
    sc, J, names = sc[:, keep], J[:, :, keep], tuple(nm for nm, k in zip(names, keep, strict=True) if k)
    n, p = sc.shape
    owners = [nm.split(".", 1)[0].replace("output", "the probes' offsets and runout") for nm in names]
    groups = {e: [i for i, o in enumerate(owners) if o == e] for e in dict.fromkeys(owners)}
    # every parameter is tested, the probes' offsets and runout too: a crack that opens on a
    # synchronous orbit moves the 1X, and the output's 1X terms take much of that move (a
    # synthetic crack appearing past the critical went unseen with them held)
    ends = _blocks(fit, n)
    if method == "blocks" or (method == "auto" and len(ends) >= max(20, MIN_BLOCKS_PER_PARAMETER * p)):
        test = sup_lm_test(sc, J, boundaries=ends, trim=trim, draws=DRAWS, seed=1993)
        moved = {e: test.group_statistic(idx) for e, idx in groups.items()}
        moved = dict(sorted(moved.items(), key=lambda kv: -kv[1]))
        return ParameterChange(test.statistic, test.p_value, p, float(t[test.index]), test.fraction, moved,
                               alpha, explained, "blocks")
    V = long_run_covariance(sc, andrews_bandwidth(sc)) / n
    S = np.cumsum(sc, axis=0)
    ks = np.arange(max(1, int(math.ceil(trim * n))), int(math.floor((1 - trim) * n)))
    lam = ks / n
    lm = np.einsum("ki,ij,kj->k", S[ks], np.linalg.pinv(V), S[ks]) / (n * lam * (1 - lam))
    j = int(np.argmax(lm))
    k, lk = ks[j], lam[j]
    null = sup_lm_distribution(p, trim)
    pval = max((np.sum(null >= lm[j]) + 1) / (len(null) + 1), 1 / _PATHS)
    moved = {}
    for e, idx in groups.items():
        Se = S[k, idx]
        moved[e] = float(Se @ np.linalg.pinv(V[np.ix_(idx, idx)]) @ Se / (n * lk * (1 - lk)))
    moved = dict(sorted(moved.items(), key=lambda kv: -kv[1]))
    return ParameterChange(float(lm[j]), float(pval), p, float(t[k]), float(lk), moved, alpha, explained, "bridge")
