"""What is specific to PGPE with ClipUp: the strategy's math, defaults, logged values, load() overrides, errors.

What every algorithm does (learning, step accounting, callbacks, logging, save/load) is in ``test_algorithms.py``
and ``test_save_load.py``; exact resumption there restores PGPE's stdevs and its optimizer's state too
(``algorithms.ALGOS``), with ClipUp and with Adam.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from algorithms import learn_logged, pendulum_env

from sb3_es import PGPE
from sb3_es.strategies import ClipUp, PGPEStrategy
from sb3_es.strategies.fitness import centered_ranks

POPULATION = 4
PENDULUM_GENERATION = POPULATION * 200  # Pendulum-v1: fixed 200-step episodes, one env


def pendulum_model(**kwargs: Any) -> PGPE:
    return PGPE("LinearPolicy", pendulum_env(), **{"population_size": POPULATION, "seed": 0, **kwargs})


# ---------------------------------------------------------------------------- strategy math
def test_symmetric_sampling_with_one_stdev_per_parameter() -> None:
    strategy = PGPEStrategy(np.array([1.0, -2.0, 0.5]), 4000, stdev_init=0.1, center_learning_rate=0.1, seed=0)
    strategy.stdev = np.array([0.1, 1.0, 3.0])
    population = strategy.ask()
    plus, minus = population[:2000] - strategy.center, population[2000:] - strategy.center
    np.testing.assert_allclose(plus, -minus, rtol=0, atol=1e-12)
    np.testing.assert_allclose(plus.std(axis=0), [0.1, 1.0, 3.0], rtol=0.05)


def test_update_rule_with_sgd() -> None:
    """Center: SGD along mean_k((f+ - f-)/2 z_k); stdev: ascent along mean_k(((f+ + f-)/2 - b)(z^2 - s^2)/s)."""
    center = np.array([0.5, -1.0, 2.0])
    strategy = PGPEStrategy(
        center, 6, stdev_init=0.2, center_learning_rate=0.3, stdev_learning_rate=0.05, optimizer="sgd", momentum=0.0
    )
    population = strategy.ask()
    z = population[:3] - center
    fitness = np.array([1.0, 5.0, 0.0, 2.0, 3.0, 0.5])
    info = strategy.tell(fitness)
    ranks = centered_ranks(fitness)
    plus, minus = ranks[:3], ranks[3:]
    center_grad = ((plus - minus) / 2) @ z / 3
    stdev_grad = ((plus + minus) / 2 - ranks.mean()) @ ((z**2 - 0.04) / 0.2) / 3
    np.testing.assert_allclose(strategy.center, center + 0.3 * center_grad, rtol=1e-12)
    expected_stdev = np.clip(0.2 + 0.05 * stdev_grad, 0.16, 0.24)
    np.testing.assert_allclose(strategy.stdev, expected_stdev, rtol=1e-12)
    assert info["grad_norm"] == pytest.approx(np.linalg.norm(center_grad))
    assert info["stdev_mean"] == pytest.approx(expected_stdev.mean())


def test_clipup_moves_the_center_by_the_learning_rate_along_the_gradient() -> None:
    center = np.zeros(5)
    strategy = PGPEStrategy(center, 10, stdev_init=0.5, center_learning_rate=0.07, max_speed=0.3, seed=1)
    assert isinstance(strategy.optimizer, ClipUp)
    population = strategy.ask()
    fitness = population @ np.arange(5.0)
    ranks = centered_ranks(fitness)
    grad = ((ranks[:5] - ranks[5:]) / 2) @ (population[:5] - center) / 5
    info = strategy.tell(fitness)
    np.testing.assert_allclose(strategy.center, 0.07 * grad / np.linalg.norm(grad), rtol=1e-12)
    assert info["speed"] == pytest.approx(0.07)


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_stdev_change_is_bounded(direction: float) -> None:
    """With a huge stdev learning rate every standard deviation moves by exactly stdev_max_change of its value."""
    strategy = PGPEStrategy(np.zeros(3), 200, stdev_init=1.0, center_learning_rate=0.1, stdev_learning_rate=1e6, seed=0)
    population = strategy.ask()
    # Fitness rewards (or punishes) distance from the center: the stdev gradient grows (or shrinks) every stdev.
    fitness = direction * np.sum(population**2, axis=1)
    strategy.tell(fitness)
    np.testing.assert_allclose(strategy.stdev, 1.0 + direction * 0.2, rtol=1e-12)


def test_max_stdev_bounds_the_adapted_stdev() -> None:
    """The update that would raise every stdev by 20% (to 1.2) stops at max_stdev; one set later applies at ask()."""
    kwargs: dict[str, Any] = dict(stdev_init=1.0, center_learning_rate=0.1, stdev_learning_rate=1e6, seed=0)
    strategy = PGPEStrategy(np.zeros(3), 200, max_stdev=1.1, **kwargs)
    population = strategy.ask()
    strategy.tell(np.sum(population**2, axis=1))
    np.testing.assert_array_equal(strategy.stdev, 1.1)
    strategy.max_stdev = 0.5
    noise = strategy.ask()[:100] - strategy.center  # the "+" half: stdev * eps
    np.testing.assert_array_equal(strategy.stdev, 0.5)
    assert np.std(noise) == pytest.approx(0.5, rel=0.1)


def test_a_strategy_saved_before_max_stdev_loads_unbounded() -> None:
    strategy = PGPEStrategy(np.zeros(3), 4, stdev_init=1.0, center_learning_rate=0.1, seed=0)
    state = dict(strategy.__dict__)
    del state["max_stdev"]
    restored = PGPEStrategy.__new__(PGPEStrategy)
    restored.__setstate__(state)
    assert restored.max_stdev is None
    restored.ask()
    restored.tell(np.arange(4.0))  # no AttributeError: updates as before
    assert not np.all(restored.stdev == 1.0)


# ---------------------------------------------------------------------------- SB3 surface
def test_defaults_follow_the_clipup_paper() -> None:
    model = pendulum_model()
    group = model.strategy.optimizer.param_groups[0]
    assert isinstance(model.strategy.optimizer, ClipUp)
    assert (group["max_speed"], group["lr"], group["momentum"]) == (0.15, 0.075, 0.9)
    assert model.strategy.stdev_max_change == 0.2
    assert model.strategy.fitness_shaping == "centered_rank"
    np.testing.assert_array_equal(model.strategy.stdev, 0.1)
    assert model.learning_rate is None  # PGPE's step size is center_learning_rate


def test_logged_train_values(tmp_path: Path) -> None:
    (row,) = learn_logged(pendulum_model(), PENDULUM_GENERATION, tmp_path)
    assert float(row["train/learning_rate"]) == pytest.approx(0.075)
    assert float(row["train/speed"]) == pytest.approx(0.075)  # first step: lr along the normalized gradient


def test_load_continues_with_a_smaller_step(tmp_path: Path) -> None:
    """``load(max_speed=...)`` cuts ClipUp's step from the next update on; a default center rate follows it."""
    model = pendulum_model()
    model.learn(3 * PENDULUM_GENERATION)
    assert model.strategy.optimizer_stats()["speed"] > 0.06
    model.save(tmp_path / "model.zip")
    loaded = PGPE.load(tmp_path / "model.zip", env=pendulum_env(), max_speed=0.02)
    assert (loaded.strategy.max_speed, loaded.strategy.center_learning_rate) == (0.02, 0.01)
    (row,) = learn_logged(loaded, PENDULUM_GENERATION, tmp_path, reset_num_timesteps=False)
    assert float(row["train/learning_rate"]) == 0.01
    assert float(row["train/speed"]) == pytest.approx(0.02)  # the saved velocity, above 0.06, was cut
    kept = PGPE.load(tmp_path / "model.zip", max_speed=0.02, center_learning_rate=0.005)
    assert (kept.strategy.max_speed, kept.strategy.center_learning_rate) == (0.02, 0.005)


