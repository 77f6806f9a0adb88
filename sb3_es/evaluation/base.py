"""What a population evaluation returns, and the interface every evaluator implements."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from stable_baselines3.common.running_mean_std import RunningMeanStd

from sb3_es.evaluation.network import HasNetworkSpec, NetworkSpec, as_network
from sb3_es.evaluation.shaping import RewardShaping
from sb3_es.strategies.noise import NoiseTablePopulation

#: Called once per vec step with ``(n_envs, infos, dones, rewards, new_obs, actions)`` (what the VecEnv's ``step``
#: took and returned); returning False stops the evaluation. A Ray evaluator's replay passes ``None`` for ``new_obs``
#: and ``actions``, which the actors do not send back.
StepHook = Callable[[int, list[dict[str, Any]], np.ndarray, np.ndarray, Any, Any], bool]


class ObsStats:
    """
    Mean and variance of a set of flattened observations, merged with Chan's parallel algorithm (SB3's
    :class:`~stable_baselines3.common.running_mean_std.RunningMeanStd`, which this wraps, started from zero counts).

    Each batch's moments are computed in two passes before the merge, so observations with a large offset
    (``1e8`` plus small noise) keep their variance, which sums of squares lose. Merging the statistics of two
    workers gives the statistics of the union (up to rounding, in any order). Rows with a NaN or infinite value are
    left out and counted in :attr:`n_nonfinite`: one bad observation must not poison the statistics for ever.

    :param dim: Size of a flattened observation.
    """

    def __init__(self, dim: int) -> None:
        self.rms = RunningMeanStd(epsilon=0.0, shape=(dim,))
        self.rms.var = np.zeros(dim)
        #: Observations left out because they had a NaN or infinite value.
        self.n_nonfinite = 0

    @classmethod
    def zeros(cls, dim: int) -> ObsStats:
        """:return: Empty statistics for observations of size ``dim``."""
        return cls(dim)

    @property
    def count(self) -> int:
        """:return: Number of observations in the statistics."""
        return int(self.rms.count)

    @property
    def mean(self) -> np.ndarray:
        """:return: Mean of the observations (zeros when empty)."""
        return self.rms.mean

    @property
    def var(self) -> np.ndarray:
        """:return: Population variance of the observations (zeros when empty)."""
        return self.rms.var

    def add(self, flat_obs: np.ndarray) -> None:
        """
        Add a batch of flattened observations (rows with a non-finite value are counted, not added).

        :param flat_obs: Observations ``(n, dim)``.
        """
        flat_obs = flat_obs.astype(np.float64, copy=False)
        finite = np.isfinite(flat_obs).all(axis=1)
        if not finite.all():
            self.n_nonfinite += int(np.count_nonzero(~finite))
            flat_obs = flat_obs[finite]
        if len(flat_obs):
            self.rms.update(flat_obs)

    def merge(self, other: ObsStats) -> None:
        """
        Add another set of statistics (e.g. from another worker).

        :param other: Statistics to add.
        """
        self.n_nonfinite += other.n_nonfinite
        if other.rms.count > 0:
            self.rms.combine(other.rms)

    def moments(self) -> tuple[np.ndarray, np.ndarray, int]:
        """:return: ``(mean, variance, count)`` for ``RunningMeanStd.update_from_moments``."""
        return self.mean, self.var, self.count


@dataclass
class PopulationResult:
    """
    Outcome of evaluating a population.

    :param returns: Undiscounted return of each episode, ``(n_candidates, n_episodes)``.
    :param lengths: Length of each episode, ``(n_candidates, n_episodes)``.
    :param obs_stats: Statistics of the observations the candidates saw (for observation normalization).
    :param n_steps: Env steps taken (every slot of every vec step, idle slots included).
    :param ep_infos: One dict per candidate episode, in the order they ended: the Monitor's ``info["episode"]``, or
        ``{"r": return, "l": length}`` measured by the evaluator (no Monitor, or an episode cut at the length cap).
    :param successes: ``info["is_success"]`` at the end of the candidates' episodes, where the env reports it.
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
    successes: list[bool] = field(default_factory=list)
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


