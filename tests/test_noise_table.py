"""Shared noise table: ARS and OpenES read perturbations as slices; a table too small is refused.

Learning CartPole and exact resumption with a table are cases of the generic tests (``test_algorithms.py``,
``test_save_load.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from algorithms import NOISE_TABLE_ALGORITHMS, Algo

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


def test_bad_noise_table_size() -> None:
    with pytest.raises(ValueError, match="noise_table_size"):
        ARS("LinearPolicy", "CartPole-v1", noise_table_size=0)
    with pytest.raises(ValueError, match="smaller than one perturbation"):
        ARS("MlpPolicy", "CartPole-v1", noise_table_size=100).learn(100)
    # CartPole's linear policy has 4 x 2 parameters: a 10-value table has 3 slices for 8 directions
    with pytest.raises(ValueError, match=r"holds 3 distinct perturbations of 8 parameters, fewer than the 8"):
        ARS("LinearPolicy", "CartPole-v1", n_delta=8, noise_table_size=10).learn(100)


@pytest.mark.parametrize("algo", NOISE_TABLE_ALGORITHMS)
def test_a_table_too_small_for_a_generation_is_refused_by_the_constructor(algo: Algo, tmp_path: Path) -> None:
    # CartPole's linear policy has 8 parameters: a 10-value table has 3 slices, fewer than a generation of 16 draws
    with pytest.raises(ValueError, match=r"holds 3 distinct perturbations of 8 parameters, fewer than the \d+"):
        algo.make("CartPole-v1", 16, noise_table_size=10, tensorboard_log=str(tmp_path))
    assert not list(tmp_path.iterdir())  # refused before any run folder was made
    # and by load(), where new hyperparameters would draw more slices than the table holds
    algo.make("CartPole-v1", 2, noise_table_size=10).save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=r"holds 3 distinct perturbations of 8 parameters, fewer than the \d+"):
        algo.cls.load(tmp_path / "model.zip", **algo.size(16))
