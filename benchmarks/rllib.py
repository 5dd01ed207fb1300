"""RLlib PPO against SB3 PPO on the same environment and hyper-parameters: env-steps/s.

Both train PPO on the identification-wrapped env with the model features
(``agents.training.make_env``, what ``rotor-id train`` trains on), with the table's
``ppo`` hyper-parameters (``agents/hyperparams.yml``; RLlib's translation in
``agents.rllib``).  Each side first runs one warm-up rollout and update (numba compiles,
Ray starts), then the timed part: ``--steps`` env steps of sampling and updates.
RLlib runs with its env runners in the driver (``--workers 0``) and in N processes.

    python benchmarks/rllib.py [--env rotor_env/RotorRunUp-v0] [--steps 8192] [--workers 0,1] [--address ADDR]
"""

from __future__ import annotations

import argparse
import time

RUN_UP = "rotor_env/RotorRunUp-v0"


def sb3_rate(env_id: str, steps: int, seed: int = 0) -> float:
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.training import _vec_env, load_hyperparams

    hp = load_hyperparams(env_id, "ppo")
    n_envs = int(hp.pop("n_envs", 1))
    policy = hp.pop("policy", "MlpPolicy")
    venv = VecNormalize(_vec_env(env_id, True, n_envs, seed, "compact"))
    model = PPO(policy, venv, seed=seed, device="cpu", verbose=0, **hp)
    model.learn(total_timesteps=hp["n_steps"] * n_envs)  # warm-up: one rollout and update
    t = time.perf_counter()
    model.learn(total_timesteps=steps, reset_num_timesteps=False)
    rate = steps / (time.perf_counter() - t)
    venv.close()
    return rate


def rllib_rate(env_id: str, steps: int, workers: int, seed: int = 0) -> float:
    from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

    from agents.rllib import ppo_config

    config, _ = ppo_config(env_id, seed=seed, workers=workers)
    algo = config.build_algo()
    first = algo.train()  # warm-up
    start = first[NUM_ENV_STEPS_SAMPLED_LIFETIME]
    t = time.perf_counter()
    done = start
    while done - start < steps:
        done = algo.train()[NUM_ENV_STEPS_SAMPLED_LIFETIME]
    rate = (done - start) / (time.perf_counter() - t)
    algo.stop()
    return rate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--env", default=RUN_UP)
    ap.add_argument("--steps", type=int, default=8192, help="timed env steps per run (default 8192)")
    ap.add_argument("--workers", default="0,1", help="RLlib env-runner processes to measure (default 0,1)")
    ap.add_argument("--address", help="a Ray cluster's address (default: a local Ray)")
    args = ap.parse_args()

    import os

    import ray

    workers = [int(w) for w in args.workers.split(",")]
    print(f"{args.env}, PPO, {args.steps} timed env steps after one warm-up iteration; "
          f"{os.cpu_count()} CPUs{f', cluster {args.address}' if args.address else ''}\n")
    rows = [("SB3 PPO (DummyVecEnv, this process)", sb3_rate(args.env, args.steps))]
    ray.init(address=args.address, include_dashboard=False, log_to_driver=False, configure_logging=False,
             num_cpus=None if args.address else max(2, max(workers) + 1))
    try:
        for w in workers:
            where = "the driver" if w == 0 else f"{w} env-runner process{'es' if w > 1 else ''}"
            rows.append((f"RLlib PPO, sampling in {where}", rllib_rate(args.env, args.steps, w)))
    finally:
        ray.shutdown()
    base = rows[0][1]
    print("| trainer | env steps/s | ratio to SB3 |")
    print("|---|---|---|")
    for name, rate in rows:
        print(f"| {name} | {rate:,.0f} | ×{rate / base:.2f} |")


if __name__ == "__main__":
    main()
