"""The ask/tell interface of a strategy: pure array math, no environment."""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from sb3_es.strategies.noise import NoiseTablePopulation


class Strategy(ABC):
    """
    A search distribution over flat parameter vectors, driven by ``ask`` and ``tell``.

    ``ask()`` returns the candidates of a generation, ``tell(fitness)`` moves the distribution using
    their fitness (higher is better). The strategy owns its random generator, so pickling it (as
    ``save()`` does) stores everything needed to continue exactly.

    :param center: Initial center (mean) of the search distribution.
    :param seed: Seed of the strategy's random generator.
    """

    def __init__(self, center: np.ndarray, seed: int | None = None) -> None:
        self.center = np.asarray(center, dtype=np.float64).copy()
        self.rng = np.random.default_rng(seed)

    @property
    def num_params(self) -> int:
        """:return: Dimension of the search space."""
        return int(self.center.shape[0])

    @abstractmethod
    def ask(self) -> np.ndarray | NoiseTablePopulation:
        """
        :return: The candidates to evaluate, ``(population_size, num_params)``: an array, or a
            :class:`~sb3_es.strategies.noise.NoiseTablePopulation` that behaves as one.
        """

    @abstractmethod
    def tell(self, fitness: np.ndarray) -> dict[str, float]:
        """
        Update the distribution from the fitness of the candidates of the last ``ask()``.

        :param fitness: One value per candidate, higher is better, all finite.
        :return: Scalars worth logging (logged under ``train/``).
        """

    def set_center(self, center: np.ndarray) -> None:
        """
        Move the center, e.g. after ``set_parameters()`` wrote new weights into the policy.

        :param center: The new center.
        """
        center = np.asarray(center, dtype=np.float64)
        if center.shape != self.center.shape:
            raise ValueError(f"Center of shape {center.shape} does not match the strategy's {self.center.shape}.")
        self.center = center.copy()


def check_fitness(fitness: np.ndarray, expected: int) -> np.ndarray:
    """
    Validate a fitness vector before a strategy uses it.

    :param fitness: Fitness of each candidate.
    :param expected: Number of candidates asked.
    :return: The fitness as a float64 array.
    """
    fitness = np.asarray(fitness, dtype=np.float64)
    if fitness.shape != (expected,):
        raise ValueError(f"Expected {expected} fitness values, got shape {fitness.shape}.")
    bad = np.flatnonzero(~np.isfinite(fitness))
    if bad.size:
        raise ValueError(
            f"Non-finite fitness for candidate(s) {bad.tolist()} (values {fitness[bad].tolist()}); "
            "the update was not applied. Check the environment's rewards (NaN/inf) or lower the noise."
        )
    return fitness
