"""What is specific to OpenES: logged values, save/load of its options, sampling, fitness shaping, optimizers, decays,
best tracking, errors.

What every algorithm does (learning, step accounting, callbacks, logging) is in ``test_algorithms.py``, with
ClipUp's learning among its CartPole cases; exact resumption (Adam's moments, the decayed step sizes included) is in
``test_save_load.py``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch as th
from algorithms import (
    assert_identical,
    learn_logged,
    pendulum_env,
    progress_at_generation_starts,
    spy_on_ask,
)
from envs import ToyEnv, read_csv, rollout
from stable_baselines3.common.logger import configure
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_es import OpenES
from sb3_es.strategies import OpenESStrategy
from sb3_es.strategies.openes import centered_ranks, shape_fitness

POPULATION = 4
PENDULUM_GENERATION = POPULATION * 200  # Pendulum-v1: fixed 200-step episodes, one env


def pendulum_model(**kwargs: Any) -> OpenES:
    return OpenES("LinearPolicy", pendulum_env(), **{"population_size": POPULATION, "seed": 0, **kwargs})


def spy_on_sigma(model: OpenES) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """Record (center, sigma, population) at every ask()."""
    return spy_on_ask(model, lambda strategy, population: (strategy.center.copy(), strategy.sigma, population))


# ---------------------------------------------------------------------------- logging
def test_logged_train_values(tmp_path: Path) -> None:
    model = pendulum_model()
    (row,) = learn_logged(model, PENDULUM_GENERATION, tmp_path)
    assert float(row["train/sigma"]) == pytest.approx(0.1)
    assert float(row["train/learning_rate"]) == pytest.approx(0.01)


# ---------------------------------------------------------------------------- save / load / resume
def test_sgd_optimizer_comes_back_from_a_save(tmp_path: Path) -> None:
    model = pendulum_model(sigma=0.05, optimizer="sgd", momentum=0.5)
    model.learn(PENDULUM_GENERATION)
    model.save(tmp_path / "model.zip")
    loaded = OpenES.load(tmp_path / "model.zip")
    assert isinstance(loaded.strategy.optimizer, th.optim.SGD)
    assert loaded.strategy.optimizer.param_groups[0]["momentum"] == 0.5
    assert_identical(loaded.strategy.optimizer.state_dict(), model.strategy.optimizer.state_dict())


# ---------------------------------------------------------------------------- sampling and fitness shaping
def test_antithetic_candidates_are_mirrored_about_the_center() -> None:
    model = pendulum_model(population_size=6)
    asked = spy_on_sigma(model)
    model.learn(2 * 6 * 200)
    assert len(asked) == 2
    for center, sigma, population in asked:
        plus, minus = population[:3], population[3:]
        np.testing.assert_allclose(plus - center, -(minus - center), atol=1e-12)
        assert sigma == 0.1
        assert not np.allclose(plus, center)
    # Without mirrored sampling, the candidates are independent.
    strategy = OpenESStrategy(np.zeros(5), 6, sigma=0.1, learning_rate=0.01, antithetic=False, seed=0)
    population = strategy.ask()
    assert not np.allclose(population[:3], -population[3:])


def test_centered_ranks() -> None:
    np.testing.assert_allclose(centered_ranks(np.array([3.0, 1.0, 2.0, 10.0])), [1 / 6, -0.5, -1 / 6, 0.5])
    x = np.random.default_rng(0).normal(size=101) * 1e3
    ranks = centered_ranks(x)
    assert ranks.min() == -0.5 and ranks.max() == 0.5
    assert np.all(np.abs(ranks) <= 0.5)
    assert np.argmax(ranks) == np.argmax(x) and np.argmin(ranks) == np.argmin(x)
    np.testing.assert_allclose(np.sort(ranks), np.linspace(-0.5, 0.5, 101))
    # Ties get distinct ranks (as in OpenAI's and estool's compute_centered_ranks).
    np.testing.assert_allclose(centered_ranks(np.ones(3)), [-0.5, 0.0, 0.5])


def test_shape_fitness_options() -> None:
    fitness = np.array([1.0, 4.0, -2.0, 7.0])
    np.testing.assert_allclose(shape_fitness(fitness, "centered_rank"), centered_ranks(fitness))
    z = shape_fitness(fitness, "zscore")
    assert z.mean() == pytest.approx(0.0, abs=1e-12) and z.std() == pytest.approx(1.0)
    np.testing.assert_allclose(z, (fitness - fitness.mean()) / fitness.std())
    np.testing.assert_array_equal(shape_fitness(np.full(4, 3.0), "zscore"), 0.0)
    for value, n in ((0.3, 10), (1 / 3, 10), (200.7, 6)):  # their std() rounds to about 1e-17, not 0: it gave +-1
        np.testing.assert_array_equal(shape_fitness(np.full(n, value), "zscore"), 0.0)
    np.testing.assert_array_equal(shape_fitness(fitness, "raw"), fitness)
    with pytest.raises(ValueError, match="fitness_shaping"):
        shape_fitness(fitness, "rank")  # type: ignore[arg-type]


@pytest.mark.parametrize("shaping", ["centered_rank", "zscore", "raw"])
def test_strategy_update_uses_the_shaped_fitness(shaping: str) -> None:
    """Plain SGD step: center + lr * noise^T shaped / (P * sigma) (no weight decay, no momentum)."""
    strategy = OpenESStrategy(
        np.array([0.5, -1.0, 2.0]),
        8,
        sigma=0.2,
        learning_rate=0.3,
        fitness_shaping=shaping,  # type: ignore[arg-type]
        optimizer="sgd",
        momentum=0.0,
        seed=0,
    )
    center = strategy.center.copy()
    population = strategy.ask()
    noise = (population - center) / 0.2
    fitness = np.array([1.0, 5.0, 0.0, 2.0, 3.0, 0.5, 7.0, 1.5])
    info = strategy.tell(fitness)
    grad = noise.T @ shape_fitness(fitness, shaping) / (8 * 0.2)  # type: ignore[arg-type]
    np.testing.assert_allclose(strategy.center, center + 0.3 * grad, rtol=1e-10)
    assert info["grad_norm"] == pytest.approx(np.linalg.norm(grad))


@pytest.mark.parametrize("shaping", ["zscore", "raw"])
@pytest.mark.parametrize("optimizer", ["clipup", "adam"])
def test_a_flat_mirrored_generation_leaves_the_center(shaping: str, optimizer: str) -> None:
    # Every candidate scores the same (e.g. all 500 on CartPole): the gradient is 0. Summed as +eps and -eps terms it
    # was about 5e-13, which ClipUp normalized into a full step in a random direction.
    strategy = OpenESStrategy(
        np.zeros(50), 32, sigma=0.1, learning_rate=0.05, optimizer=optimizer, fitness_shaping=shaping, seed=0
    )
    strategy.ask()
    info = strategy.tell(np.full(32, 500.0))
    assert info["grad_norm"] == 0.0
    np.testing.assert_array_equal(strategy.center, 0.0)


def test_adam_and_sgd_momentum_steps() -> None:
    fitness = [np.array([1.0, 5.0, 0.0, 2.0]), np.array([3.0, -1.0, 2.0, 4.0])]

    def run(optimizer: str) -> tuple[list[np.ndarray], list[np.ndarray]]:
        strategy = OpenESStrategy(
            np.array([0.5, -1.0]), 4, sigma=0.1, learning_rate=0.05, optimizer=optimizer, weight_decay=0.1, seed=0
        )
        centers, grads = [strategy.center.copy()], []
        for f in fitness:
            population = strategy.ask()
            noise = (population - strategy.center) / 0.1
            # Descent direction of the optimizers: -(estimated gradient) + weight_decay * center.
            grads.append(-(noise.T @ centered_ranks(f)) / (4 * 0.1) + 0.1 * strategy.center)
            strategy.tell(f)
            centers.append(strategy.center.copy())
        return centers, grads

    centers, grads = run("sgd")  # momentum 0.9: v1 = g1, v2 = 0.9 v1 + g2
    np.testing.assert_allclose(centers[1], centers[0] - 0.05 * grads[0], rtol=1e-10)
    np.testing.assert_allclose(centers[2], centers[1] - 0.05 * (0.9 * grads[0] + grads[1]), rtol=1e-10)

    centers, grads = run("adam")  # first bias-corrected Adam step: lr * g / (|g| + eps)
    np.testing.assert_allclose(centers[1], centers[0] - 0.05 * grads[0] / (np.abs(grads[0]) + 1e-8), rtol=1e-7)


def test_sgd_optimizer_option() -> None:
    model = pendulum_model(optimizer="sgd", momentum=0.5, learning_rate=0.02)
    assert isinstance(model.strategy.optimizer, th.optim.SGD)
    assert model.strategy.optimizer.param_groups[0]["momentum"] == 0.5
    initial = model.strategy.center.copy()
    model.learn(2 * PENDULUM_GENERATION)
    assert model._n_updates == 2
    assert not np.array_equal(model.strategy.center, initial)
    assert np.all(np.isfinite(model.policy.parameters_to_vector()))
    assert isinstance(pendulum_model().strategy.optimizer, th.optim.Adam)


# ---------------------------------------------------------------------------- sigma / learning rate
def test_sigma_and_learning_rate_decay_to_their_floor(tmp_path: Path) -> None:
    model = pendulum_model(
        population_size=2,
        sigma=0.1,
        sigma_decay=0.5,
        sigma_limit=0.02,
        learning_rate=0.04,
        learning_rate_decay=0.5,
        learning_rate_limit=0.01,
    )
    asked = spy_on_sigma(model)
    rows = learn_logged(model, 5 * 2 * 200, tmp_path)
    assert len(rows) == 5
    np.testing.assert_allclose([float(r["train/sigma"]) for r in rows], [0.1, 0.05, 0.025, 0.02, 0.02])
    np.testing.assert_allclose([float(r["train/learning_rate"]) for r in rows], [0.04, 0.02, 0.01, 0.01, 0.01])
    # The perturbations really use the decayed noise: candidates are center +/- sigma * eps.
    for (center, sigma, population), row in zip(asked, rows):
        assert sigma == pytest.approx(float(row["train/sigma"]))
        np.testing.assert_allclose(population[0] - center, center - population[1], atol=1e-12)


def test_sb3_schedules(tmp_path: Path) -> None:
    total = 4 * PENDULUM_GENERATION
    model = pendulum_model(sigma=lambda progress: 0.1 * progress, learning_rate=lambda progress: 0.02 * progress)
    asked = spy_on_sigma(model)
    rows = learn_logged(model, total, tmp_path)
    assert len(rows) == 4
    progress = progress_at_generation_starts(rows, total)
    np.testing.assert_allclose([float(r["train/sigma"]) for r in rows], [0.1 * p for p in progress])
    np.testing.assert_allclose([float(r["train/learning_rate"]) for r in rows], [0.02 * p for p in progress])
    for (_, sigma, _), p in zip(asked, progress):
        assert sigma == pytest.approx(0.1 * p)


def test_values_below_the_floor_are_not_raised(tmp_path: Path) -> None:
    """estool only decays while above the limit; a value set below it is used as given."""
    model = pendulum_model(sigma=0.005, learning_rate=1e-4)  # defaults: sigma_limit=0.01, learning_rate_limit=1e-3
    row = learn_logged(model, PENDULUM_GENERATION, tmp_path)[0]
    assert float(row["train/sigma"]) == pytest.approx(0.005)
    assert float(row["train/learning_rate"]) == pytest.approx(1e-4)


# ---------------------------------------------------------------------------- weight decay, best tracking
@pytest.mark.parametrize("weight_decay", [0.0, 0.05])
def test_weight_decay_with_flat_fitness(weight_decay: float) -> None:
    """CartPole with alive_bonus_offset=-1: every fitness is 0, so only weight decay moves the center."""
    model = OpenES(
        "LinearPolicy",
        "CartPole-v1",
        population_size=4,
        alive_bonus_offset=-1.0,
        fitness_shaping="zscore",
        weight_decay=weight_decay,
        learning_rate=0.01,
        seed=0,
    )
    initial = np.array([0.5, -0.3, 0.2, -0.8, 0.1, 0.4, -0.6, 0.7])
    model.policy.load_from_vector(initial)
    model.strategy.set_center(initial)
    model.learn(1)
    model.learn(1, reset_num_timesteps=False)
    assert model._n_updates == 2
    center = model.strategy.center
    if weight_decay == 0:
        np.testing.assert_array_equal(center, initial)
    else:
        # The decay gradient is weight_decay * center: Adam moves every weight toward zero by about lr per step.
        np.testing.assert_array_equal(np.sign(center), np.sign(initial))
        np.testing.assert_allclose(np.abs(initial) - np.abs(center), 2 * 0.01, rtol=0.01)


def test_forget_best_in_the_strategy() -> None:
    """With ``forget_best`` the best is the latest generation's (the default is checked for every strategy)."""
    strategy = OpenESStrategy(np.zeros(3), 4, sigma=0.1, learning_rate=0.01, forget_best=True, seed=0)
    strategy.ask()
    strategy.tell(np.array([1.0, 9.0, 3.0, 2.0]))
    assert strategy.best_fitness == 9.0
    second = strategy.ask().copy()
    strategy.tell(np.array([4.0, 0.0, 5.0, 1.0]))
    assert strategy.best_fitness == 5.0
    np.testing.assert_array_equal(strategy.best_params, second[2])


