"""Steps per second of the rotor environments against Gymnasium's CartPole, in one run.

    python benchmarks/env_speed.py [--seconds 3] [--num-envs 1024] [--parallel]

* single env: ``gym.make(id)`` (with Gymnasium's default wrappers) against
  ``gym.make("CartPole-v1")``, constant actions, reset on episode end;
* vector env: ``gym.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")``
  against ``gym.make_vec("CartPole-v1", num_envs=N, vectorization_mode=
  "vector_entry_point")`` (Gymnasium's numpy ``CartPoleVectorEnv``), with autoreset.

The rotor configurations differ in the decision step, the sensor samples per step and
whether the samples are returned; every configuration integrates >= 10 RK4 sub-steps of
<= 0.01 per step.  Compilation (numba) happens before the timing.  Prints a Markdown
table.
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

RUN_UP, BALANCING = rotor_env.ENV_IDS


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="timing per row")
    ap.add_argument("--num-envs", type=int, default=1024)
    ap.add_argument("--parallel", action="store_true", help="also time the prange kernel")
    args = ap.parse_args()
    sec, n = args.seconds, args.num_envs

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

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"\n{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, numba threads "
          f"{numba.config.NUMBA_NUM_THREADS}, load average {load:.2f}, {sec:g} s per row\n")
    print("| kind | environment | RK4 sub-steps / step | steps/s | ratio to CartPole |")
    print("|---|---|---|---|---|")
    for kind, name, sub, rate, ref in rows:
        print(f"| {kind} | {name} | {sub} | {rate:,.0f} | {rate / ref:.3f} |")


if __name__ == "__main__":
    main()
