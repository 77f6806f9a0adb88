"""Augmented Random Search (Mania, Guy and Recht, 2018) as an SB3 algorithm."""

from __future__ import annotations

from typing import Any, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule

from sb3_es.ars.policies import FlatPolicy
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
from sb3_es.strategies import ARSStrategy
from sb3_es.strategies.base import check_count

SelfARS = TypeVar("SelfARS", bound="ARS")


class ARS(PopulationAlgorithm):
    """
    Augmented Random Search: https://arxiv.org/abs/1803.07055

    Hyperparameters have the names and meanings of sb3-contrib's ARS, so rl-baselines3-zoo's
    ``ars.yml`` entries run unchanged. The paper's variants: V1 is ``policy_kwargs=dict(
    normalize_observations=False)``, V2 (the default) normalizes observations inside the policy, and
    the ``-t`` variants use ``n_top < n_delta``.

    :param n_delta: Number of random directions per generation (``2 * n_delta`` candidates).
    :param n_top: Number of best directions used in the update (``b`` in the paper); defaults to ``n_delta``.
    :param learning_rate: Step size ``alpha``, a float or a schedule.
    :param delta_std: Exploration noise ``nu``, a float or a schedule.
    :param noise_table_size: Size of the shared noise table to read perturbations from (``None``: drawn fresh).

    The other parameters are those of :class:`~sb3_es.common.population_algorithm.PopulationAlgorithm`.
    """

    strategy: ARSStrategy
    scheduled_hyperparameters = ("learning_rate", "delta_std")
    strategy_hyperparameters = ("n_delta", "n_top")

    def __init__(
        self,
        policy: str | type[FlatPolicy],
        env: GymEnv | str | None,
        n_delta: int = 8,
        n_top: int | None = None,
        learning_rate: float | Schedule = 0.02,
        delta_std: float | Schedule = 0.05,
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
        n_delta = check_count("n_delta", n_delta)
        n_top = n_delta if n_top is None else check_count("n_top", n_top)
        if n_top > n_delta:
            raise ValueError(f"n_top={n_top} must be an integer between 1 and n_delta={n_delta}.")
        delta_std = constant_value(delta_std)
        check_positive("delta_std", delta_std)
        super().__init__(**base_arguments(super().__init__, locals()))
        self.n_delta = n_delta
        self.n_top = n_top
        self.delta_std = delta_std
        self.noise_table_size = check_noise_table_size(noise_table_size)
        if _init_setup_model:
            self._setup_model()

    @classmethod
    def _changed_hyperparameters(cls, data: dict[str, Any], kwargs: dict[str, Any]) -> dict[str, Any]:
        if "n_delta" in kwargs and "n_top" not in kwargs and data.get("n_top") == data.get("n_delta"):
            kwargs = {**kwargs, "n_top": None}  # a model that used every direction goes on using every direction
        return super()._changed_hyperparameters(data, kwargs)

    def _apply_hyperparameters(self, changed: dict[str, Any]) -> None:
        if "n_top" in changed and changed["n_top"] is None:  # as in the constructor: every direction
            self.n_top = self.n_delta
            changed = {**changed, "n_top": self.n_delta}
        super()._apply_hyperparameters(changed)

    def _make_strategy(self, center: np.ndarray, seed: np.random.SeedSequence) -> ARSStrategy:
        return ARSStrategy(
            center,
            self.n_delta,
            self.n_top,
            delta_std=initial_value(self.delta_std),
            learning_rate=initial_value(self.learning_rate),
            seed=seed,
            noise_table=make_noise_table(self.noise_table_size, seed, center.size),
        )

    def learn(
        self: SelfARS,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "ARS_ES",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfARS:
        return super().learn(total_timesteps, callback, log_interval, tb_log_name, reset_num_timesteps, progress_bar)
