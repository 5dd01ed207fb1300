"""The Gymnasium environments: API conformance, reproducibility, vector == single, edge cases."""

from __future__ import annotations

import copy
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

import rotor_env
from rotor_env.envs import RotorBalancingEnv, RotorRunUpEnv
from rotor_env.envs.base import MIN_SUBSTEPS
from rotor_env.measurements import COLUMNS
from rotor_env.params import Crack, RotorParams
from rotor_env.simulator import simulate

IDS = rotor_env.ENV_IDS
CLASSES = {"rotor_env/RotorRunUp-v0": RotorRunUpEnv, "rotor_env/RotorBalancing-v0": RotorBalancingEnv}
UNSTABLE = RotorParams().replace(D=5.0)  # shaft stiffness k - D < 0: diverges within a few steps


def _act(env, value):
    return np.full(env.action_space.shape, value, dtype=np.float32)


def _episode(env, seed, n_steps, rng_seed=0):
    """obs, rewards, flags and measurements of a random-action episode prefix."""
    rng = np.random.default_rng(rng_seed)
    obs, info = env.reset(seed=seed)
    out = [obs]
    for _ in range(n_steps):
        obs, r, te, tr, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        out += [obs, r, te, tr, info["measurements"]]
        if te or tr:
            break
    return out, info["params"]


# ----------------------------------------------------------------------------- API
@pytest.mark.parametrize("env_id", IDS)
def test_registered_with_vector_entry_point(env_id):
    spec = gym.spec(env_id)
    assert spec.entry_point and spec.vector_entry_point
    assert spec.max_episode_steps is None  # the env truncates itself (info["reason"])


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_check_env_no_warnings(env_id):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("env_id", IDS)
def test_sb3_check_env_no_warnings(env_id):
    from stable_baselines3.common.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make(env_id).unwrapped)
        check_env(gym.make(env_id))


@pytest.mark.parametrize("env_id", IDS)
def test_info_params_can_be_copied_and_pickled(env_id):
    env = gym.make(env_id)
    _, info = env.reset(seed=3)
    p = info["params"]
    assert copy.deepcopy(p) == p
    assert pickle.loads(pickle.dumps(p)) == p


# ------------------------------------------------------------------ reproducibility
@pytest.mark.parametrize("env_id", IDS)
def test_seed_reproduces_episode_exactly(env_id):
    a, pa = _episode(gym.make(env_id), seed=11, n_steps=40)
    b, pb = _episode(gym.make(env_id), seed=11, n_steps=40)
    assert pa == pb
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x, y)
    _, pc = _episode(gym.make(env_id), seed=12, n_steps=1)
    assert pc != pa


def test_randomization_covers_the_table():
    env = RotorRunUpEnv()
    ps = [env.reset(seed=s)[1]["params"] for s in range(200)]
    k = np.array([p.k for p in ps])
    assert 0.64 <= k.min() and k.max() <= 1.44 and k.max() - k.min() > 0.6
    beta = np.array([p.beta for p in ps])
    assert beta.min() < -2.5 and beta.max() > 2.5
    for effect in ("asymmetry", "structural_damping", "nonlinear_stiffness"):
        frac = np.mean([effect in p.effects for p in ps])
        assert 0.35 < frac < 0.65
    assert all(RotorRunUpEnv.critical_speed(p) < 2.0 for p in ps)


def test_randomize_false_and_options_params():
    env = RotorRunUpEnv(randomize=False)
    assert env.reset(seed=1)[1]["params"] == RotorParams()
    custom = RotorParams(values={"k": 1.2, "tau": 0.01}, effects=("stiffness", "unbalance"))
    _, info = env.reset(options={"params": custom})
    assert info["params"] == custom
    _, _, _, _, info = env.step(_act(env, 0.0))
    assert info["params"] == custom
    with pytest.raises(ValueError, match="unsupported effect"):
        env.reset(options={"params": RotorParams(effects=("stiffness", "unbalance_in_phase"))})


