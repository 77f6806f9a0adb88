"""What is specific to CMA-ES: logged values, pycma state in save/load, private random state, covariance and
population size, stop conditions and restarts, pycma options, errors.

What every algorithm does (learning, step accounting, callbacks, logging) is in ``test_algorithms.py``; exact
resumption, pycma's state included (``algorithms.cma_state``), full and separable, in ``test_save_load.py``.
"""

from __future__ import annotations

import copy
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from algorithms import assert_identical, cma_state, covariance, learn_logged, pendulum_env, policy_state, spy_on_ask
from envs import read_csv
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import configure
from torch import nn

from sb3_es import CMAES
from sb3_es.strategies import CMAESStrategy

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import cma

PENDULUM_POPULATION = 7  # pycma's default for the 3 parameters of a linear Pendulum policy: 4 + int(3 ln 3)
PENDULUM_GENERATION = PENDULUM_POPULATION * 200  # fixed 200-step episodes, one env
#: The seed document's network for BipedalWalker-v3: 24-40-40-4, tanh, 2,804 parameters.
WALKER_KWARGS = dict(net_arch=[40, 40], activation_fn=nn.Tanh)
#: pycma options that make it stop after its first generation on CartPole (returns differ by less than 1e3).
QUICK_STOP = {"tolfun": 1e3, "tolfunhist": 1e3}


def pendulum_model(**kwargs: Any) -> CMAES:
    return CMAES("LinearPolicy", pendulum_env(), **{"seed": 0, **kwargs})


def spy_on_population_sizes(model: CMAES) -> list[tuple[int, float]]:
    """Record (population size, sigma) of every generation asked."""
    return spy_on_ask(model, lambda strategy, _: (strategy.population_size, strategy.sigma))


def assert_same_cma_state(a: CMAES, b: CMAES) -> None:
    assert_identical(policy_state(a), policy_state(b))
    assert_identical(cma_state(a), cma_state(b))
    np.testing.assert_array_equal(a.strategy.ask(), b.strategy.ask())


# ---------------------------------------------------------------------------- logging
def test_logged_train_values(tmp_path: Path) -> None:
    model = pendulum_model()
    rows = learn_logged(model, 2 * PENDULUM_GENERATION, tmp_path)
    assert not any(key.startswith("train/stop_") for key in rows[0])
    assert [float(r["train/population_size"]) for r in rows] == [PENDULUM_POPULATION] * 2
    assert float(rows[-1]["train/sigma"]) == pytest.approx(model.strategy.es.sigma)


# ---------------------------------------------------------------------------- save / load / resume
def test_save_load_restores_the_pycma_state(tmp_path: Path) -> None:
    model = CMAES("MlpPolicy", pendulum_env(), sigma=0.2, population_size=6, seed=0, policy_kwargs=dict(net_arch=[8]))
    model.learn(2 * 6 * 200)
    model.save(tmp_path / "model.zip")
    loaded = CMAES.load(tmp_path / "model.zip")
    assert (loaded.sigma, loaded.population_size, loaded.diagonal, loaded.restarts) == (0.2, 6, "auto", None)
    np.testing.assert_array_equal(loaded.strategy.es.mean, model.strategy.es.mean)
    assert loaded.strategy.es.sigma == model.strategy.es.sigma
    np.testing.assert_array_equal(covariance(loaded.strategy), covariance(model.strategy))
    assert loaded.strategy.es.countiter == model.strategy.es.countiter == 2


def test_loaded_strategy_asks_what_the_saved_one_would(tmp_path: Path) -> None:
    model = pendulum_model()
    model.learn(PENDULUM_GENERATION)
    np.random.seed(1)
    model.save(tmp_path / "a.zip")
    np.random.seed(2)
    model.save(tmp_path / "b.zip")
    expected = model.strategy.ask()
    np.testing.assert_array_equal(CMAES.load(tmp_path / "a.zip").strategy.ask(), expected)
    np.testing.assert_array_equal(CMAES.load(tmp_path / "b.zip").strategy.ask(), expected)