def test_load_narrows_the_search_distribution(tmp_path: Path) -> None:
    """``load(max_stdev=...)`` bounds the adapted standard deviations from the next generation on."""
    model = pendulum_model()
    model.learn(3 * PENDULUM_GENERATION)
    assert model.strategy.stdev.min() > 0.05  # the bound below lowers every one
    model.save(tmp_path / "model.zip")
    loaded = PGPE.load(tmp_path / "model.zip", env=pendulum_env(), max_stdev=0.05)
    assert loaded.max_stdev == loaded.strategy.max_stdev == 0.05
    (row,) = learn_logged(loaded, PENDULUM_GENERATION, tmp_path, reset_num_timesteps=False)
    assert float(row["train/stdev_max"]) <= 0.05
    assert loaded.strategy.stdev.max() <= 0.05


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (dict(max_stdev=0.05), r"stdev_init=0.1 is above max_stdev=0.05: lower it, or raise max_stdev"),
        (dict(max_stdev=0.0, stdev_init=0.1), r"max_stdev=0.0: it must be a positive number"),
    ],
)
def test_max_stdev_errors(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        pendulum_model(**kwargs)


def test_load_refuses_max_speed_without_clipup(tmp_path: Path) -> None:
    model = pendulum_model(optimizer="adam", center_learning_rate=0.01)
    model.save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=r"optimizer='adam' with .*max_speed=0.1: .* and no max_speed"):
        PGPE.load(tmp_path / "model.zip", max_speed=0.1)
