"""Agents: every baseline runs, a smoke training saves and loads, committed policies evaluate."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import rotor_env  # noqa: F401 - registers the environments
from agents.baselines import ConstantRamp, Fastest, ModelBasedBalancer, ModelBasedRunUp, NoControl
from agents.evaluation import (
    BALANCING,
    RUN_UP,
    default_agents,
    evaluate,
    policy_folder,
    run_episode,
)
from agents.features import ModelFeatures
from agents.oracle import RunUpOracle, schedule_peak
from agents.training import TrainedPolicy, make_env, train
from rotor_env import RotorParams
from rotor_env.cli import main


def test_every_run_up_baseline_runs_an_episode():
    env = make_env(RUN_UP, identifier=True)
    u = env.unwrapped
    plain = u.observation_space.shape[0]
    agents = [
        (ConstantRamp(u.a_max, 0.01), plain),
        (Fastest(), plain),
        (ModelBasedRunUp.for_env(env), None),
        (RunUpOracle.for_env(env, max_evaluations=15), plain),
    ]
    results = {type(a).__name__: run_episode(env, a, seed=7, observe_plain=p) for a, p in agents}
    for r in results.values():
        assert np.isfinite([r["peak_amplitude"], r["rms_amplitude"], r["return"], r["effort"]]).all()
        assert r["time_to_speed"] <= u.t_max
    # the constant ramp reaches speed 2.0 at t = 200 (within one step); the fastest at 40
    assert results["ConstantRamp"]["time_to_speed"] == pytest.approx(200.0, abs=0.6)
    assert results["Fastest"]["time_to_speed"] == pytest.approx(u.target_speed / u.a_max, abs=0.6)


def test_constant_ramp_action_maps_to_the_paper_rate():
    env = gym.make(RUN_UP, randomize=False)
    env.reset(seed=0)
    a = ConstantRamp(env.unwrapped.a_max, 0.01).predict(np.zeros(10, np.float32))[0]
    _, _, _, _, info = env.step(a)
    assert info["measurements"][-1, 3] == pytest.approx(0.01)
    # batched observations give batched actions (the SB3 predict shape)
    batch, _ = Fastest().predict(np.zeros((3, 10), np.float32))
    assert batch.shape == (3, 1)


def test_slow_fast_slow_cuts_the_peak_without_dry_friction():
    """The issue's physics: slow-fast-slow cuts the peak strongly without dry friction."""
    p = RotorParams().replace(h=0.0)
    wc = np.sqrt(1.0 / (1.0 - p.ip))
    const = schedule_peak(p, 0.0, 0.0, 0.01, 0.01, 0.05, 2.0, 250.0)
    v1, v2, slow = 0.8 * wc, 1.3 * wc, 0.008
    after = (2.0 - v2) / (200.0 - v1 / slow - (v2 - v1) / 0.05)  # arrive at t = 200 as well
    best = schedule_peak(p, v1, v2, slow, after, 0.05, 2.0, 250.0)
    assert const == pytest.approx(0.252, abs=0.003)
    assert best < 0.75 * const


def test_oracle_beats_the_fixed_schedules_on_the_true_rotor():
    env = gym.make(RUN_UP)
    _, info = env.reset(seed=11)
    oracle = RunUpOracle.for_env(env, max_evaluations=20).fit(info["params"])
    best = oracle.episode_return(info["params"], oracle.plan)
    constant = oracle.episode_return(info["params"], (0.0, 0.0, 0.0))  # the floor: the 0.01 ramp
    fastest = oracle.episode_return(info["params"], (0.0, np.inf, 0.0))
    assert best > max(constant, fastest)
    # the same numbers as the environment's own episode with the oracle acting
    oracle.fit(info["params"])
    assert run_episode(make_env(RUN_UP, identifier=False), oracle, seed=11)["return"] == pytest.approx(best)


def test_balancing_baselines_and_the_model_based_balancer_target():
    """Model-based balancing lowers the RMS vibration through resonance by >= 80 %."""
    env = make_env(BALANCING, identifier=True)
    agents = {"no_control": (NoControl(), False), "model_based": (ModelBasedBalancer.for_env(env), True)}
    res = evaluate(BALANCING, episodes=3, agents=agents)["agents"]
    assert res["model_based"]["rms_amplitude"] <= 0.2 * res["no_control"]["rms_amplitude"]
    assert res["model_based"]["rub_rate"] == 0.0