class GlobalRandomUser(BaseCallback):
    """Draws from NumPy's global random state at every step, as other code in the process might."""

    def _on_step(self) -> bool:
        np.random.rand(3)
        return True


def test_private_random_state_ignores_and_preserves_the_global_one() -> None:
    reference = pendulum_model(seed=5)
    reference.learn(2 * PENDULUM_GENERATION)

    model = pendulum_model(seed=5)
    np.random.seed(0)
    model.learn(PENDULUM_GENERATION, callback=GlobalRandomUser())
    np.random.seed(1)
    np.random.rand(7)
    model.learn(PENDULUM_GENERATION, reset_num_timesteps=False, callback=GlobalRandomUser())
    assert_same_cma_state(reference, model)

    # pycma's draws do not consume or reseed the global state (SB3 seeds it when the model is built, not in learn()).
    other = pendulum_model(seed=6)
    np.random.seed(7)
    other.learn(2 * PENDULUM_GENERATION)
    drawn = np.random.rand(5)
    np.random.seed(7)
    np.testing.assert_array_equal(drawn, np.random.rand(5))
    strategy = CMAESStrategy(np.zeros(4), sigma=0.1, seed=0)
    np.random.seed(7)
    strategy.tell(-np.sum(strategy.ask() ** 2, axis=1))
    np.testing.assert_array_equal(drawn, np.random.rand(5))


# ---------------------------------------------------------------------------- covariance and population size
def test_diagonal_auto_small_policy_uses_full_covariance() -> None:
    model = CMAES("LinearPolicy", "CartPole-v1", seed=0)
    assert model.policy.num_params == 8 <= CMAES.DIAGONAL_THRESHOLD
    assert model.strategy.diagonal is False
    assert not model.strategy.es.opts["CMA_diagonal"]
    assert covariance(model.strategy).shape == (8, 8)
    forced = CMAES("LinearPolicy", "CartPole-v1", diagonal=True, seed=0)
    assert forced.strategy.diagonal is True
    assert forced.strategy.es.opts["CMA_diagonal"] is True
    assert covariance(forced.strategy).shape == (8,)


def test_diagonal_auto_threshold() -> None:
    """Full covariance up to DIAGONAL_THRESHOLD parameters, diagonal above (a class attribute one can change)."""

    class AtThreshold(CMAES):
        DIAGONAL_THRESHOLD = 8

    class BelowThreshold(CMAES):
        DIAGONAL_THRESHOLD = 7

    assert AtThreshold("LinearPolicy", "CartPole-v1", seed=0).strategy.diagonal is False
    assert BelowThreshold("LinearPolicy", "CartPole-v1", seed=0).strategy.diagonal is True
    assert BelowThreshold("LinearPolicy", "CartPole-v1", diagonal=False, seed=0).strategy.diagonal is False


@pytest.fixture(scope="module")
def walker_model() -> CMAES:
    return CMAES(
        "MlpPolicy", make_vec_env("BipedalWalker-v3", n_envs=1), population_size=8, seed=0, policy_kwargs=WALKER_KWARGS
    )


def test_diagonal_auto_large_policy_uses_diagonal_covariance(walker_model: CMAES) -> None:
    assert walker_model.policy.num_params == 2804 > CMAES.DIAGONAL_THRESHOLD
    assert walker_model.strategy.diagonal is True
    assert walker_model.strategy.es.opts["CMA_diagonal"] is True
    assert covariance(walker_model.strategy).shape == (2804,)