@dataclass(frozen=True)
class Generation:
    """
    What one evaluation runs: the arguments of :meth:`PopulationEvaluator.evaluate`, the network resolved to its
    spec. Each evaluator implements :meth:`PopulationEvaluator._evaluate` on it.

    :param network: The network and its (frozen) observation statistics.
    :param population: Candidate parameter vectors ``(n_candidates, num_params)``.
    :param center: Parameters of the center (mean) policy, run by slots left idle at the end.
    :param n_episodes: Episodes per candidate.
    :param seed: Seed for the environments' resets in this generation.
    :param shaping: Per-step reward shaping of the fitness; ``None`` for none.
    :param max_episode_steps: Episode length cap (``None``: the env's own limit only).
    :param reset_seeds: Reset seed of each candidate's episodes ``(n_candidates, n_episodes)``: each of these episodes
        starts with ``reset(seed=...)``, so that candidates given the same seed start from the same state (common
        random numbers). ``None``: every env slot goes on with its own random sequence, seeded from ``seed``.
    """

    network: NetworkSpec
    population: np.ndarray | NoiseTablePopulation
    center: np.ndarray
    n_episodes: int
    seed: int
    shaping: RewardShaping | None = None
    max_episode_steps: int | None = None
    reset_seeds: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.reset_seeds is not None and np.shape(self.reset_seeds) != (self.n_candidates, self.n_episodes):
            raise ValueError(
                f"reset_seeds has shape {np.shape(self.reset_seeds)}: it needs one seed per candidate and episode, "
                f"({self.n_candidates}, {self.n_episodes})."
            )

    @property
    def n_candidates(self) -> int:
        """:return: Number of candidates."""
        return int(self.population.shape[0])

    @property
    def shaped(self) -> bool:
        """:return: Whether the fitness is shaped (``shaped_returns`` is filled in)."""
        return self.shaping is not None and not self.shaping.is_identity

    def empty_result(self) -> PopulationResult:
        """:return: A result of the right shape with nothing in it yet."""
        return PopulationResult.empty(self.n_candidates, self.n_episodes, self.network.obs_dim, shaped=self.shaped)


class PopulationEvaluator(ABC):
    """
    Runs the candidates of a population in environments and reports their returns.

    A new evaluator implements :meth:`_evaluate`; :meth:`evaluate` gathers its arguments into a :class:`Generation`.
    """

    def evaluate(
        self,
        network: NetworkSpec | HasNetworkSpec,
        population: np.ndarray | NoiseTablePopulation,
        center: np.ndarray,
        n_episodes: int,
        seed: int,
        step_hook: StepHook | None = None,
        shaping: RewardShaping | None = None,
        max_episode_steps: int | None = None,
        reset_seeds: np.ndarray | None = None,
    ) -> PopulationResult:
        """
        Evaluate every candidate for ``n_episodes`` episodes.

        :param network: The network and its (frozen) observation statistics, or a policy giving them
            (``policy.network_spec()``).
        :param population: Candidate parameter vectors ``(n_candidates, num_params)``.
        :param center: Parameters of the center (mean) policy, run by slots left idle at the end.
        :param n_episodes: Episodes per candidate.
        :param seed: Seed for the environments' resets in this generation (makes runs reproducible).
        :param step_hook: Called once per vec step; returning False stops the evaluation.
        :param shaping: Per-step reward shaping of the fitness (``shaped_returns``); ``None`` for none.
        :param max_episode_steps: End an episode that reaches this many steps as a time limit would (see
            :func:`~sb3_es.evaluation.time_limit.end_capped_episodes`); ``None``: the env's own limit only.
        :param reset_seeds: Reset seed of each candidate's episodes ``(n_candidates, n_episodes)`` (see
            :class:`Generation`); ``None``: the slots' own random sequences.
        :return: The results.
        """
        generation = Generation(
            as_network(network), population, center, n_episodes, seed, shaping, max_episode_steps, reset_seeds
        )
        return self._evaluate(generation, step_hook)

    @abstractmethod
    def _evaluate(self, generation: Generation, step_hook: StepHook | None) -> PopulationResult:
        """
        :param generation: What to run.
        :param step_hook: Called once per vec step (see :data:`StepHook`); returning False stops the evaluation.
        :return: The results.
        """

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release resources (worker processes, actors)."""
