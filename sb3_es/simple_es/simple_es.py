"""The elementary evolution strategies of seed 002 (WinnerES, weighted average of the top children) as an SB3
algorithm."""

from __future__ import annotations

from typing import Any, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule

from sb3_es.common.arguments import base_arguments
from sb3_es.common.base_class import constant_value
from sb3_es.common.population_algorithm import (
    PopulationAlgorithm,
    check_noise_table_size,
    check_positive,
    initial_value,
    make_noise_table,
)
from sb3_es.evaluation import PopulationEvaluator
from sb3_es.simple_es.policies import FlatPolicy
from sb3_es.strategies.base import check_count
from sb3_es.strategies.simple_es import EliteWeights, SimpleESStrategy

SelfSimpleES = TypeVar("SelfSimpleES", bound="SimpleES")


class SimpleES(PopulationAlgorithm):
    """
    The simplest evolution strategy: ``population_size`` children ``center + sigma * eps``, and the center moves
    to the weighted average of the ``n_elite`` best (see :class:`~sb3_es.strategies.SimpleESStrategy`).

    - **WinnerES** (the default, ``n_elite=1``): the center moves to the best child.
    - **Weighted average of the top n children**: ``n_elite=n``, with rank-based ``weights``.

    :param population_size: Children per generation.
    :param sigma: Standard deviation of the children, a float or an SB3 schedule.
    :param n_elite: Number of best children averaged (1: WinnerES).
    :param weights: ``"log"`` (CMA-ES's recombination weights, the default), ``"linear"`` or ``"equal"``.
    :param noise_table_size: Size of the shared noise table to read perturbations from (``None``: drawn fresh).

    The other parameters are those of :class:`~sb3_es.common.population_algorithm.PopulationAlgorithm`.
    """

    strategy: SimpleESStrategy
    scheduled_hyperparameters = ("sigma",)
    strategy_hyperparameters = ("population_size",)

    def __init__(
        self,
        policy: str | type[FlatPolicy],
        env: GymEnv | str | None,
        population_size: int = 16,
        sigma: float | Schedule = 0.1,
        n_elite: int = 1,
        weights: EliteWeights = "log",
        zero_policy: bool = True,
        alive_bonus_offset: float = 0,
        reward_clip: tuple[float, float] | None = None,
        terminal_reward: float | None = None,
        n_eval_episodes: int = 1,
        common_seeds: bool = False,
        policy_kwargs: dict[str, Any] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        seed: int | None = None,
        verbose: int = 0,
        device: th.device | str = "cpu",
        evaluator: str | PopulationEvaluator = "local",
        noise_table_size: int | None = None,
        max_episode_steps: int | None = None,
        _init_setup_model: bool = True,
    ) -> None:
        sigma = constant_value(sigma)  # rl-zoo's "lin_X" string, or a constant schedule
        check_positive("sigma", sigma)
        super().__init__(**base_arguments(super().__init__, locals()))
        self.population_size = check_count("population_size", population_size, 2)
        self.sigma = sigma
        self.n_elite = check_count("n_elite", n_elite)
        self.weights: EliteWeights = weights
        self.noise_table_size = check_noise_table_size(noise_table_size)
        if _init_setup_model:
            self._setup_model()

    def _make_strategy(self, center: np.ndarray, seed: np.random.SeedSequence) -> SimpleESStrategy:
        return SimpleESStrategy(
            center,
            self.population_size,
            sigma=initial_value(self.sigma),
            n_elite=self.n_elite,
            weights=self.weights,
            seed=seed,
            noise_table=make_noise_table(self.noise_table_size, seed, center.size),
        )

    def learn(
        self: SelfSimpleES,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "SimpleES",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfSimpleES:
        return super().learn(total_timesteps, callback, log_interval, tb_log_name, reset_num_timesteps, progress_bar)