@pytest.mark.parametrize("forget_best", [False, True])
def test_best_tracking_in_training(tmp_path: Path, forget_best: bool) -> None:
    env = DummyVecEnv([ToyEnv])
    model = OpenES(
        "LinearPolicy",
        env,
        population_size=6,
        sigma=0.3,
        forget_best=forget_best,
        seed=0,
        policy_kwargs=dict(normalize_observations=False),
    )
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(1)
    for _ in range(3):
        model.learn(1, reset_num_timesteps=False)
    rows = read_csv(tmp_path / "progress.csv")
    best = [float(r["train/best_fitness"]) for r in rows]
    generation_max = [float(r["rollout/candidate_return_max"]) for r in rows]
    expected = generation_max if forget_best else np.maximum.accumulate(generation_max)
    np.testing.assert_allclose(best, expected)
    # best_params reproduce best_fitness (ToyEnv is deterministic, no observation normalization).
    assert model.best_params is model.strategy.best_params
    episode_return, _, _ = rollout(ToyEnv(), model.policy, model.best_params)
    assert episode_return == pytest.approx(model.strategy.best_fitness, abs=1e-9)


# ---------------------------------------------------------------------------- errors
@pytest.mark.parametrize("population_size", [3, 7])
def test_odd_population_with_antithetic(population_size: int) -> None:
    with pytest.raises(ValueError, match="population_size"):
        OpenES("LinearPolicy", "Pendulum-v1", population_size=population_size)
    model = OpenES("LinearPolicy", "Pendulum-v1", population_size=population_size, antithetic=False)
    assert model.strategy.ask().shape == (population_size, model.policy.num_params)


