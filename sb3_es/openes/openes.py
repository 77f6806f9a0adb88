"""OpenAI's evolution strategy (Salimans et al., 2017) as an SB3 algorithm."""

from __future__ import annotations

from typing import Any, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule

from sb3_es.common.arguments import base_arguments
from sb3_es.common.base_class import constant_value, python_number
from sb3_es.common.population_algorithm import (
    PopulationAlgorithm,
    check_noise_table_size,
    check_positive,
    initial_value,
    make_noise_table,
)
from sb3_es.evaluation import PopulationEvaluator
from sb3_es.openes.policies import FlatPolicy
from sb3_es.strategies.base import check_count, check_flag, check_non_negative, check_number
from sb3_es.strategies.openes import FitnessShaping, OpenESStrategy
from sb3_es.strategies.optimizers import OptimizerName

SelfOpenES = TypeVar("SelfOpenES", bound="OpenES")

#: The hyperparameters that :func:`check_decays` checks together.
DECAY_SETTINGS = frozenset(
    {"sigma", "sigma_decay", "sigma_limit", "learning_rate", "learning_rate_decay", "learning_rate_limit"}
)


def check_decays(
    sigma: Any,
    sigma_decay: float,
    learning_rate: Any,
    learning_rate_decay: float,
    limits: tuple[float, float] | None = None,
) -> None:
    """
    :param limits: ``sigma_limit`` and ``learning_rate_limit``, to check that a decay applies to the starting values
        (at construction; a value later decayed to its limit is expected).
    :raises ValueError: For a decay outside (0, 1], one given with a schedule (which sets the value itself), or one
        that would never apply.
    """
    pairs = (("sigma", sigma, sigma_decay), ("learning_rate", learning_rate, learning_rate_decay))
    for (name, value, rate), limit in zip(pairs, limits or (None, None), strict=True):
        if limit is not None:
            check_non_negative(f"{name}_limit", limit)
        if not 0 < check_number(f"{name}_decay", rate) <= 1:
            raise ValueError(f"{name}_decay={rate}: it must be in (0, 1].")
        # estool decays only above the limit; 0 (load(learning_rate=0), no update, as rl-zoo's enjoy gives) is no start
        if limit is not None and rate != 1 and not callable(value) and 0 < value <= limit:
            raise ValueError(
                f"{name}_decay={rate} would never apply: {name}={value} starts at or below {name}_limit={limit}, "
                f"where the decay stops. Lower {name}_limit, or leave {name}_decay at 1."
            )
        if callable(value) and rate != 1:
            raise ValueError(
                f"{name}_decay={rate} decays a float {name}, but {name} is a schedule, which sets every "
                f"generation's value itself: put the decay into the schedule, or pass a float {name}."
            )


