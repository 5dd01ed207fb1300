"""Steps per second of the rotor environments against Gymnasium's CartPole, in one run.

    python benchmarks/env_speed.py [--seconds 3] [--num-envs 1024] [--parallel] [--wrapper-only]

* single env: ``gym.make(id)`` (with Gymnasium's default wrappers) against
  ``gym.make("CartPole-v1")``, constant actions, reset on episode end;
* vector env: ``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")``
  against ``gym.make_vec("CartPole-v1", num_envs=N, vectorization_mode=
  "vector_entry_point")`` (Gymnasium's numpy ``CartPoleVectorEnv``), with autoreset.

The rotor configurations differ in the decision step, the sensor samples per step and
whether the samples are returned; every configuration integrates >= 10 RK4 sub-steps of
<= 0.01 per step.  Compilation (numba) happens before the timing.  Prints a Markdown
table.

A second table gives the cost of the identification wrapper (defaults) against the bare
env measured in the same run: ``IdentificationWrapper(gym.make(id))`` against
``gym.make(id)`` and ``VectorIdentificationWrapper`` on ``make_vec(id, num_envs=16)``
against the bare vector env.  Bare and wrapped are timed in alternating rounds (so a load
change on the machine hits both); the table gives each one's best round, the cost ratio
``wrapped time per step / bare time per step`` of the best rounds and the range of the
per-round ratios (the target of the issue: <= 2x for the single env).  ``--wrapper-only``
prints only that table.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import gymnasium as gym
import numba
import numpy as np

import rotor_env
from rotor_env import IdentificationWrapper, VectorIdentificationWrapper

RUN_UP, BALANCING = rotor_env.ENV_IDS
WRAPPER_ROUNDS = 6
WRAPPER_NUM_ENVS = 16


def _time_single(env, action, seconds: float) -> float:
    env.reset(seed=0)
    env.step(action)  # compile / warm up
    env.reset(seed=0)
    n = 0
    t0 = time.perf_counter()
    deadline = t0 + seconds
    while True:
        for _ in range(200):
            _, _, term, trunc, _ = env.step(action)
            if term or trunc:
                env.reset()
        n += 200
        if time.perf_counter() >= deadline:
            break
    return n / (time.perf_counter() - t0)


def _time_vector(envs, actions, seconds: float) -> float:
    envs.reset(seed=0)
    envs.step(actions)  # compile / warm up
    n = 0
    t0 = time.perf_counter()
    deadline = t0 + seconds
    while time.perf_counter() < deadline:
        envs.step(actions)
        n += 1
    return n * envs.num_envs / (time.perf_counter() - t0)


def _wrapper_cost(bare, wrapped, timer, action, seconds: float) -> tuple[float, float, float, float, float]:
    """``(bare steps/s, wrapped steps/s, cost ratio, min, max of the per-round ratios)``.

    Alternating rounds of ``seconds / WRAPPER_ROUNDS`` each (after a warm-up of both);
    steps/s are the best round's, the ratio is ``bare rate / wrapped rate``.
    """
    per = seconds / WRAPPER_ROUNDS
    timer(bare, action, 0.05)  # compile / warm up
    timer(wrapped, action, 0.05)
    b_rates, w_rates = [], []
    for _ in range(WRAPPER_ROUNDS):
        b_rates.append(timer(bare, action, per))
        w_rates.append(timer(wrapped, action, per))
    ratios = [b / w for b, w in zip(b_rates, w_rates, strict=True)]
    b, w = max(b_rates), max(w_rates)
    return b, w, b / w, min(ratios), max(ratios)


def wrapper_rows(seconds: float) -> list[tuple[str, str, float, float, float, float, float]]:
    rows = []
    for env_id in (RUN_UP, BALANCING):
        bare = gym.make(env_id)
        wrapped = IdentificationWrapper(gym.make(env_id))
        act = np.ones(bare.action_space.shape, np.float32)
        rows.append(("single", f"IdentificationWrapper({env_id.split('/')[1]})",
                     *_wrapper_cost(bare, wrapped, _time_single, act, seconds)))
    n = WRAPPER_NUM_ENVS
    for env_id in (RUN_UP, BALANCING):
        kw = {"num_envs": n, "vectorization_mode": "vector_entry_point"}
        bare = gym.make_vec(env_id, **kw)
        wrapped = VectorIdentificationWrapper(gym.make_vec(env_id, **kw))
        acts = np.ones(bare.action_space.shape, np.float32)
        rows.append(("vector", f"VectorIdentificationWrapper({env_id.split('/')[1]} x{n})",
                     *_wrapper_cost(bare, wrapped, _time_vector, acts, seconds)))
    return rows


def _print_wrapper_table(rows) -> None:
    print(f"\nIdentification wrapper (defaults) vs the bare env, {WRAPPER_ROUNDS} alternating rounds; "
          "cost = wrapped time per step / bare time per step (best rounds; per-round range)\n")
    print("| kind | wrapped environment | bare steps/s | wrapped steps/s | cost (x bare step) | per-round range |")
    print("|---|---|---|---|---|---|")
    for kind, name, b, w, ratio, lo, hi in rows:
        print(f"| {kind} | {name} | {b:,.0f} | {w:,.0f} | {ratio:.2f} | {lo:.2f}–{hi:.2f} |")


def _header(sec: float) -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")  # after the timing
    return (f"\n{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, numba threads "
            f"{numba.config.NUMBA_NUM_THREADS}, load average {load:.2f}, {sec:g} s per row\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="timing per row")
    ap.add_argument("--num-envs", type=int, default=1024)
    ap.add_argument("--parallel", action="store_true", help="also time the prange kernel")
    ap.add_argument("--wrapper-only", action="store_true", help="only the identification wrapper table")
    args = ap.parse_args()
    sec, n = args.seconds, args.num_envs

    if args.wrapper_only:
        wrows = wrapper_rows(2 * sec)
        print(_header(sec))
        _print_wrapper_table(wrows)
        return

    rows: list[tuple[str, str, str, float, float]] = []

    # ------------------------------------------------------------- single env
    cart = gym.make("CartPole-v1")
    cart_rate = _time_single(cart, 1, sec)
    rows.append(("single", "CartPole-v1 (gym.make)", "—", cart_rate, cart_rate))
    single_cfgs = [
        (RUN_UP, {}, "default: step 0.5, 50 samples"),
        (BALANCING, {}, "default: step 0.5, 50 samples"),
        (RUN_UP, {"step_dt": 0.1}, "step 0.1, 10 samples"),
    ]
    for env_id, kw, label in single_cfgs:
        env = gym.make(env_id, **kw)
        rate = _time_single(env, np.ones(env.action_space.shape, np.float32), sec)
        sub = env.unwrapped.substeps_per_step
        rows.append(("single", f"{env_id.split('/')[1]} — {label}", str(sub), rate, cart_rate))

    # ------------------------------------------------------------- vector env
    cartv = gym.make_vec("CartPole-v1", num_envs=n, vectorization_mode="vector_entry_point")
    cartv_rate = _time_vector(cartv, np.ones(n, dtype=np.int64), sec)
    rows.append(("vector", f"CartPoleVectorEnv x{n}", "—", cartv_rate, cartv_rate))
    vec_cfgs = [
        (RUN_UP, {}, "default: step 0.5, 50 samples"),
        (BALANCING, {}, "default: step 0.5, 50 samples"),
        (RUN_UP, {"step_dt": 0.1}, "step 0.1, 10 samples"),
        (RUN_UP, {"step_dt": 0.1, "sensor_dt": 0.1}, "step 0.1, 1 sample"),
        (RUN_UP, {"step_dt": 0.1, "sensor_dt": 0.1, "return_measurements": False},
         "step 0.1, 1 sample, no measurements"),
    ]
    for parallel in ([False, True] if args.parallel else [False]):
        for env_id, kw, label in vec_cfgs:
            envs = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                                parallel=parallel, **kw)
            acts = np.ones(envs.action_space.shape, np.float32)
            rate = _time_vector(envs, acts, sec)
            sub = envs.unwrapped._tpl.substeps_per_step
            tag = "prange" if parallel else "serial"
            rows.append(("vector", f"{env_id.split('/')[1]} x{n} ({tag}) — {label}", str(sub), rate, cartv_rate))
            envs.close()

    wrows = wrapper_rows(2 * sec)

    print(_header(sec))
    print("| kind | environment | RK4 sub-steps / step | steps/s | ratio to CartPole |")
    print("|---|---|---|---|---|")
    for kind, name, sub, rate, ref in rows:
        print(f"| {kind} | {name} | {sub} | {rate:,.0f} | {rate / ref:.3f} |")
    _print_wrapper_table(wrows)


if __name__ == "__main__":
    main()
