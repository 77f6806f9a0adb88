"""Reward shaping of the fitness (raw returns stay logged) and the MLP initialization of ``zero_policy``."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from algorithms import POPULATION_ALGORITHMS, Algo
from stable_baselines3.common.env_util import make_vec_env

from sb3_es import ARS
from sb3_es.evaluation import PopulationResult, RewardShaping, VecEnvEvaluator


class RecordingEvaluator(VecEnvEvaluator):
    """The local engine, keeping every generation's result."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self.results: list[PopulationResult] = []

    def evaluate(self, *args: Any, **kwargs: Any) -> PopulationResult:
        result = super().evaluate(*args, **kwargs)
        self.results.append(result)
        return result


def test_shaping_replaces_terminal_rewards_only_on_termination() -> None:
    shaping = RewardShaping.create(terminal_reward=0.0)
    rewards = np.array([-100.0, -100.0, 0.5])
    dones = np.array([True, True, False])
    infos = [{}, {"TimeLimit.truncated": True}, {}]
    np.testing.assert_array_equal(shaping(rewards, dones, infos), [0.0, -100.0, 0.5])


def test_shaping_order_terminal_then_clip_then_offset() -> None:
    shaping = RewardShaping.create(reward_clip=[-1, 1], terminal_reward=-5.0, alive_bonus_offset=-0.1)
    out = shaping(np.array([-100.0, 3.0, 0.5]), np.array([True, False, False]), [{}, {}, {}])
    np.testing.assert_allclose(out, [-1.1, 0.9, 0.4])
    assert not shaping.is_identity
    assert RewardShaping.create().is_identity


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(reward_clip=(1, -1)), "low < high"),
        (dict(reward_clip=5), "two finite numbers"),
        (dict(reward_clip=(0, float("inf"))), "two finite numbers"),
        (dict(reward_clip=[0, "1"]), "two finite numbers"),
        (dict(reward_clip=(True, 2)), "two finite numbers"),
        (dict(terminal_reward=float("nan")), "terminal_reward=nan"),
        (dict(terminal_reward="5"), "terminal_reward='5'"),
        (dict(alive_bonus_offset=True), "alive_bonus_offset=True"),
        # a number that YAML read as a string: the message says so, as for every other hyperparameter
        (dict(reward_clip=["-1e0", 1]), r"two finite numbers .* \(a string; a YAML file reads a number without a dot"),
        (dict(terminal_reward="1e-2"), r"terminal_reward='1e-2': .* \(a string; a YAML file"),
        (dict(alive_bonus_offset="-1e-1"), r"alive_bonus_offset='-1e-1': .* \(a string; a YAML file"),
    ],
)
def test_bad_shaping_is_refused_at_construction(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ARS("LinearPolicy", "CartPole-v1", **kwargs)


def test_reward_clip_from_a_numpy_array() -> None:
    shaping = RewardShaping.create(reward_clip=np.array([-1.0, 1.0]))
    assert shaping.reward_clip == (-1.0, 1.0) and all(type(v) is float for v in shaping.reward_clip)


@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
def test_shaping_changes_the_fitness_not_the_logged_returns(algo: Algo) -> None:
    """CartPole pays 1 per step; a fall (termination) pays -5 in the fitness, a time limit keeps its 1."""
    env = make_vec_env("CartPole-v1", n_envs=2, seed=0)
    evaluator = RecordingEvaluator(env)
    model = algo.make(env, 4, terminal_reward=-5.0, reward_clip=(-10, 0.5), evaluator=evaluator)
    model.learn(1, log_interval=10)
    result = evaluator.results[-1]
    assert result.shaped_returns is not None
    # Raw: 1 per step. Shaped: 0.5 per step (clip), the terminating step -5 instead.
    np.testing.assert_array_equal(result.returns, result.lengths)
    terminated = result.lengths < 500
    expected = np.where(terminated, 0.5 * (result.lengths - 1) - 5.0, 0.5 * result.lengths)
    np.testing.assert_allclose(result.shaped_returns, expected)
    logged = sorted(info["r"] for info in model.ep_info_buffer)
    assert logged == sorted(result.returns.ravel().tolist())


def test_no_shaping_gives_raw_fitness_and_no_extra_array() -> None:
    env = make_vec_env("CartPole-v1", n_envs=2, seed=0)
    evaluator = RecordingEvaluator(env)
    ARS("LinearPolicy", env, n_delta=2, evaluator=evaluator, seed=0).learn(1)
    assert evaluator.results[-1].shaped_returns is None
    assert evaluator.results[-1].fitness_returns is evaluator.results[-1].returns


def test_alive_bonus_offset_is_a_per_step_shaping() -> None:
    env = make_vec_env("CartPole-v1", n_envs=1, seed=0)
    evaluator = RecordingEvaluator(env)
    ARS("LinearPolicy", env, n_delta=2, alive_bonus_offset=-0.25, evaluator=evaluator, seed=0).learn(1)
    result = evaluator.results[-1]
    np.testing.assert_allclose(result.fitness_returns, 0.75 * result.lengths)


def test_shaping_is_saved_and_loaded(tmp_path: Any) -> None:
    model = ARS("LinearPolicy", "CartPole-v1", n_delta=2, reward_clip=[-1, 1], terminal_reward=0, seed=0)
    model.save(tmp_path / "model")
    loaded = ARS.load(tmp_path / "model")
    assert loaded.reward_shaping == model.reward_shaping == RewardShaping((-1.0, 1.0), 0.0, 0.0)


# ---------------------------------------------------------------------------- zero_policy
@pytest.mark.parametrize("algo", POPULATION_ALGORITHMS)
def test_zero_policy_zeroes_only_the_output_layer(algo: Algo) -> None:
    model = algo.make("Pendulum-v1", 4, policy="MlpPolicy", zero_policy=True)
    center = model.strategy.center
    out = model.policy.output_layer_slice()
    assert out.stop == model.policy.num_params
    np.testing.assert_array_equal(center[out], 0.0)
    assert np.all(center[: out.start] != 0.0) or np.count_nonzero(center[: out.start]) > 0.9 * out.start
    linear = algo.make("Pendulum-v1", 4, policy="LinearPolicy", zero_policy=True)
    np.testing.assert_array_equal(linear.strategy.center, 0.0)


def test_zero_policy_mlp_predicts_zero_at_start() -> None:
    """The output layer at zero gives the zero action (that it then learns: ``algorithms.CARTPOLE_CASES``)."""
    model = ARS("MlpPolicy", "CartPole-v1", seed=1)
    np.testing.assert_array_equal(model.predict(np.ones(4, dtype=np.float32))[0], 0)  # argmax of zero outputs
