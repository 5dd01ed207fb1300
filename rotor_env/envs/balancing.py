"""``rotor_env/RotorBalancing-v0``: active balancing during a prescribed run-up."""

from __future__ import annotations

from collections.abc import Mapping

from .base import RotorEnvBase, check_positive
from .core import MODE_BALANCING

__all__ = ["RotorBalancingEnv"]


class RotorBalancingEnv(RotorEnvBase):
    r"""Cancel the vibration of a rotor run up through its critical speed with two moments.

    ## Description

    The rotor of ``docs/PHYSICS.md`` (a disk on a flexible shaft; dimensionless units with the
    nominal natural frequency ``sqrt(k) = 1``) is run up from rest with the prescribed
    constant spin acceleration ``spin_rate`` (default 0.01, the paper's run-up): by
    ``t_max = 250`` it reaches the speed 2.5, well past the critical speed
    ``sqrt(k / (1 - ip))`` (0.84–1.70 for the randomised rotors).  An actuator (a magnetic
    bearing or an active balancing head) applies two bounded correction moments ``M_x,
    M_y`` to the disk; they add to the right-hand sides of the equations of motion.  The
    agent must cancel the unbalance response (a synchronous forcing at the spin angle
    ``phi + beta``: a model-based balancer needs ``cos phi, sin phi`` and the speed, which
    are observed) and damp the self-excited whirl that dry friction sustains above the
    critical speed — on a rotor drawn anew each episode.  Every step also hands out all
    sensor samples recorded during the step (``info["measurements"]``) so an online
    identifier can run alongside.

    With zero action the dynamics equal :func:`rotor_env.simulator.simulate` with
    ``run_up=spin_rate``.

    ## Action Space

    ``Box(-1, 1, (2,), float32)``; out-of-range values (also ``+-inf``) are clipped to
    ``[-1, 1]``; ``NaN`` or a wrongly shaped action raises ``ValueError``.

    | Num | Action  | Mapping                                   |
    |-----|---------|-------------------------------------------|
    | 0   | `u_x`   | moment `M_x = m_max * u_x` (x equation)   |
    | 1   | `u_y`   | moment `M_y = m_max * u_y` (y equation)   |

    The moments are constant during a step (zero-order hold).

    ## Observation Space

    ``Box(low, high, (10,), float32)``, every entry scaled and clipped to its bounds:

    | Num | Observation                          | Scale                      | Min | Max |
    |-----|--------------------------------------|----------------------------|-----|-----|
    | 0   | spin speed `phi_dot`                 | `/ (spin_rate * t_max)`    | 0   | 1   |
    | 1   | spin acceleration `phi_ddot`         | `/ spin_rate` (always 1)   | 0   | 1   |
    | 2   | `cos(phi)` (spin angle)              | —                          | -1  | 1   |
    | 3   | `sin(phi)`                           | —                          | -1  | 1   |
    | 4   | inclination `theta_x`                | `/ clearance`              | -10 | 10  |
    | 5   | inclination `theta_y`                | `/ clearance`              | -10 | 10  |
    | 6   | rate `theta_x_dot`                   | `/ clearance`              | -10 | 10  |
    | 7   | rate `theta_y_dot`                   | `/ clearance`              | -10 | 10  |
    | 8   | amplitude `sqrt(theta_x^2+theta_y^2)`| `/ clearance`              | 0   | 10  |
    | 9   | time `t`                             | `/ t_max`                  | 0   | 1   |

    ## Rewards

    Per step, with ``A_j`` the amplitude at the step's sensor samples::

        r = -( w_vibration * min(mean_j (A_j / clearance)^2, 1)
             + w_effort    * (u_x^2 + u_y^2) / 2 )
            - fail_penalty * [episode ends by rub or instability]

    ``fail_penalty`` defaults to ``max_steps * (w_vibration + w_effort)``, more than any
    episode can lose otherwise, so ending early never pays.

    ## Starting State

    ``t = 0``, ``phi = phi_dot = 0`` and the disk at rest.  The rotor is drawn from
    ``self.np_random`` in ``reset`` (``randomize=True``):

    | parameter           | distribution     | notes                                      |
    |---------------------|------------------|--------------------------------------------|
    | `k` (stiffness)     | U(0.64, 1.44)    | natural frequency `sqrt(k)` in [0.8, 1.2]  |
    | `ip` (inertia ratio)| U(0.1, 0.5)      | critical speed `sqrt(k/(1-ip)) <= 1.70`    |
    | `tau` (unbalance)   | U(0.01, 0.03)    | always present                             |
    | `beta` (its phase)  | U(-pi, pi)       |                                            |
    | `c` (viscous)       | U(0.02, 0.05)    | always present                             |
    | `D` (asymmetry)     | U(0.01, 0.05)    | present with probability 0.5               |
    | `h` (dry friction)  | U(0.002, 0.008)  | present with probability 0.5               |
    | `k30, k21, k12, k03`| U(0, 0.06) each  | present with probability 0.5 (together)    |

    ``randomize=False`` uses the paper's Table 1 rotor;
    ``reset(options={"params": RotorParams(...)})`` fixes the rotor for that episode.
    Equal seeds give equal episodes.

    ## Episode End

    * Termination, ``info["reason"] == "rub"``: the amplitude exceeds ``clearance`` at
      any sensor sample of the step.
    * Termination, ``info["reason"] == "unstable"``: the simulation diverged; the samples
      after the divergence are ``NaN``, the observation is the last finite state (clipped).
    * Truncation, ``info["reason"] == "time_limit"``: ``t`` reaches ``t_max``.

    ``info`` (also from ``reset``) holds ``"params"`` (the true :class:`RotorParams`),
    ``"ip"`` (its inertia ratio, which an identifier needs), ``"peak_amplitude"`` (max
    ``|theta|`` so far), ``"effort"`` (``integral (M_x^2 + M_y^2) dt`` so far),
    ``"reason"`` (``None`` while running) and, from ``step``, ``"control"`` (a new array
    ``(M_x, M_y)``: the moments applied during the step, known inputs an identifier
    subtracts) and ``"measurements"``: a new ``(n_samples, 10)`` float64 array of the
    step's sensor samples with the columns :data:`rotor_env.measurements.COLUMNS`
    (``phi_ddot`` is the spin acceleration; the moments are not among the columns).

    ## Arguments

    ```python
    import gymnasium as gym
    import rotor_env
    env = gym.make("rotor_env/RotorBalancing-v0", render_mode="rgb_array", m_max=0.1)
    envs = gym.make_vec("rotor_env/RotorBalancing-v0", num_envs=1024)  # numba-batched
    ```

    * ``render_mode``: ``None``, ``"rgb_array"`` or ``"human"``.
    * ``randomize=True``: draw the rotor per episode; ``False``: Table 1.
    * ``spin_rate=0.01``: prescribed spin acceleration from rest.
    * ``t_max=250.0``: episode length (truncation); final speed ``spin_rate * t_max``.
    * ``m_max=0.1``: largest correction moment (the unbalance moment at the critical
      speed is ``(1 - ip) tau phi_dot^2 = tau k``, 0.006–0.043; the friction limit ``h``
      is <= 0.008; at the final speed 2.5 it is ``(1 - ip) tau 6.25`` <= 0.17).
    * ``clearance=0.6``: rub limit of the amplitude.
    * ``step_dt=0.5`` (500 steps), ``sensor_dt=0.01`` (50 samples per step),
      ``max_substep=0.01`` (>= 10 RK4 sub-steps per step are required).
    * ``w_vibration=1.0, w_effort=0.1, fail_penalty=None``: reward weights.
    * ``return_measurements=True``: ``False`` leaves ``"measurements"`` out of ``info``
    * ``faults=None``: field faults drawn per episode with ``randomize=True``, effect ->
      probability (``{"shaft_bow": 0.3, "support_anisotropy": 0.3}``; ranges in
      :data:`rotor_env.envs.randomization.FAULT_RANGES`); ``info["params"].effects`` says
      which the rotor has.

    ## Version History

    * v0: initial version.
    """

    _act_dim = 2
    _mode = MODE_BALANCING
    _title = "RotorBalancing-v0"

    def __init__(
        self,
        render_mode: str | None = None,
        *,
        randomize: bool = True,
        spin_rate: float = 0.01,
        t_max: float = 250.0,
        m_max: float = 0.1,
        clearance: float = 0.6,
        step_dt: float = 0.5,
        sensor_dt: float = 0.01,
        max_substep: float = 0.01,
        w_vibration: float = 1.0,
        w_effort: float = 0.1,
        fail_penalty: float | None = None,
        return_measurements: bool = True,
        faults: Mapping[str, float] | None = None,
    ) -> None:
        self.spin_rate = check_positive("spin_rate", spin_rate)
        self.m_max = check_positive("m_max", m_max)
        t_max = check_positive("t_max", t_max)
        self._setup(
            render_mode=render_mode,
            randomize=randomize,
            clearance=clearance,
            t_max=t_max,
            step_dt=step_dt,
            sensor_dt=sensor_dt,
            max_substep=max_substep,
            w_vibration=w_vibration,
            w_time=0.0,
            w_effort=w_effort,
            fail_penalty=fail_penalty,
            speed_scale=self.spin_rate * t_max,
            phidd_scale=self.spin_rate,
            m_max=self.m_max,
            spin_rate=self.spin_rate,
            return_measurements=return_measurements,
            faults=faults,
        )