def test_smoke_training_saves_and_loads(tmp_path):
    out = train(RUN_UP, "ppo", 1024, identifier=True, seed=3, out=tmp_path / "p", eval_freq=1024,
                eval_episodes=1, progress=False)
    for f in ("model.zip", "vecnormalize.npz", "run.json"):
        assert (out / f).stat().st_size > 0
    meta = json.loads((out / "run.json").read_text())
    assert meta["seed"] == 3 and meta["identifier"] is True and "rotor-id train" in meta["command"]
    assert meta["features"] is not None  # the identified model as features, applied on load
    policy = TrainedPolicy.load(out)
    assert isinstance(policy.features, ModelFeatures)
    env = make_env(RUN_UP, identifier=True)
    obs, _ = env.reset(seed=1)
    a1, _ = policy.predict(obs)
    a2, _ = policy.predict(obs)
    assert env.action_space.contains(np.asarray(a1, dtype=np.float32))
    np.testing.assert_array_equal(a1, a2)  # deterministic
    with pytest.raises(FileExistsError):
        train(RUN_UP, "ppo", 64, out=out, progress=False)


@pytest.mark.parametrize("env_id", [RUN_UP, BALANCING])
def test_committed_policies_load_and_evaluate_on_three_rotors(env_id):
    for ident in (True, False):
        assert (policy_folder(env_id, ident) / "model.zip").stat().st_size <= 2 * 1024 * 1024
    env = make_env(env_id, identifier=True)
    names = set(default_agents(env_id, env))
    assert {"sb3_identifier", "sb3_plain"} <= names
    res = evaluate(env_id, episodes=3, agents={k: v for k, v in default_agents(env_id, env).items()
                                               if k.startswith("sb3")})
    for m in res["agents"].values():
        assert all(np.isfinite(v) for v in m.values())
    if env_id == RUN_UP:  # the committed run-up agent corrects the model-based scheduler
        assert TrainedPolicy.load(policy_folder(RUN_UP, True)).residual.base_name == "model_based_runup"