@pytest.mark.parametrize("env_id", ["CartPole-v1", "BipedalWalker-v3"])
def test_default_population_size_is_pycmas(env_id: str) -> None:
    kwargs = dict(policy_kwargs=WALKER_KWARGS) if env_id == "BipedalWalker-v3" else {}
    policy = "MlpPolicy" if kwargs else "LinearPolicy"
    model = CMAES(policy, env_id, seed=0, **kwargs)  # type: ignore[arg-type]
    n = model.policy.num_params
    expected = 4 + int(3 * math.log(n))
    assert model.strategy.population_size == expected == model.strategy.default_population_size
    es = cma.CMAEvolutionStrategy(np.zeros(n), 1.0, {"verbose": -9, "CMA_diagonal": True})
    assert es.popsize == expected
    assert (n, expected) in ((8, 10), (2804, 27))


def test_large_policy_generation_save_load_resume(walker_model: CMAES, tmp_path: Path) -> None:
    model = copy.deepcopy(walker_model)  # the module's model stays untrained
    model.learn(1)
    assert model._n_updates == 1
    assert model.num_timesteps > 0
    assert model.strategy.population_size == 8
    model.save(tmp_path / "walker.zip")
    loaded = CMAES.load(tmp_path / "walker.zip", env=make_vec_env("BipedalWalker-v3", n_envs=1))
    np.testing.assert_array_equal(loaded.policy.parameters_to_vector(), model.policy.parameters_to_vector())
    np.testing.assert_array_equal(loaded.strategy.es.mean, model.strategy.es.mean)
    np.testing.assert_array_equal(covariance(loaded.strategy), covariance(model.strategy))
    assert loaded.strategy.diagonal is True and loaded.strategy.population_size == 8
    steps = loaded.num_timesteps
    loaded.learn(1, reset_num_timesteps=False)
    assert loaded._n_updates == 2 and loaded.strategy.es.countiter == 2
    assert loaded.num_timesteps > steps
    assert np.all(np.isfinite(loaded.policy.parameters_to_vector()))


# ---------------------------------------------------------------------------- stop conditions and restarts
def test_stop_conditions_end_training(tmp_path: Path) -> None:
    model = CMAES("LinearPolicy", "CartPole-v1", seed=0, cma_options=QUICK_STOP)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    with pytest.warns(UserWarning, match=r"CMA-ES stop conditions fired \(.*\) at \d+ env steps; training ends before"):
        model.learn(100_000)  # said whatever the verbosity: learn() returns before total_timesteps
    assert model._n_updates == 1
    assert model.num_timesteps < 10 * 500
    assert model.strategy.stopped
    assert set(model.strategy.last_stop) & {"tolfun", "tolfunhist"}
    rows = read_csv(tmp_path / "progress.csv")
    assert len(rows) == 1
    stop_keys = {key for key in rows[0] if key.startswith("train/stop_")}
    assert stop_keys == {f"train/stop_{key}" for key in model.strategy.last_stop}
    assert all(rows[0][key] != "" for key in stop_keys)


def test_no_stop_without_the_options() -> None:
    model = pendulum_model()
    model.learn(3 * PENDULUM_GENERATION)
    assert model._n_updates == 3
    assert not model.strategy.stopped


def test_ipop_restart_doubles_the_population(tmp_path: Path) -> None:
    model = CMAES("LinearPolicy", "CartPole-v1", seed=0, restarts="ipop", max_restarts=5, cma_options=QUICK_STOP)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    asked = spy_on_population_sizes(model)
    model.learn(1)
    model.learn(1, reset_num_timesteps=False)
    model.learn(1, reset_num_timesteps=False)
    assert [size for size, _ in asked] == [10, 20, 40]
    assert model.strategy.n_restarts == 3
    assert not model.strategy.stopped
    rows = read_csv(tmp_path / "progress.csv")
    assert [float(r["train/population_size"]) for r in rows] == [10, 20, 40]
    assert [float(r["train/restarts"]) for r in rows] == [0, 1, 2]
    # Every restart starts from the best candidate found so far, with the initial step size.
    np.testing.assert_array_equal(model.strategy.es.x0, model.strategy.best_params)
    assert all(sigma == pytest.approx(0.1) for _, sigma in asked)


