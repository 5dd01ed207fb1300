"""Training PPO on the rotor environments with RLlib (Ray), beside the SB3 path.

``rotor-id train --backend rllib --env ID [--workers N] [--address ADDR]`` trains RLlib's
PPO (the new API stack: an ``RLModule`` and ``EnvRunner``\\ s) on the same environments
:func:`agents.training.make_env` builds for SB3 (identification wrapper, model features,
residual policy), with the same hyper-parameter table (``agents/hyperparams.yml``'s
``ppo`` entry, translated below), and saves a folder that ``rotor-id evaluate --model``
reads like an SB3 one:

* ``policy.npz`` — the RLModule's weights (numpy arrays; no pickle), rebuilt from the
  spaces and ``run.json``'s network description at load time;
* ``vecnormalize.npz`` — the observation normalisation RLlib's ``MeanStdFilter``
  connector learned, in the SB3 file's layout (``obs_var`` is ``(std + 1e-6)^2`` and
  ``epsilon`` 0, so that SB3's ``(x - mean) / sqrt(var + epsilon)`` is RLlib's
  ``(x - mean) / (std + 1e-6)``; clipped to +-10);
* ``run.json`` — ``backend: "rllib"``, the command, seed, hyper-parameters, versions;
* ``logs/progress.csv`` and TensorBoard event files (``tensorboardX``): one row per
  training iteration (env steps, episode return and length, losses, entropy, rate).

The environment is registered with Ray's registry under :func:`registered_name` so that
remote env runners (``--workers N``: processes, or a cluster's nodes with ``--address``)
build it there; each sub-env is seeded once from the run's seed, its worker and its
index (``seed + 1000 * worker + index``) and then draws a new rotor at every reset.
On one machine ``--workers 0`` (the default) samples in the driver process, which is
the fastest on a few cores (no inter-process traffic).

PPO's hyper-parameters from the SB3 table: ``n_envs`` -> envs per env runner,
``n_steps * n_envs`` -> the train batch, ``batch_size`` -> minibatch, ``n_epochs`` ->
epochs, ``gamma``, ``gae_lambda`` -> ``lambda_``, ``learning_rate`` -> ``lr``,
``ent_coef`` -> ``entropy_coeff``, ``clip_range`` -> ``clip_param``,
``policy_kwargs.net_arch`` -> ``fcnet_hiddens``.  Deterministic evaluation takes the
mean of RLlib's Gaussian action distribution, which acts in ``[-1, 1]`` and is mapped
to the action space's bounds as RLlib's ``normalize_actions`` does.
"""

from __future__ import annotations

import csv
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from .training import EVAL_SEED, FEATURES, TrainedPolicy, load_hyperparams, make_env

__all__ = ["RLModuleModel", "load_rllib_policy", "ppo_config", "registered_name", "train_rllib"]

#: RLlib's MeanStdFilter: (x - mean) / (std + 1e-6), clipped to +-10
_FILTER_CLIP = 10.0
_FILTER_EPS = 1e-6
#: seeds of sub-envs: seed + WORKER_STRIDE * worker index + vector index
WORKER_STRIDE = 1000


def registered_name(env_id: str) -> str:
    """The name the env is registered under in Ray's registry (workers build it by name)."""
    return "rotor_id:" + env_id


def _env_creator(env_config):
    """Build one sub-env for an RLlib env runner (``env_config`` is RLlib's EnvContext)."""
    import rotor_env  # noqa: F401 - registers the environments in this (worker) process

    env = make_env(env_config["env_id"], env_config["identifier"], env_config["model_features"],
                   env_config["residual"])
    worker = int(getattr(env_config, "worker_index", 0))
    index = int(getattr(env_config, "vector_index", 0))
    # RLlib seeds the vector env at its first reset when ``debugging(seed=)`` is set; this
    # makes every sub-env's rotor sequence distinct even where it does not
    env.reset(seed=int(env_config["seed"]) + WORKER_STRIDE * worker + index)
    return env


def _translate(hp: dict) -> tuple[dict, int, list[int]]:
    """SB3 PPO hyper-parameters -> (RLlib ``training()`` kwargs, envs per runner, hidden layers)."""
    n_envs = int(hp.pop("n_envs", 1))
    hp.pop("policy", None)
    net = list((hp.pop("policy_kwargs", None) or {}).get("net_arch", [64, 64]))
    if isinstance(net[0], dict):  # SB3's dict(pi=[...], vf=[...]): RLlib's default net is shared-size
        net = list(net[0].get("pi", [64, 64]))
    n_steps = int(hp.pop("n_steps", 2048))
    names = {"batch_size": "minibatch_size", "n_epochs": "num_epochs", "gamma": "gamma",
             "gae_lambda": "lambda_", "learning_rate": "lr", "ent_coef": "entropy_coeff",
             "clip_range": "clip_param", "vf_coef": "vf_loss_coeff", "max_grad_norm": "grad_clip"}
    training = {"train_batch_size_per_learner": n_steps * n_envs}
    unknown = [k for k in hp if k not in names]
    if unknown:
        raise ValueError(f"hyper-parameters {unknown} have no RLlib PPO equivalent (known: {sorted(names)})")
    for k, v in hp.items():
        training[names[k]] = float(v) if k != "batch_size" and k != "n_epochs" else int(v)
    return training, n_envs, net


