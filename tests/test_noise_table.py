"""Shared noise table: ARS and OpenES read perturbations as slices, and save/load keeps the run exact."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_es import ARS, OpenES
from sb3_es.strategies.noise import NoiseTablePopulation


def test_ars_population_is_read_from_the_table() -> None:
    model = ARS("LinearPolicy", "CartPole-v1", n_delta=3, delta_std=0.05, noise_table_size=10_000, seed=0)
    model.strategy.center = np.arange(model.policy.num_params, dtype=np.float64)
    population = model._ask()
    assert isinstance(population, NoiseTablePopulation)
    table, dim = model.strategy.noise_table, model.policy.num_params
    assert table is not None
    dense = np.asarray(population)
    for i in range(3):
        noise = table.get(int(population.offsets[i]), dim).astype(np.float64)
        np.testing.assert_array_equal(dense[i], model.strategy.center + 0.05 * noise)
        np.testing.assert_array_equal(dense[i + 3], model.strategy.center - 0.05 * noise)


def test_openes_antithetic_pairs_from_the_table() -> None:
    model = OpenES("LinearPolicy", "CartPole-v1", population_size=6, sigma=0.2, noise_table_size=10_000, seed=0)
    dense = np.asarray(model._ask())
    center = model.strategy.center
    np.testing.assert_allclose(dense[:3] - center, center - dense[3:], rtol=0, atol=1e-12)


@pytest.mark.parametrize("algo", [ARS, OpenES])
def test_learns_cartpole_with_a_noise_table(algo: type) -> None:
    kwargs = dict(n_delta=2) if algo is ARS else dict(population_size=16, sigma=0.5, learning_rate=0.1)
    model = algo("LinearPolicy", "CartPole-v1", seed=0, noise_table_size=100_000, **kwargs)
    model.learn(50_000)
    mean, _ = evaluate_policy(model, make_vec_env("CartPole-v1", n_envs=1, seed=123), n_eval_episodes=10)
    assert mean >= 475


def test_resume_with_a_noise_table_is_exact(tmp_path: Path) -> None:
    generation = 2 * 2 * 200  # n_delta=2, Pendulum's 200-step episodes, one env

    def make() -> ARS:
        env = make_vec_env("Pendulum-v1", n_envs=1, seed=0)
        return ARS("LinearPolicy", env, n_delta=2, noise_table_size=50_000, seed=5)

    straight = make()
    straight.learn(4 * generation)
    resumed = make()
    resumed.learn(2 * generation)
    resumed.save(tmp_path / "model.zip")
    loaded = ARS.load(tmp_path / "model.zip", env=make_vec_env("Pendulum-v1", n_envs=1, seed=0))
    loaded.learn(2 * generation, reset_num_timesteps=False)
    np.testing.assert_array_equal(loaded.policy.parameters_to_vector(), straight.policy.parameters_to_vector())
    np.testing.assert_array_equal(loaded.strategy.center, straight.strategy.center)


def test_bad_noise_table_size() -> None:
    with pytest.raises(ValueError, match="noise_table_size"):
        ARS("LinearPolicy", "CartPole-v1", noise_table_size=0)
    with pytest.raises(ValueError, match="smaller than one perturbation"):
        ARS("MlpPolicy", "CartPole-v1", noise_table_size=100).learn(100)
