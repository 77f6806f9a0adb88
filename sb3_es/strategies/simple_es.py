"""The elementary evolution strategies of seed 002: WinnerES and the weighted average of the top children."""

from __future__ import annotations

from typing import Literal

import numpy as np

from sb3_es.strategies.base import Population, Strategy, check_count, check_positive_number
from sb3_es.strategies.noise import NoiseTablePopulation, SharedNoiseTable

EliteWeights = Literal["equal", "linear", "log"]
#: The weighting schemes of the elite, for validation messages.
ELITE_WEIGHTS: tuple[EliteWeights, ...] = ("equal", "linear", "log")


def elite_weights(n_elite: int, weights: EliteWeights) -> np.ndarray:
    """
    Recombination weights of the ``n_elite`` best children, best first, summing to 1.

    :param n_elite: Number of children averaged.
    :param weights: ``"equal"`` (truncation selection), ``"linear"`` (``n, n-1, ..., 1``) or ``"log"``
        (``log(n + 1/2) - log(i)``, CMA-ES's default recombination weights, Hansen 2016).
    :return: The weights, float64, decreasing.
    """
    ranks = np.arange(1, n_elite + 1, dtype=np.float64)
    if weights == "equal":
        raw = np.ones(n_elite)
    elif weights == "linear":
        raw = n_elite + 1 - ranks
    elif weights == "log":
        raw = np.log(n_elite + 0.5) - np.log(ranks)
    else:
        raise ValueError(f"weights={weights!r}: choose one of {', '.join(map(repr, ELITE_WEIGHTS))}.")
    return raw / raw.sum()


class SimpleESStrategy(Strategy):
    """
    The simplest evolution strategy, a (mu/mu_w, lambda)-ES with a fixed ``sigma``: sample
    ``center + sigma * eps`` for ``population_size`` children, then move the center to the weighted average
    of the ``n_elite`` best children (the parent is not kept, even when every child is worse).

    - ``n_elite=1`` is **WinnerES** of seed 002: the center moves to the best child.
    - ``n_elite > 1`` is the **weighted average of the top n children** of seed 002. The seed weighs the
      children by their fitness; the weights here depend on the ranks only (``weights``), so that the update
      does not change when every return is shifted or scaled, e.g. a negative return (Pendulum) never turns a
      child's weight negative.

    :param center: Initial center.
    :param population_size: Children per generation.
    :param sigma: Standard deviation of the children around the center.
    :param n_elite: Number of best children averaged (1: WinnerES).
    :param weights: ``"log"`` (default), ``"linear"`` or ``"equal"``; see :func:`elite_weights`.
    :param seed: Seed of the random generator.
    :param noise_table: Draw each child's noise as a slice of this shared table: ``ask()`` then returns the children
        as a :class:`~sb3_es.strategies.noise.NoiseTablePopulation` (offsets and scales, which Ray ships instead of
        vectors).
    """

    def __init__(
        self,
        center: np.ndarray,
        population_size: int,
        *,
        sigma: float,
        n_elite: int = 1,
        weights: EliteWeights = "log",
        seed: int | np.random.SeedSequence | None = None,
        noise_table: SharedNoiseTable | None = None,
    ) -> None:
        super().__init__(center, seed)
        self.noise_table = noise_table
        self.population_size = population_size
        self.sigma = sigma
        self.n_elite = n_elite
        self.weights: EliteWeights = weights
        self.check_settings()

    def check_settings(self) -> None:
        self.population_size = check_count("population_size", self.population_size, 2)
        self.n_elite = check_count("n_elite", self.n_elite)
        if self.n_elite > self.population_size:
            raise ValueError(f"n_elite={self.n_elite} must be between 1 and population_size={self.population_size}.")
        self.sigma = check_positive_number("sigma", self.sigma)
        self.elite_weights = elite_weights(self.n_elite, self.weights)  # checks the name; follows a new n_elite
        self._check_noise_table(self.population_size)

    def _ask(self) -> Population:
        if self.noise_table is None:
            return self.center + self.sigma * self.rng.standard_normal((self.population_size, self.num_params))
        offsets = self.noise_table.sample_offsets(self.rng, self.num_params, self.population_size)
        return NoiseTablePopulation(
            self.noise_table, self.center.copy(), offsets, np.full(self.population_size, self.sigma)
        )

    def _tell(self, fitness: np.ndarray) -> dict[str, float]:
        assert self._asked is not None
        elite = np.argsort(-fitness, kind="stable")[: self.n_elite]  # ties: the first asked wins
        asked = self._asked
        rows = asked.rows(elite) if isinstance(asked, NoiseTablePopulation) else np.asarray(asked)[elite]
        center = self.elite_weights @ rows  # n_elite=1: exactly the best child
        step_norm = float(np.linalg.norm(center - self.center))
        self.center = center
        return {"sigma": self.sigma, "step_norm": step_norm}
