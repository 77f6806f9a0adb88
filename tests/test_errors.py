"""Clear errors for bad hyperparameters, unsupported environments and non-finite returns."""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest
from envs import ConstantObsEnv, MultiDiscreteActionEnv, NaNRewardWrapper
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_es import ARS


# ---------------------------------------------------------------------------- hyperparameters
@pytest.mark.parametrize(("n_delta", "n_top"), [(2, 3), (4, 5), (4, 0), (4, -1), (4, 1.5)])
def test_bad_n_top(n_delta: int, n_top: float) -> None:
    with pytest.raises(ValueError, match="n_top"):
        ARS("LinearPolicy", "Pendulum-v1", n_delta=n_delta, n_top=n_top)


@pytest.mark.parametrize("n_delta", [0, -1, 2.5])
def test_bad_n_delta(n_delta: float) -> None:
    with pytest.raises(ValueError, match="n_delta"):
        ARS("LinearPolicy", "Pendulum-v1", n_delta=n_delta)


@pytest.mark.parametrize("delta_std", [0.0, -0.05, float("nan"), float("inf"), lambda progress: -progress])
def test_bad_delta_std(delta_std) -> None:
    with pytest.raises(ValueError, match="delta_std"):
        ARS("LinearPolicy", "Pendulum-v1", delta_std=delta_std)


@pytest.mark.parametrize("learning_rate", [0.0, -0.02, float("nan"), float("inf"), lambda progress: 0.0])
def test_bad_learning_rate(learning_rate) -> None:
    with pytest.raises(ValueError, match="learning_rate"):
        ARS("LinearPolicy", "Pendulum-v1", learning_rate=learning_rate)


@pytest.mark.parametrize("n_eval_episodes", [0, -2, 1.5])
def test_bad_n_eval_episodes(n_eval_episodes: float) -> None:
    with pytest.raises(ValueError, match="n_eval_episodes"):
        ARS("LinearPolicy", "Pendulum-v1", n_eval_episodes=n_eval_episodes)


def test_delta_std_schedule_reaching_zero_during_training() -> None:
    """A schedule that becomes non-positive mid-run stops with a clear error before that generation."""
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=1, delta_std=lambda progress: progress - 0.5, seed=0)
    with pytest.raises(ValueError, match="delta_std"):
        model.learn(4 * 400)
    # Generations ran while the schedule was positive (progress 1.0 and 0.75), then it stopped at 0.5.
    assert model._n_updates == 2
    assert model.num_timesteps == 2 * 400


# ---------------------------------------------------------------------------- environments and policies
def test_unknown_env_id() -> None:
    with pytest.raises(gym.error.Error, match="NoSuchEnvAtAll"):
        ARS("LinearPolicy", "NoSuchEnvAtAll-v0")


def test_multi_discrete_action_env() -> None:
    with pytest.raises(ValueError, match="MultiDiscrete") as info:
        ARS("LinearPolicy", MultiDiscreteActionEnv())
    assert "action space" in str(info.value)


def test_unknown_policy_alias() -> None:
    with pytest.raises(ValueError, match="CnnPolicy"):
        ARS("CnnPolicy", "Pendulum-v1")


class NotFlatPolicy(BasePolicy):
    """A valid SB3 policy without flat parameters."""

    def _predict(self, observation, deterministic: bool = False):  # pragma: no cover - never called
        raise NotImplementedError


def test_non_flat_policy_class() -> None:
    with pytest.raises(TypeError, match="FlatPolicy"):
        ARS(NotFlatPolicy, "Pendulum-v1")


# ---------------------------------------------------------------------------- non-finite returns
def spy_on_ask(model: ARS) -> list[np.ndarray]:
    asked: list[np.ndarray] = []
    ask = model.strategy.ask

    def spy() -> np.ndarray:
        population = ask()
        asked.append(population)
        return population

    model.strategy.ask = spy  # type: ignore[method-assign]
    return asked


def snapshot(model: ARS) -> dict[str, np.ndarray]:
    return dict(
        params=model.policy.parameters_to_vector(),
        center=model.strategy.center.copy(),
        obs_mean=model.policy.obs_mean.numpy().copy(),
        obs_var=model.policy.obs_var.numpy().copy(),
        obs_count=model.policy.obs_count.numpy().copy(),
    )


def assert_unchanged(before: dict[str, np.ndarray], model: ARS) -> None:
    after = snapshot(model)
    for key, value in before.items():
        np.testing.assert_array_equal(after[key], value, err_msg=key)


def test_nan_rewards_for_some_candidates() -> None:
    """Constant observation 1: a candidate's action has the sign of its weight, NaN reward when positive."""
    model = ARS("LinearPolicy", DummyVecEnv([ConstantObsEnv]), n_delta=3, seed=0, zero_policy=False)
    asked = spy_on_ask(model)
    before = snapshot(model)
    with pytest.raises(ValueError, match="candidate") as info:
        model.learn(100)
    population = asked[0]
    bad = np.flatnonzero(population[:, 0] > 0).tolist()
    assert 0 < len(bad) < len(population)
    assert str(bad) in str(info.value)
    assert_unchanged(before, model)
    assert model._n_updates == 0


def test_nan_rewards_after_training_leave_last_update() -> None:
    model = ARS("LinearPolicy", make_vec_env("Pendulum-v1", n_envs=1), n_delta=2, seed=0)
    model.learn(800)
    assert model._n_updates == 1
    before = snapshot(model)
    model.set_env(make_vec_env("Pendulum-v1", n_envs=1, wrapper_class=NaNRewardWrapper))
    with pytest.raises(ValueError, match=re.escape("candidate(s) [0, 1, 2, 3]")):
        model.learn(800, reset_num_timesteps=False)
    assert_unchanged(before, model)
    assert model._n_updates == 1
