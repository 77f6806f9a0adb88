"""``benchmarks/walker_shaping.py``: a walker-walk fitness that pays more for a high torso (raw reward kept), and
upright starts."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import shimmy
from dm_control.utils import rewards
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.monitor import Monitor

from benchmarks.walker_shaping import StandBonus, UprightStart
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


def test_upright_start_puts_the_walker_upright_within_the_noise_and_observes_it() -> None:
    env = UprightStart(gym.make(ENV_ID), probability=1.0, noise=0.1)
    physics = env.unwrapped._env.physics  # type: ignore[attr-defined]
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        qpos = physics.data.qpos.copy()
        assert physics.torso_height() == pytest.approx(1.3) and physics.torso_upright() > np.cos(0.1)
        assert np.all(np.abs(qpos[2:]) <= 0.1) and not np.any(physics.data.qvel)
        low, high = physics.model.jnt_range[2:].T
        limited = physics.model.jnt_limited[2:].astype(bool)
        assert np.all(qpos[2:][limited] >= low[limited]) and np.all(qpos[2:][limited] <= high[limited])
        # the first observation is the upright state's, as the task computes it
        assert float(obs["height"]) == pytest.approx(physics.torso_height())
        np.testing.assert_allclose(obs["orientations"], physics.orientations())
        obs, *_ = env.step(np.zeros(6))
        assert physics.torso_height() > 1.2  # it is still up one step later (a random start falls from 1.3 m)


def test_upright_start_takes_its_share_and_leaves_the_others_as_the_task_starts_them() -> None:
    raw = gym.make(ENV_ID)
    never = UprightStart(gym.make(ENV_ID), probability=0.0)
    for seed in range(3):
        expected, _ = raw.reset(seed=seed)
        got, _ = never.reset(seed=seed)
        for key in expected:
            np.testing.assert_array_equal(got[key], expected[key])
    half = UprightStart(gym.make(ENV_ID), probability=0.5)
    physics = half.unwrapped._env.physics  # type: ignore[attr-defined]
    half.reset(seed=0)
    upright = []
    for _ in range(60):
        half.reset()
        upright.append(physics.torso_upright() > np.cos(0.1) and np.all(np.abs(physics.data.qpos[2:]) <= 0.1))
    assert 15 <= sum(upright) <= 45  # random starts are upright within the noise only by rare chance


def test_workers_rebuild_the_upright_start() -> None:
    venv = make_vec_env(ENV_ID, n_envs=1, wrapper_class=UprightStart, wrapper_kwargs={"probability": 0.25})
    _, args = env_recipe(venv, "processes")
    worker_env = args["wrapper_class"](Monitor(gym.make(ENV_ID)))
    assert isinstance(worker_env, UprightStart) and (worker_env.probability, worker_env.noise) == (0.25, 0.1)
    venv.close()


def test_upright_start_refuses_bad_input_with_the_reason() -> None:
    with pytest.raises(ValueError, match=r"probability in \[0, 1\]"):
        UprightStart(gym.make(ENV_ID), probability=1.5)
    with pytest.raises(ValueError, match="UprightStart needs a dm_control walker env"):
        UprightStart(gym.make("Pendulum-v1"))