# -------------------------------------------------------------- physics agreement
def test_balancing_zero_action_equals_simulator():
    env = RotorBalancingEnv(randomize=False, t_max=160.0)
    env.reset(seed=0)
    chunks = []
    while True:
        _, _, te, tr, info = env.step(_act(env, 0.0))
        chunks.append(info["measurements"])
        if te or tr:
            break
    assert info["reason"] == "time_limit"
    got = np.concatenate(chunks)
    ref = simulate(RotorParams(), t_end=160.0, dt=0.01, run_up=0.01).data[1:]
    assert got.shape == ref.shape
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-8)
    assert info["peak_amplitude"] == pytest.approx(0.307, abs=1e-3)  # PHYSICS.md section 2


def test_crack_switches_D_like_the_simulator():
    p = RotorParams().replace(crack=Crack(time=100.004, D=0.3))
    env = RotorBalancingEnv(t_max=130.0, clearance=10.0)
    env.reset(options={"params": p})
    chunks = []
    for _ in range(260):
        _, _, te, tr, info = env.step(_act(env, 0.0))
        chunks.append(info["measurements"])
    ref = simulate(p, t_end=130.0).data[1:]
    no_crack = simulate(p.replace(crack=None), t_end=130.0).data[1:]
    got = np.concatenate(chunks)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-8)
    assert np.abs(got - no_crack).max() > 1e-3


def test_run_up_holds_target_speed_and_reports_time_to_speed():
    env = RotorRunUpEnv(randomize=False, a_max=0.05, target_speed=2.0)
    env.reset(seed=0)
    tts = []
    speed = []
    for _ in range(120):
        _, _, _, _, info = env.step(_act(env, 1.0))
        tts.append(info["time_to_speed"])
        speed.append(info["measurements"][:, 2].max())
    assert max(speed) <= 2.0
    assert tts[78] is None and tts[79] == pytest.approx(40.0)  # 2.0 / 0.05
    assert tts[-1] == pytest.approx(40.0)
    assert info["measurements"][-1, 2] == 2.0 and info["measurements"][-1, 3] == 0.0
    assert info["effort"] == pytest.approx(0.05**2 * 40.0)


@pytest.mark.parametrize("sprint_steps", [0, 60])
def test_run_up_deadline_floor_and_reward_terms(sprint_steps):
    # with a deadline every schedule arrives in time: commands below the rate still
    # needed are raised to it (u = -1 is the constant ramp), whatever came before
    kw = {"randomize": False, "t_max": 240.0, "w_vibration": 1.0, "w_effort": 0.1, "w_time": 3.0}
    env = RotorRunUpEnv(deadline=200.0, **kw)
    env.reset(seed=0)
    k = 0
    while True:
        u = np.array([1.0 if k < sprint_steps else -1.0], dtype=np.float32)
        _, r, term, trunc, info = env.step(u)
        m = info["measurements"]
        t0, speed0 = m[0, 0] - 0.01, m[0, 2] - 0.01 * m[0, 3]
        a = m[-1, 3]
        if k < sprint_steps:
            assert a == pytest.approx(0.05)
        elif t0 < 200.0 - 1e-9:
            assert a == pytest.approx((2.0 - speed0) / (200.0 - t0), rel=1e-9)  # the floor
        amp = np.hypot(m[:, 4], m[:, 5])
        assert r == pytest.approx(-(min(np.mean((amp / 0.6) ** 2), 1.0) + 0.1 * (a / 0.05) ** 2), rel=1e-9, abs=1e-12)
        k += 1
        if term or trunc:
            break
    assert info["time_to_speed"] == pytest.approx(200.0)
    assert info["measurements"][-1, 2] == 2.0


