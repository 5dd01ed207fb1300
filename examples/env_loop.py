"""The plain Gymnasium loop: run a rotor up twice, fast and slow, and compare.

    python examples/env_loop.py

Crossing the critical speed quickly keeps the resonance peak low; a slow run-up lets
the vibration build up.  Every step also hands out the step's sensor samples
(``info["measurements"]``, columns ``rotor_env.measurements.COLUMNS``).
"""

import gymnasium as gym
import numpy as np

import rotor_env  # noqa: F401  (registers the environment ids)

env = gym.make("rotor_env/RotorRunUp-v0")

for name, command in (("fast run-up", 1.0), ("slow run-up", -0.6)):  # -0.6 -> phi_ddot = 0.01
    obs, info = env.reset(seed=42)  # the same rotor for both policies
    total_reward, n_samples = 0.0, 0
    while True:
        action = np.array([command], dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        total_reward += reward
        n_samples += len(info["measurements"])
        if terminated or truncated:
            break
    print(
        f"{name}: return {total_reward:8.1f}   peak |theta| {info['peak_amplitude']:.3f}   "
        f"time to speed {info['time_to_speed']}   end: {info['reason']} at t = "
        f"{info['measurements'][-1, 0]:.1f}   ({n_samples} sensor samples)"
    )

p = info["params"]
print(f"rotor: effects {', '.join(p.effects)}; critical speed "
      f"{np.sqrt(p.k / (1 - p.ip)):.2f}")
env.close()
