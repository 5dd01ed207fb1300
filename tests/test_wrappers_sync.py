"""VectorIdentificationWrapper on Gymnasium's own SyncVectorEnv (issue 11, item 9)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import rotor_env  # noqa: F401  (registers the ids)
from rotor_env.wrappers import IdentificationWrapper, VectorIdentificationWrapper

RUN_UP = "rotor_env/RotorRunUp-v0"


def test_sync_vector_env_where_every_sub_env_ends_together():
    # Identical short episodes end on the same step; SyncVectorEnv then resets every
    # sub-env on the next step and hands out only reset infos (no "measurements"): this
    # raised a raw KeyError.  Each identifier must follow a single wrapper that is reset
    # when its episode ended (next-step autoreset), observation for observation.
    n = 2
    vec = VectorIdentificationWrapper(
        gym.vector.SyncVectorEnv([lambda: gym.make(RUN_UP, t_max=1.0) for _ in range(n)]))
    singles = [IdentificationWrapper(gym.make(RUN_UP, t_max=1.0)) for _ in range(n)]
    obs, _ = vec.reset(seed=[3, 3])
    np.testing.assert_array_equal(obs, np.stack([w.reset(seed=3)[0] for w in singles]))
    action = np.ones((n, 1), dtype=np.float32)
    ended = np.zeros(n, dtype=bool)
    together = 0
    for _ in range(30):
        obs, _, term, trunc, _ = vec.step(action)
        expected = []
        for i, w in enumerate(singles):
            if ended[i]:
                expected.append(w.reset()[0])
                ended[i] = False
            else:
                o, _, te, tr, _ = w.step(action[i])
                expected.append(o)
                ended[i] = te or tr
        np.testing.assert_array_equal(obs, np.stack(expected))
        np.testing.assert_array_equal(term | trunc, ended)
        together += int(ended.all())
    assert together >= 2  # the case happened, more than once