def ppo_config(env_id: str, *, identifier: bool = True, model_features: str = "compact", residual: float = 0.0,
               seed: int = 0, workers: int = 0, hyperparams: str | Path | None = None,
               overrides: dict | None = None):
    """The RLlib ``PPOConfig`` of ``rotor-id train --backend rllib`` (returns ``(config, run info)``)."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.connectors.env_to_module.mean_std_filter import MeanStdFilter
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.tune.registry import register_env

    hp = load_hyperparams(env_id, "ppo", hyperparams, residual=bool(residual))
    hp.update(overrides or {})
    sb3_hp = dict(hp)
    training, n_envs, net = _translate(hp)
    register_env(registered_name(env_id), _env_creator)
    env_config = {"env_id": env_id, "identifier": identifier, "model_features": model_features,
                  "residual": float(residual), "seed": int(seed)}
    config = (
        PPOConfig()
        .environment(registered_name(env_id), env_config=env_config)
        .framework("torch")
        .env_runners(num_env_runners=int(workers), num_envs_per_env_runner=n_envs,
                     env_to_module_connector=lambda env, spaces=None, device=None: MeanStdFilter(),
                     num_cpus_per_env_runner=1)
        .learners(num_learners=0)
        .training(**training)
        .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=net, fcnet_activation="tanh"))
        .debugging(seed=int(seed), log_level="ERROR")
    )
    info = {"n_envs": n_envs, "hyperparams": sb3_hp, "rllib_training": training,
            "network": {"fcnet_hiddens": net, "fcnet_activation": "tanh"}}
    return config, info


def _filter_stats(algo) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance of the MeanStdFilter on the local env runner (merged from workers)."""
    from ray.rllib.connectors.env_to_module.mean_std_filter import MeanStdFilter
    from ray.rllib.utils.filter import RunningStat

    runner = algo.env_runner_group.local_env_runner
    if runner is None or not hasattr(runner, "_env_to_module"):
        raise RuntimeError("the local env runner holds no env-to-module connector")
    pieces = [c for c in runner._env_to_module.connectors if isinstance(c, MeanStdFilter)]
    if not pieces:
        raise RuntimeError("no MeanStdFilter in the env-to-module pipeline")
    state = pieces[0].get_state()[None]
    stat = RunningStat.from_state(state["running_stats"][0])
    # SB3's layout divides by sqrt(var + epsilon): with epsilon 0 and this "variance" it
    # divides by RLlib's std + 1e-6 exactly
    scale = np.asarray(stat.std, dtype=float) + _FILTER_EPS
    return np.asarray(stat.mean, dtype=float), scale**2


def _scalar_metrics(result: dict) -> dict:
    """The per-iteration row of ``progress.csv`` (flat scalars)."""
    from ray.rllib.utils.metrics import (
        ENV_RUNNER_RESULTS,
        EPISODE_LEN_MEAN,
        EPISODE_RETURN_MEAN,
        LEARNER_RESULTS,
        NUM_ENV_STEPS_SAMPLED_LIFETIME,
    )

    env = result.get(ENV_RUNNER_RESULTS, {})
    learner = result.get(LEARNER_RESULTS, {}).get("default_policy", {})
    row = {
        "iteration": result.get("training_iteration"),
        "env_steps": result.get(NUM_ENV_STEPS_SAMPLED_LIFETIME, env.get(NUM_ENV_STEPS_SAMPLED_LIFETIME)),
        "episode_return_mean": env.get(EPISODE_RETURN_MEAN),
        "episode_len_mean": env.get(EPISODE_LEN_MEAN),
        "num_episodes": env.get("num_episodes_lifetime"),
    }
    for k in ("policy_loss", "vf_loss", "entropy", "mean_kl_loss", "curr_kl_coeff"):
        if k in learner:
            row[k] = learner[k]
    out = {}
    for k, v in row.items():
        try:
            out[k] = float(v) if v is not None else math.nan
        except (TypeError, ValueError):
            out[k] = math.nan
    return out


