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

from .baselines import ConstantRamp, Fastest, ModelBasedBalancer, ModelBasedRunUp, NoControl
from .episodes import run_episode, statistics, versions
from .oracle import RunUpOracle
from .training import TrainedPolicy, make_env

__all__ = ["EVAL_SEED0", "METRICS", "default_agents", "evaluate", "load_model", "policy_folder", "run_episode",
           "statistics", "versions"]

EVAL_SEED0 = 50_000
RUN_UP = "rotor_env/RotorRunUp-v0"
BALANCING = "rotor_env/RotorBalancing-v0"
_SHORT = {RUN_UP: "runup", BALANCING: "balancing"}


def policy_folder(env_id: str, identifier: bool) -> Path:
    """Where the committed trained policy of ``env_id`` lives (inside the package)."""
    name = f"{_SHORT[env_id]}_{'identifier' if identifier else 'plain'}"
    return Path(str(resources.files("agents").joinpath("policies", name)))


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


METRICS = ("peak_amplitude", "rms_amplitude", "time_to_speed", "effort", "rub_rate", "return")

#: Each metric's unit (the environments are dimensionless: docs/PHYSICS.md section 1.4, time
#: ``t' = t sqrt(k/I_t)``, moments in units of ``k``); in the table's header and the JSON.
METRIC_UNITS = {
    "peak_amplitude": "rad",  # peak |theta| over the episode (disk inclination)
    "rms_amplitude": "rad",
    "time_to_speed": "t'",  # model time units
    "effort": "u^2 t'",  # integral of the squared drive command (RunUp: phi'', Balancing: M_x^2 + M_y^2)
    "rub_rate": "fraction",  # of the episodes ended by a rub
    "return": "reward",
}
UNITS_NOTE = ("units: rad = disk inclination; t' = model time (t sqrt(k/I_t)); u^2 t' = integral of the squared "
              "drive command (RunUp: phi'', Balancing: the correction moments M_x, M_y in units of k) over model "
              "time; rub_rate = fraction of the episodes ended by a rub")


def load_model(path: str | Path, env_id: str | None = None, name: str | None = None) -> tuple[str, object, bool]:
    """A model saved by ``rotor-id train`` (its folder, or the ``model.zip`` in it) as an
    agent: ``(name, policy, sees the identifier)``; refuses one trained on another env."""
    import json

    folder = Path(path)
    if folder.is_file() and folder.suffix == ".zip":
        folder = folder.parent
    meta_path = folder / "run.json"
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    rllib = meta.get("backend") == "rllib"
    weights = folder / ("policy.npz" if rllib else "model.zip")
    if not meta or not weights.is_file() or not (folder / "vecnormalize.npz").is_file():
        raise ValueError(f"--model {path}: expected a folder written by 'rotor-id train' (run.json, vecnormalize.npz "
                         "and model.zip, or policy.npz for --backend rllib)")
    if env_id is not None and meta.get("env") != env_id:
        raise ValueError(f"--model {path} was trained on {meta.get('env')}, not {env_id}")
    name = name or f"model:{folder.resolve().name}"
    if rllib:
        from .rllib import load_rllib_policy

        return name, load_rllib_policy(folder, name), bool(meta.get("identifier", True))
    return name, TrainedPolicy.load(folder, name), bool(meta.get("identifier", True))


def evaluate(env_id: str, episodes: int = 50, agents: dict | None = None, progress: bool = False,
             models: list | None = None, baselines: bool = True, seed0: int = EVAL_SEED0) -> dict:
    """Every agent over ``episodes`` held-out rotors (seeds ``seed0 + i``).

    Returns ``{"env", "episodes", "seeds", "agents": {name: {metric: mean}},
    "statistics": {name: {metric: {"mean", "std", "ci95", "n"}}}, "versions"}``.
    ``models``: folders of models saved by ``rotor-id train``, evaluated beside the
    baselines (``baselines=False``: alone).
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    loaded = [load_model(m, env_id) for m in (models or [])]
    env = make_env(env_id, identifier=True)
    plain_dim = env.unwrapped.observation_space.shape[0]
    if agents is None:
        agents = default_agents(env_id, env) if baselines else {}
    else:
        agents = dict(agents)
    for name, policy, ident in loaded:
        while name in agents:
            name += "'"
        agents[name] = (policy, ident)
    if not agents:
        raise ValueError("nothing to evaluate: give --model or keep the baselines")
    results, stats = {}, {}
    from rotor_env.progress import bar

    pbar = bar(f"evaluating {len(agents)} agents", episodes * len(agents), "episodes", enabled=progress)
    for name, (agent, sees_identifier) in agents.items():
        rows = []
        for i in range(episodes):
            rows.append(run_episode(env, agent, seed0 + i, None if sees_identifier else plain_dim))
            if pbar is not None:
                pbar.update(1)
        per = {k: [float(r["rub"] if k == "rub_rate" else r[k]) for r in rows] for k in METRICS}
        stats[name] = {k: statistics(v) for k, v in per.items()}
        results[name] = {k: stats[name][k]["mean"] for k in METRICS}
    if pbar is not None:
        pbar.close()
    env.close()
    return {"env": env_id, "episodes": episodes, "seeds": [seed0 + i for i in range(episodes)],
            "agents": results, "statistics": stats,
            "interval": "95 % Student-t interval of the mean over the episodes", "units": dict(METRIC_UNITS),
            "versions": versions()}


def format_table(result: dict) -> str:
    """Means; with the statistics, ``mean ± half-width of the 95 % interval``."""
    keys = METRICS
    stats = result.get("statistics", {})
    lines = ["| agent | " + " | ".join(f"{k} ({METRIC_UNITS[k]})" for k in keys) + " |",
             "|---" * (len(keys) + 1) + "|"]

    def cell(name, k, v):
        if not math.isfinite(v):
            return "—"
        ci = stats.get(name, {}).get(k, {}).get("ci95")
        return f"{v:.4g} ± {(ci[1] - ci[0]) / 2:.2g}" if ci else f"{v:.4g}"

    for name, m in result["agents"].items():
        lines.append(f"| {name} | " + " | ".join(cell(name, k, m[k]) for k in keys) + " |")
    return "\n".join([*lines, "", UNITS_NOTE])
