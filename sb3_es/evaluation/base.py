"""What a population evaluation returns, and the interface every evaluator implements."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sb3_es.common.policies import FlatPolicy
from sb3_es.evaluation.shaping import RewardShaping
from sb3_es.strategies.noise import NoiseTablePopulation

#: Called once per vec step with ``(n_envs, infos, dones)``; returning False stops the evaluation.
StepHook = Callable[[int, list[dict[str, Any]], np.ndarray], bool]


@dataclass
class ObsStats:
    """
    Sufficient statistics of a set of flattened observations: merging two is exact addition.

    :param count: Number of observations.
    :param total: Sum of the observations.
    :param total_sq: Sum of their squares.
    """

    count: int
    total: np.ndarray
    total_sq: np.ndarray

    @classmethod
    def zeros(cls, dim: int) -> ObsStats:
        """:return: Empty statistics for observations of size ``dim``."""
        return cls(0, np.zeros(dim), np.zeros(dim))

    def add(self, flat_obs: np.ndarray) -> None:
        """
        Add a batch of flattened observations.

        :param flat_obs: Observations ``(n, dim)``.
        """
        flat_obs = flat_obs.astype(np.float64, copy=False)
        self.count += flat_obs.shape[0]
        self.total += flat_obs.sum(axis=0)
        self.total_sq += np.square(flat_obs).sum(axis=0)

    def merge(self, other: ObsStats) -> None:
        """
        Add another set of statistics (e.g. from another worker).

        :param other: Statistics to add.
        """
        self.count += other.count
        self.total += other.total
        self.total_sq += other.total_sq

    def moments(self) -> tuple[np.ndarray, np.ndarray, int]:
        """:return: ``(mean, variance, count)`` for ``RunningMeanStd.update_from_moments``."""
        mean = self.total / max(self.count, 1)
        var = np.maximum(self.total_sq / max(self.count, 1) - np.square(mean), 0.0)
        return mean, var, self.count


@dataclass
class PopulationResult:
    """
    Outcome of evaluating a population.

    :param returns: Undiscounted return of each episode, ``(n_candidates, n_episodes)``.
    :param lengths: Length of each episode, ``(n_candidates, n_episodes)``.
    :param obs_stats: Statistics of the observations the candidates saw (for observation normalization).
    :param n_steps: Env steps taken (every slot of every vec step, idle slots included).
    :param ep_infos: Monitor ``info["episode"]`` dicts of the candidates' episodes.
    :param center_returns: Returns of completed episodes of the center (mean) policy, run by idle slots.
    :param center_lengths: Lengths of those episodes.
    :param stopped: True when a callback stopped the evaluation: the results are then incomplete.
    :param shaped_returns: Fitness of each episode under a :class:`~sb3_es.evaluation.RewardShaping`, same shape as
        ``returns``; ``None`` when no shaping was asked for (the fitness is then ``returns``).
    """

    returns: np.ndarray
    lengths: np.ndarray
    obs_stats: ObsStats
    n_steps: int = 0
    ep_infos: list[dict[str, Any]] = field(default_factory=list)
    center_returns: list[float] = field(default_factory=list)
    center_lengths: list[int] = field(default_factory=list)
    stopped: bool = False
    shaped_returns: np.ndarray | None = None

    @property
    def fitness_returns(self) -> np.ndarray:
        """:return: The per-episode fitness: ``shaped_returns`` if shaping was applied, else ``returns``."""
        return self.returns if self.shaped_returns is None else self.shaped_returns

    @classmethod
    def empty(cls, n_candidates: int, n_episodes: int, obs_dim: int, shaped: bool = False) -> PopulationResult:
        """
        :param n_candidates: Candidates in the population.
        :param n_episodes: Episodes per candidate.
        :param obs_dim: Size of a flattened observation.
        :param shaped: Whether to allocate ``shaped_returns``.
        :return: A result with zero returns and lengths and no observations, to be filled in.
        """
        returns = np.zeros((n_candidates, n_episodes))
        lengths = np.zeros((n_candidates, n_episodes), dtype=np.int64)
        result = cls(returns, lengths, ObsStats.zeros(obs_dim))
        if shaped:
            result.shaped_returns = np.zeros((n_candidates, n_episodes))
        return result


class PopulationEvaluator(ABC):
    """Runs the candidates of a population in environments and reports their returns."""

    @abstractmethod
    def evaluate(
        self,
        policy: FlatPolicy,
        population: np.ndarray | NoiseTablePopulation,
        center: np.ndarray,
        n_episodes: int,
        seed: int,
        step_hook: StepHook | None = None,
        shaping: RewardShaping | None = None,
    ) -> PopulationResult:
        """
        Evaluate every candidate for ``n_episodes`` episodes.

        :param policy: Policy giving the architecture and the (frozen) observation statistics.
        :param population: Candidate parameter vectors ``(n_candidates, num_params)``.
        :param center: Parameters of the center (mean) policy, run by slots left idle at the end.
        :param n_episodes: Episodes per candidate.
        :param seed: Seed for the environments' resets in this generation (makes runs reproducible).
        :param step_hook: Called once per vec step; returning False stops the evaluation.
        :param shaping: Per-step reward shaping of the fitness (``shaped_returns``); ``None`` for none.
        :return: The results.
        """

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release resources (worker processes, actors)."""