def test_run_up_without_deadline_rewards_arriving_early():
    env = RotorRunUpEnv(randomize=False, deadline=None, w_time=3.0)
    env.reset(seed=0)
    _, r, _, _, info = env.step(np.array([-1.0], dtype=np.float32))  # no floor: a = 0
    assert info["measurements"][-1, 2] == 0.0
    assert r == pytest.approx(-3.0)  # the whole speed is missing; at rest nothing vibrates
    _, r, _, _, info = env.step(np.array([1.0], dtype=np.float32))
    speed = info["measurements"][-1, 2]
    assert speed == pytest.approx(0.025)
    amp = np.hypot(info["measurements"][:, 4], info["measurements"][:, 5])
    assert r == pytest.approx(-(np.mean((amp / 0.6) ** 2) + 3.0 * (1 - speed / 2.0) + 0.1), rel=1e-9)
    for bad in (-1.0, 39.0):
        with pytest.raises(ValueError, match="deadline"):
            RotorRunUpEnv(deadline=bad)


# ------------------------------------------------------------------------ actions
@pytest.mark.parametrize("cls", [RotorRunUpEnv, RotorBalancingEnv])
def test_nan_and_wrong_shape_actions_raise(cls):
    env = cls()
    env.reset(seed=0)
    dim = env.action_space.shape[0]
    for bad in (np.full(dim, np.nan), np.zeros(dim + 1), np.zeros((1, dim)), 0.5, "x", None):
        with pytest.raises(ValueError):
            env.step(bad)
    env.step(np.zeros(dim))  # still usable


@pytest.mark.parametrize("cls", [RotorRunUpEnv, RotorBalancingEnv])
def test_out_of_range_actions_are_clipped(cls):
    results = []
    for value in (1.0, 7.5, np.inf, -1.0, -3.0, -np.inf):
        env = cls()
        env.reset(seed=5)
        obs, r, *_, info = env.step(np.full(env.action_space.shape, value))
        results.append((obs, r, info["measurements"]))
        if cls is RotorBalancingEnv:  # the applied moments, for an identifier
            assert np.array_equal(info["control"], np.full(2, np.clip(value, -1, 1) * env.m_max))
    for i, j in ((0, 1), (0, 2), (3, 4), (3, 5)):
        assert np.array_equal(results[i][0], results[j][0]) and results[i][1] == results[j][1]
        assert np.array_equal(results[i][2], results[j][2])


# ------------------------------------------------------------------- measurements
@pytest.mark.parametrize("cls", [RotorRunUpEnv, RotorBalancingEnv])
def test_measurements_shape_columns_and_freshness(cls):
    assert COLUMNS[0] == "t" and len(COLUMNS) == 10
    env, twin = cls(), cls()
    env.reset(seed=8)
    twin.reset(seed=8)
    a = _act(env, 0.3)
    for _ in range(3):
        obs, _, _, _, info = env.step(a)
        obs2, _, _, _, info2 = twin.step(a)
    m = info["measurements"]
    assert m.shape == (50, 10) and m.dtype == np.float64
    np.testing.assert_allclose(np.diff(m[:, 0]), 0.01, atol=1e-9)
    assert m[-1, 0] == pytest.approx(1.5)
    # the last sample is the end of the step: it matches the observation
    assert obs[4] == pytest.approx(m[-1, 4] / env.clearance, abs=1e-6)
    assert obs[0] == pytest.approx(m[-1, 2] / env._speed_max, rel=1e-6)
    # new arrays every call; mutating them does not affect the env
    m[:] = 1e9
    obs[:] = 1e9
    _, _, _, _, nxt = env.step(a)
    _, _, _, _, nxt2 = twin.step(a)
    assert nxt["measurements"] is not m
    assert np.array_equal(nxt["measurements"], nxt2["measurements"])


def test_configurable_sensor_rate_and_substep_floor():
    env = RotorRunUpEnv(step_dt=0.1, sensor_dt=0.1)
    env.reset(seed=0)
    assert env.step(_act(env, 0))[4]["measurements"].shape == (1, 10)
    assert env.substeps_per_step == MIN_SUBSTEPS
    with pytest.raises(ValueError, match="at least 10"):
        RotorRunUpEnv(step_dt=0.05)
    with pytest.raises(ValueError, match="multiple"):
        RotorRunUpEnv(step_dt=0.5, sensor_dt=0.03)
    with pytest.raises(ValueError, match="clearance"):
        RotorBalancingEnv(clearance=-1)


