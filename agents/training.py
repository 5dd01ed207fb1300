"""Training Stable-Baselines3 controllers on the rotor environments.

``rotor-id train --env ID --algo ppo|sac --steps N [--identifier/--no-identifier]``
builds ``n_envs`` environments (each in a ``Monitor``; with the identification
wrapper unless ``--no-identifier``), normalises observations and rewards
(``VecNormalize``, statistics saved beside the model), evaluates on held-out seeds
during training (``EvalCallback``), shows a progress bar, and saves ``model.zip``,
``vecnormalize.npz`` (JSON/npz, no pickle) and ``run.json`` (the exact command, seed
and hyper-parameters) in the output folder.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import gymnasium as gym
import numpy as np

import rotor_env  # noqa: F401 - registers the environments
from rotor_env import IdentificationWrapper

from .features import ModelFeatures, ModelFeatureWrapper
from .residual import Residual, ResidualActionWrapper

__all__ = ["ALGOS", "TrainedPolicy", "load_hyperparams", "make_env", "train"]

ALGOS = ("ppo", "sac")
#: seeds of the evaluation rotors during training (held out from the training seeds)
EVAL_SEED = 10_000


def load_hyperparams(env_id: str, algo: str, path: str | Path | None = None, residual: bool = False) -> dict:
    """The table of ``env_id`` and ``algo``; for a residual policy ``<algo>_residual`` where given."""
    import yaml

    text = Path(path).read_text() if path else resources.files("agents").joinpath("hyperparams.yml").read_text()
    table = yaml.safe_load(text)
    if env_id not in table:
        raise ValueError(f"no hyper-parameters for {env_id!r}; known: {', '.join(table)}")
    if algo not in table[env_id]:
        raise ValueError(f"no hyper-parameters for {algo!r} on {env_id}; known: {', '.join(table[env_id])}")
    if residual and f"{algo}_residual" in table[env_id]:
        return dict(table[env_id][f"{algo}_residual"])
    return dict(table[env_id][algo])


FEATURES = ("compact", "full", "none")


def make_env(env_id: str, identifier: bool, model_features: str = "none", residual: float = 0.0,
             **env_kwargs) -> gym.Env:
    """The env as an agent sees it: with the identification wrapper, and optionally the
    identified model as features (:mod:`agents.features`): ``"full"`` (the significant
    effects' coefficients and the critical-speed ratio), ``"compact"`` (the env
    observation and the critical-speed ratio only) or ``"none"`` (the raw wrapper).
    ``residual > 0`` (with the identifier): the agent's action is a correction of at most
    ``residual`` on the env's model-based baseline (:mod:`agents.residual`)."""
    if model_features not in FEATURES:
        raise ValueError(f"model_features must be one of {FEATURES}, got {model_features!r}")
    if not (np.isfinite(residual) and residual >= 0):
        raise ValueError(f"residual must be a scale >= 0 (0: no residual), got {residual!r}")
    if residual and not identifier:
        raise ValueError("a residual policy builds on the model-based baseline, which needs the identifier")
    env = gym.make(env_id, **env_kwargs)
    if identifier:
        env = IdentificationWrapper(env)
        if residual:
            env = ResidualActionWrapper(env, Residual.for_env(env, env_id, residual))
        if model_features != "none":
            env = ModelFeatureWrapper(env, compact=model_features == "compact")
    return env


VEC_ENVS = ("dummy", "numba")


def _vec_env(env_id: str, identifier: bool, n_envs: int, seed: int, model_features: str = "none",
             residual: float = 0.0, vec_env: str = "dummy"):
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    if vec_env == "numba":  # every sub-env in one compiled call (agents.vec_env)
        if identifier:
            raise ValueError("--vec-env numba steps the bare env: use it with --no-identifier")
        from .vec_env import make_numba_vec_env

        return make_numba_vec_env(env_id, n_envs, seed=seed)
    if vec_env != "dummy":
        raise ValueError(f"vec_env must be one of {VEC_ENVS}, got {vec_env!r}")

    def factory(i):
        def _make():
            env = make_env(env_id, identifier, model_features, residual)
            env = Monitor(env)
            env.reset(seed=seed + i)
            return env

        return _make

    venv = DummyVecEnv([factory(i) for i in range(n_envs)])
    venv.seed(seed)
    return venv


def save_vecnormalize(vn, path: Path) -> None:
    """VecNormalize statistics as ``.npz`` (no pickle)."""
    np.savez(
        path,
        obs_mean=vn.obs_rms.mean, obs_var=vn.obs_rms.var, obs_count=np.array(vn.obs_rms.count),
        ret_mean=np.array(vn.ret_rms.mean), ret_var=np.array(vn.ret_rms.var),
        ret_count=np.array(vn.ret_rms.count), clip_obs=np.array(vn.clip_obs),
        epsilon=np.array(vn.epsilon),
    )