def train_rllib(
    env_id: str,
    steps: int = 100_000,
    *,
    identifier: bool = True,
    seed: int = 0,
    out: str | Path = "runs/policy",
    hyperparams: str | Path | None = None,
    eval_episodes: int = 5,
    command: str | None = None,
    force: bool = False,
    model_features: str = "compact",
    residual: float = 0.0,
    workers: int = 0,
    address: str | None = None,
    overrides: dict | None = None,
    stream=None,
    after_training=None,
) -> Path:
    """Train RLlib's PPO until ``steps`` env steps are sampled; save the folder described in
    the module docstring; evaluate the deterministic policy on ``eval_episodes`` held-out
    rotors (seeds ``EVAL_SEED + seed + i``).  A line per iteration goes to ``stream``
    (stderr): steps, rate, time left, the iteration's mean episode return.
    ``after_training(algo)``, if given, is called with the trained ``Algorithm`` before it
    stops (to save RLlib's own checkpoint, say, or inspect it)."""
    import ray

    from .episodes import run_episode, statistics, versions

    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    if model_features not in FEATURES:
        raise ValueError(f"model_features must be one of {FEATURES}, got {model_features!r}")
    if workers < 0:
        raise ValueError(f"workers must be >= 0, got {workers}")
    from rotor_env.outputs import OutputFolder

    out = Path(out)
    OutputFolder.check(out, force=force)  # said before Ray starts
    model_features = model_features if identifier else "none"
    stream = stream or sys.stderr
    started_ray = not ray.is_initialized()
    if started_ray:
        ray.init(address=address, include_dashboard=False, log_to_driver=False,
                 configure_logging=False, num_cpus=None if address else max(1, workers + 1))
    try:
        config, info = ppo_config(env_id, identifier=identifier, model_features=model_features, residual=residual,
                                  seed=seed, workers=workers, hyperparams=hyperparams, overrides=overrides)
        # new, empty, or a previous run's (its marker): --force replaces only that run's files
        folder = OutputFolder(out, force=force)
        folder.register(["policy.npz", "vecnormalize.npz", "run.json", "logs/progress.csv"])
        before = folder.snapshot()
        algo = config.build_algo()
        rows = _train_loop(algo, int(steps), out / "logs", stream)
        obs_mean, obs_var = _filter_stats(algo)
        module = algo.get_module()
        state = module.get_state(inference_only=True)
        np.savez(out / "policy.npz", **{k: np.asarray(v) for k, v in state.items()})
        np.savez(out / "vecnormalize.npz", obs_mean=obs_mean, obs_var=obs_var, obs_count=np.array(rows[-1]["env_steps"]),
                 clip_obs=np.array(_FILTER_CLIP), epsilon=np.array(0.0))
        env_probe = make_env(env_id, identifier, model_features, residual)
        run = {
            "env": env_id, "algo": "ppo", "backend": "rllib", "steps": int(steps), "identifier": identifier,
            "seed": seed, "n_envs": info["n_envs"], "workers": workers, "hyperparams": info["hyperparams"],
            "rllib_training": info["rllib_training"], "network": info["network"],
            "model_features": model_features, "residual_scale": float(residual),
            "iterations": len(rows), "env_steps": int(rows[-1]["env_steps"]),
            "command": command or f"rotor-id train --backend rllib --env {env_id} --steps {steps} "
            f"{'--identifier' if identifier else '--no-identifier'}"
            f"{f' --model-features {model_features}' if identifier else ''}"
            f"{f' --residual {residual}' if residual else ''} --seed {seed} --workers {workers} --out {out}",
            "logs": {"folder": "logs", "formats": ["csv", "tensorboard"]},
            "features": env_probe.get_wrapper_attr("features").to_json() if model_features != "none" else None,
            "residual": env_probe.get_wrapper_attr("residual").to_json() if residual else None,
            "versions": versions(),
        }
        env_probe.close()
        if after_training is not None:
            after_training(algo)
        algo.stop()
    finally:
        if started_ray:
            ray.shutdown()
    folder.write_text("run.json", json.dumps(run, indent=2))
    folder.adopt_new(before)  # the TensorBoard event files
    if eval_episodes > 0:  # the saved policy, as evaluate --model will load it
        policy = load_rllib_policy(out)
        env_obs = make_env(env_id, identifier=True)  # evaluate sees the wrapper's layout
        plain = None if identifier else env_obs.unwrapped.observation_space.shape[0]
        returns = [run_episode(env_obs, policy, EVAL_SEED + seed + i, plain)["return"] for i in range(eval_episodes)]
        env_obs.close()
        run["eval"] = {"seeds": [EVAL_SEED + seed + i for i in range(eval_episodes)],
                       "return": statistics(returns)}
        run["eval_mean_reward"] = float(np.mean(returns))
        folder.write_text("run.json", json.dumps(run, indent=2))
    folder.adopt_new(before)  # the TensorBoard event files
    return out


