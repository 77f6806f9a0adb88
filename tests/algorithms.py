"""
The algorithms the generic tests are parametrized over (:data:`ALGORITHMS`, as SB3's tests over ``MODEL_LIST``),
and the helpers that train, inspect and compare their models. A new algorithm is covered by every generic test by
adding its entry to :data:`ALGOS`.

(Environments and wrappers are in ``envs.py``, which Ray workers receive by value.)
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch as th
from envs import read_csv
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, ProgressBarCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.logger import configure
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.vec_env import VecEnv

from sb3_es import ARS, CMAES, PGPE, REINFORCE, OpenES, SimpleES
from sb3_es.common.population_algorithm import PopulationAlgorithm


# ---------------------------------------------------------------------------- the algorithms
def torch_optimizer_steps(optimizer: th.optim.Optimizer) -> int:
    """:return: The steps a torch optimizer has taken (Adam counts them in its state; 0 before the first)."""
    state = optimizer.state_dict()["state"]
    return int(next(iter(state.values()))["step"]) if state else 0


def gradient_strategy_state(model: Any) -> dict[str, Any]:
    """:return: The center's torch copy and its optimizer's state (Adam's moments, ClipUp's velocity): OpenES, PGPE."""
    return {"theta": model.strategy._theta, "optimizer": model.strategy.optimizer.state_dict()}


def covariance(strategy: Any) -> np.ndarray:
    """:return: A CMA-ES strategy's full covariance matrix, or the diagonal of separable CMA-ES."""
    es = strategy.es
    return np.asarray(es.sm.C if hasattr(es.sm, "C") else es.dC)


def cma_state(model: Any) -> dict[str, Any]:
    """:return: pycma's state: mean, step size, covariance, iterations."""
    es = model.strategy.es
    return {"mean": es.mean, "sigma": es.sigma, "covariance": covariance(model.strategy), "countiter": es.countiter}


def population_of(n: int) -> dict[str, int]:
    """:return: The keyword arguments for ``n`` candidates per generation (OpenES, CMA-ES, PGPE, SimpleES)."""
    return {"population_size": n}


@dataclass(frozen=True)
class Algo:
    """
    An algorithm as the generic tests build it; they are parametrized over :data:`ALGORITHMS`.

    :param cls: The algorithm class.
    :param size: Keyword arguments for ``n`` candidates per generation (``n`` even), or ``n`` episodes per
        update for a policy-gradient method: the unit of work after which the parameters change.
    :param cartpole: Keyword arguments with which ``cls`` (seed 0) reaches a mean return of 475 on CartPole-v1
        within ``cartpole_steps`` env steps on ``cartpole_envs`` env slots.
    :param cartpole_steps: Budget of the CartPole learning check.
    :param cartpole_envs: Env slots of the CartPole learning check.
    :param policy: The policy alias the generic tests use.
    :param defaults: Keyword arguments every generic test passes.
    :param optimizer_steps: The updates the strategy (or optimizer) has applied, read from its own state, or
        ``None`` when it keeps no count: an interrupted or failed generation must not reach that state.
    :param logged: The ``train/`` keys (prefix left out) that every update logs, given ``logged_with``.
    :param logged_with: Keyword arguments that switch on the optional ones of ``logged``.
    :param extra_state: The state that only this algorithm's strategy keeps (an optimizer's moments, pycma's
        covariance), for :func:`assert_identical`: exact resumption must restore it too.
    """

    cls: type[BaseAlgorithm]
    size: Callable[[int], dict[str, int]]
    cartpole: dict[str, Any]
    cartpole_steps: int = 50_000
    cartpole_envs: int = 1
    policy: str = "LinearPolicy"
    defaults: dict[str, Any] = field(default_factory=dict)
    optimizer_steps: Callable[[Any], int] | None = None
    logged: tuple[str, ...] = ()
    logged_with: dict[str, Any] = field(default_factory=dict)
    extra_state: Callable[[Any], dict[str, Any]] | None = None

    @property
    def name(self) -> str:
        """:return: The class name (the test id)."""
        return self.cls.__name__

    @property
    def tb_log_name(self) -> str:
        """:return: The TensorBoard run name of ``learn()``'s default."""
        return str(inspect.signature(self.cls.learn).parameters["tb_log_name"].default)

    @property
    def population(self) -> bool:
        """:return: Whether this is a population method (candidates evaluated side by side, a strategy)."""
        return issubclass(self.cls, PopulationAlgorithm)

    def make(self, env: GymEnv | str, n: int, policy: str | None = None, **kwargs: Any) -> Any:
        """
        :param env: Environment, env id or VecEnv.
        :param n: Candidates per generation (episodes per update).
        :param policy: Policy alias (default: :attr:`policy`).
        :param kwargs: More keyword arguments (``seed`` defaults to 0).
        :return: A new model.
        """
        return self.cls(policy or self.policy, env, **{**self.defaults, "seed": 0, **self.size(n), **kwargs})

    def strategy_state(self, model: Any) -> dict[str, Any]:
        """:return: A population method's strategy state beyond the policy: center, best candidate, ``extra_state``."""
        strategy = model.strategy
        state = {"center": strategy.center, "best_params": strategy.best_params, "best_fitness": strategy.best_fitness}
        return state | (self.extra_state(model) if self.extra_state else {})