def test_evaluate_cli_json(capsys):
    assert main(["evaluate", "--env", BALANCING, "--episodes", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for name in ("no_control", "model_based", "sb3_identifier", "sb3_plain"):
        assert set(out["agents"][name]) >= {
            "peak_amplitude", "rms_amplitude", "time_to_speed", "effort", "rub_rate", "return"}


def test_model_features_keep_the_significant_model_and_place_the_critical_speed():
    env = make_env(RUN_UP, identifier=True, model_features="full")
    inner = env.env  # the identification wrapper
    feats = env.get_wrapper_attr("features")
    off, lay = inner.offset, inner.layout
    obs = np.zeros(inner.observation_space.shape, np.float32)
    obs[0] = 0.5  # speed 1.0 of the target 2.0
    obs[off + lay["ip"].start] = 0.2
    obs[off + lay["stiffness.coefficients"].start] = 1.25
    obs[off + lay["stiffness.significant"].start] = 1.0
    obs[off + lay["nonlinear_stiffness.coefficients"].start] = 3e5  # not significant: dropped
    ub = slice(off + lay["unbalance.coefficients"].start, off + lay["unbalance.coefficients"].stop)
    obs[ub] = [40.0, -0.02]
    obs[off + lay["unbalance.significant"].start] = 1.0  # significant: clipped to +-10
    out = feats(obs)
    assert out.shape == (obs.size + 2,) and env.observation_space.contains(out)
    assert out[off + lay["nonlinear_stiffness.coefficients"].start] == 0.0
    np.testing.assert_allclose(out[ub], [10.0, -0.02], rtol=1e-6)
    assert out[-2] == pytest.approx(1.0 / np.sqrt(1.25 / 0.8)) and out[-1] == 1.0
    obs[off + lay["stiffness.significant"].start] = 0.0  # stiffness not known: no critical speed
    assert feats(obs)[-2:].tolist() == [0.0, 0.0]
    np.testing.assert_array_equal(feats(np.stack([obs, obs]))[1], feats(obs))
    # the map survives its JSON round trip (run.json)
    again = ModelFeatures.from_json(json.loads(json.dumps(feats.to_json())))
    np.testing.assert_array_equal(again(obs), feats(obs))
    # compact: the env observation and the critical-speed ratio only
    compact = make_env(RUN_UP, identifier=True, model_features="compact")
    small = compact.get_wrapper_attr("features")(obs)
    np.testing.assert_array_equal(small, np.concatenate([obs[:off], feats(obs)[-2:]]))
    assert compact.observation_space.shape == small.shape and compact.observation_space.contains(small)
    with pytest.raises(ValueError, match="model_features"):
        make_env(RUN_UP, identifier=True, model_features="yes")


def test_residual_wrapper_applies_the_baseline_plus_the_bounded_correction():
    env = make_env(RUN_UP, identifier=True, model_features="compact", residual=0.5)
    wrapper = env.env  # inside the feature wrapper: the residual action wrapper
    residual = env.get_wrapper_attr("residual")
    base = ModelBasedRunUp.for_env(env)
    rng = np.random.default_rng(4)
    raw, _ = wrapper.reset(seed=5)
    obs, _ = env.reset(seed=5)
    for _ in range(25):
        net = rng.uniform(-3, 3, size=1).astype(np.float32)  # out-of-range actions are clipped first
        expected = np.clip(base.act(raw) + 0.5 * np.clip(net, -1, 1), -1, 1)
        obs, _, term, trunc, info = env.step(net)
        np.testing.assert_allclose(info["applied_action"], expected, rtol=0, atol=1e-7)
        raw = wrapper._obs
        assert env.observation_space.contains(obs)
        if term or trunc:
            break
    # the JSON description rebuilds the same map (run.json)
    again = type(residual).from_json(json.loads(json.dumps(residual.to_json())))
    batch = np.stack([raw, raw])
    np.testing.assert_array_equal(again(batch, [[0.3], [-2.0]]), residual(batch, [[0.3], [-2.0]]))
    with pytest.raises(ValueError, match="identifier"):
        make_env(RUN_UP, identifier=False, residual=0.5)
    with pytest.raises(ValueError, match="residual"):
        make_env(RUN_UP, identifier=True, residual=-1.0)
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.array([np.nan], np.float32))


def test_a_zero_residual_is_the_model_based_baseline():
    """An untrained correction (zero) acts exactly like the baseline it corrects."""

    class Zero:
        def reset(self):
            pass

        def predict(self, obs, deterministic=True):
            return np.zeros(2, np.float32), None

    env = make_env(BALANCING, identifier=True)
    res_env = make_env(BALANCING, identifier=True, residual=1.0)
    a = run_episode(env, ModelBasedBalancer.for_env(env), seed=12)
    b = run_episode(res_env, Zero(), seed=12)
    assert a == b


def test_smoke_training_of_a_residual_policy(tmp_path):
    out = train(RUN_UP, "ppo", 512, identifier=True, seed=1, out=tmp_path / "r", eval_freq=512,
                eval_episodes=1, progress=False, residual=0.25)
    meta = json.loads((out / "run.json").read_text())
    assert meta["residual"]["base"] == "model_based_runup" and meta["residual"]["scale"] == 0.25
    assert "--residual 0.25" in meta["command"]
    assert meta["hyperparams"]["policy_kwargs"]["log_std_init"] == -1.0  # ppo_residual's table
    policy = TrainedPolicy.load(out)
    env = make_env(RUN_UP, identifier=True)
    raw, _ = env.reset(seed=2)
    net, _ = policy.model.predict(policy.normalize(policy.features(raw)).astype(np.float32), deterministic=True)
    action, _ = policy.predict(raw)
    np.testing.assert_allclose(action, policy.residual(raw, net))
    with pytest.raises(ValueError, match="identifier"):
        train(RUN_UP, "ppo", 64, identifier=False, out=tmp_path / "x", residual=0.5, progress=False)
