"""Speed and accuracy of rotor-id's simulator against the LSODA reference.

The paper's run: Table-1 parameters, at rest at t = 0, phi'' = 0.01, t in [0, 400],
samples every 0.01 (40 001 rows).  rotor-id's fixed-step RK4 (numba, after a warm-up
compile; best of ``--repeat``) against ``rotor_env.reference.reference_solution``
(LSODA, rtol 1e-9, atol 1e-12, friction regularised with eps 1e-6; ``t_eval`` at every
sample; best of ``--ref-repeat``), both in this process.  Accuracy: the largest
deviation of ``theta_x``, ``theta_y`` from the reference over all samples, relative to
the reference's peak amplitude.  That reference's friction regularisation (the disk
creeps while it should stick) dominates the deviation, so the table also gives the
deviation from a tighter reference (eps 1e-8): the simulator's own error.

``reference_solution`` integrates each segment twice (once with ``t_eval``, once more
for the segment's final state); the speed-up is also given against its ``t_eval``
pass alone (one ``solve_ivp`` call, timed by wrapping it), the cost of one LSODA run.

    python benchmarks/simulator_speed.py            # prints a Markdown table
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from rotor_env import reference as reference_module
from rotor_env.params import RotorParams
from rotor_env.reference import reference_solution
from rotor_env.simulator import MAX_SUBSTEP, simulate


def best_of(fn, repeat: int) -> tuple[float, object]:
    best, result = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return best, result


class _Angles:
    def __init__(self, states: np.ndarray) -> None:
        self.theta_x, self.theta_y = states[:, 0], states[:, 1]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--t-end", type=float, default=400.0)
    ap.add_argument("--dt", type=float, default=0.01)
    ap.add_argument("--repeat", type=int, default=5, help="runs of the simulator (best of)")
    ap.add_argument("--ref-repeat", type=int, default=3, help="runs of the reference (best of)")
    args = ap.parse_args(argv)

    params = RotorParams()  # Table 1
    t0 = time.perf_counter()
    simulate(params, t_end=1.0, dt=args.dt)  # warm-up: numba compiles the kernel
    compile_s = time.perf_counter() - t0

    t_eval = np.arange(int(round(args.t_end / args.dt)) + 1) * args.dt
    solve_ivp = reference_module.solve_ivp
    pass_times: list[float] = []

    def timed_solve_ivp(*a, **kw):
        t0 = time.perf_counter()
        sol = solve_ivp(*a, **kw)
        if kw.get("t_eval") is not None:
            pass_times.append(time.perf_counter() - t0)
        return sol

    reference_module.solve_ivp = timed_solve_ivp
    try:
        t_ref, ref = best_of(lambda: reference_solution(params, t_eval), args.ref_repeat)
    finally:
        reference_module.solve_ivp = solve_ivp
    t_pass = min(pass_times)
    tight = reference_solution(params, t_eval, eps=1e-8)
    peak = float(np.hypot(ref[:, 0], ref[:, 1]).max())

    def deviation(meas, r) -> float:
        dev = max(np.abs(meas.theta_x - r[:, 0]).max(), np.abs(meas.theta_y - r[:, 1]).max())
        return float(dev) / peak

    rows = []
    for label, substep in (
        (f"rotor-id RK4, max_substep={MAX_SUBSTEP:g} (default)", MAX_SUBSTEP),
        ("rotor-id RK4, max_substep=0.005", 0.005),
    ):
        simulate(params, t_end=1.0, dt=args.dt, max_substep=substep)  # same kernel, warm
        secs, meas = best_of(
            lambda s=substep: simulate(params, t_end=args.t_end, dt=args.dt, max_substep=s),
            args.repeat,
        )
        assert np.allclose(meas.t, np.arange(len(meas)) * args.dt)
        rows.append(
            (label, secs, t_ref / secs, t_pass / secs, deviation(meas, ref), deviation(meas, tight))
        )

    n = len(ref)
    print(
        f"Paper run (Table 1, t 0-{args.t_end:g}, {n} samples every {args.dt:g}); "
        f"{platform.processor() or platform.machine()}, numba compile {compile_s:.1f} s "
        f"(once per process, not in the times)\n"
    )
    print(
        "| integrator | time [s] | speed-up vs reference_solution | speed-up vs one LSODA pass "
        "| max abs(theta) deviation / peak | same, vs LSODA with eps 1e-8 |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    print(
        f"| LSODA reference_solution (rtol 1e-9, atol 1e-12, eps 1e-6) | {t_ref:.3f} | 1x | "
        f"{t_pass / t_ref:.2f}x | (reference) | {deviation(_Angles(ref), tight):.1e} |"
    )
    print(f"| its t_eval pass alone (one solve_ivp) | {t_pass:.3f} | | 1x | | |")
    for label, secs, ratio, ratio_pass, rel, rel_tight in rows:
        print(
            f"| {label} | {secs:.4f} | {ratio:.0f}x | {ratio_pass:.0f}x | {rel:.1e} | {rel_tight:.1e} |"
        )
    print(f"\npeak abs(theta) of the reference: {peak:.4f}; target speed-up >= 50x")


if __name__ == "__main__":
    main()