#: Every algorithm; a new one is covered by every generic test by adding its entry here.
ALGOS = [
    Algo(
        ARS,
        lambda n: {"n_delta": n // 2},
        dict(n_delta=2),
        cartpole_steps=40_000,
        logged=("step_size", "delta_std", "return_std", "learning_rate", "best_fitness", "n_updates"),
    ),
    Algo(
        OpenES,
        population_of,
        dict(population_size=16, sigma=0.5, learning_rate=0.1),
        optimizer_steps=lambda model: torch_optimizer_steps(model.strategy.optimizer),
        logged=("sigma", "learning_rate", "grad_norm", "best_fitness", "n_updates"),
        extra_state=lambda m: gradient_strategy_state(m) | {"sigma": m.strategy.sigma, "lr": m.strategy.learning_rate},
    ),
    Algo(
        CMAES,
        population_of,
        dict(sigma=0.5, n_eval_episodes=2),
        optimizer_steps=lambda m: m.strategy.es.countiter,
        logged=("sigma", "population_size", "restarts", "best_fitness", "n_updates"),
        extra_state=cma_state,
    ),
    Algo(
        PGPE,
        population_of,
        dict(population_size=16, stdev_init=0.5, max_speed=0.3),
        cartpole_steps=30_000,
        logged=("learning_rate", "stdev_mean", "stdev_min", "stdev_max", "speed", "grad_norm", "best_fitness"),
        extra_state=lambda model: gradient_strategy_state(model) | {"stdev": model.strategy.stdev},
    ),
    Algo(
        SimpleES,
        population_of,
        dict(population_size=16, sigma=0.5, n_elite=4),
        cartpole_steps=30_000,
        logged=("sigma", "step_norm", "best_fitness", "n_updates"),
    ),
    Algo(
        REINFORCE,
        lambda n: {"n_episodes": n},
        dict(learning_rate=1e-2, n_episodes=8, gamma=0.99),
        cartpole_steps=60_000,
        cartpole_envs=4,
        policy="MlpPolicy",
        defaults=dict(device="cpu"),
        optimizer_steps=lambda model: torch_optimizer_steps(model.policy.optimizer),
        logged=("policy_loss", "entropy", "learning_rate", "value_loss", "grad_norm", "n_steps", "n_updates"),
        logged_with=dict(use_baseline=True, max_grad_norm=1.0),
    ),
]
#: ``@pytest.mark.parametrize("algo", ALGORITHMS)``: every algorithm, with its name as the test id.
ALGORITHMS = [pytest.param(algo, id=algo.name) for algo in ALGOS]
#: The population methods (ask/tell strategy, candidates side by side, observation statistics in the policy).
POPULATION_ALGORITHMS = [pytest.param(algo, id=algo.name) for algo in ALGOS if algo.population]
#: Each algorithm by its class, for the cases of one algorithm below.
ALGO_OF = {algo.cls: algo for algo in ALGOS}
#: The algorithms that can read their perturbations from a shared noise table (``noise_table_size``).
NOISE_TABLE_ALGOS = [algo for algo in ALGOS if "noise_table_size" in inspect.signature(algo.cls).parameters]
NOISE_TABLE_ALGORITHMS = [pytest.param(algo, id=algo.name) for algo in NOISE_TABLE_ALGOS]


def cartpole_case(
    algo: Algo, variant: str = "", steps: int | None = None, policy: str | None = None, **kwargs: Any
) -> Any:
    """
    :param variant: What the case checks beyond ``algo``'s own case (the test id's suffix).
    :param steps: Budget (default: ``algo.cartpole_steps``), on ``algo.cartpole_envs`` env slots.
    :param policy: Policy alias (default: ``algo.policy``).
    :param kwargs: The settings (default: ``algo.cartpole``), over ``algo.defaults`` and seed 0.
    :return: A case of ``test_learns_cartpole``: ``(algo, policy, kwargs, steps)``.
    """
    return pytest.param(
        algo,
        policy or algo.policy,
        kwargs or algo.cartpole,
        steps or algo.cartpole_steps,
        id=f"{algo.name}-{variant}" if variant else algo.name,
    )


#: The settings that reach a mean return of 475 on CartPole-v1 within their budget (a few seconds each on 2 CPU
#: cores): each algorithm's own, and the options whose learning is checked too.
CARTPOLE_CASES = [
    *(cartpole_case(algo) for algo in ALGOS),
    # ClipUp with learning rate max_speed / 2 (the ClipUp paper's setting)
    cartpole_case(
        ALGO_OF[OpenES], "clipup", **{**ALGO_OF[OpenES].cartpole, "optimizer": "clipup", "learning_rate": 0.15}
    ),
    # seed 002's WinnerES (n_elite=1): with these settings 5 of the seeds 0-5 reached 475 within 30,000 steps for each
    # of n_elite=1 and 4 when this case was written (seed 1 stayed below)
    cartpole_case(ALGO_OF[SimpleES], "winner_es", **{**ALGO_OF[SimpleES].cartpole, "n_elite": 1}),
    # an MLP whose output layer starts at zero (zero_policy, ARS's default): its hidden layers give a signal at once
    cartpole_case(ALGO_OF[ARS], "zero_policy_mlp", steps=20_000, policy="MlpPolicy", zero_policy=True, seed=1),
    *(cartpole_case(algo, "noise_table", **algo.cartpole, noise_table_size=100_000) for algo in NOISE_TABLE_ALGOS),
]


# ---------------------------------------------------------------------------- training and logging
def pendulum_env() -> VecEnv:
    """One Pendulum-v1 env: its episodes last exactly 200 steps, so a generation of ``n`` candidates is ``200 n``."""
    return make_vec_env("Pendulum-v1", n_envs=1)


def learn_logged(model: BaseAlgorithm, total_timesteps: int, folder: Path, **learn_kwargs: Any) -> list[dict[str, str]]:
    """
    ``learn()`` with SB3's CSV logger writing into ``folder``.

    :return: The rows of ``progress.csv``.
    """
    model.set_logger(configure(str(folder), ["csv"]))
    model.learn(total_timesteps, **learn_kwargs)
    return read_csv(folder / "progress.csv")


def progress_at_generation_starts(rows: list[dict[str, str]], total: int) -> list[float]:
    """
    :param rows: ``progress.csv`` rows, one per generation, of a ``learn(total)`` run.
    :return: SB3's remaining progress (the argument of schedules) at the start of each generation.
    """
    starts = [0] + [int(row["time/total_timesteps"]) for row in rows[:-1]]
    return [1.0 - start / total for start in starts]


# ---------------------------------------------------------------------------- inspecting a model
def policy_vector(model: BaseAlgorithm) -> np.ndarray:
    """:return: A copy of the policy's trainable parameters, as one vector."""
    return th.nn.utils.parameters_to_vector(model.policy.parameters()).detach().cpu().numpy().copy()


def policy_state(model: BaseAlgorithm) -> dict[str, np.ndarray]:
    """:return: A copy of the policy's state dict (parameters and buffers, e.g. observation statistics)."""
    return {key: value.detach().cpu().numpy().copy() for key, value in model.policy.state_dict().items()}


def as_array(x: th.Tensor | np.ndarray) -> np.ndarray:
    """:return: A NumPy view of a tensor or array."""
    return x.detach().cpu().numpy() if isinstance(x, th.Tensor) else np.asarray(x)


def assert_identical(a: Any, b: Any, where: str = "") -> None:
    """
    Two nested structures (dicts, lists, tuples of arrays, tensors and plain values, e.g. :func:`policy_state` or
    ``get_parameters()``) hold the same keys and exactly the same values.
    """
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), where
        for key in a:
            assert_identical(a[key], b[key], f"{where}/{key}")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_identical(x, y, f"{where}/{i}")
    elif isinstance(a, (th.Tensor, np.ndarray)):
        np.testing.assert_array_equal(as_array(a), as_array(b), err_msg=where)
    else:
        assert a == b, where


