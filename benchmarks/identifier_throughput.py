"""Throughput and peak memory of the recursive QR identifier against common alternatives.

Run:  python benchmarks/identifier_throughput.py [--quick] [--repeats 3] [--statsmodels-large]

n = 7 regressors, m = 40 000 and 400 000 samples (``--quick``: 40 000 only).  Methods:

* rotor-id, all nested residual energies J_0..J_7 after every sample
  (``update_many(..., return_energies=True)``), streamed in chunks of 20 000;
* rotor-id, all nested coefficients (orders 1..7) after every sample
  (``return_coefficients="all"``), streamed in chunks of 20 000;
* rotor-id, state only (no per-sample histories), for reference;
* statsmodels ``RecursiveLS`` (Kalman filter; full-model coefficients per sample).  At
  400 000 samples it needs ~5 GiB and ~20 s, so it runs there only with
  ``--statsmodels-large``;
* a plain numpy P-matrix RLS loop in Python (full-model coefficients per sample);
  40 000 samples only unless ``--python-large``;
* one batch ``numpy.linalg.lstsq`` on all data (final coefficients only).

Timing: wall clock (``perf_counter``), best of ``--repeats`` (the slow methods at 400 000:
one run); numba is warmed up first.  Peak memory: what the method allocates on
top of its input data, measured in a separate, untimed run in a fresh subprocess: the
larger of the ``tracemalloc`` peak (numpy / statsmodels buffers, even where the allocator
reuses freed memory) and the rise of the peak resident set size (``VmHWM``, reset through
``/proc/self/clear_refs`` on Linux; it also sees LAPACK work space and numba's buffers,
which tracemalloc does not).

This is a script, not a test.
"""

from __future__ import annotations

import argparse
import gc
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Callable

import numpy as np
import statsmodels.api as sm

from identifier import RecursiveQR

N = 7
CHUNK = 20_000