@pytest.mark.parametrize("max_restarts", [1, 2])
def test_ipop_runs_max_restarts_restarts(max_restarts: int) -> None:
    model = CMAES(
        "LinearPolicy", "CartPole-v1", seed=0, restarts="ipop", max_restarts=max_restarts, cma_options=QUICK_STOP
    )
    asked = spy_on_population_sizes(model)
    model.learn(100_000)
    assert model.strategy.stopped
    # The first run plus max_restarts restarted runs, each stopping after one generation.
    assert [size for size, _ in asked] == [10 * 2**k for k in range(max_restarts + 1)]


def test_a_model_out_of_restarts_searches_on_when_loaded_with_more(tmp_path: Path) -> None:
    model = CMAES("LinearPolicy", "CartPole-v1", seed=0, restarts="ipop", max_restarts=1, cma_options=QUICK_STOP)
    with pytest.warns(UserWarning, match=r"All max_restarts=1 restarts have run; .*CMAES.load\(path, max_restarts="):
        model.learn(100_000)
    assert model.strategy.stopped and model.strategy.n_restarts == 1
    model.save(tmp_path / "model.zip")
    loaded = CMAES.load(tmp_path / "model.zip", env=make_vec_env("CartPole-v1"), max_restarts=3)
    assert not loaded.strategy.stopped
    asked = spy_on_population_sizes(loaded)
    with pytest.warns(UserWarning, match="All max_restarts=3 restarts have run"):
        loaded.learn(100_000, reset_num_timesteps=False)
    # The stopped run is restarted at the next generation: two more restarts, each doubling the population.
    assert loaded.strategy.n_restarts == 3
    assert [size for size, _ in asked] == [40, 80]


def test_without_restarts_the_stop_warning_names_restarts() -> None:
    model = CMAES("LinearPolicy", "CartPole-v1", seed=0, cma_options=QUICK_STOP)
    with pytest.warns(UserWarning, match=r"To keep searching, train with restarts='ipop' or 'bipop'"):
        model.learn(100_000)
    with pytest.warns(UserWarning, match=r"CMA-ES has stopped .*; learn\(\) does nothing. To keep searching"):
        model.learn(1_000)
    # Weights written into the policy start a new pycma run from them.
    steps = model.num_timesteps
    model.policy.load_from_vector(model.best_params + 0.01)
    with pytest.warns(UserWarning, match="CMA-ES stop conditions fired"):
        model.learn(1_000, reset_num_timesteps=False)
    assert model.num_timesteps > steps and model.strategy.es.countiter == 1


def test_a_copy_taken_between_ask_and_tell_can_tell() -> None:
    strategy = CMAESStrategy(np.zeros(5), sigma=0.5, population_size=6, seed=0)
    strategy.ask()
    copied = copy.deepcopy(strategy)
    strategy.tell(np.arange(6.0))
    copied.tell(np.arange(6.0))
    np.testing.assert_array_equal(copied.center, strategy.center)


def test_center_follows_a_restart() -> None:
    model = CMAES("LinearPolicy", "CartPole-v1", seed=0, restarts="ipop", cma_options=QUICK_STOP)
    model.learn(1)
    assert model.strategy.n_restarts == 1
    np.testing.assert_array_equal(model.strategy.center, model.strategy.es.mean)
    np.testing.assert_array_equal(model.policy.parameters_to_vector(), model.strategy.es.mean.astype(np.float32))