def spy_on_ask(model: Any, record: Callable[[Any, np.ndarray], Any] = lambda strategy, population: population) -> list:
    """
    Record something at every ``strategy.ask()`` of a population method.

    :param model: The model.
    :param record: ``(strategy, population) -> entry``, called right after each ``ask()``; the default keeps
        the population.
    :return: The list the entries are appended to.
    """
    entries: list = []
    ask = model.strategy.ask

    def spy() -> np.ndarray:
        population = ask()
        entries.append(record(model.strategy, np.array(population, copy=True)))
        return population

    model.strategy.ask = spy
    return entries


class GenerationRecorder(BaseCallback):
    """
    Counts callback calls and remembers, at each generation (rollout) start, the vec-step count and the policy's
    parameters and state. ``stop_at``: return False from that call of ``on_step`` on;
    ``stop_in_generation``/``offset``: stop on the ``offset``-th vec step of that generation.
    """

    def __init__(self, stop_at: int | None = None, stop_in_generation: int | None = None, offset: int = 0) -> None:
        super().__init__()
        self.stop_at = stop_at
        self.stop_in_generation = stop_in_generation
        self.offset = offset
        self.rollout_starts: list[int] = []
        self.rollout_ends = 0
        self.params_at_start: list[np.ndarray] = []
        self.state_at_start: list[dict[str, np.ndarray]] = []
        self.training_started = 0
        self.training_ended = 0

    def _on_training_start(self) -> None:
        self.training_started += 1

    def _on_rollout_start(self) -> None:
        self.rollout_starts.append(self.n_calls)
        self.params_at_start.append(policy_vector(self.model))
        self.state_at_start.append(policy_state(self.model))
        if self.stop_in_generation is not None and len(self.rollout_starts) == self.stop_in_generation:
            self.stop_at = self.n_calls + self.offset

    def _on_rollout_end(self) -> None:
        self.rollout_ends += 1

    def _on_step(self) -> bool:
        return self.stop_at is None or self.n_calls < self.stop_at

    def _on_training_end(self) -> None:
        self.training_ended += 1


