"""VecEnvEvaluator: slot-based evaluation of a population on a VecEnv."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from envs import IMAGE_ID, StepCounter, ToyEnv, rollout
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.monitor import Monitor, load_results
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize, VecTransposeImage

from sb3_es import ARS
from sb3_es.common.policies import FlatPolicy, LinearPolicy, MlpPolicy
from sb3_es.evaluation import Generation, PopulationResult, VecEnvEvaluator


def make_population(policy: FlatPolicy, n: int, seed: int = 0, scale: float = 0.6) -> np.ndarray:
    return scale * np.random.default_rng(seed).standard_normal((n, policy.num_params))


def reference(policy: FlatPolicy, population: np.ndarray, n_episodes: int, **env_kwargs: Any) -> dict[str, Any]:
    """Sequential rollouts, one candidate after another, with ``predict()``."""
    env = ToyEnv(**env_kwargs)
    returns = np.zeros((len(population), n_episodes))
    lengths = np.zeros((len(population), n_episodes), dtype=np.int64)
    seen = []
    for k, params in enumerate(population):
        for e in range(n_episodes):
            returns[k, e], lengths[k, e], obs = rollout(env, policy, params)
            seen.extend(obs)
    seen = np.array(seen)
    return dict(returns=returns, lengths=lengths, obs_mean=seen.mean(0), obs_var=seen.var(0))


def toy_vec_env(n_envs: int, counter: list[int] | None = None, **env_kwargs: Any) -> DummyVecEnv:
    def make() -> gym.Env:
        env: gym.Env = ToyEnv(**env_kwargs)
        return StepCounter(env, counter) if counter is not None else env

    return DummyVecEnv([make for _ in range(n_envs)])


def evaluate_counting(
    evaluator: VecEnvEvaluator, policy: FlatPolicy, population: np.ndarray, n_episodes: int, **kwargs: Any
) -> tuple[PopulationResult, int]:
    calls = [0]

    def hook(n_envs: int, infos: list, dones: np.ndarray, *_: Any) -> bool:
        calls[0] += 1
        return True

    result = evaluator.evaluate(policy, population, population.mean(0), n_episodes, seed=123, step_hook=hook, **kwargs)
    return result, calls[0]


@pytest.mark.parametrize("n_envs", [1, 3, 4])
@pytest.mark.parametrize("n_episodes", [1, 2])
@pytest.mark.parametrize("discrete", [False, True])
def test_returns_match_sequential_rollouts(n_envs: int, n_episodes: int, discrete: bool) -> None:
    policy = LinearPolicy(ToyEnv(discrete=discrete).observation_space, ToyEnv(discrete=discrete).action_space)
    # Non-trivial (frozen) observation statistics must be used the same way by both paths.
    policy.update_obs_rms(np.array([0.2, 0.3]), np.array([0.5, 0.1]), 50)
    population = make_population(policy, 6)
    expected = reference(policy, population, n_episodes, discrete=discrete)
    # The toy env must distinguish candidates: several different lengths and returns.
    assert np.unique(expected["lengths"][:, 0]).size >= 3
    assert np.unique(np.round(expected["returns"][:, 0], 4)).size >= 3

    counter = [0]
    env = toy_vec_env(n_envs, counter, discrete=discrete)
    result, hook_calls = evaluate_counting(VecEnvEvaluator(env), policy, population, n_episodes)

    assert result.returns.shape == (6, n_episodes) and result.lengths.shape == (6, n_episodes)
    np.testing.assert_array_equal(result.lengths, expected["lengths"])
    np.testing.assert_allclose(result.returns, expected["returns"], rtol=1e-5, atol=1e-5)
    assert not result.stopped
    # Step accounting: every slot of every vec step, and exactly what the envs executed.
    assert result.n_steps == n_envs * hook_calls
    assert counter[0] == result.n_steps
    # Only the candidates' observations enter the statistics (not the idle slots running the center).
    assert result.obs_stats.count == expected["lengths"].sum()
    np.testing.assert_allclose(result.obs_stats.mean, expected["obs_mean"], rtol=1e-5)
    np.testing.assert_allclose(result.obs_stats.var, expected["obs_var"], rtol=1e-5)


def test_each_candidate_gets_exactly_n_episodes() -> None:
    """With a Monitor below the VecEnv, exactly n_episodes candidate episodes are reported per candidate."""
    policy = MlpPolicy(ToyEnv().observation_space, ToyEnv().action_space, net_arch=[4])
    population = make_population(policy, 5, seed=1)
    n_episodes = 3
    env = DummyVecEnv([lambda: Monitor(ToyEnv()) for _ in range(2)])
    result, _ = evaluate_counting(VecEnvEvaluator(env), policy, population, n_episodes)
    expected = reference(policy, population, n_episodes)
    np.testing.assert_array_equal(result.lengths, expected["lengths"])
    np.testing.assert_allclose(result.returns, expected["returns"], rtol=1e-5, atol=1e-5)
    assert np.all(result.lengths > 0)
    assert len(result.ep_infos) == 5 * n_episodes
    # The Monitor's episode records are the candidates' episodes.
    assert sorted(info["l"] for info in result.ep_infos) == sorted(expected["lengths"].ravel().tolist())


def test_idle_slots_run_the_center() -> None:
    """Slots left without a job run the center policy; their completed episodes are the center's returns."""
    policy = LinearPolicy(ToyEnv().observation_space, ToyEnv().action_space)
    population = make_population(policy, 3, seed=2)
    center = np.array([5.0, 0.0])  # a = clip(5 x): leaves |x| < 1 in two steps
    env = toy_vec_env(4)
    result = VecEnvEvaluator(env).evaluate(policy, population, center, 1, seed=0)
    center_return, center_length, _ = rollout(ToyEnv(), policy, center)
    assert center_length == 2
    assert len(result.center_returns) >= 1
    np.testing.assert_allclose(result.center_returns, center_return, rtol=1e-5)
    assert set(result.center_lengths) == {center_length}


