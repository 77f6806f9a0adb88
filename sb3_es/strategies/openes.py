"""OpenAI's evolution strategy (Salimans et al., 2017), in the extended form of estool."""

from __future__ import annotations

from typing import Any

import numpy as np

from sb3_es.strategies.base import (
    Population,
    check_count,
    check_flag,
    check_non_negative,
    check_number,
    check_positive_number,
    mirrored_groups,
)
from sb3_es.strategies.fitness import FitnessShaping, centered_ranks, shape_fitness
from sb3_es.strategies.noise import NoiseTablePopulation, SharedNoiseTable
from sb3_es.strategies.optimizers import GradientStrategy, OptimizerName

__all__ = ["FitnessShaping", "OpenESStrategy", "centered_ranks", "decay", "shape_fitness"]


def decay(value: float, rate: float, limit: float) -> float:
    """
    One generation of estool's decay: ``value * rate``, not below ``limit``; a value already at or below the
    limit is left unchanged (the limit bounds the decay, it never raises a value).

    :param value: Current value.
    :param rate: Multiplicative decay per generation (1: constant).
    :param limit: Floor of the decay.
    :return: The value for the next generation.
    """
    return max(limit, value * rate) if value > limit else value


class OpenESStrategy(GradientStrategy):
    """
    OpenAI-ES: isotropic Gaussian perturbations (optionally mirrored), shaped fitness, and a gradient step
    on the mean with Adam, SGD or ClipUp (:mod:`sb3_es.strategies.optimizers`); L2 weight decay as in
    OpenAI's code; ``sigma`` and ``learning_rate`` decayed after every generation as in estool.

    :param center: Initial mean.
    :param population_size: Candidates per generation (even when ``antithetic``).
    :param sigma: Noise standard deviation.
    :param learning_rate: Optimizer step size.
    :param antithetic: Mirrored sampling ``theta +/- sigma * eps``.
    :param fitness_shaping: ``"centered_rank"`` (default), ``"zscore"`` or ``"raw"``.
    :param optimizer: ``"adam"``, ``"sgd"`` or ``"clipup"``.
    :param momentum: SGD's and ClipUp's momentum.
    :param betas: Adam's betas.
    :param max_speed: ClipUp's largest step (``None``: ``2 * learning_rate``).
    :param weight_decay: L2 coefficient added to the descent direction.
    :param forget_best: Keep only the latest generation's best candidate.
    :param sigma_decay: Multiplicative decay of ``sigma`` after every generation (1: constant).
    :param sigma_limit: Floor of the decayed ``sigma``.
    :param learning_rate_decay: Multiplicative decay of ``learning_rate`` after every generation.
    :param learning_rate_limit: Floor of the decayed ``learning_rate``.
    :param seed: Seed of the random generator.
    :param noise_table: Read the perturbations from this shared table (``ask()`` then returns a
        :class:`~sb3_es.strategies.noise.NoiseTablePopulation`, which Ray ships as offsets).
    """

    pending_attributes = (*GradientStrategy.pending_attributes, "_noise")

    def __init__(
        self,
        center: np.ndarray,
        population_size: int,
        *,
        sigma: float,
        learning_rate: float,
        antithetic: bool = True,
        fitness_shaping: FitnessShaping = "centered_rank",
        optimizer: OptimizerName = "adam",
        momentum: float = 0.9,
        betas: tuple[float, float] = (0.9, 0.999),
        max_speed: float | None = None,
        weight_decay: float = 0.0,
        forget_best: bool = False,
        sigma_decay: float = 1.0,
        sigma_limit: float = 0.0,
        learning_rate_decay: float = 1.0,
        learning_rate_limit: float = 0.0,
        seed: int | np.random.SeedSequence | None = None,
        noise_table: SharedNoiseTable | None = None,
    ) -> None:
        super().__init__(center, learning_rate, optimizer, momentum, betas, max_speed, seed)
        self.noise_table = noise_table
        self.population_size = population_size
        self.sigma = sigma
        self.antithetic = antithetic
        self.fitness_shaping = fitness_shaping
        self.weight_decay = weight_decay
        self.forget_best = forget_best
        self.sigma_decay, self.sigma_limit = sigma_decay, sigma_limit
        self.learning_rate_decay, self.learning_rate_limit = learning_rate_decay, learning_rate_limit
        self.check_settings()
        self._noise: np.ndarray | None = None

    def check_settings(self) -> None:
        population_size = self.population_size = check_count("population_size", self.population_size, 2)
        self.antithetic = check_flag("antithetic", self.antithetic)
        self.forget_best = check_flag("forget_best", self.forget_best)
        if self.antithetic and population_size % 2:
            raise ValueError(
                f"population_size={population_size}: it must be at least 2, and even with antithetic sampling."
            )
        self.sigma = check_positive_number("sigma", self.sigma)
        check_non_negative("learning_rate", self.learning_rate)  # a learning-rate schedule may end at 0
        for name, value in (
            ("weight_decay", self.weight_decay),
            ("sigma_limit", self.sigma_limit),
            ("learning_rate_limit", self.learning_rate_limit),
        ):
            check_non_negative(name, value)
        for name, rate in (("sigma_decay", self.sigma_decay), ("learning_rate_decay", self.learning_rate_decay)):
            if not 0 < check_number(name, rate) <= 1:
                raise ValueError(f"{name}={rate}: it must be in (0, 1].")
        shape_fitness(np.zeros(2), self.fitness_shaping)  # validates the name
        self._check_noise_table(self._n_drawn)

    @property
    def _n_drawn(self) -> int:
        """:return: Perturbations drawn per generation (each used twice, mirrored, with antithetic sampling)."""
        return self.population_size // 2 if self.antithetic else self.population_size

    def seed_groups(self, n_candidates: int) -> np.ndarray:
        """:return: Mirrored pairs share their reset seeds (the whole population without antithetic sampling)."""
        return mirrored_groups(n_candidates) if self.antithetic else super().seed_groups(n_candidates)

    def _ask(self) -> Population:
        half = self._n_drawn
        if self.noise_table is None:
            eps = self.rng.standard_normal((half, self.num_params))
            self._noise = np.concatenate([eps, -eps]) if self.antithetic else eps
            return self.center + self.sigma * self._noise
        offsets = self.noise_table.sample_offsets(self.rng, self.num_params, half)
        eps = np.stack([self.noise_table.get(o, self.num_params) for o in offsets]).astype(np.float64)
        signs = np.repeat([1.0, -1.0], half) if self.antithetic else np.ones(half)
        self._noise = np.concatenate([eps, -eps]) if self.antithetic else eps
        return NoiseTablePopulation(
            self.noise_table,
            self.center.copy(),
            np.tile(offsets, 2) if self.antithetic else offsets,
            self.sigma * signs,
        )

    def _tell(self, fitness: np.ndarray) -> dict[str, float]:
        assert self._noise is not None
        if self.antithetic:  # from each pair's difference: exactly 0 for equal members (a sum of +-eps is not)
            half = self.population_size // 2
            grad = self._noise[:half].T @ (fitness[:half] - fitness[half:]) / (self.population_size * self.sigma)
        else:
            grad = self._noise.T @ fitness / (self.population_size * self.sigma)
        # OpenAI-ES adds l2coeff * theta to the descent direction.
        self._ascend(grad - self.weight_decay * self.center)
        self._noise = None
        stats = {"sigma": self.sigma, "learning_rate": self.learning_rate, "grad_norm": float(np.linalg.norm(grad))}
        self.sigma = decay(self.sigma, self.sigma_decay, self.sigma_limit)
        self.learning_rate = decay(self.learning_rate, self.learning_rate_decay, self.learning_rate_limit)
        return {**stats, **self.optimizer_stats()}

    def __setstate__(self, state: dict[str, Any]) -> None:
        # Before version 2 the algorithm decayed sigma and the learning rate: no decay until it says otherwise.
        for name, default in (("sigma_decay", 1.0), ("learning_rate_decay", 1.0)):
            state.setdefault(name, default)
        for name in ("sigma_limit", "learning_rate_limit"):
            state.setdefault(name, 0.0)
        super().__setstate__(state)