# ------------------------------------------------------------------ episode ends
@pytest.mark.parametrize("cls", [RotorRunUpEnv, RotorBalancingEnv])
def test_rub_terminates(cls):
    env = cls(randomize=False, clearance=0.01)
    env.reset(seed=0)
    for _ in range(600):
        obs, r, te, tr, info = env.step(_act(env, 0.0))
        if te or tr:
            break
    assert te and not tr and info["reason"] == "rub"
    assert info["peak_amplitude"] > 0.01
    assert r < -env.fail_penalty
    assert env.observation_space.contains(obs)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(_act(env, 0.0))


@pytest.mark.parametrize("cls", [RotorRunUpEnv, RotorBalancingEnv])
def test_unstable_rotor_terminates_cleanly(cls):
    env = cls(clearance=1e6)  # no rub first
    env.reset(options={"params": UNSTABLE})
    for _ in range(100):
        obs, r, te, tr, info = env.step(_act(env, 1.0))
        if te or tr:
            break
    assert te and info["reason"] == "unstable"
    assert np.isfinite(obs).all() and env.observation_space.contains(obs)
    assert np.isfinite(r)
    m = info["measurements"]
    assert np.isnan(m[-1]).all()  # samples after the divergence are NaN


@pytest.mark.parametrize("cls", [RotorRunUpEnv, RotorBalancingEnv])
def test_time_limit_truncates(cls):
    env = cls(t_max=2.0)
    env.reset(seed=0)
    flags = [env.step(_act(env, 0.0))[2:4] for _ in range(4)]
    assert flags[:3] == [(False, False)] * 3 and flags[3] == (False, True)
    env.reset(seed=0)
    for _ in range(4):
        *_, info = env.step(_act(env, 0.0))
    assert info["reason"] == "time_limit"
    assert info["measurements"][-1, 0] == pytest.approx(2.0)


