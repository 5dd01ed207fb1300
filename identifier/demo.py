"""A worked example: identify a known linear system online and test each term.

The system is a damped oscillator sampled at ``dt`` and written as a regression
``y = x^T theta + e`` with one irrelevant candidate column, so the significance
tests have something to reject.  It is generic numerics: no rotor involved.
"""

from __future__ import annotations

import numpy as np

from .recursive_qr import RecursiveQR


def oscillator_regression(m: int = 20_000, noise: float = 0.01, seed: int = 0):
    """Data of ``q'' + 2 zeta w q' + w^2 q = u`` written as ``q'' = x^T theta``.

    Columns ``forcing`` (u, true 1), ``damping`` (-q', true 2 zeta w = 0.1),
    ``stiffness`` (-q, true w^2 = 4) and ``spurious`` (an unrelated random signal,
    true 0).  Returns ``X, y, theta_true, names``.
    """
    rng = np.random.default_rng(seed)
    dt = 0.01
    t = np.arange(m) * dt
    u = np.sin(0.7 * t) + 0.5 * np.sin(2.3 * t) + 0.3 * rng.standard_normal(m)
    zeta_w2, w2 = 0.1, 4.0
    q = np.zeros(m)
    v = np.zeros(m)
    a = np.zeros(m)
    for k in range(m):  # semi-implicit Euler; accelerations exact from the equation
        a[k] = u[k] - zeta_w2 * v[k] - w2 * q[k]
        if k + 1 < m:
            v[k + 1] = v[k] + dt * a[k]
            q[k + 1] = q[k] + dt * v[k + 1]
    spurious = rng.standard_normal(m)
    X = np.column_stack([u, -v, -q, spurious])
    y = a + noise * rng.standard_normal(m)
    return X, y, np.array([1.0, zeta_w2, w2, 0.0]), ("forcing", "damping", "stiffness", "spurious")


def run(print_fn=print) -> RecursiveQR:
    X, y, theta, names = oscillator_regression()
    est = RecursiveQR(columns=names)
    hist = est.update_many(X, y, return_coefficients=len(names))
    print_fn("rotor-id identifier demo: damped oscillator, 20 000 samples, noise std 0.01\n")
    print_fn("coefficient tracks (online, full model):")
    print_fn(f"{'sample':>8}  " + "  ".join(f"{n:>10}" for n in names))
    for k in (100, 1_000, 5_000, 20_000):
        print_fn(f"{k:>8}  " + "  ".join(f"{v:10.5f}" for v in hist.coefficients[len(names)][k - 1]))
    print_fn(f"{'truth':>8}  " + "  ".join(f"{v:10.5f}" for v in theta))
    se = est.standard_errors()
    print_fn("\nfinal estimate ± standard error:")
    for n, c, s, tr in zip(names, est.coefficients(), se, theta, strict=True):
        print_fn(f"  {n:<10} {c: .6f} ± {s:.2e}   (true {tr:g})")
    print_fn("")
    print_fn(str(est.nested_tests()))
    print_fn("")
    print_fn(str(est.effect_tests()))
    ic = est.information_criteria()
    print_fn(f"\nbest order: AIC {ic.best_order('aic')}, BIC {ic.best_order('bic')}, "
             f"FPE {ic.best_order('fpe')} (of 0..{len(names)})")
    return est
