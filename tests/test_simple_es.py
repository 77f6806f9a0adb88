"""What is specific to SimpleES: seed 002's WinnerES (n_elite=1) and weighted average of the top n children, its sigma
schedule and save/load, errors (generic behaviour: ``test_algorithms.py``, whose CartPole cases include WinnerES)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from algorithms import spy_on_ask

from sb3_es import SimpleES
from sb3_es.strategies import SimpleESStrategy
from sb3_es.strategies.noise import NoiseTablePopulation, SharedNoiseTable
from sb3_es.strategies.simple_es import elite_weights


# ---------------------------------------------------------------------------- strategy
def test_winner_es_moves_the_center_to_the_best_child() -> None:
    strategy = SimpleESStrategy(np.array([1.0, -1.0]), 5, sigma=0.3, n_elite=1, seed=0)
    population = strategy.ask().copy()
    strategy.tell(np.array([0.0, 3.0, -1.0, 7.0, 2.0]))
    np.testing.assert_array_equal(strategy.center, population[3])
    # Even a worse child replaces the parent: a comma (1, lambda) selection.
    population = strategy.ask().copy()
    strategy.tell(np.full(5, -100.0) + np.arange(5))
    np.testing.assert_array_equal(strategy.center, population[4])


@pytest.mark.parametrize("weights", ["equal", "linear", "log"])
def test_top_n_weighted_average(weights: str) -> None:
    strategy = SimpleESStrategy(np.zeros(3), 6, sigma=1.0, n_elite=3, weights=weights, seed=0)  # type: ignore[arg-type]
    population = strategy.ask().copy()
    fitness = np.array([5.0, -2.0, 9.0, 0.0, 7.0, 1.0])
    strategy.tell(fitness)
    top = [2, 4, 0]  # best first
    w = elite_weights(3, weights)  # type: ignore[arg-type]
    np.testing.assert_allclose(strategy.center, w @ population[top], rtol=1e-12)
    # Ranks only: shifting and scaling the fitness changes nothing.
    again = SimpleESStrategy(np.zeros(3), 6, sigma=1.0, n_elite=3, weights=weights, seed=0)  # type: ignore[arg-type]
    again.ask()
    again.tell(1000 * fitness - 5e4)
    np.testing.assert_array_equal(again.center, strategy.center)


def test_elite_weights() -> None:
    np.testing.assert_allclose(elite_weights(4, "equal"), 0.25)
    np.testing.assert_allclose(elite_weights(3, "linear"), [3 / 6, 2 / 6, 1 / 6])
    log = elite_weights(3, "log")
    raw = np.log(3.5) - np.log([1.0, 2.0, 3.0])
    np.testing.assert_allclose(log, raw / raw.sum())
    for weights in ("equal", "linear", "log"):
        w = elite_weights(5, weights)  # type: ignore[arg-type]
        assert w.sum() == pytest.approx(1.0) and np.all(np.diff(w) <= 0)
    np.testing.assert_array_equal(elite_weights(1, "log"), [1.0])
    with pytest.raises(ValueError, match="weights='fitness'"):
        elite_weights(3, "fitness")  # type: ignore[arg-type]


def test_noise_table_population() -> None:
    strategy = SimpleESStrategy(np.ones(4), 6, sigma=0.2, noise_table=SharedNoiseTable(10_000, seed=0), seed=0)
    population = strategy.ask()
    assert isinstance(population, NoiseTablePopulation)
    dense = np.asarray(population).copy()
    np.testing.assert_array_equal(population.scales, 0.2)
    strategy.tell(np.array([0.0, 1.0, 5.0, 2.0, 3.0, 4.0]))
    np.testing.assert_array_equal(strategy.center, dense[2])
    # The elite rows are read alone: the whole population is not built (a remote evaluator never builds it).
    strategy = SimpleESStrategy(
        np.ones(4), 6, sigma=0.2, n_elite=2, noise_table=SharedNoiseTable(10_000, seed=0), seed=0
    )
    population = strategy.ask()
    assert isinstance(population, NoiseTablePopulation)
    dense = NoiseTablePopulation(population.table, population.center, population.offsets, population.scales).dense()
    strategy.tell(np.array([0.0, 1.0, 5.0, 2.0, 3.0, 4.0]))
    assert population._dense is None
    np.testing.assert_allclose(strategy.center, strategy.elite_weights @ dense[[2, 5]], rtol=1e-12)


def test_sigma_schedule_and_save_load(tmp_path: Path) -> None:
    model = SimpleES("LinearPolicy", "Pendulum-v1", population_size=4, sigma=lambda p: 0.2 * p, n_elite=2, seed=0)
    sigmas = spy_on_ask(model, lambda strategy, _: strategy.sigma)
    model.learn(4 * 4 * 200)
    np.testing.assert_allclose(sigmas, [0.2, 0.15, 0.1, 0.05])
    del model.strategy.ask  # the spy (an instance attribute) is not saved
    model.save(tmp_path / "simple.zip")
    loaded = SimpleES.load(tmp_path / "simple.zip")
    assert (loaded.n_elite, loaded.weights) == (2, "log")
    np.testing.assert_array_equal(loaded.strategy.ask(), model.strategy.ask())