@dataclass
class TrainedPolicy:
    """A trained SB3 model with its observation normalisation, as a ``predict`` policy."""

    model: object
    obs_mean: np.ndarray
    obs_var: np.ndarray
    clip_obs: float
    epsilon: float
    name: str = "sb3"
    features: ModelFeatures | None = None
    residual: Residual | None = None

    def reset(self) -> None:
        pass

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        return np.clip((obs - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon), -self.clip_obs, self.clip_obs)

    def predict(self, observation, state=None, episode_start=None, deterministic: bool = True):
        raw = np.asarray(observation, dtype=np.float32)
        obs = self.features(raw) if self.features is not None else raw  # trained on the model as features
        obs = self.normalize(obs).astype(np.float32)
        action, state = self.model.predict(obs, state=state, episode_start=episode_start,
                                           deterministic=deterministic)
        if self.residual is not None:  # the network learned a correction of the baseline
            action = self.residual(raw, action)
        return action, state

    @classmethod
    def load(cls, folder: str | Path, name: str = "sb3") -> TrainedPolicy:
        from stable_baselines3 import PPO, SAC

        folder = Path(folder)
        meta = json.loads((folder / "run.json").read_text())
        algo = {"ppo": PPO, "sac": SAC}[meta["algo"]]
        model = algo.load(folder / "model.zip", device="cpu")
        features = ModelFeatures.from_json(meta["features"]) if meta.get("features") else None
        residual = Residual.from_json(meta["residual"]) if meta.get("residual") else None
        with np.load(folder / "vecnormalize.npz", allow_pickle=False) as z:
            return cls(model, z["obs_mean"], z["obs_var"], float(z["clip_obs"]), float(z["epsilon"]), name,
                       features, residual)


def _has_tensorboard() -> bool:
    import importlib.util

    return importlib.util.find_spec("tensorboard") is not None


def progress_lines(total_steps: int, every_s: float = 10.0, stream=None, eval_callback=None):
    """An SB3 callback printing one progress line every ``every_s`` seconds (at the end of a
    rollout) and one at the end: what ``rotor-id train`` shows when not in a terminal."""
    import time

    from stable_baselines3.common.callbacks import BaseCallback

    from rotor_env.progress import active

    class ProgressLines(BaseCallback):
        def _on_training_start(self) -> None:
            self.t0 = self.last = time.perf_counter()
            self.start_steps = self.reported = self.num_timesteps
            self.command = active()  # under rotor-id: its lines (rotor_env/progress.py) carry the steps
            if self.command is not None:
                self.command.step("training", total_steps, "steps")

        def _report(self) -> None:
            self.command.advance(self.num_timesteps - self.reported)
            self.reported = self.num_timesteps

        def _on_rollout_start(self) -> None:
            # steps count as done once their rollout's network update is done too: the
            # rate (and the time left) then include the updates
            if self.command is not None:
                self._report()

        def _on_step(self) -> bool:
            if self.command is not None:
                r = getattr(eval_callback, "last_mean_reward", None)
                if r is not None and np.isfinite(r):
                    self.command.note = f"last evaluation: mean reward {r:.4g}"
            return True

        def _line(self, final: bool = False) -> None:
            done = self.num_timesteps - self.start_steps
            elapsed = time.perf_counter() - self.t0
            rate = done / elapsed if elapsed > 0 else 0.0
            left = f", ~{(total_steps - done) / rate:.0f} s left" if rate > 0 and not final else ""
            r = getattr(eval_callback, "last_mean_reward", None)
            evs = f", last eval mean reward {r:.4g}" if r is not None and np.isfinite(r) else ""
            word = "done" if final else "steps"
            print(f"rotor-id train: {done}/{total_steps} {word} ({100 * done / max(total_steps, 1):.0f} %), "
                  f"{elapsed:.0f} s, {rate:.0f} steps/s{left}{evs}", file=stream or sys.stderr, flush=True)

        def _on_rollout_end(self) -> None:
            if self.command is not None:
                return
            now = time.perf_counter()
            if now - self.last >= every_s and self.num_timesteps - self.start_steps < total_steps:
                self.last = now
                self._line()

        def _on_training_end(self) -> None:
            if self.command is None:
                self._line(final=True)
            else:
                self._report()

    return ProgressLines()