# ---------------------------------------------------------------------- rendering
@pytest.mark.parametrize("env_id", IDS)
def test_render_rgb_array_and_human_headless(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(10):
        env.step(env.action_space.sample())
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert frame.shape[0] > 100 and frame.shape[1] > 100 and frame.std() > 0
    env.close()
    human = gym.make(env_id, render_mode="human")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        human.reset(seed=0)
        human.step(human.action_space.sample())
        assert human.render() is None
    human.close()


# -------------------------------------------------------------------------- vector
@pytest.mark.parametrize(
    "env_id,parallel", [(IDS[0], False), (IDS[1], False), (IDS[0], True)]
)
def test_vector_env_equals_single_env_step_by_step(env_id, parallel):
    n = 4
    kw = {"t_max": 6.0, "clearance": 0.04}  # short episodes: truncations, rubs and autoresets
    venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", parallel=parallel, **kw)
    assert venv.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
    assert venv.single_observation_space == CLASSES[env_id](**kw).observation_space
    singles = [CLASSES[env_id](**kw) for _ in range(n)]
    vobs, vinfo = venv.reset(seed=100)
    for i, env in enumerate(singles):
        obs, info = env.reset(seed=100 + i)
        assert np.array_equal(vobs[i], obs) and vinfo["params"][i] == info["params"]
    rng = np.random.default_rng(1)
    ended = [False] * n
    n_ends = n_resets = 0
    for _ in range(45):
        actions = rng.uniform(-1.3, 1.3, venv.action_space.shape).astype(np.float32)
        vobs, vrew, vterm, vtrunc, vinfo = venv.step(actions)
        assert vinfo["measurements"].shape == (n, 50, 10)
        for i, env in enumerate(singles):
            if ended[i]:  # next-step autoreset
                obs, info = env.reset()
                rew, term, trunc = 0.0, False, False
                assert not vinfo["_measurements"][i] and np.isnan(vinfo["measurements"][i]).all()
                n_resets += 1
            else:
                obs, rew, term, trunc, info = env.step(actions[i])
                assert vinfo["_measurements"][i]
                assert np.array_equal(vinfo["measurements"][i], info["measurements"], equal_nan=True)
                assert vinfo["reason"][i] == info["reason"]
                if "control" in info:
                    assert np.array_equal(vinfo["control"][i], info["control"])
            assert np.array_equal(vobs[i], obs)
            assert vrew[i] == rew and vterm[i] == term and vtrunc[i] == trunc
            assert vinfo["params"][i] == info["params"] and vinfo["ip"][i] == info["ip"]
            assert vinfo["peak_amplitude"][i] == info["peak_amplitude"]
            ended[i] = term or trunc
            n_ends += ended[i]
    assert n_ends >= 4 and n_resets >= 4
    venv.close()


def test_vector_env_options_actions_and_render():
    venv = gym.make_vec(IDS[1], num_envs=3, render_mode="rgb_array", max_render_envs=2, clearance=1e6)
    obs, info = venv.reset(seed=0, options={"params": UNSTABLE})
    assert all(p == UNSTABLE for p in info["params"])
    push = np.ones((3, 2))  # the moment beats the dry friction that holds the disk at rest
    _, _, term, _, info = venv.step(push)
    for _ in range(20):
        if term.all():
            break
        _, _, term, _, info = venv.step(push)
    assert term.all() and list(info["reason"]) == ["unstable"] * 3
    mask = np.array([True, False, False])
    obs, info = venv.reset(seed=[5, None, None], options={"reset_mask": mask})
    assert info["_params"].tolist() == [True, False, False]
    assert np.isfinite(obs).all()
    with pytest.raises(ValueError, match="NaN"):
        venv.step(np.array([[0, 0], [np.nan, 0], [0, 0]]))
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((3, 1)))
    frames = venv.render()
    assert len(frames) == 2 and frames[0].ndim == 3 and frames[0].dtype == np.uint8
    venv.close()


_EPISODE_SCRIPT = """
import json, sys
import numpy as np
import gymnasium as gym
import rotor_env
from rotor_env.envs.core import kernels
env = gym.make(sys.argv[1])
obs, _ = env.reset(seed=7)
rows = [obs.tolist()]
for k in range(25):
    obs, r, term, trunc, info = env.step(np.full(env.action_space.shape, 0.5 if k % 2 else -0.3, np.float32))
    rows.append([*obs.tolist(), float(r)])
    if term or trunc:
        break
print(json.dumps({"rows": rows, "cached": kernels()._cached is not None}))
"""


def test_disk_cached_step_kernels_equal_the_in_memory_ones(tmp_path):
    """The step kernels generated into the kernel cache (numba caches them on disk: no
    compilation in a second process) step exactly as the ones compiled in memory."""
    import json
    import os
    import subprocess
    import sys

    def run(**env):
        proc = subprocess.run([sys.executable, "-c", _EPISODE_SCRIPT, "rotor_env/RotorBalancing-v0"],
                              capture_output=True, text=True,
                              timeout=600, env={**os.environ, "ROTOR_ID_CACHE_DIR": str(tmp_path), **env})
        assert proc.returncode == 0, proc.stderr[-2000:]
        return json.loads(proc.stdout)

    cached = run()
    plain = run(ROTOR_ID_NO_KERNEL_CACHE="1")
    assert cached["cached"] and not plain["cached"]
    (source,) = (tmp_path / "kernels").glob("rotor_id_env_step_*.py")
    # numba wrote its cache of the step kernels (index files beside the generated source)
    assert list((tmp_path / "kernels" / "__pycache__").glob(f"{source.stem}.step_one-*.nbi"))
    assert cached["rows"] == plain["rows"]
