"""``benchmarks/walker_shaping.py``: a walker-walk fitness that pays more for a high torso, raw reward kept."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import shimmy
from dm_control.utils import rewards
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.monitor import Monitor

from benchmarks.walker_shaping import StandBonus
from sb3_es.common.env_recipe import env_recipe

gym.register_envs(shimmy)
ENV_ID = "dm_control/walker-walk-v0"


def test_bonus_is_the_torso_height_term_and_monitor_keeps_the_raw_return() -> None:
    raw_env = Monitor(gym.make(ENV_ID))
    shaped_env = StandBonus(Monitor(gym.make(ENV_ID)), weight=2.0)
    physics = shaped_env.unwrapped._env.physics  # type: ignore[attr-defined]
    raw_env.reset(seed=3)
    shaped_env.reset(seed=3)
    action = np.zeros(shaped_env.action_space.shape, dtype=np.float32)
    bonuses = []
    done = False
    while not done:
        _, raw, *_ = raw_env.step(action)
        _, shaped, terminated, truncated, info = shaped_env.step(action)
        standing = rewards.tolerance(physics.torso_height(), bounds=(1.2, float("inf")), margin=0.6)
        assert float(shaped) == pytest.approx(float(raw) + 2.0 * standing)
        bonuses.append(standing)
        done = terminated or truncated
    # The walker falls from its standing start: the bonus changes along the episode, not a constant.
    assert max(bonuses) > 0.9 and min(bonuses) < 0.5
    assert info["episode"]["r"] == pytest.approx(raw_env.get_episode_rewards()[0])


def test_workers_rebuild_the_bonus_after_monitor() -> None:
    venv = make_vec_env(ENV_ID, n_envs=1, wrapper_class=StandBonus, wrapper_kwargs={"weight": 0.5})
    _, args = env_recipe(venv, "processes")
    worker_env = args["wrapper_class"](Monitor(gym.make(ENV_ID)))
    assert isinstance(worker_env, StandBonus) and worker_env.weight == 0.5
    venv.close()


def test_other_envs_are_refused_with_the_reason() -> None:
    with pytest.raises(ValueError, match="needs a dm_control walker env"):
        StandBonus(gym.make("Pendulum-v1"))