def train(
    env_id: str,
    algo: str = "ppo",
    steps: int = 100_000,
    *,
    identifier: bool = True,
    seed: int = 0,
    out: str | Path = "runs/policy",
    hyperparams: str | Path | None = None,
    eval_freq: int = 10_000,
    eval_episodes: int = 5,
    progress: bool | None = None,
    command: str | None = None,
    force: bool = False,
    model_features: str = "compact",
    residual: float = 0.0,
    log_every_s: float = 10.0,
    vec_env: str = "dummy",
) -> Path:
    """Train, evaluate during training, save the model and its normalisation statistics.

    Logs go to ``out/logs/``: ``progress.csv`` (SB3's logger: rollout, train and eval
    statistics) and TensorBoard event files when ``tensorboard`` is installed.  Without a
    progress bar (``progress`` false, or not in a terminal) a line every ``log_every_s``
    seconds tells the steps done, the rate, the time left and the last evaluation.

    ``model_features`` (with ``identifier``; see :func:`make_env`): the policy sees the
    identified model as features (:class:`agents.features.ModelFeatures`), recorded in
    ``run.json`` so that :class:`TrainedPolicy` applies the same map.  ``residual``
    (scale > 0, with ``identifier``): the network learns a correction of the env's
    model-based baseline (:mod:`agents.residual`), also recorded in ``run.json``.
    """
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import CallbackList, EvalCallback
    from stable_baselines3.common.logger import configure
    from stable_baselines3.common.vec_env import VecNormalize

    if algo not in ALGOS:
        raise ValueError(f"algo must be one of {ALGOS}, got {algo!r}")
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    from rotor_env.outputs import OutputFolder

    # new, empty, or a previous run's (its marker): --force replaces only that run's files
    folder = OutputFolder(out, force=force)
    out = folder.path
    folder.register(["model.zip", "vecnormalize.npz", "run.json", "logs/progress.csv", "eval/evaluations.npz"])
    before = folder.snapshot()
    hp = load_hyperparams(env_id, algo, hyperparams, residual=bool(residual))
    n_envs = int(hp.pop("n_envs", 1))
    policy = hp.pop("policy", "MlpPolicy")
    if model_features not in FEATURES:
        raise ValueError(f"model_features must be one of {FEATURES}, got {model_features!r}")
    model_features = model_features if identifier else "none"
    venv = VecNormalize(_vec_env(env_id, identifier, n_envs, seed, model_features, residual, vec_env),
                        norm_obs=True, norm_reward=True)
    # the eval env is built as the training env is (EvalCallback syncs the normalisation
    # statistics wrapper by wrapper: a VecMonitor on one side only fails); both kinds run
    # the same episodes step for step
    eval_env = VecNormalize(_vec_env(env_id, identifier, 1, EVAL_SEED + seed, model_features, residual, vec_env),
                            norm_obs=True, norm_reward=False, training=False)
    cls = {"ppo": PPO, "sac": SAC}[algo]
    model = cls(policy, venv, seed=seed, verbose=0, device="cpu", **hp)
    callback = EvalCallback(eval_env, n_eval_episodes=eval_episodes, eval_freq=max(1, eval_freq // n_envs),
                            deterministic=True, verbose=0, log_path=str(out / "eval"))
    # EvalCallback syncs the normalisation statistics from the training env
    if progress is None:
        progress = sys.stderr.isatty()
    formats = ["csv", "tensorboard"] if _has_tensorboard() else ["csv"]
    model.set_logger(configure(str(out / "logs"), formats))
    callbacks = CallbackList([callback] if progress else [callback, progress_lines(int(steps), log_every_s, eval_callback=callback)])
    model.learn(total_timesteps=int(steps), callback=callbacks, progress_bar=bool(progress))
    model.save(out / "model.zip")
    save_vecnormalize(venv, out / "vecnormalize.npz")
    run = {
        "env": env_id, "algo": algo, "steps": int(steps), "identifier": identifier, "seed": seed,
        "n_envs": n_envs, "policy": policy, "hyperparams": hp,
        "command": command or f"rotor-id train --env {env_id} --algo {algo} --steps {steps} "
        f"{'--identifier' if identifier else '--no-identifier'}{f' --model-features {model_features}' if identifier else ''}"
        f"{f' --residual {residual}' if residual else ''} --seed {seed} --out {out}",
        "eval_mean_reward": float(callback.last_mean_reward) if callback.last_mean_reward > -np.inf else None,
        "logs": {"folder": "logs", "formats": formats},
        "vec_env": vec_env,
        "features": venv.venv.envs[0].get_wrapper_attr("features").to_json() if model_features != "none" else None,
        "residual": venv.venv.envs[0].get_wrapper_attr("residual").to_json() if residual else None,
    }
    folder.write_text("run.json", json.dumps(run, indent=2))
    folder.adopt_new(before)  # the TensorBoard event files SB3 named itself
    venv.close()
    eval_env.close()
    return out
