"""One episode of an agent, and the statistics an evaluation reports over episodes.

Shared by the evaluation of every agent (:mod:`agents.evaluation`) and the evaluation
that closes an RLlib training run (:mod:`agents.rllib`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["run_episode", "statistics", "versions"]


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


def statistics(values) -> dict:
    """Mean, sample standard deviation and the 95 % Student-t interval of the mean
    (``std``/``ci95`` are None for a single episode)."""
    from scipy import stats

    x = np.asarray(values, dtype=float)
    n = len(x)
    mean = float(np.mean(x))
    if n < 2:
        return {"mean": mean, "std": None, "ci95": None, "n": n}
    std = float(np.std(x, ddof=1))
    half = float(stats.t.ppf(0.975, n - 1)) * std / math.sqrt(n)
    return {"mean": mean, "std": std, "ci95": [mean - half, mean + half], "n": n}


def versions() -> dict:
    """The versions an evaluation ran with (for its JSON)."""
    import platform
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for dist in ("rotor-id", "numpy", "numba", "gymnasium", "stable-baselines3", "torch", "ray", "tensorboardX"):
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            pass
    return out
