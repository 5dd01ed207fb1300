"""``rotor-id train`` and ``rotor-id evaluate`` (plugged into the CLI via entry points)."""

from __future__ import annotations

import argparse
import json
import shlex
import sys

ENV_IDS = ("rotor_env/RotorRunUp-v0", "rotor_env/RotorBalancing-v0")


def _cmd_train(args: argparse.Namespace) -> int:
    from .training import train

    command = "rotor-id " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:2] == ["train"] else None
    if args.backend == "rllib":
        if args.algo != "ppo":
            print("rotor-id train: error: --backend rllib trains PPO (--algo ppo)", file=sys.stderr)
            return 2
        if args.vec_env != "dummy":
            print("rotor-id train: error: --vec-env is SB3's; RLlib samples with its own env runners (--workers)",
                  file=sys.stderr)
            return 2
        from .rllib import train_rllib

        out = train_rllib(args.env, args.steps, identifier=args.identifier, seed=args.seed, out=args.out,
                          hyperparams=args.hyperparams, command=command, force=args.force,
                          model_features=args.model_features, residual=args.residual, workers=args.workers,
                          address=args.address, eval_episodes=args.eval_episodes)
        print(f"saved {out}/policy.npz, {out}/vecnormalize.npz and {out}/run.json (logs in {out}/logs)")
        return 0
    if args.workers or args.address:
        print("rotor-id train: error: --workers/--address are for --backend rllib", file=sys.stderr)
        return 2
    out = train(args.env, args.algo, args.steps, identifier=args.identifier, seed=args.seed, out=args.out,
                hyperparams=args.hyperparams, eval_freq=args.eval_freq, eval_episodes=args.eval_episodes,
                command=command, force=args.force, model_features=args.model_features, residual=args.residual, vec_env=args.vec_env)
    print(f"saved {out}/model.zip, {out}/vecnormalize.npz and {out}/run.json")
    return 0


def add_train_parser(sub) -> None:
    p = sub.add_parser("train", help="train a controller: Stable-Baselines3 (PPO or SAC) or RLlib (PPO)")
    p.add_argument("--env", required=True, choices=ENV_IDS)
    p.add_argument("--backend", choices=("sb3", "rllib"), default="sb3",
                   help="'sb3' (default): Stable-Baselines3 in this process; 'rllib': Ray RLlib's PPO, sampling in "
                        "this process (--workers 0) or in N env-runner processes, on a cluster with --address")
    p.add_argument("--workers", type=int, default=0, metavar="N",
                   help="with --backend rllib: remote env runners (default 0: sample in the driver)")
    p.add_argument("--address", metavar="ADDR", help="with --backend rllib: a Ray cluster's address (default: a "
                   "local Ray started for the run)")
    p.add_argument("--eval-episodes", type=int, default=5, metavar="N",
                   help="held-out rotors evaluated during (SB3) or after (RLlib) training (default 5)")
    p.add_argument("--algo", default="ppo", choices=("ppo", "sac"))
    p.add_argument("--steps", type=int, default=100_000, help="environment steps (default 100000)")
    p.add_argument("--identifier", action=argparse.BooleanOptionalAction, default=True,
                   help="observe the identified parameters (IdentificationWrapper; default on)")
    p.add_argument("--model-features", choices=("compact", "full", "none"), default="compact",
                   help="with --identifier, what the policy sees of the identified model: 'compact' (default) the "
                        "speed over the identified critical speed, 'full' also the significant effects' "
                        "coefficients, 'none' the raw wrapper observation")
    p.add_argument("--residual", type=float, default=0.0, metavar="SCALE",
                   help="with --identifier, learn a correction of at most SCALE on the env's model-based baseline "
                        "(residual policy learning; default 0: the network acts alone)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="runs/policy", metavar="DIR")
    p.add_argument("--hyperparams", metavar="FILE.yml", help="hyper-parameter table (default: agents/hyperparams.yml)")
    p.add_argument("--eval-freq", type=int, default=10_000, help="evaluate every N steps")
    p.add_argument("--force", action="store_true", help="overwrite a non-empty --out folder")
    p.add_argument("--vec-env", choices=("dummy", "numba"), default="dummy",
                   help="'numba': with --no-identifier, step all sub-envs in one compiled call (the numba vector env "
                        "through an SB3 VecEnv adapter) instead of DummyVecEnv")
    p.set_defaults(func=_cmd_train)


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluation import EVAL_SEED0, evaluate, format_table, load_model

    env_id = args.env
    if env_id is None:
        if not args.model:
            print("rotor-id evaluate: error: give --env ID (or --model PATH, whose env is used)", file=sys.stderr)
            return 2
        env_id = json.loads((_model_folder(args.model[0]) / "run.json").read_text())["env"]
        load_model(args.model[0])  # a clear error for a folder that is not a saved model
    seed0 = EVAL_SEED0 if args.seed is None else args.seed
    result = evaluate(env_id, args.episodes, progress=sys.stderr.isatty() and not args.json, models=args.model,
                      baselines=args.baselines, seed0=seed0)
    if args.json:
        print(json.dumps(result))
    else:
        print(f"{env_id}: {args.episodes} held-out rotors (seeds {seed0}-{seed0 + args.episodes - 1}); "
              "mean ± half-width of the 95 % interval (Student t) over the episodes\n")
        print(format_table(result))
    return 0


def _model_folder(path: str):
    from pathlib import Path

    p = Path(path)
    return p.parent if p.suffix == ".zip" else p


def add_evaluate_parser(sub) -> None:
    p = sub.add_parser("evaluate", help="compare agents (baselines, saved models) on held-out randomised rotors")
    p.add_argument("--env", choices=ENV_IDS, help="the environment (default: the --model's)")
    p.add_argument("--model", action="append", metavar="PATH",
                   help="a model saved by 'rotor-id train' (its --out folder or model.zip), evaluated beside the "
                        "baselines (repeatable)")
    p.add_argument("--baselines", action=argparse.BooleanOptionalAction, default=True,
                   help="evaluate the baselines and the committed policies too (default on)")
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--seed", type=int, default=None, metavar="SEED0",
                   help="the rotors are drawn with seeds SEED0, SEED0+1, ... (default 50000, never used in training)")
    p.add_argument("--json", action="store_true",
                   help="print {env, episodes, seeds, agents: {name: means}, statistics: {name: {metric: {mean, std, "
                        "ci95}}}, versions} as JSON")
    p.set_defaults(func=_cmd_evaluate)
