"""SB3 on the numba vector env (``agents.vec_env.RotorVecEnv``) against ``DummyVecEnv``.

Two measures, each with the numba kernels compiled beforehand:

* env-steps/s of random actions through the SB3 ``VecEnv`` interface (``VecMonitor`` over
  the adapter; ``DummyVecEnv`` of ``Monitor``-wrapped single envs), for several ``n_envs``;
* PPO training wall time (``--ppo-steps``, ``n_envs`` 16, the committed hyper-parameters
  otherwise), where the network's updates are the same on both sides.

    python benchmarks/vec_env.py [--env rotor_env/RotorRunUp-v0] [--steps 20000] [--ppo-steps 16384]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def dummy(env_id: str, n: int, seed: int = 0):
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agents.training import make_env

    v = DummyVecEnv([lambda: Monitor(make_env(env_id, False)) for _ in range(n)])
    v.seed(seed)
    return v


def numba_env(env_id: str, n: int, seed: int = 0):
    from agents.vec_env import make_numba_vec_env

    return make_numba_vec_env(env_id, n, seed=seed)


def steps_per_s(venv, steps: int) -> float:
    n = venv.num_envs
    rng = np.random.default_rng(0)
    acts = rng.uniform(-1, 1, size=(64, n, *venv.action_space.shape)).astype(np.float32)
    venv.reset()
    for k in range(50):  # warm-up (compiles)
        venv.step(acts[k % 64])
    t = time.perf_counter()
    calls = max(1, steps // n)
    for k in range(calls):
        venv.step(acts[k % 64])
    return calls * n / (time.perf_counter() - t)


def ppo_time(make, env_id: str, steps: int) -> float:
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    venv = VecNormalize(make(env_id, 16))
    model = PPO("MlpPolicy", venv, n_steps=256, batch_size=256, n_epochs=10, gamma=0.995, seed=0, device="cpu",
                policy_kwargs={"net_arch": [64, 64]})
    t = time.perf_counter()
    model.learn(total_timesteps=steps)
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="rotor_env/RotorRunUp-v0")
    ap.add_argument("--steps", type=int, default=20_000, help="env steps per throughput measurement")
    ap.add_argument("--n-envs", default="4,16,64")
    ap.add_argument("--ppo-steps", type=int, default=16_384, help="PPO steps per training run (0: skip)")
    args = ap.parse_args()
    print(f"{args.env}, random actions through the SB3 VecEnv interface\n")
    print("| n_envs | DummyVecEnv (steps/s) | numba adapter (steps/s) | speed-up |")
    print("|---|---|---|---|")
    for n in (int(x) for x in args.n_envs.split(",")):
        d = steps_per_s(dummy(args.env, n), args.steps)
        v = steps_per_s(numba_env(args.env, n), args.steps)
        print(f"| {n} | {d:,.0f} | {v:,.0f} | ×{v / d:.2f} |", flush=True)
    if args.ppo_steps:
        ppo_time(numba_env, args.env, 512)  # compile both sides' kernels first
        ppo_time(dummy, args.env, 512)
        td = ppo_time(dummy, args.env, args.ppo_steps)
        tv = ppo_time(numba_env, args.env, args.ppo_steps)
        print(f"\nPPO, {args.ppo_steps} steps, n_envs 16: DummyVecEnv {td:.1f} s, numba adapter {tv:.1f} s "
              f"(×{td / tv:.2f})")


if __name__ == "__main__":
    main()