def test_bipop_runs_large_and_small_regimes() -> None:
    model = CMAES("LinearPolicy", "CartPole-v1", seed=0, restarts="bipop", max_restarts=9, cma_options=QUICK_STOP)
    asked = spy_on_population_sizes(model)
    model.learn(60_000)
    assert model.strategy.n_restarts >= 4
    restarted = asked[1:]
    base = model.strategy.base_population_size
    assert any(size > base and sigma == pytest.approx(0.1) for size, sigma in restarted)  # large regime
    assert any(size <= base and sigma < 0.1 for size, sigma in restarted)  # small regime: smaller steps
    # The first run counts on the small budget (as in pycma's fmin and Hansen's code): the first restart is large.
    assert restarted[0] == (2 * base, pytest.approx(0.1))
    assert np.all(np.isfinite(model.policy.parameters_to_vector()))


def test_bipop_small_runs_are_capped_and_do_not_count_as_restarts() -> None:
    # pycma's fmin: a small-population run gets at most half the evaluations of the large runs so far (maxiter), and
    # only large runs count against maxrestarts
    strategy = CMAESStrategy(np.zeros(5), sigma=0.5, restarts="bipop", max_restarts=1, seed=0)
    strategy._budget = {"large": 2_000, "small": 0}
    strategy.es.countevals = 500  # the run now ending (small: the first run counts on the small budget)
    strategy._restart()
    assert strategy._regime == "small" and strategy.n_restarts == 1
    assert strategy.es.opts["maxiter"] == int(0.5 * 2_000 / strategy.population_size)
    assert strategy._restart_left()  # the small run did not use up max_restarts=1
    strategy.es.countevals = 2_000  # the small budget reaches the large one: a large run next
    strategy._restart()
    assert strategy._regime == "large" and strategy.population_size == 2 * strategy.base_population_size
    assert strategy.es.opts["maxiter"] != int(0.5 * 2_000 / strategy.population_size)  # pycma's default
    assert not strategy._restart_left()
    # a user's smaller maxiter stays
    strategy = CMAESStrategy(np.zeros(5), sigma=0.5, restarts="bipop", cma_options={"maxiter": 3}, seed=0)
    strategy._budget = {"large": 2_000, "small": 0}
    strategy._restart()
    assert strategy._regime == "small" and strategy.es.opts["maxiter"] == 3


@pytest.mark.parametrize("options", [dict(ftarget=1e-2), dict(maxfevals=200)], ids=["ftarget", "maxfevals"])
def test_ftarget_and_maxfevals_end_the_search_without_a_restart(options: dict) -> None:
    # as in pycma's fmin: they restarted IPOP three more times (maxfevals counted per run)
    def sphere(x: np.ndarray) -> np.ndarray:
        return -np.sum((x - 1.0) ** 2, axis=1)

    strategy = CMAESStrategy(np.zeros(6), sigma=0.5, seed=0, restarts="ipop", max_restarts=3, cma_options=options)
    evaluations = 0
    while not strategy.stopped and evaluations < 100_000:
        population = strategy.ask()
        evaluations += len(population)
        strategy.tell(sphere(population))
    assert strategy.stopped and strategy.reached_an_end and strategy.n_restarts == 0
    assert set(strategy.last_stop) & set(options)
    assert evaluations <= options.get("maxfevals", np.inf) + strategy.population_size


def test_maxfevals_counts_the_evaluations_of_every_run() -> None:
    strategy = CMAESStrategy(np.zeros(5), sigma=0.5, restarts="ipop", cma_options={"maxfevals": 1_000}, seed=0)
    strategy.es.countevals = 300  # the run now ending, stopped by another condition
    strategy._restart()
    assert strategy.es.opts["maxfevals"] == 700


def test_the_stop_warning_after_ftarget_does_not_advise_restarts() -> None:
    model = CMAES("LinearPolicy", "CartPole-v1", seed=0, restarts="ipop", cma_options=dict(ftarget=-10.0))
    with pytest.warns(UserWarning, match=r"ftarget and maxfevals end the search, as in pycma's fmin"):
        model.learn(100_000)
    assert model.strategy.stopped and model.strategy.n_restarts == 0


