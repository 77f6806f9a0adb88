"""PGPE (Sehnke et al., 2010) with symmetric sampling and ClipUp (Toklu et al., 2020), as an ask/tell strategy."""

from __future__ import annotations

from typing import Any

import numpy as np

from sb3_es.strategies.base import check_count, check_non_negative, check_number, check_positive_number, mirrored_groups
from sb3_es.strategies.fitness import FitnessShaping, shape_fitness
from sb3_es.strategies.optimizers import GradientStrategy, OptimizerName


class PGPEStrategy(GradientStrategy):
    """
    Parameter-exploring policy gradients: a separable Gaussian with one standard deviation per parameter.

    Candidates come in symmetric pairs ``center +/- stdev * eps_k`` (``k < population_size / 2``; the
    ``+`` half first). With ``z_k = stdev * eps_k`` and the shaped fitness ``f+_k``, ``f-_k`` of a pair,
    averaged over the pairs (Sehnke et al., 2010, symmetric sampling; as EvoTorch computes them):

    - center gradient ``mean_k((f+_k - f-_k) / 2 * z_k)``, followed by the optimizer (ClipUp by default,
      whose step length does not depend on the gradient's scale);
    - standard deviation gradient ``mean_k(((f+_k + f-_k) / 2 - b) * (z_k**2 - stdev**2) / stdev)`` with the
      baseline ``b`` the mean shaped fitness, followed by plain gradient ascent with ``stdev_learning_rate``;
      each standard deviation then moves by at most ``stdev_max_change`` times its value (0.2 in the ClipUp
      paper), which also keeps it positive, and stays at or below ``max_stdev`` where one is given.

    :param center: Initial center.
    :param population_size: Candidates per generation (even: symmetric pairs).
    :param stdev_init: Initial standard deviation of every parameter.
    :param center_learning_rate: Step size of the center optimizer (ClipUp: length of one normalized step).
    :param stdev_learning_rate: Step size of the standard deviations.
    :param stdev_max_change: Largest relative change of a standard deviation in one generation, in (0, 1).
    :param max_stdev: Upper bound of every standard deviation (``None``: none). A bound set later (``load()``)
        lowers the larger ones at the next ``ask()``: a run goes on with a narrower search distribution.
    :param optimizer: ``"clipup"`` (default), ``"adam"`` or ``"sgd"``.
    :param max_speed: ClipUp's largest step (``None``: ``2 * center_learning_rate``).
    :param momentum: ClipUp's and SGD's momentum.
    :param betas: Adam's betas.
    :param fitness_shaping: ``"centered_rank"`` (default), ``"zscore"`` or ``"raw"``.
    :param seed: Seed of the random generator.
    """

    pending_attributes = (*GradientStrategy.pending_attributes, "_scaled_noise")

    def __init__(
        self,
        center: np.ndarray,
        population_size: int,
        *,
        stdev_init: float,
        center_learning_rate: float,
        stdev_learning_rate: float = 0.1,
        stdev_max_change: float = 0.2,
        max_stdev: float | None = None,
        optimizer: OptimizerName = "clipup",
        max_speed: float | None = None,
        momentum: float = 0.9,
        betas: tuple[float, float] = (0.9, 0.999),
        fitness_shaping: FitnessShaping = "centered_rank",
        seed: int | np.random.SeedSequence | None = None,
    ) -> None:
        check_positive_number("center_learning_rate", center_learning_rate)  # named as here, before the base checks
        super().__init__(center, center_learning_rate, optimizer, momentum, betas, max_speed, seed)
        self.population_size = population_size
        check_positive_number("stdev_init", stdev_init)
        self.stdev = np.full(self.num_params, float(stdev_init))
        self.stdev_learning_rate = stdev_learning_rate
        self.stdev_max_change = stdev_max_change
        self.fitness_shaping = fitness_shaping
        self.max_stdev = max_stdev
        self.check_settings()
        if self.max_stdev is not None and self.max_stdev < stdev_init:
            raise ValueError(f"stdev_init={stdev_init} is above max_stdev={max_stdev}: lower it, or raise max_stdev.")
        self._scaled_noise: np.ndarray | None = None

    def check_settings(self) -> None:
        population_size = self.population_size = check_count("population_size", self.population_size, 2)
        if population_size % 2:
            raise ValueError(f"population_size={population_size}: it must be even (symmetric pairs) and at least 2.")
        self.stdev_learning_rate = check_non_negative("stdev_learning_rate", self.stdev_learning_rate)  # 0: fixed
        self.stdev_max_change = check_number("stdev_max_change", self.stdev_max_change)
        if not 0 < self.stdev_max_change < 1:
            raise ValueError(
                f"stdev_max_change={self.stdev_max_change}: it must be in (0, 1) (a relative change; 0.2 in the "
                "ClipUp paper), so that every standard deviation stays positive."
            )
        if self.max_stdev is not None:
            self.max_stdev = check_positive_number("max_stdev", self.max_stdev)
        shape_fitness(np.zeros(2), self.fitness_shaping)  # validates the name

    @property
    def center_learning_rate(self) -> float:
        """:return: The center optimizer's step size (``learning_rate`` of :class:`GradientStrategy`)."""
        return self.learning_rate

    @center_learning_rate.setter
    def center_learning_rate(self, value: float) -> None:
        check_positive_number("center_learning_rate", value)
        self.learning_rate = float(value)

    def _bound_stdev(self) -> None:
        if self.max_stdev is not None:
            self.stdev = np.minimum(self.stdev, self.max_stdev)

    def seed_groups(self, n_candidates: int) -> np.ndarray:
        """:return: The two candidates of each mirrored pair share their reset seeds."""
        return mirrored_groups(n_candidates)

    def _ask(self) -> np.ndarray:
        self._bound_stdev()  # a max_stdev set since the last update (load()) applies from this generation on
        half = self.population_size // 2
        self._scaled_noise = self.stdev * self.rng.standard_normal((half, self.num_params))
        return np.concatenate([self.center + self._scaled_noise, self.center - self._scaled_noise])

    def _tell(self, fitness: np.ndarray) -> dict[str, float]:
        assert self._scaled_noise is not None
        z, half = self._scaled_noise, self.population_size // 2
        plus, minus = fitness[:half], fitness[half:]
        center_grad = (plus - minus) / 2 @ z / half
        stdev_grad = ((plus + minus) / 2 - fitness.mean()) @ ((z**2 - self.stdev**2) / self.stdev) / half
        self._ascend(center_grad)
        target = self.stdev + self.stdev_learning_rate * stdev_grad
        bound = self.stdev_max_change * self.stdev
        self.stdev = np.clip(target, self.stdev - bound, self.stdev + bound)
        self._bound_stdev()
        self._scaled_noise = None
        return {
            "learning_rate": self.learning_rate,
            "grad_norm": float(np.linalg.norm(center_grad)),
            "stdev_mean": float(self.stdev.mean()),
            "stdev_min": float(self.stdev.min()),
            "stdev_max": float(self.stdev.max()),
            **self.optimizer_stats(),
        }

    def __setstate__(self, state: dict[str, Any]) -> None:
        state.setdefault("max_stdev", None)  # saved before max_stdev existed
        super().__setstate__(state)