class OpenES(PopulationAlgorithm):
    """
    OpenAI-ES (https://arxiv.org/abs/1703.03864), with estool's extensions: mirrored sampling,
    centered-rank fitness shaping, weight decay, Adam, SGD or ClipUp on the mean, decaying noise and step
    size, and tracking of the best candidate.

    :param population_size: Candidates per generation (even with ``antithetic``).
    :param sigma: Noise standard deviation: a float (decayed by ``sigma_decay`` down to ``sigma_limit``)
        or an SB3 schedule (then ``sigma_decay`` must be 1: the schedule sets every generation's value).
    :param learning_rate: Optimizer step size: a float (decayed by ``learning_rate_decay`` down to
        ``learning_rate_limit``) or an SB3 schedule (then ``learning_rate_decay`` must be 1). With
        ``optimizer="clipup"`` it is the length of one normalized step (ClipUp's paper: ``max_speed / 2``).
    :param sigma_decay: Multiplicative decay of a float ``sigma`` per generation (1 = constant).
    :param sigma_limit: Floor of the decayed ``sigma``.
    :param learning_rate_decay: Multiplicative decay of a float learning rate per generation.
    :param learning_rate_limit: Floor of the decayed learning rate.
    :param antithetic: Mirrored sampling.
    :param fitness_shaping: ``"centered_rank"`` (estool's ``rank_fitness=True``), ``"zscore"`` or ``"raw"``.
    :param optimizer: ``"adam"``, ``"sgd"`` or ``"clipup"`` (Toklu et al., 2020; see
        :class:`~sb3_es.strategies.optimizers.ClipUp`).
    :param momentum: SGD's and ClipUp's momentum.
    :param max_speed: ClipUp's largest step (``None``: twice the initial learning rate); ClipUp only.
    :param weight_decay: L2 coefficient on the mean (OpenAI-ES's ``l2coeff`` divided by ``sigma``).
    :param forget_best: Track only the latest generation's best candidate.
    :param noise_table_size: Size of the shared noise table to read perturbations from (``None``: drawn fresh).

    The other parameters are those of :class:`~sb3_es.common.population_algorithm.PopulationAlgorithm`.
    """

    strategy: OpenESStrategy
    scheduled_hyperparameters = ("learning_rate", "sigma")
    strategy_hyperparameters = (
        "population_size",
        "antithetic",
        "fitness_shaping",
        "weight_decay",
        "forget_best",
        "sigma_decay",
        "sigma_limit",
        "learning_rate_decay",
        "learning_rate_limit",
    )
    max_speed: float | None = None  # class default for files saved before ClipUp existed

    def __init__(
        self,
        policy: str | type[FlatPolicy],
        env: GymEnv | str | None,
        population_size: int = 32,
        sigma: float | Schedule = 0.1,
        learning_rate: float | Schedule = 0.01,
        sigma_decay: float = 1.0,
        sigma_limit: float = 0.01,
        learning_rate_decay: float = 1.0,
        learning_rate_limit: float = 0.001,
        antithetic: bool = True,
        fitness_shaping: FitnessShaping = "centered_rank",
        optimizer: OptimizerName = "adam",
        momentum: float = 0.9,
        max_speed: float | None = None,
        weight_decay: float = 0.005,
        forget_best: bool = False,
        zero_policy: bool = False,
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
        # rl-zoo passes a number from a hyperparameter file as a constant schedule: a number, which the decay applies to
        learning_rate, sigma = constant_value(learning_rate), constant_value(sigma)
        check_positive("sigma", sigma)
        check_decays(sigma, sigma_decay, learning_rate, learning_rate_decay, (sigma_limit, learning_rate_limit))
        super().__init__(**base_arguments(super().__init__, locals()))
        self.population_size = check_count("population_size", population_size, 2)
        self.sigma = sigma
        self.sigma_decay = python_number(sigma_decay)
        self.sigma_limit = python_number(sigma_limit)
        self.learning_rate_decay = python_number(learning_rate_decay)
        self.learning_rate_limit = python_number(learning_rate_limit)
        self.antithetic = check_flag("antithetic", antithetic)
        self.fitness_shaping: FitnessShaping = fitness_shaping
        self.optimizer = optimizer
        self.momentum = python_number(momentum)
        self.max_speed = python_number(max_speed)
        self.weight_decay = python_number(weight_decay)
        self.forget_best = check_flag("forget_best", forget_best)
        self.noise_table_size = check_noise_table_size(noise_table_size)
        if _init_setup_model:
            self._setup_model()

    def _apply_hyperparameters(self, changed: dict[str, Any]) -> None:
        super()._apply_hyperparameters(changed)  # the strategy checks each value's type and range
        # Only when one of them changes: a save from before version 2 may hold a decay beside a schedule.
        if changed.keys() & DECAY_SETTINGS:
            limits = (self.sigma_limit, self.learning_rate_limit)  # a decay must apply to the configured start
            check_decays(self.sigma, self.sigma_decay, self.learning_rate, self.learning_rate_decay, limits)

    def _make_strategy(self, center: np.ndarray, seed: np.random.SeedSequence) -> OpenESStrategy:
        return OpenESStrategy(
            center,
            self.population_size,
            sigma=initial_value(self.sigma),
            learning_rate=initial_value(self.learning_rate),
            antithetic=self.antithetic,
            fitness_shaping=self.fitness_shaping,
            optimizer=self.optimizer,
            momentum=self.momentum,
            max_speed=self.max_speed,
            weight_decay=self.weight_decay,
            forget_best=self.forget_best,
            sigma_decay=self.sigma_decay,
            sigma_limit=self.sigma_limit,
            learning_rate_decay=self.learning_rate_decay,
            learning_rate_limit=self.learning_rate_limit,
            seed=seed,
            noise_table=make_noise_table(self.noise_table_size, seed, center.size),
        )

    def _upgrade_legacy_strategy(self) -> None:
        # Before version 2 this class decayed sigma and the learning rate (closed form in the generation count).
        strategy, generation = self.strategy, self._n_updates
        for name, rate, limit in (
            ("sigma", self.sigma_decay, self.sigma_limit),
            ("learning_rate", self.learning_rate_decay, self.learning_rate_limit),
        ):
            setattr(strategy, f"{name}_decay", rate)
            setattr(strategy, f"{name}_limit", limit)
            base = getattr(self, name)
            if not callable(base):
                setattr(strategy, name, max(min(limit, float(base)), float(base) * rate**generation))

    def learn(
        self: SelfOpenES,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "OpenES",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfOpenES:
        return super().learn(total_timesteps, callback, log_interval, tb_log_name, reset_num_timesteps, progress_bar)