def make_data(m: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((m, N))
    y = X @ np.linspace(1.0, 0.1, N) + 0.1 * rng.standard_normal(m)
    return X, y


# ------------------------------------------------------------------------- methods
def rotor_id_energies(X, y):
    est = RecursiveQR(N)
    last = None
    for a in range(0, X.shape[0], CHUNK):
        hist = est.update_many(X[a : a + CHUNK], y[a : a + CHUNK], return_energies=True)
        last = hist.energies[-1]  # a consumer would use the chunk here; it is then dropped
    return last


def rotor_id_coefficients(X, y):
    est = RecursiveQR(N)
    last = None
    for a in range(0, X.shape[0], CHUNK):
        hist = est.update_many(X[a : a + CHUNK], y[a : a + CHUNK], return_coefficients="all")
        last = hist.coefficients[N][-1]
    return last


def rotor_id_state_only(X, y):
    est = RecursiveQR(N)
    for a in range(0, X.shape[0], CHUNK):
        est.update_many(X[a : a + CHUNK], y[a : a + CHUNK])
    return est.coefficients()


def statsmodels_recursive_ls(X, y):
    res = sm.RecursiveLS(y, X).fit()
    return res.recursive_coefficients.filtered[:, -1]


def python_p_matrix_rls(X, y, delta: float = 1e6):
    """Textbook RLS with the inverse-correlation matrix P, one sample per Python step."""
    P = delta * np.eye(N)
    theta = np.zeros(N)
    for k in range(X.shape[0]):
        x = X[k]
        Px = P @ x
        g = Px / (1.0 + x @ Px)
        theta = theta + g * (y[k] - x @ theta)
        P = P - np.outer(g, Px)
    return theta


def batch_lstsq(X, y):
    return np.linalg.lstsq(X, y, rcond=None)[0]


# ------------------------------------------------------------------------ measuring
def best_time(fn: Callable, X, y, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(X, y)
        best = min(best, time.perf_counter() - t0)
    return best


def _proc_status_mib(key: str) -> float | None:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def _reset_peak_rss() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")  # resets VmHWM to the current RSS (Linux >= 4.0)
        return True
    except OSError:
        return False


def peak_mib(fn: Callable, X, y) -> float:
    """Memory allocated by ``fn(X, y)`` beyond its inputs (MiB); see the module docstring."""
    gc.collect()
    rss_ok = _reset_peak_rss()
    rss0 = _proc_status_mib("VmRSS") if rss_ok else None
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    fn(X, y)
    traced = (tracemalloc.get_traced_memory()[1] - base) / 2**20
    tracemalloc.stop()
    hwm = _proc_status_mib("VmHWM") if rss_ok else None
    rss = hwm - rss0 if (hwm is not None and rss0 is not None) else 0.0
    return max(traced, rss)


def peak_mib_in_subprocess(name: str, m: int) -> float:
    """Run one method once in a fresh interpreter (clean heap) and return its peak MiB."""
    out = subprocess.run(
        [sys.executable, __file__, "--peak-of", name, str(m)],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    return float(out.strip().splitlines()[-1])


def warm_up() -> None:
    X, y = make_data(500, seed=1)
    for fn in (rotor_id_energies, rotor_id_coefficients, rotor_id_state_only):
        fn(X, y)


METHODS = {
    # name: (function, fast -> best of repeats, runs at large m by default)
    "rotor-id: all nested energies / sample": (rotor_id_energies, True, True),
    "rotor-id: all nested coefficients / sample": (rotor_id_coefficients, True, True),
    "rotor-id: state only (no histories)": (rotor_id_state_only, True, True),
    "statsmodels RecursiveLS": (statsmodels_recursive_ls, False, False),
    "numpy P-matrix RLS, Python loop": (python_p_matrix_rls, False, False),
    "numpy.linalg.lstsq, one batch": (batch_lstsq, True, True),
}
SM, LS = "statsmodels RecursiveLS", "numpy.linalg.lstsq, one batch"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="only m = 40 000")
    ap.add_argument("--repeats", type=int, default=3, help="best of this many (fast methods)")
    ap.add_argument("--statsmodels-large", action="store_true", help="RecursiveLS at 400 000 too")
    ap.add_argument("--python-large", action="store_true", help="Python RLS loop at 400 000 too")
    ap.add_argument("--peak-of", nargs=2, metavar=("METHOD", "M"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.peak_of:  # internal: memory of one method, in this fresh process
        name, m = args.peak_of[0], int(args.peak_of[1])
        X, y = make_data(m)
        warm_up()
        print(peak_mib(METHODS[name][0], X, y))
        return

    large_ok = {SM: args.statsmodels_large, "numpy P-matrix RLS, Python loop": args.python_large}
    sizes = [40_000] if args.quick else [40_000, 400_000]
    warm_up()
    rows = []
    for m in sizes:
        X, y = make_data(m)
        res: dict[str, tuple[float, float] | None] = {}
        for name, (fn, fast, large) in METHODS.items():
            if m > 40_000 and not (large or large_ok.get(name, False)):
                res[name] = None
                continue
            # slow methods: best of repeats where that is cheap (40 000), else one run
            t = best_time(fn, X, y, args.repeats if (fast or m <= 40_000) else 1)
            res[name] = (m / t, peak_mib_in_subprocess(name, m))
        for name in METHODS:
            r = res[name]
            if r is None:
                why = (
                    "not run (extrapolated ~5 GiB, ~25 s; --statsmodels-large)"
                    if name == SM
                    else "not run (extrapolated ~5 s; --python-large)"
                )
                rows.append((name, m, why, "", "", ""))
                continue
            vs_sm = f"{r[0] / res[SM][0]:.3g}" if res[SM] else "n/a (statsmodels not run)"
            vs_ls = f"{r[0] / res[LS][0]:.3g}"
            rows.append((name, m, f"{r[0]:,.0f}", f"{r[1]:,.1f}", vs_sm, vs_ls))

    head = ("method", "m", "samples/s", "peak MiB", "ratio vs statsmodels", "ratio vs lstsq")
    print(f"n = {N}; rotor-id streams chunks of {CHUNK:,} samples; ratios are of samples/s")
    print()
    print("| " + " | ".join(head) + " |")
    print("|" + "|".join(["---", "---:", "---:", "---:", "---:", "---:"]) + "|")
    for name, m, rate, mem, vs_sm, vs_ls in rows:
        print(f"| {name} | {m:,} | {rate} | {mem} | {vs_sm} | {vs_ls} |")


if __name__ == "__main__":
    main()
