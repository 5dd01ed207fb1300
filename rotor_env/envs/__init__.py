"""Gymnasium environments of the accelerating rotor.

* ``rotor_env/RotorRunUp-v0`` — :class:`RotorRunUpEnv`: schedule the spin acceleration
  through the critical speed (vibration vs time to speed vs drive effort).
* ``rotor_env/RotorBalancing-v0`` — :class:`RotorBalancingEnv`: two correction moments
  cancel the vibration during a prescribed run-up.

Both have numba-batched vector versions (:mod:`.vector`) used by
``gymnasium.make_vec(id, num_envs=N)``.  The ids are registered on ``import rotor_env``.
"""

from .balancing import RotorBalancingEnv
from .randomization import PRESENCE, RANGES, sample_params
from .run_up import RotorRunUpEnv
from .vector import RotorBalancingVectorEnv, RotorRunUpVectorEnv

__all__ = [
    "PRESENCE",
    "RANGES",
    "RotorBalancingEnv",
    "RotorBalancingVectorEnv",
    "RotorRunUpEnv",
    "RotorRunUpVectorEnv",
    "sample_params",
]