def test_decay_of_one_is_accepted() -> None:
    # a decay of 1 keeps the value: the limits below it never act
    model = OpenES(
        "LinearPolicy", "Pendulum-v1", population_size=4, sigma=0.3, learning_rate=0.05, sigma_decay=1.0,
        learning_rate_decay=1.0, sigma_limit=0.01, learning_rate_limit=0.001, seed=0,
    )  # fmt: skip
    model.learn(2 * 4 * 200)
    assert model._n_updates == 2
    assert (model.strategy.sigma, model.strategy.learning_rate) == (0.3, 0.05)


# ---------------------------------------------------------------------------- ClipUp
def test_clipup_optimizer_option() -> None:
    """optimizer="clipup": the first step has length learning_rate along the estimated gradient."""
    strategy = OpenESStrategy(np.array([0.5, -1.0, 2.0]), 8, sigma=0.2, learning_rate=0.05, optimizer="clipup", seed=0)
    center = strategy.center.copy()
    population = strategy.ask()
    noise = (population - center) / 0.2
    fitness = np.array([1.0, 5.0, 0.0, 2.0, 3.0, 0.5, 7.0, 1.5])
    info = strategy.tell(fitness)
    grad = noise.T @ centered_ranks(fitness) / (8 * 0.2)
    np.testing.assert_allclose(strategy.center, center + 0.05 * grad / np.linalg.norm(grad), rtol=1e-10)
    assert info["speed"] == pytest.approx(0.05)
    model = pendulum_model(optimizer="clipup", learning_rate=0.1, max_speed=0.15)
    assert model.strategy.optimizer.param_groups[0]["max_speed"] == 0.15
    with pytest.raises(ValueError, match="max_speed"):
        pendulum_model(optimizer="adam", max_speed=0.15)


def test_schedule_and_decay_together_are_rejected() -> None:
    with pytest.raises(ValueError, match="sigma_decay=0.9 decays a float sigma"):
        OpenES("LinearPolicy", "Pendulum-v1", sigma=lambda progress: 0.1 * progress, sigma_decay=0.9)
    with pytest.raises(ValueError, match="learning_rate_decay"):
        OpenES("LinearPolicy", "Pendulum-v1", learning_rate=lambda progress: 0.1, learning_rate_decay=0.5)
