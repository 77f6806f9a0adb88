"""What is specific to ARS: its logged values, schedules, update rule, V1/V2, n_top, alive bonus, environments.

What every algorithm does (learning, step accounting, callbacks, logging) is in ``test_algorithms.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from algorithms import learn_logged, progress_at_generation_starts, spy_on_ask
from envs import counting_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

from sb3_es import ARS
from sb3_es.strategies import ARSStrategy

PENDULUM_GENERATION = 2 * 2 * 200  # n_delta=2, 200-step episodes, 1 env


# ---------------------------------------------------------------------------- logging
def test_logged_train_values(tmp_path: Path) -> None:
    model = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0)
    (row,) = learn_logged(model, PENDULUM_GENERATION, tmp_path)
    assert float(row["train/learning_rate"]) == pytest.approx(0.02)
    assert float(row["train/delta_std"]) == pytest.approx(0.05)
    assert float(row["train/return_std"]) > 0 and float(row["train/step_size"]) > 0


# ---------------------------------------------------------------------------- hyperparameters
def test_schedules_are_applied(tmp_path: Path) -> None:
    total = 4 * PENDULUM_GENERATION
    model = ARS(
        "LinearPolicy",
        "Pendulum-v1",
        n_delta=2,
        learning_rate=lambda progress: 0.02 * progress,
        delta_std=lambda progress: 0.05 * progress,
        seed=0,
    )
    asked = spy_on_ask(
        model,
        lambda strategy, population: (strategy.delta_std, strategy.center.copy(), population, strategy._deltas.copy()),
    )
    rows = learn_logged(model, total, tmp_path)
    assert len(rows) == 4
    progress = progress_at_generation_starts(rows, total)
    np.testing.assert_allclose([float(r["train/learning_rate"]) for r in rows], [0.02 * p for p in progress])
    np.testing.assert_allclose([float(r["train/delta_std"]) for r in rows], [0.05 * p for p in progress])
    # The perturbations really use the scheduled noise.
    for (delta_std, center, population, deltas), p in zip(asked, progress):
        assert delta_std == pytest.approx(0.05 * p)
        np.testing.assert_allclose(population[:2] - center, delta_std * deltas, atol=1e-12)
        np.testing.assert_allclose(population[2:] - center, -delta_std * deltas, atol=1e-12)


def test_ars_strategy_update_rule() -> None:
    """One tell(): top-b directions by max(r+, r-), step lr / (b * std of the 2b returns used)."""
    strategy = ARSStrategy(np.array([1.0, -1.0, 0.5]), n_delta=4, n_top=2, delta_std=0.2, learning_rate=0.1, seed=0)
    center = strategy.center.copy()
    population = strategy.ask()
    deltas = (population[:4] - center) / 0.2
    fitness = np.array([1.0, 5.0, 0.0, 2.0, 3.0, 0.5, 7.0, 1.0])
    info = strategy.tell(fitness)
    plus, minus = fitness[:4], fitness[4:]
    top = [2, 1]  # max(r+, r-) = [3, 5, 7, 2]
    used = np.concatenate([plus[top], minus[top]])
    step = 0.1 / (2 * used.std())
    expected = center + step * ((plus[top] - minus[top]) @ deltas[top])
    np.testing.assert_allclose(strategy.center, expected, rtol=1e-10)
    assert info["step_size"] == pytest.approx(step)
    assert info["return_std"] == pytest.approx(used.std())


def test_v1_leaves_obs_stats_untouched_v2_updates_them() -> None:
    v1 = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0, policy_kwargs=dict(normalize_observations=False))
    v1.learn(PENDULUM_GENERATION)
    np.testing.assert_array_equal(v1.policy.obs_mean.numpy(), 0.0)
    np.testing.assert_array_equal(v1.policy.obs_var.numpy(), 1.0)
    assert v1.policy.obs_count.item() == pytest.approx(1e-4)
    assert v1._n_updates == 1

    v2 = ARS("LinearPolicy", "Pendulum-v1", n_delta=2, seed=0)
    v2.learn(PENDULUM_GENERATION)
    assert not np.allclose(v2.policy.obs_mean.numpy(), 0.0)
    assert not np.allclose(v2.policy.obs_var.numpy(), 1.0)
    # Every step of every candidate (one env: no idle slot) is counted once.
    assert v2.policy.obs_count.item() == pytest.approx(PENDULUM_GENERATION + 1e-4)
    # Pendulum observations are (cos, sin, angular velocity): |cos|, |sin| <= 1.
    assert np.all(np.abs(v2.policy.obs_mean.numpy()[:2]) <= 1.0)


def test_n_top_smaller_than_n_delta() -> None:
    # the same directions and returns (same seed), but the update keeps the 2 best of 4: another step
    models = {n_top: ARS("LinearPolicy", "Pendulum-v1", n_delta=4, n_top=n_top, seed=0) for n_top in (2, 4)}
    for model in models.values():
        model.learn(4 * 2 * 200)
        assert model._n_updates == 1
    top2, every = (models[n].policy.parameters_to_vector() for n in (2, 4))
    assert np.any(top2 != 0.0) and not np.allclose(top2, every)


def test_alive_bonus_offset_changes_the_fitness() -> None:
    """With CartPole (reward 1 per step), an offset of -1 makes every fitness 0: no update at all."""
    model = ARS("LinearPolicy", "CartPole-v1", n_delta=2, alive_bonus_offset=-1.0, seed=0)
    model.learn(1)
    assert model._n_updates == 1
    np.testing.assert_array_equal(model.policy.parameters_to_vector(), 0.0)
    reference = ARS("LinearPolicy", "CartPole-v1", n_delta=2, seed=0)
    reference.learn(1)
    assert np.any(reference.policy.parameters_to_vector() != 0.0)


# ---------------------------------------------------------------------------- environments
def test_mlp_pendulum_subproc_vec_env() -> None:
    env = make_vec_env("Pendulum-v1", n_envs=2, vec_env_cls=SubprocVecEnv)
    try:
        model = ARS("MlpPolicy", env, n_delta=2, seed=0, policy_kwargs=dict(net_arch=[16, 16]))
        model.learn(2 * PENDULUM_GENERATION)
        assert model._n_updates == 2
        assert model.num_timesteps == 2 * PENDULUM_GENERATION
        assert np.any(model.policy.parameters_to_vector() != 0.0)
        assert np.all(np.isfinite(model.policy.parameters_to_vector()))
    finally:
        env.close()


def test_mlp_pendulum_vec_normalize() -> None:
    env = VecNormalize(make_vec_env("Pendulum-v1", n_envs=2))
    model = ARS("MlpPolicy", env, n_delta=2, seed=0, policy_kwargs=dict(net_arch=[16], normalize_observations=False))
    model.learn(PENDULUM_GENERATION)
    assert model._n_updates == 1
    assert model.get_vec_normalize_env() is env
    assert env.obs_rms.count > PENDULUM_GENERATION  # VecNormalize saw the training steps
    action, _ = model.predict(env.reset())
    assert action.shape == (2, 1)


@pytest.mark.parametrize(("env_id", "n_envs"), [("Swimmer-v5", 1), ("BipedalWalker-v3", 2)])
def test_mujoco_and_box2d_run_a_generation(env_id: str, n_envs: int) -> None:
    counter = [0]
    env = counting_env(env_id, n_envs, counter)
    model = ARS("LinearPolicy", env, n_delta=1, seed=0)
    model.learn(1)
    assert model._n_updates == 1
    assert model.num_timesteps == counter[0] > 0
    assert np.all(np.isfinite(model.policy.parameters_to_vector()))