def test_linger_keeps_all_slots_on_the_center() -> None:
    """``linger`` is asked only once the candidates are done; while it says True, every slot runs the center."""
    policy = LinearPolicy(ToyEnv().observation_space, ToyEnv().action_space)
    population = make_population(policy, 3, seed=2)
    center = np.array([5.0, 0.0])  # two-step center episodes
    plain = VecEnvEvaluator(toy_vec_env(4)).evaluate(policy, population, center, 1, seed=0)
    counter = [0]
    asked = []

    def linger() -> bool:
        asked.append(counter[0])
        return len(asked) <= 6  # six more vec steps

    generation = Generation(policy.network_spec(), population, center, 1, seed=0)
    result = VecEnvEvaluator(toy_vec_env(4, counter)).run(generation, linger=linger)
    # First asked at the step the plain run ended on; the candidates' results are unchanged.
    assert asked[0] == plain.n_steps
    np.testing.assert_array_equal(result.returns, plain.returns)
    np.testing.assert_array_equal(result.obs_stats.mean, plain.obs_stats.mean)
    assert result.n_steps == counter[0] == plain.n_steps + 6 * 4
    # Six steps of 4 slots on the two-step center: at least 3 more center episodes per slot, all alike.
    assert len(result.center_returns) >= len(plain.center_returns) + 4 * 2
    assert set(result.center_lengths) == {2}


def test_step_hook_stops_promptly() -> None:
    policy = LinearPolicy(ToyEnv().observation_space, ToyEnv().action_space)
    population = make_population(policy, 6)
    counter = [0]
    env = toy_vec_env(2, counter)
    calls = []

    def hook(n_envs: int, infos: list, dones: np.ndarray, *_: Any) -> bool:
        assert n_envs == 2 and len(infos) == 2 and dones.shape == (2,)
        calls.append(1)
        return len(calls) < 4

    result = VecEnvEvaluator(env).evaluate(policy, population, population[0], 2, seed=0, step_hook=hook)
    assert result.stopped
    assert len(calls) == 4
    assert result.n_steps == 8
    assert counter[0] == 8


def test_step_hook_stop_after_last_job_is_not_a_stop() -> None:
    """A hook that says stop on the very step that completes the last job leaves complete results."""
    policy = LinearPolicy(ToyEnv().observation_space, ToyEnv().action_space)
    population = make_population(policy, 2)
    expected = reference(policy, population, 1)
    steps_needed = int(expected["lengths"].max())
    calls = [0]

    def hook(n_envs: int, infos: list, dones: np.ndarray, *_: Any) -> bool:
        calls[0] += 1
        return calls[0] < steps_needed

    result = VecEnvEvaluator(toy_vec_env(2)).evaluate(policy, population, population[0], 1, seed=0, step_hook=hook)
    assert calls[0] == steps_needed
    assert not result.stopped
    np.testing.assert_array_equal(result.lengths, expected["lengths"])


