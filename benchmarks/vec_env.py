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


def ppo_time(make, env_id: str, steps: int) -> tuple[float, float]:
    """Wall time of ``PPO.learn(steps)`` with 16 envs, and the part of it spent stepping the envs."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecEnvWrapper, VecNormalize

    class Timed(VecEnvWrapper):  # the envs' own time, under the normalisation
        spent = 0.0

        def reset(self):
            return self.venv.reset()

        def step_wait(self):
            t0 = time.perf_counter()
            out = self.venv.step_wait()
            Timed.spent += time.perf_counter() - t0
            return out

    venv = VecNormalize(Timed(make(env_id, 16)))
    model = PPO("MlpPolicy", venv, n_steps=256, batch_size=256, n_epochs=10, gamma=0.995, seed=0, device="cpu",
                policy_kwargs={"net_arch": [64, 64]})
    Timed.spent = 0.0
    t = time.perf_counter()
    model.learn(total_timesteps=steps)
    return time.perf_counter() - t, Timed.spent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="rotor_env/RotorRunUp-v0")
    ap.add_argument("--steps", type=int, default=20_000, help="env steps per throughput measurement")
    ap.add_argument("--n-envs", default="4,16,64")
    ap.add_argument("--ppo-steps", type=int, default=16_384, help="PPO steps per training run (0: skip)")
    ap.add_argument("--repeat", type=int, default=3, help="PPO runs per side (interleaved; the median is shown)")
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
        runs: dict[str, list[tuple[float, float]]] = {"dummy": [], "numba": []}
        for _ in range(args.repeat):  # interleaved: a load that comes and goes hits both
            runs["dummy"].append(ppo_time(dummy, args.env, args.ppo_steps))
            runs["numba"].append(ppo_time(numba_env, args.env, args.ppo_steps))
        med = {k: sorted(v)[len(v) // 2] for k, v in runs.items()}
        (td, ed), (tv, ev) = med["dummy"], med["numba"]
        print(f"\nPPO, {args.ppo_steps} steps, n_envs 16, median of {args.repeat} interleaved runs: DummyVecEnv "
              f"{td:.1f} s (envs {ed:.1f} s, {100 * ed / td:.0f} %), numba adapter {tv:.1f} s (envs {ev:.1f} s, "
              f"{100 * ev / tv:.0f} %): ×{td / tv:.2f}")
        print("runs (wall s, env s): " + "; ".join(f"{k}: " + ", ".join(f"{w:.1f}/{e:.1f}" for w, e in v)
                                                  for k, v in runs.items()))

if __name__ == "__main__":
    main()
