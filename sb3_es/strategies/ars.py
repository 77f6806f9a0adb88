"""Augmented Random Search update (Mania et al., 2018), as an ask/tell strategy."""

from __future__ import annotations

import numpy as np

from sb3_es.strategies.base import (
    Population,
    Strategy,
    check_count,
    check_non_negative,
    check_positive_number,
    mirrored_groups,
)
from sb3_es.strategies.noise import NoiseTablePopulation, SharedNoiseTable


class ARSStrategy(Strategy):
    """
    ARS: antithetic perturbations ``theta +/- delta_std * delta``, top-``n_top`` directions, and a step
    scaled by the standard deviation of the returns used (ARS paper, Algorithm 2, V1/V2 and V1-t/V2-t).

    Candidates are ordered ``[theta + delta_std * d_1..n, theta - delta_std * d_1..n]``.

    :param center: Initial parameters.
    :param n_delta: Number of random directions per generation.
    :param n_top: Number of best directions used in the update (``b`` in the paper).
    :param delta_std: Exploration noise ``nu``.
    :param learning_rate: Step size ``alpha``.
    :param seed: Seed of the random generator.
    :param noise_table: Read the directions from this shared table (``ask()`` then returns a
        :class:`~sb3_es.strategies.noise.NoiseTablePopulation`, which Ray ships as offsets) instead of
        drawing them fresh.
    """

    pending_attributes = (*Strategy.pending_attributes, "_deltas")

    def __init__(
        self,
        center: np.ndarray,
        n_delta: int,
        n_top: int,
        *,
        delta_std: float,
        learning_rate: float,
        seed: int | np.random.SeedSequence | None = None,
        noise_table: SharedNoiseTable | None = None,
    ) -> None:
        super().__init__(center, seed)
        self.noise_table = noise_table
        self.n_delta = n_delta
        self.n_top = n_top
        self.delta_std = delta_std
        self.learning_rate = learning_rate
        self.check_settings()
        self._deltas: np.ndarray | None = None

    def check_settings(self) -> None:
        self.n_delta = check_count("n_delta", self.n_delta)
        self.n_top = check_count("n_top", self.n_top)
        if not 1 <= self.n_top <= self.n_delta:
            raise ValueError(f"n_top={self.n_top!r} must be between 1 and n_delta={self.n_delta}.")
        self.delta_std = check_positive_number("delta_std", self.delta_std)
        self.learning_rate = check_non_negative("learning_rate", self.learning_rate)  # a schedule may end at 0
        self._check_noise_table(self.n_delta)

    @property
    def population_size(self) -> int:
        """:return: ``2 * n_delta``."""
        return 2 * self.n_delta

    def seed_groups(self, n_candidates: int) -> np.ndarray:
        """:return: The two candidates of each mirrored pair share their reset seeds."""
        return mirrored_groups(n_candidates)

    def _ask(self) -> Population:
        if self.noise_table is not None:
            offsets = self.noise_table.sample_offsets(self.rng, self.num_params, self.n_delta)
            self._deltas = np.stack([self.noise_table.get(o, self.num_params) for o in offsets]).astype(np.float64)
            scales = np.repeat([self.delta_std, -self.delta_std], self.n_delta)
            return NoiseTablePopulation(self.noise_table, self.center.copy(), np.tile(offsets, 2), scales)
        self._deltas = self.rng.standard_normal((self.n_delta, self.num_params))
        scaled = self.delta_std * self._deltas
        return np.concatenate([self.center + scaled, self.center - scaled])

    def _tell(self, fitness: np.ndarray) -> dict[str, float]:
        assert self._deltas is not None
        plus, minus = fitness[: self.n_delta], fitness[self.n_delta :]
        # Directions ranked by max(r+, r-); ties keep the sampling order (stable sort).
        top = np.argsort(-np.maximum(plus, minus), kind="stable")[: self.n_top]
        used = np.concatenate([plus[top], minus[top]])
        # Population standard deviation of the 2b returns used, as in the paper and its reference code.
        return_std = float(used.std())
        step_size = self.learning_rate / (self.n_top * return_std) if return_std > 0 else 0.0
        self.center = self.center + step_size * ((plus[top] - minus[top]) @ self._deltas[top])
        self._deltas = None
        return {
            "learning_rate": self.learning_rate,
            "delta_std": self.delta_std,
            "step_size": step_size,
            "return_std": return_std,
        }