def test_generation_depends_only_on_seed_and_parameters() -> None:
    """Evaluating twice on the same VecEnv (whatever state it was left in) gives the same results."""
    env = make_vec_env("Pendulum-v1", n_envs=3)
    policy = LinearPolicy(env.observation_space, env.action_space)
    population = make_population(policy, 4, scale=0.3)
    evaluator = VecEnvEvaluator(env)
    first = evaluator.evaluate(policy, population, population.mean(0), 1, seed=7)
    second = evaluator.evaluate(policy, population, population.mean(0), 1, seed=7)
    np.testing.assert_array_equal(first.returns, second.returns)
    other = evaluator.evaluate(policy, population, population.mean(0), 1, seed=8)
    assert not np.array_equal(first.returns, other.returns)
    env.close()


def test_subproc_vec_env() -> None:
    env = make_vec_env("Pendulum-v1", n_envs=2, vec_env_cls=SubprocVecEnv)
    try:
        policy = MlpPolicy(env.observation_space, env.action_space, net_arch=[8])
        population = make_population(policy, 3, scale=0.3)
        result, hook_calls = evaluate_counting(VecEnvEvaluator(env), policy, population, 2)
        # Pendulum episodes are truncated at 200 steps.
        assert np.all(result.lengths == 200)
        assert result.returns.shape == (3, 2) and np.all(np.isfinite(result.returns)) and np.all(result.returns < 0)
        assert result.n_steps == 2 * hook_calls == 2 * 3 * 200
        assert result.obs_stats.count == 3 * 2 * 200
        assert len(result.ep_infos) == 6
        # Same results as the same seeds on a DummyVecEnv.
        dummy = make_vec_env("Pendulum-v1", n_envs=2)
        result_dummy, _ = evaluate_counting(VecEnvEvaluator(dummy), policy, population, 2)
        np.testing.assert_allclose(result.returns, result_dummy.returns, rtol=1e-6)
    finally:
        env.close()


@pytest.mark.parametrize("norm_reward", [False, True])
def test_vec_normalize_wrapper(norm_reward: bool) -> None:
    env = VecNormalize(make_vec_env("Pendulum-v1", n_envs=2), norm_reward=norm_reward)
    policy = LinearPolicy(env.observation_space, env.action_space, normalize_observations=False)
    population = make_population(policy, 2, scale=0.3)
    result, hook_calls = evaluate_counting(VecEnvEvaluator(env), policy, population, 1)
    assert np.all(result.lengths == 200)
    assert result.n_steps == 2 * hook_calls
    # Returns are the raw returns reported by the Monitor below VecNormalize, also with norm_reward=True (whose scale
    # changes within the generation: the first candidates' rewards would be scaled otherwise than the last ones').
    monitor_returns = sorted(info["r"] for info in result.ep_infos)
    np.testing.assert_allclose(sorted(result.returns.ravel()), monitor_returns, rtol=1e-4, atol=1e-3)
    # The policy sees the normalized observations (VecNormalize statistics were updated while stepping).
    assert env.obs_rms.count > 400
    # Raw Pendulum observations have an angular-velocity variance of about 34, normalized ones about 1.
    assert np.all(result.obs_stats.var < 3.0)


def test_episodes_cut_through_vec_transpose_image_reach_the_monitor(tmp_path: Path) -> None:
    """SB3 puts channels-last images in VecTransposeImage: a cut episode still ends in its slot's Monitor."""
    env = make_vec_env(IMAGE_ID, n_envs=2, monitor_dir=str(tmp_path))
    model = ARS("LinearPolicy", env, n_delta=2, max_episode_steps=7, seed=0)
    assert isinstance(model.env, VecTransposeImage)
    model.learn(50)
    env.close()
    episodes = load_results(str(tmp_path))
    assert len(episodes) >= 4 and (episodes["l"] == 7).all()


def test_episodes_cut_in_another_process_are_said_to_miss_the_monitor(tmp_path: Path) -> None:
    """A SubprocVecEnv's Monitors run in its processes, where a cut episode cannot be ended: a warning says so."""
    env = make_vec_env(
        "Pendulum-v1",
        n_envs=2,
        monitor_dir=str(tmp_path),
        vec_env_cls=SubprocVecEnv,
        vec_env_kwargs=dict(start_method="fork"),
    )
    model = ARS("LinearPolicy", env, n_delta=1, max_episode_steps=30, seed=0)
    with pytest.warns(UserWarning, match=r"cut at max_episode_steps=30 .* runs in another process \(SubprocVecEnv\)"):
        model.learn(60)
    env.close()
    assert model.ep_info_buffer is not None and {info["l"] for info in model.ep_info_buffer} == {30}
