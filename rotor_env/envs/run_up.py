"""``rotor_env/RotorRunUp-v0``: schedule the spin acceleration through the critical speed."""

from __future__ import annotations

from collections.abc import Mapping

from .base import RotorEnvBase, check_positive
from .core import MODE_RUN_UP

__all__ = ["RotorRunUpEnv"]


class RotorRunUpEnv(RotorEnvBase):
    r"""Run a rotor up from rest to its operating speed, through the critical speed.

    ## Description

    A rigid disk on a flexible shaft (the Jeffcott-type rotor of Zhou & Shi 2004, see
    ``docs/PHYSICS.md``; dimensionless units in which the nominal natural frequency is
    ``sqrt(k) = 1``) starts at rest.  Its inclinations ``theta_x, theta_y`` are driven by
    the unbalance, which grows with the speed squared and resonates at the critical speed
    ``sqrt(k / (1 - ip))`` (0.84–1.70 for the randomised rotors).  The agent schedules the
    spin acceleration of the drive: crossing the critical speed fast keeps the resonance
    peak low, but costs drive effort.  Once the target speed is reached the speed is held.
    Each episode draws a new rotor (domain randomisation, below), including dry
    friction, shaft asymmetry and non-linear stiffness, so a policy must cope with a family
    of machines.  Every step also hands out all sensor samples recorded during the step
    (``info["measurements"]``) so an online identifier can run alongside.

    The dynamics are the simulator's (:func:`rotor_env.simulator.integrate`, RK4 with the
    switch-model dry friction): until the target speed is reached, a constant action
    reproduces :func:`rotor_env.simulator.simulate` with that run-up rate.

    ## Action Space

    ``Box(-1, 1, (1,), float32)``; out-of-range values (also ``+-inf``) are clipped to
    ``[-1, 1]``; ``NaN`` or a wrongly shaped action raises ``ValueError``.

    | Num | Action            | Mapping                                          |
    |-----|-------------------|--------------------------------------------------|
    | 0   | drive command `u` | spin acceleration `phi_ddot = a_max * (u + 1)/2` in `[0, a_max]` |

    The acceleration is constant during a step.  With a ``deadline`` (default) a command
    below the rate still needed to reach the target by the deadline,
    ``(target_speed - phi_dot) / (deadline - t)``, is raised to it: every schedule
    arrives in time, ``u = -1`` is the constant ramp ``target_speed / deadline``, and the
    agent decides where to spend acceleration beyond it.  The acceleration is reduced to
    ``(target_speed - phi_dot) / step_dt`` when it would overshoot the target, so the
    speed never exceeds ``target_speed`` (and stays there: then ``phi_ddot = 0``).

    ## Observation Space

    ``Box(low, high, (10,), float32)``, every entry scaled and clipped to its bounds:

    | Num | Observation                          | Scale             | Min | Max |
    |-----|--------------------------------------|-------------------|-----|-----|
    | 0   | spin speed `phi_dot`                 | `/ target_speed`  | 0   | 1   |
    | 1   | spin acceleration of the last step   | `/ a_max`         | 0   | 1   |
    | 2   | `cos(phi)` (spin angle)              | —                 | -1  | 1   |
    | 3   | `sin(phi)`                           | —                 | -1  | 1   |
    | 4   | inclination `theta_x`                | `/ clearance`     | -10 | 10  |
    | 5   | inclination `theta_y`                | `/ clearance`     | -10 | 10  |
    | 6   | rate `theta_x_dot`                   | `/ clearance`     | -10 | 10  |
    | 7   | rate `theta_y_dot`                   | `/ clearance`     | -10 | 10  |
    | 8   | amplitude `sqrt(theta_x^2+theta_y^2)`| `/ clearance`     | 0   | 10  |
    | 9   | time `t`                             | `/ t_max`         | 0   | 1   |

    (Rates are scaled like angles: the natural frequency is about 1.)

    ## Rewards

    The task (default): the drive must have the rotor at the target speed by
    ``deadline`` (200, when the paper's constant 0.01 run-up gets there — the drive
    enforces it, above); spend as little vibration and drive effort as possible on the
    way.  Per step, with ``A_j`` the amplitude at the step's sensor samples and ``a``
    the applied acceleration::

        r = -( w_vibration * min(mean_j (A_j / clearance)^2, 1)
             + w_effort    * (a / a_max)^2
             + w_time      * (1 - phi_dot / target_speed) * [deadline is None] )
            - fail_penalty * [episode ends by rub or instability]

    Each bracketed term lies in ``[0, 1]``.  Effort is cheapest at the constant rate
    (the floor), vibration lowest when the critical speed is crossed fast: the best
    schedule is slow–fast–slow around *this* rotor's critical speed, which is randomised
    (below) — what an identified model tells and a fixed schedule cannot know.  With
    ``deadline=None`` the drive has no floor and the time term rewards arriving early
    (a minimum-time run-up).  ``fail_penalty`` defaults to ``max_steps * (w_vibration +
    w_time + w_effort)``, more than any episode can lose otherwise, so ending early
    never pays.

    ## Starting State

    ``t = 0``, ``phi = phi_dot = 0`` and the disk at rest (all inclinations and rates 0).
    The rotor is drawn from ``self.np_random`` in ``reset`` (``randomize=True``):

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

    Absent effects are missing from ``info["params"].effects``.  ``randomize=False`` uses
    the paper's Table 1 rotor; ``reset(options={"params": RotorParams(...)})`` fixes the
    rotor for that episode (any subset of the physical effects; a ``Crack`` switches
    ``D`` at the sensor sample nearest to its time).  Equal seeds give equal episodes.

    ## Episode End

    * Termination, ``info["reason"] == "rub"``: the amplitude exceeds ``clearance`` at
      any sensor sample of the step.
    * Termination, ``info["reason"] == "unstable"``: the simulation diverged (``|theta| >
      1e3``); the samples after the divergence are ``NaN`` in ``info["measurements"]``,
      the observation is the last finite state (clipped).
    * Truncation, ``info["reason"] == "time_limit"``: ``t`` reaches ``t_max``.

    ``info`` (also from ``reset``) holds ``"params"`` (the true :class:`RotorParams`),
    ``"ip"`` (its inertia ratio, which an identifier needs), ``"peak_amplitude"`` (max
    ``|theta|`` so far), ``"effort"`` (``integral phi_ddot^2 dt`` so far),
    ``"time_to_speed"`` (``t`` when the target speed was reached, ``None`` before),
    ``"reason"`` (``None`` while running) and, from ``step``, ``"measurements"``: a new
    ``(n_samples, 10)`` float64 array of the step's sensor samples, columns
    :data:`rotor_env.measurements.COLUMNS` (``t, phi, phi_dot, phi_ddot, theta_x,
    theta_y, theta_x_dot, theta_y_dot, theta_x_ddot, theta_y_ddot``), sampled every
    ``sensor_dt`` (the last row is the end of the step).

    ## Arguments

    ```python
    import gymnasium as gym
    import rotor_env
    env = gym.make("rotor_env/RotorRunUp-v0", render_mode="rgb_array", target_speed=2.0)
    envs = gym.make_vec("rotor_env/RotorRunUp-v0", num_envs=1024)  # numba-batched
    ```

    * ``render_mode``: ``None``, ``"rgb_array"`` (orbit and amplitude-vs-speed picture as
      an ``(H, W, 3)`` uint8 array) or ``"human"`` (a matplotlib window).
    * ``randomize=True``: draw the rotor per episode (table above); ``False``: Table 1.
    * ``target_speed=2.0``: operating speed (above every critical speed of the table).
    * ``a_max=0.05``: largest spin acceleration (0 → 2.0 in 40 time units).
    * ``clearance=0.6``: rub limit of the amplitude.
    * ``t_max=300.0``: time limit.
    * ``step_dt=0.5``: decision interval (600 steps at most by default).
    * ``sensor_dt=0.01``: sensor sample interval (50 samples per step).
    * ``max_substep=0.01``: largest RK4 sub-step; a step has ``>= 10`` sub-steps
      (``ValueError`` otherwise).  Defaults: 50 sub-steps per step.
    * ``deadline=200.0``: time by which the drive reaches the target speed (at least
      ``target_speed / a_max``); ``None``: no deadline, minimum-time reward.
    * ``w_vibration=1.0, w_time=1.0, w_effort=0.1, fail_penalty=None``: reward weights.
    * ``return_measurements=True``: ``False`` leaves ``"measurements"`` out of ``info``
    * ``faults=None``: field faults drawn per episode with ``randomize=True``, effect ->
      probability (``{"shaft_bow": 0.3, "support_anisotropy": 0.3}``; ranges in
      :data:`rotor_env.envs.randomization.FAULT_RANGES`); ``info["params"].effects`` says
      which the rotor has
      (a little faster, for pure RL training).

    ## Version History

    * v0: initial version; before the first release the drive got its deadline (and the
      time term went to ``deadline=None``), so that the run-up has a schedule worth
      identifying.
    """

    _mode = MODE_RUN_UP
    _act_dim = 1
    _title = "RotorRunUp-v0"

    def __init__(
        self,
        render_mode: str | None = None,
        *,
        randomize: bool = True,
        target_speed: float = 2.0,
        a_max: float = 0.05,
        clearance: float = 0.6,
        t_max: float = 300.0,
        step_dt: float = 0.5,
        sensor_dt: float = 0.01,
        max_substep: float = 0.01,
        w_vibration: float = 1.0,
        w_time: float = 1.0,
        w_effort: float = 0.1,
        deadline: float | None = 200.0,
        fail_penalty: float | None = None,
        return_measurements: bool = True,
        faults: Mapping[str, float] | None = None,
    ) -> None:
        self.target_speed = check_positive("target_speed", target_speed)
        self.a_max = check_positive("a_max", a_max)
        if deadline is not None and not (deadline >= self.target_speed / self.a_max):
            raise ValueError(
                f"deadline must be None or >= target_speed / a_max = {self.target_speed / self.a_max:g} "
                f"(the fastest run-up), got {deadline!r}"
            )
        self.deadline = None if deadline is None else float(deadline)
        self._setup(
            render_mode=render_mode,
            randomize=randomize,
            clearance=clearance,
            t_max=t_max,
            step_dt=step_dt,
            sensor_dt=sensor_dt,
            max_substep=max_substep,
            w_vibration=w_vibration,
            w_time=w_time,
            w_effort=w_effort,
            fail_penalty=fail_penalty,
            speed_scale=self.target_speed,
            phidd_scale=self.a_max,
            target_speed=self.target_speed,
            a_max=self.a_max,
            deadline=-1.0 if self.deadline is None else self.deadline,
            return_measurements=return_measurements,
            faults=faults,
        )
