"""Evaluating every agent on the same held-out randomised rotors.

Each agent runs ``episodes`` episodes on rotors drawn with the fixed seeds
``EVAL_SEED0 + i`` (never used in training).  All agents see the identification
wrapper's observation layout; agents trained without it (``sb3_plain``) get the
bare environment observation (its first part).  Metrics per agent (means over the
episodes): peak amplitude, RMS amplitude (over the sensor samples of the episode),
time to speed (run-up; ``t_max`` when never reached), effort (the env's drive or
control effort integral), rub rate and return.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import numpy as np

from .baselines import ConstantRamp, Fastest, ModelBasedBalancer, ModelBasedRunUp, NoControl
from .oracle import RunUpOracle
from .training import TrainedPolicy, make_env

__all__ = ["EVAL_SEED0", "default_agents", "evaluate", "policy_folder", "run_episode"]

EVAL_SEED0 = 50_000
RUN_UP = "rotor_env/RotorRunUp-v0"
BALANCING = "rotor_env/RotorBalancing-v0"
_SHORT = {RUN_UP: "runup", BALANCING: "balancing"}


def policy_folder(env_id: str, identifier: bool) -> Path:
    """Where the committed trained policy of ``env_id`` lives (inside the package)."""
    name = f"{_SHORT[env_id]}_{'identifier' if identifier else 'plain'}"
    return Path(str(resources.files("agents").joinpath("policies", name)))


def run_episode(env, agent, seed: int, observe_plain: int | None = None) -> dict:
    """One episode; ``observe_plain`` cuts the observation to the bare env's part."""
    obs, info = env.reset(seed=seed)
    if hasattr(agent, "fit") and hasattr(agent, "plan"):
        agent.fit(info["params"])  # the oracle knows the true rotor
    agent.reset()
    total, amps, done, info_last = 0.0, [], False, info
    while not done:
        o = obs[:observe_plain] if observe_plain is not None else obs
        action, _ = agent.predict(o, deterministic=True)
        obs, reward, terminated, truncated, info_last = env.step(action)
        total += float(reward)
        m = info_last["measurements"]
        amp = np.hypot(m[:, 4], m[:, 5])
        amps.append(amp[np.isfinite(amp)])
        done = terminated or truncated
    amps = np.concatenate(amps) if amps else np.zeros(1)
    u = env.unwrapped
    tts = info_last.get("time_to_speed")
    return {
        "peak_amplitude": float(info_last["peak_amplitude"]),
        "rms_amplitude": float(np.sqrt(np.mean(amps**2))),
        "time_to_speed": float(tts) if tts is not None else float(u.t_max),
        "effort": float(info_last["effort"]),
        "rub": info_last.get("reason") == "rub",
        "return": total,
    }


def default_agents(env_id: str, env, with_sb3: bool = True) -> dict[str, tuple[object, bool]]:
    """name -> (agent, sees the identifier features)."""
    u = env.unwrapped
    if env_id == RUN_UP:
        agents: dict[str, tuple[object, bool]] = {
            "constant_ramp": (ConstantRamp(u.a_max, 0.01), False),
            "fastest": (Fastest(), False),
            "model_based": (ModelBasedRunUp.for_env(env), True),
            "oracle": (RunUpOracle.for_env(env), False),
        }
    elif env_id == BALANCING:
        agents = {
            "no_control": (NoControl(), False),
            "model_based": (ModelBasedBalancer.for_env(env), True),
        }
    else:
        raise ValueError(f"unknown env {env_id!r}; known: {RUN_UP}, {BALANCING}")
    if with_sb3:
        for ident in (True, False):
            folder = policy_folder(env_id, ident)
            name = "sb3_identifier" if ident else "sb3_plain"
            if (folder / "model.zip").exists():
                agents[name] = (TrainedPolicy.load(folder, name), ident)
    return agents


def evaluate(env_id: str, episodes: int = 50, agents: dict | None = None, progress: bool = False) -> dict:
    """``{"agents": {name: metrics}}`` over ``episodes`` held-out rotors."""
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    env = make_env(env_id, identifier=True)
    plain_dim = env.unwrapped.observation_space.shape[0]
    agents = default_agents(env_id, env) if agents is None else agents
    results = {}
    pbar = None
    if progress:
        from tqdm.auto import tqdm

        pbar = tqdm(total=episodes * len(agents), desc="evaluating", unit="episode", leave=False)
    for name, (agent, sees_identifier) in agents.items():
        rows = []
        for i in range(episodes):
            rows.append(run_episode(env, agent, EVAL_SEED0 + i, None if sees_identifier else plain_dim))
            if pbar is not None:
                pbar.update(1)
        results[name] = {
            "peak_amplitude": float(np.mean([r["peak_amplitude"] for r in rows])),
            "rms_amplitude": float(np.mean([r["rms_amplitude"] for r in rows])),
            "time_to_speed": float(np.mean([r["time_to_speed"] for r in rows])),
            "effort": float(np.mean([r["effort"] for r in rows])),
            "rub_rate": float(np.mean([r["rub"] for r in rows])),
            "return": float(np.mean([r["return"] for r in rows])),
        }
    if pbar is not None:
        pbar.close()
    env.close()
    return {"env": env_id, "episodes": episodes, "agents": results}


def format_table(result: dict) -> str:
    keys = ("peak_amplitude", "rms_amplitude", "time_to_speed", "effort", "rub_rate", "return")
    lines = ["| agent | " + " | ".join(keys) + " |", "|---" * (len(keys) + 1) + "|"]
    for name, m in result["agents"].items():
        lines.append(f"| {name} | " + " | ".join(
            f"{m[k]:.4g}" if math.isfinite(m[k]) else "—" for k in keys) + " |")
    return "\n".join(lines)
