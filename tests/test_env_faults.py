"""The environments draw the field faults of the library (``faults=``), and the
identification wrapper's layout follows whatever effects it is given.

* the default draw is unchanged (no field fault, the same rotor for the same seed);
* with ``faults`` each fault appears at about its probability, its parameters inside
  :data:`FAULT_RANGES`, reproducibly from the seed, in the single and the vector env;
* a rotor with field faults, driven with zero control, is exactly the simulator's run
  (same declaration, same kernel);
* both env checkers pass with faults on; bad ``faults`` give clear errors;
* the wrapper with a field-fault effect lays out its coefficients and flag.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import rotor_env  # noqa: F401  (registers the environments)
from rotor_env.envs import RotorBalancingEnv, RotorRunUpEnv
from rotor_env.envs.randomization import FAULT_RANGES, sample_params
from rotor_env.params import RotorParams
from rotor_env.simulator import simulate
from rotor_env.wrappers import WRAPPER_EFFECTS, IdentificationWrapper

FAULTS = {"shaft_bow": 0.5, "support_anisotropy": 0.5, "misalignment": 0.3, "cross_coupled_stiffness": 0.3,
          "breathing_crack": 0.2, "rub": 0.3}


def test_default_draw_is_unchanged():
    for seed in range(20):
        a = sample_params(np.random.default_rng(seed))
        b = sample_params(np.random.default_rng(seed), None)
        assert a == b
        assert not set(a.effects) & set(FAULT_RANGES)


def test_faults_drawn_at_their_rates_inside_their_ranges():
    n = 400
    rotors = [sample_params(np.random.default_rng(s), FAULTS) for s in range(n)]
    for fault, p in FAULTS.items():
        share = np.mean([fault in r.effects for r in rotors])
        assert abs(share - p) < 4 * np.sqrt(p * (1 - p) / n), (fault, share)
        for r in rotors:
            if fault in r.effects:
                for rng in FAULT_RANGES[fault]:
                    assert rng.low <= r.values[rng.name] <= rng.high
    # reproducible from the seed; the healthy part is the same draw as without faults
    again = sample_params(np.random.default_rng(7), FAULTS)
    assert again == rotors[7]
    plain = sample_params(np.random.default_rng(7))
    assert {k: plain.values[k] for k in ("tau", "beta", "c", "k")} == {k: again.values[k] for k in ("tau", "beta", "c", "k")}


def _zero_control_and_simulated(params: RotorParams, fault: str) -> tuple[np.ndarray, np.ndarray]:
    """The balancing env's samples under zero control, and the simulator's run of the same rotor."""
    env = RotorBalancingEnv(randomize=False, t_max=60.0, faults={fault: 1.0})
    env.reset(seed=0, options={"params": params})
    chunks = []
    while True:
        _, _, te, tr, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        chunks.append(info["measurements"])
        if te or tr:
            break
    return np.concatenate(chunks), simulate(params, t_end=60.0, dt=0.01, run_up=0.01).data[1:]


@pytest.mark.parametrize("fault", list(FAULT_RANGES))
def test_zero_control_equals_the_simulator(fault):
    values = {r.name: 0.5 * (r.low + r.high) + 0.1 * (r.high - r.low) for r in FAULT_RANGES[fault]}
    params = RotorParams(effects=(*RotorParams().effects, fault), values=values)
    got, ref = _zero_control_and_simulated(params, fault)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-8)


def test_rub_in_contact_equals_the_simulator():
    """A rub whose clearance the orbit crosses (the contact on, its clearance passed to the
    env's kernel in the coefficient vector): still exactly the simulator's run."""
    values = {"h": 0.0, "rub_stiffness": 0.8, "rub_friction": 0.3, "rub_clearance": 0.004}  # no dry-friction stick
    params = RotorParams(effects=(*RotorParams().effects, "rub"), values=values)
    got, ref = _zero_control_and_simulated(params, "rub")
    amp = np.hypot(ref[:, 4], ref[:, 5])
    assert 0.1 < np.mean(amp > values["rub_clearance"]) < 0.9  # it touches, not all the time
    free = simulate(RotorParams(values={"h": 0.0}), t_end=60.0, dt=0.01, run_up=0.01).data[1:]
    assert np.abs(free[:, 4:6] - ref[:, 4:6]).max() > 1e-4  # and the contact changes the motion
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-8)


def test_a_rotor_with_a_fault_the_env_does_not_simulate_is_refused():
    params = RotorParams(effects=(*RotorParams().effects, "shaft_bow"), values={"bow": 0.005})
    env = RotorRunUpEnv(randomize=False)
    with pytest.raises(ValueError, match=r"unsupported effect.*shaft_bow.*faults="):
        env.reset(seed=0, options={"params": params})


@pytest.mark.parametrize("bad, match", [({"crack": 0.5}, "unknown field fault 'crack'"),
                                        ({"shaft_bow": 1.5}, r"probability of 'shaft_bow' must be in \[0, 1\]")])
def test_bad_faults(bad, match):
    with pytest.raises(ValueError, match=match):
        RotorRunUpEnv(faults=bad)


@pytest.mark.parametrize("env_id", ["rotor_env/RotorRunUp-v0", "rotor_env/RotorBalancing-v0"])
def test_checkers_with_faults(env_id):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make(env_id, faults=FAULTS).unwrapped)
        sb3_check(gym.make(env_id, faults=FAULTS))


def test_vector_env_draws_the_same_faulty_rotors():
    env_id = "rotor_env/RotorRunUp-v0"
    vec = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", faults=FAULTS)
    _, info = vec.reset(seed=11)
    singles = []
    for i in range(3):
        single = gym.make(env_id, faults=FAULTS)
        _, inf = single.reset(seed=11 + i)
        singles.append(inf["params"])
    assert [p.effects for p in info["params"]] == [p.effects for p in singles]


def test_wrapper_layout_follows_the_effects():
    effects = (*WRAPPER_EFFECTS, "support_anisotropy")
    env = IdentificationWrapper(RotorRunUpEnv(faults={"support_anisotropy": 1.0}), effects=effects)
    assert list(env.core.spec.groups) == list(effects)
    sl = env.layout["support_anisotropy.coefficients"]
    assert sl.stop - sl.start == 1 and "support_anisotropy.significant" in env.layout
    obs, _ = env.reset(seed=3)
    assert obs.shape == env.observation_space.shape
    for _ in range(30):
        obs, *_ = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs)