def _train_loop(algo, steps: int, logs: Path, stream) -> list[dict]:
    from tensorboardX import SummaryWriter

    rows: list[dict] = []
    t0 = time.perf_counter()
    writer = SummaryWriter(str(logs))
    with open(logs / "progress.csv", "w", newline="") as fh:
        csv_writer = None
        done = 0
        while done < steps:
            result = algo.train()
            row = _scalar_metrics(result)
            row["time_s"] = time.perf_counter() - t0
            done = int(row["env_steps"]) if math.isfinite(row["env_steps"]) else done
            rows.append(row)
            if csv_writer is None:
                csv_writer = csv.DictWriter(fh, fieldnames=list(row))
                csv_writer.writeheader()
            csv_writer.writerow(row)
            fh.flush()
            for k, v in row.items():
                if k not in ("iteration", "env_steps") and math.isfinite(v):
                    writer.add_scalar(f"rllib/{k}", v, done)
            rate = done / row["time_s"] if row["time_s"] > 0 else 0.0
            left = f", ~{(steps - done) / rate:.0f} s left" if 0 < rate and done < steps else ""
            ret = row["episode_return_mean"]
            rs = f", mean episode return {ret:.4g}" if math.isfinite(ret) else ""
            print(f"rotor-id train (rllib): {min(done, steps)}/{steps} steps ({100 * min(done, steps) / steps:.0f} %), "
                  f"iteration {int(row['iteration'])}, {row['time_s']:.0f} s, {rate:.0f} steps/s{left}{rs}",
                  file=stream, flush=True)
    writer.close()
    return rows


class RLModuleModel:
    """An RLlib ``RLModule`` behind SB3's ``predict`` signature (what :class:`TrainedPolicy` calls)."""

    def __init__(self, module, action_space) -> None:
        self.module = module
        self.low = np.asarray(action_space.low, dtype=np.float64)
        self.high = np.asarray(action_space.high, dtype=np.float64)
        self.dist_cls = module.get_inference_action_dist_cls()

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        import torch

        obs = np.asarray(observation, dtype=np.float32)
        single = obs.ndim == 1
        batch = torch.from_numpy(obs[None] if single else obs)
        with torch.no_grad():
            logits = self.module.forward_inference({"obs": batch})["action_dist_inputs"]
            dist = self.dist_cls.from_logits(logits)
            a = (dist.to_deterministic() if deterministic else dist).sample().numpy().astype(np.float64)
        # normalize_actions: the network acts in [-1, 1], mapped onto the space's bounds
        a = self.low + (np.clip(a, -1.0, 1.0) + 1.0) * 0.5 * (self.high - self.low)
        a = a.astype(np.float32)
        return (a[0] if single else a), state


def load_rllib_policy(folder: str | Path, name: str = "rllib") -> TrainedPolicy:
    """A folder saved by :func:`train_rllib` as a ``predict`` policy (weights from ``policy.npz``)."""
    from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import DefaultPPOTorchRLModule
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from .features import ModelFeatures
    from .residual import Residual

    folder = Path(folder)
    meta = json.loads((folder / "run.json").read_text())
    if meta.get("backend") != "rllib":
        raise ValueError(f"{folder}: run.json is not an RLlib run (backend {meta.get('backend')!r})")
    feats = meta["features"]
    # the env as the network saw it in training: its spaces size the network
    env = make_env(meta["env"], meta["identifier"], meta["model_features"], float(meta["residual_scale"]))
    spec = RLModuleSpec(module_class=DefaultPPOTorchRLModule, observation_space=env.observation_space,
                        action_space=env.action_space, inference_only=True,
                        model_config=DefaultModelConfig(**meta["network"]))
    env.close()
    module = spec.build()
    with np.load(folder / "policy.npz", allow_pickle=False) as z:
        state = {k: z[k] for k in z.files}
    expected = set(module.state_dict())
    if not expected <= set(state):
        raise ValueError(f"{folder}/policy.npz: weights {sorted(expected - set(state))} missing (another network?)")
    module.set_state(state)
    module.eval()
    model = RLModuleModel(module, env.action_space)
    features = ModelFeatures.from_json(feats) if feats else None
    residual = Residual.from_json(meta["residual"]) if meta.get("residual") else None
    with np.load(folder / "vecnormalize.npz", allow_pickle=False) as z:
        return TrainedPolicy(model, z["obs_mean"], z["obs_var"], float(z["clip_obs"]), float(z["epsilon"]), name,
                             features, residual)
