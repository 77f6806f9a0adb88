"""CMA-ES over the policy's flat parameters, with pycma doing the strategy."""

from __future__ import annotations

import warnings
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback

from sb3_es.cmaes.policies import FlatPolicy
from sb3_es.common.arguments import base_arguments
from sb3_es.common.base_class import python_number
from sb3_es.common.population_algorithm import PopulationAlgorithm
from sb3_es.evaluation import PopulationEvaluator
from sb3_es.strategies.base import check_count, check_positive_number
from sb3_es.strategies.cmaes import CMAESStrategy, Restarts

#: Restarts allowed with ``restarts="ipop"`` or ``"bipop"`` unless ``max_restarts`` is given.
DEFAULT_MAX_RESTARTS = 9


def check_restarts_on(restarts: Restarts, max_restarts: int) -> None:
    """:raises ValueError: For a ``max_restarts`` given without restarts, where it would do nothing."""
    if restarts is None:
        raise ValueError(
            f"max_restarts={max_restarts} has no effect without restarts: pass restarts='ipop' or 'bipop', or "
            "drop max_restarts."
        )


SelfCMAES = TypeVar("SelfCMAES", bound="CMAES")


class CMAES(PopulationAlgorithm):
    """
    CMA-ES (Hansen and Ostermeier, 2001) on the policy's flat parameters, through pycma.

    Full covariance by default for small policies; with ``diagonal="auto"`` (the default) policies of
    more than ``DIAGONAL_THRESHOLD`` parameters use separable CMA-ES (diagonal covariance), whose cost
    per generation is linear in the number of parameters instead of cubic. When pycma's stop
    conditions fire, training ends (logged under ``train/stop_*``) or restarts (IPOP/BIPOP).

    :param sigma: Initial step size ``sigma0``.
    :param population_size: Candidates per generation; ``None`` for pycma's default ``4 + 3 ln(n)``.
    :param diagonal: ``True`` for separable (diagonal) CMA-ES, ``False`` for full covariance, ``"auto"``
        for full covariance up to ``DIAGONAL_THRESHOLD`` parameters.
    :param restarts: ``None``, ``"ipop"`` or ``"bipop"``.
    :param max_restarts: Maximum number of restarts (only with ``restarts``: a value other than the default without
        them is an error).
    :param cma_options: Other pycma options, passed through.

    The other parameters are those of :class:`~sb3_es.common.population_algorithm.PopulationAlgorithm`.
    """

    #: Above this many parameters, ``diagonal="auto"`` picks separable CMA-ES.
    DIAGONAL_THRESHOLD: ClassVar[int] = 1000
    strategy_hyperparameters = ("max_restarts",)
    strategy: CMAESStrategy

    def __init__(
        self,
        policy: str | type[FlatPolicy],
        env: GymEnv | str | None,
        sigma: float = 0.1,
        population_size: int | None = None,
        diagonal: bool | str = "auto",
        restarts: Restarts = None,
        max_restarts: int = DEFAULT_MAX_RESTARTS,
        cma_options: dict[str, Any] | None = None,
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
        max_episode_steps: int | None = None,
        _init_setup_model: bool = True,
    ) -> None:
        check_positive_number("sigma", sigma)
        diagonal = bool(diagonal) if isinstance(diagonal, np.bool_) else diagonal  # as every other flag
        if not (isinstance(diagonal, bool) or diagonal == "auto"):  # 1 == True: not a flag
            raise ValueError(f"diagonal={diagonal!r}: choose True, False or 'auto'.")
        super().__init__(**base_arguments(super().__init__, locals()))
        self.sigma = python_number(sigma)
        self.population_size = None if population_size is None else check_count("population_size", population_size, 2)
        self.diagonal = diagonal
        self.restarts = restarts
        self.max_restarts = check_count("max_restarts", max_restarts, 0)
        if self.max_restarts != DEFAULT_MAX_RESTARTS:
            check_restarts_on(restarts, max_restarts)
        self.cma_options = cma_options
        if _init_setup_model:
            self._setup_model()

    def _apply_hyperparameters(self, changed: dict[str, Any]) -> None:
        super()._apply_hyperparameters(changed)  # the strategy checks the count
        if changed.get("max_restarts", DEFAULT_MAX_RESTARTS) != DEFAULT_MAX_RESTARTS:  # as the constructor checks it
            check_restarts_on(self.restarts, changed["max_restarts"])

    def _make_strategy(self, center: np.ndarray, seed: np.random.SeedSequence) -> CMAESStrategy:
        diagonal = len(center) > self.DIAGONAL_THRESHOLD if self.diagonal == "auto" else bool(self.diagonal)
        return CMAESStrategy(
            center,
            sigma=self.sigma,
            population_size=self.population_size,
            diagonal=diagonal,
            restarts=self.restarts,
            max_restarts=self.max_restarts,
            cma_options=self.cma_options,
            seed=seed,
        )

    def _keep_searching(self) -> str:
        """:return: How to keep searching once the stop conditions fired with no restart left."""
        if self.strategy.reached_an_end:
            return (
                "cma_options' ftarget and maxfevals end the search, as in pycma's fmin (no restart follows); the "
                "policy holds what it found. To search on, train a new model with a lower ftarget or more maxfevals."
            )
        if self.restarts is None:
            return (
                "To keep searching, train with restarts='ipop' or 'bipop', or relax the stop conditions with "
                "cma_options."
            )
        return (
            f"All max_restarts={self.max_restarts} restarts have run; to keep searching, save the model and load it "
            "with a larger max_restarts (CMAES.load(path, max_restarts=...)), then learn() again."
        )

    def _run_generation(self, evaluator, callback) -> bool:  # type: ignore[no-untyped-def]
        self._follow_policy_weights(self.strategy)  # weights written into the policy start a new pycma run
        if self.strategy.stopped:
            warnings.warn(
                f"CMA-ES has stopped ({self.strategy.last_stop}); learn() does nothing. {self._keep_searching()}",
                stacklevel=2,
            )
            return False
        completed = super()._run_generation(evaluator, callback)
        if completed and self.strategy.last_stop:
            for key, value in self.strategy.last_stop.items():
                self.logger.record(f"train/stop_{key}", float(value) if isinstance(value, (int, float)) else str(value))
            if self.strategy.stopped:  # a warning, not a print: learn() returns before total_timesteps
                warnings.warn(
                    f"CMA-ES stop conditions fired ({self.strategy.last_stop}) at {self.num_timesteps} env steps; "
                    f"training ends before total_timesteps. {self._keep_searching()}",
                    stacklevel=2,
                )
                self._stop_training = True
        return completed

    def learn(
        self: SelfCMAES,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "CMAES",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfCMAES:
        return super().learn(total_timesteps, callback, log_interval, tb_log_name, reset_num_timesteps, progress_bar)
