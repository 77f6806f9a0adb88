"""PGPE with ClipUp (Sehnke et al., 2010; Toklu et al., 2020) as an SB3 algorithm."""

from __future__ import annotations

from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback

from sb3_es.common.arguments import base_arguments
from sb3_es.common.base_class import python_number
from sb3_es.common.population_algorithm import PopulationAlgorithm
from sb3_es.evaluation import PopulationEvaluator
from sb3_es.pgpe.policies import FlatPolicy
from sb3_es.strategies.base import check_count, check_positive_number
from sb3_es.strategies.fitness import FitnessShaping
from sb3_es.strategies.optimizers import OptimizerName, check_optimizer_name
from sb3_es.strategies.pgpe import PGPEStrategy

SelfPGPE = TypeVar("SelfPGPE", bound="PGPE")


def check_step_sizes(optimizer: str, max_speed: float | None, center_learning_rate: float | None) -> None:
    """
    :raises ValueError: For an unknown optimizer, a step size that is not positive, or one that ``optimizer`` does
        not use.
    """
    check_optimizer_name(optimizer)
    for name, value in (("max_speed", max_speed), ("center_learning_rate", center_learning_rate)):
        if value is not None:
            check_positive_number(name, value)
    if optimizer != "clipup" and (center_learning_rate is None or max_speed is not None):
        raise ValueError(
            f"optimizer={optimizer!r} with center_learning_rate={center_learning_rate}, max_speed={max_speed}: pass "
            "center_learning_rate (None means max_speed / 2, a ClipUp setting) and no max_speed (ClipUp's speed limit)."
        )


class PGPE(PopulationAlgorithm):
    """
    Parameter-exploring policy gradients (Sehnke et al., 2010, https://doi.org/10.1016/j.neunet.2009.12.004)
    with the ClipUp optimizer (Toklu et al., 2020, https://arxiv.org/abs/2008.02387), as in EvoTorch:
    symmetric sampling, one adaptive standard deviation per parameter with a bounded relative change, and
    centered-rank fitness shaping. See :class:`~sb3_es.strategies.PGPEStrategy` for the update.

    :param population_size: Candidates per generation (even: symmetric pairs).
    :param stdev_init: Initial standard deviation of every parameter.
    :param max_speed: ClipUp's largest step (norm of the velocity), a distance in parameter space; ``None``:
        ``DEFAULT_MAX_SPEED`` (0.15). ClipUp only. ``load()`` may change it, and ``center_learning_rate``, to
        continue a run with a smaller step.
    :param center_learning_rate: Step size of the center optimizer. ``None``: ``max_speed / 2`` with ClipUp (the
        ClipUp paper's recommendation); required with ``"adam"`` or ``"sgd"``.
    :param stdev_learning_rate: Step size of the standard deviations.
    :param stdev_max_change: Largest relative change of a standard deviation per generation, in (0, 1).
    :param max_stdev: Upper bound of every standard deviation (``None``: none). ``load()`` may set or change it,
        to continue a run with a narrower search distribution.
    :param optimizer: ``"clipup"`` (default), ``"adam"`` or ``"sgd"`` for the center.
    :param momentum: ClipUp's (and SGD's) momentum.
    :param fitness_shaping: ``"centered_rank"`` (default), ``"zscore"`` or ``"raw"``.

    The other parameters are those of :class:`~sb3_es.common.population_algorithm.PopulationAlgorithm`.
    """

    strategy: PGPEStrategy
    strategy_hyperparameters = (
        "population_size",
        "stdev_learning_rate",
        "stdev_max_change",
        "max_stdev",
        "fitness_shaping",
        "max_speed",
        "center_learning_rate",
    )
    #: ClipUp's max speed when ``max_speed`` is not given (pgpelib's CartPole example; the center learning rate
    #: is then 0.075).
    DEFAULT_MAX_SPEED: ClassVar[float] = 0.15

    def __init__(
        self,
        policy: str | type[FlatPolicy],
        env: GymEnv | str | None,
        population_size: int = 50,
        stdev_init: float = 0.1,
        max_speed: float | None = None,
        center_learning_rate: float | None = None,
        stdev_learning_rate: float = 0.1,
        stdev_max_change: float = 0.2,
        max_stdev: float | None = None,
        optimizer: OptimizerName = "clipup",
        momentum: float = 0.9,
        fitness_shaping: FitnessShaping = "centered_rank",
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
        max_episode_steps: int | None = None,
        _init_setup_model: bool = True,
    ) -> None:
        check_step_sizes(optimizer, max_speed, center_learning_rate)
        super().__init__(**base_arguments(super().__init__, locals()))
        self.population_size = check_count("population_size", population_size, 2)
        self.stdev_init = python_number(stdev_init)
        self.max_speed = python_number(max_speed)
        self.center_learning_rate = python_number(center_learning_rate)
        self.stdev_learning_rate = python_number(stdev_learning_rate)
        self.stdev_max_change = python_number(stdev_max_change)
        self.max_stdev = python_number(max_stdev)
        self.optimizer = optimizer
        self.momentum = python_number(momentum)
        self.fitness_shaping: FitnessShaping = fitness_shaping
        if _init_setup_model:
            self._setup_model()

    def _step_sizes(self) -> dict[str, Any]:
        """:return: The center optimizer's ``max_speed`` (``None`` unless ClipUp) and ``center_learning_rate``."""
        max_speed = self.DEFAULT_MAX_SPEED if self.max_speed is None else self.max_speed
        learning_rate = max_speed / 2 if self.center_learning_rate is None else self.center_learning_rate
        return dict(max_speed=max_speed if self.optimizer == "clipup" else None, center_learning_rate=learning_rate)

    def _make_strategy(self, center: np.ndarray, seed: np.random.SeedSequence) -> PGPEStrategy:
        return PGPEStrategy(
            center,
            self.population_size,
            stdev_init=self.stdev_init,
            stdev_learning_rate=self.stdev_learning_rate,
            stdev_max_change=self.stdev_max_change,
            max_stdev=self.max_stdev,
            optimizer=self.optimizer,
            momentum=self.momentum,
            fitness_shaping=self.fitness_shaping,
            seed=seed,
            **self._step_sizes(),
        )

    def _apply_hyperparameters(self, changed: dict[str, Any]) -> None:
        # A new max_speed also moves a center learning rate left to its default (max_speed / 2).
        if changed.keys() & {"max_speed", "center_learning_rate"}:
            check_step_sizes(self.optimizer, self.max_speed, self.center_learning_rate)
            changed = {**changed, **self._step_sizes()}
        super()._apply_hyperparameters(changed)

    def learn(
        self: SelfPGPE,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "PGPE",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfPGPE:
        return super().learn(total_timesteps, callback, log_interval, tb_log_name, reset_num_timesteps, progress_bar)