@pytest.mark.parametrize("key", ["bounds", "fixed_variables", "scaling_of_variables", "typical_x", "transformation"])
def test_cma_options_that_transform_the_search_space_are_refused(key: str) -> None:
    # pycma's mean is then not the policy's parameters: typical_x=[5]*4 put [-4, ...] into the policy while pycma's
    # solution was [1, ...]; fixed_variables failed with a shape error
    with pytest.raises(ValueError, match=rf"cma_options\['{key}'\]: this option makes pycma search a transformed"):
        CMAESStrategy(np.zeros(4), sigma=0.3, seed=0, cma_options={key: None})


def test_weights_written_during_a_bipop_small_run_keep_its_cap_and_its_evaluations() -> None:
    strategy = CMAESStrategy(np.zeros(5), sigma=0.5, restarts="bipop", max_restarts=1, seed=0)
    strategy._budget = {"large": 2_000, "small": 0}
    strategy._restart()  # a small run, capped
    cap = strategy.es.opts["maxiter"]
    for _ in range(2):
        strategy.ask()
        strategy.tell(np.arange(float(strategy.population_size)))
    spent, budget = strategy.es.countevals, dict(strategy._budget)
    strategy.set_center(np.ones(5))
    assert strategy._budget == {"large": 2_000, "small": budget["small"] + spent}
    assert strategy.es.opts["maxiter"] == cap - 2


@pytest.mark.parametrize("key", ["popsize", "seed", "CMA_diagonal"])
def test_cma_options_set_by_sb3_es_are_rejected(key: str) -> None:
    with pytest.raises(ValueError, match=key):
        CMAES("LinearPolicy", "Pendulum-v1", cma_options={key: 8})


def test_cma_options_are_passed_to_pycma() -> None:
    model = CMAES("LinearPolicy", "Pendulum-v1", cma_options={"tolx": 1e-7, "CMA_elitist": True})
    assert model.strategy.es.opts["tolx"] == 1e-7
    assert model.strategy.es.opts["CMA_elitist"] is True
    # Strings are evaluated by pycma ("1e-3", as YAML 1.1 reads 1e-3), and the valid string values are kept.
    model = CMAES("LinearPolicy", "Pendulum-v1", cma_options={"tolfun": "1e-3", "CMA_elitist": "initial"})
    assert model.strategy.es.opts["tolfun"] == 1e-3 and model.strategy.es.opts["CMA_elitist"] == "initial"


@pytest.mark.filterwarnings("ignore:.*is not a safe string")
def test_cma_options_that_pycma_cannot_read_as_a_number_are_refused_at_construction() -> None:
    """pycma keeps a string it cannot evaluate and fails in the middle of ``learn()``; the constructor refuses it."""
    with pytest.raises(ValueError, match=r"cma_options\['tolfun'\]='abc': pycma cannot read it as a number"):
        CMAES("LinearPolicy", "Pendulum-v1", cma_options={"tolfun": "abc"})


# ---------------------------------------------------------------------------- strategy alone
def test_strategy_alone_is_reproducible() -> None:
    def run(seed: int) -> np.ndarray:
        strategy = CMAESStrategy(np.zeros(3), sigma=0.3, diagonal=True, seed=seed)
        for _ in range(5):
            population = strategy.ask()
            strategy.tell(-np.sum(population**2, axis=1))
        return strategy.center

    np.testing.assert_array_equal(run(0), run(0))
    assert not np.array_equal(run(0), run(1))


# ---------------------------------------------------------------------------- errors
def test_no_learning_rate(tmp_path: Path) -> None:
    """CMA-ES adapts its own step size: the model has no learning rate (no dummy value) and logs none."""
    model = pendulum_model()
    assert model.learning_rate is None
    assert not hasattr(model.strategy, "learning_rate")
    (row,) = learn_logged(model, PENDULUM_GENERATION, tmp_path)
    assert "train/sigma" in row and "train/learning_rate" not in row