# ---------------------------------------------------------------------------- save / load
def hyperparameters(model: BaseAlgorithm) -> dict[str, Any]:
    """:return: The model's attributes that are plain values (hyperparameters, counters), ``None`` left out."""
    plain = (bool, int, float, str, tuple)
    return {key: value for key, value in vars(model).items() if isinstance(value, plain)}


def check_resume(build: Callable[[VecEnv], Any], env: Callable[[], VecEnv], n: int, path: Path) -> tuple[Any, Any]:
    """
    Check that ``learn(n)``, ``save``, ``load`` and learning the rest of ``2 n`` steps gives exactly the model
    that ``learn(2 n)`` gives, and the model that continued in memory; also after one more generation, which
    checks the state that is not in the policy (strategy, optimizer, random generators).

    :param build: A new model on the given env (same seed every call).
    :param env: A new env.
    :param n: Steps before the save.
    :param path: Where to save.
    :return: The uninterrupted model and the resumed one, for algorithm-specific checks.
    """
    straight = build(env())
    straight.learn(2 * n)
    first = build(env())
    first.learn(n)
    halfway = policy_vector(first)
    first.save(path)
    th.manual_seed(123)  # the global random states must not matter
    np.random.seed(123)
    resumed = type(first).load(path, env=env())
    np.random.rand(10)
    # Updates end at episode boundaries: ask for what is left of 2 n.
    resumed.learn(2 * n - resumed.num_timesteps, reset_num_timesteps=False)
    first.learn(2 * n - first.num_timesteps, reset_num_timesteps=False)
    for other in (resumed, first):
        assert other.num_timesteps == straight.num_timesteps
        assert other._n_updates == straight._n_updates
        assert_identical(policy_state(other), policy_state(straight))
    assert_identical(resumed.get_parameters(), straight.get_parameters())  # torch optimizers included
    assert not np.array_equal(halfway, policy_vector(straight))  # training moved: the equalities are not trivial
    for model in (straight, resumed):
        model.learn(1, reset_num_timesteps=False)  # one more generation (update)
    assert_identical(policy_state(resumed), policy_state(straight))
    return straight, resumed


def progress_bar_after_learn(model: Any, steps: int) -> Any:
    """:return: The progress bar (tqdm) of ``model.learn(steps, progress_bar=True)``, after it."""
    bars: list[ProgressBarCallback] = []
    init_callback = model._init_callback

    def spy(callback: Any, progress_bar: bool = False) -> Any:
        callbacks = init_callback(callback, progress_bar)
        bars.extend(c for c in getattr(callbacks, "callbacks", [callbacks]) if isinstance(c, ProgressBarCallback))
        return callbacks

    model._init_callback = spy
    model.learn(steps, progress_bar=True)
    (bar,) = bars
    return bar.pbar
