"""OpenAI's evolution strategy (Salimans et al., 2017) as an SB3 algorithm."""

from __future__ import annotations

from typing import Any, Literal, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import FloatSchedule

from sb3_es.common.population_algorithm import PopulationAlgorithm, check_positive, make_noise_table
from sb3_es.evaluation import PopulationEvaluator
from sb3_es.openes.policies import FlatPolicy
from sb3_es.strategies.noise import NoiseTablePopulation
from sb3_es.strategies.openes import FitnessShaping, OpenESStrategy

SelfOpenES = TypeVar("SelfOpenES", bound="OpenES")


def decayed(base: float | Schedule, progress: float, generation: int, decay: float, floor: float) -> float:
    """
    Value of a hyperparameter that is a schedule, or a float decayed geometrically to a floor (estool style).

    :param base: Float or SB3 schedule ``progress_remaining -> value``.
    :param progress: SB3 progress remaining (1 to 0).
    :param generation: Number of updates done.
    :param decay: Multiplicative decay per generation (floats only).
    :param floor: Lower bound of the decayed value (floats only).
    :return: The value for this generation.
    """
    if callable(base):
        return float(base(progress))
    # The floor bounds the decay; it never raises a value that starts below it.
    return max(min(floor, float(base)), float(base) * decay**generation)


class OpenES(PopulationAlgorithm):
    """
    OpenAI-ES (https://arxiv.org/abs/1703.03864), with estool's extensions: mirrored sampling,
    centered-rank fitness shaping, weight decay, Adam or SGD on the mean, decaying noise and step
    size, and tracking of the best candidate.

    :param policy: ``"MlpPolicy"``, ``"LinearPolicy"`` or a :class:`~sb3_es.common.policies.FlatPolicy` class.
    :param env: Environment, env id or VecEnv; each env slot evaluates a different candidate.
    :param population_size: Candidates per generation (even with ``antithetic``).
    :param sigma: Noise standard deviation: a float (decayed by ``sigma_decay`` down to ``sigma_limit``)
        or an SB3 schedule.
    :param learning_rate: Optimizer step size: a float (decayed by ``learning_rate_decay`` down to
        ``learning_rate_limit``) or an SB3 schedule.
    :param sigma_decay: Multiplicative decay of ``sigma`` per generation (1 = constant).
    :param sigma_limit: Floor of the decayed ``sigma``.
    :param learning_rate_decay: Multiplicative decay of the learning rate per generation.
    :param learning_rate_limit: Floor of the decayed learning rate.
    :param antithetic: Mirrored sampling.
    :param fitness_shaping: ``"centered_rank"`` (estool's ``rank_fitness=True``), ``"zscore"`` or ``"raw"``.
    :param optimizer: ``"adam"`` or ``"sgd"``.
    :param momentum: SGD momentum.
    :param weight_decay: L2 coefficient on the mean.
    :param forget_best: Track only the latest generation's best candidate.
    :param zero_policy: Start with the output layer at zero (hidden layers keep their random initialization; a
        linear policy starts all-zero, as in the ARS paper).
    :param alive_bonus_offset: Added to the fitness once per step.
    :param reward_clip: Clip each step's reward to ``(low, high)`` in the fitness only (``None``: no clipping).
    :param terminal_reward: In the fitness only, replace the reward of an episode's terminating step (e.g. ``0`` for
        BipedalWalker's -100 fall penalty); ``None`` keeps it. See :class:`~sb3_es.evaluation.RewardShaping`.
    :param n_eval_episodes: Episodes per candidate.
    :param policy_kwargs: Keyword arguments for the policy.
    :param stats_window_size: Episodes averaged in ``rollout/ep_rew_mean``.
    :param tensorboard_log: TensorBoard log directory.
    :param seed: Random seed.
    :param verbose: Verbosity.
    :param device: Torch device.
    :param evaluator: ``"local"`` or a :class:`~sb3_es.evaluation.PopulationEvaluator` (e.g. Ray); not saved.
    :param noise_table_size: Read perturbations from a shared noise table of this many float32 values (e.g.
        ``2**24``) instead of drawing them fresh, so that a Ray evaluator sends an offset per candidate
        rather than a parameter vector. ``None`` (default) draws them fresh.
    :param max_episode_steps: Longest episode training runs, in env steps (an episode reaching it is truncated);
        ``None``: the env's ``TimeLimit``, or 1000 steps, with a warning, for an env without one.
    :param _init_setup_model: Whether to build the model at construction.
    """

    strategy: OpenESStrategy

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
        optimizer: Literal["adam", "sgd"] = "adam",
        momentum: float = 0.9,
        weight_decay: float = 0.005,
        forget_best: bool = False,
        zero_policy: bool = False,
        alive_bonus_offset: float = 0,
        reward_clip: tuple[float, float] | None = None,
        terminal_reward: float | None = None,
        n_eval_episodes: int = 1,
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
        check_positive("sigma", sigma)
        for name, value in (("sigma_decay", sigma_decay), ("learning_rate_decay", learning_rate_decay)):
            if not 0 < value <= 1:
                raise ValueError(f"{name}={value}: it must be in (0, 1].")
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            n_eval_episodes=n_eval_episodes,
            alive_bonus_offset=alive_bonus_offset,
            reward_clip=reward_clip,
            terminal_reward=terminal_reward,
            zero_policy=zero_policy,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            seed=seed,
            verbose=verbose,
            device=device,
            evaluator=evaluator,
            max_episode_steps=max_episode_steps,
        )
        self.population_size = population_size
        self.sigma = sigma
        self.sigma_decay = sigma_decay
        self.sigma_limit = sigma_limit
        self.learning_rate_decay = learning_rate_decay
        self.learning_rate_limit = learning_rate_limit
        self.antithetic = antithetic
        self.fitness_shaping: FitnessShaping = fitness_shaping
        self.optimizer = optimizer
        self.momentum = momentum
        self.weight_decay = weight_decay
        self.forget_best = forget_best
        if noise_table_size is not None and int(noise_table_size) < 1:
            raise ValueError(f"noise_table_size={noise_table_size}: use a positive size or None.")
        self.noise_table_size = noise_table_size
        if _init_setup_model:
            self._setup_model()

    def _make_strategy(self, center: np.ndarray, seed: np.random.SeedSequence) -> OpenESStrategy:
        return OpenESStrategy(
            center,
            self.population_size,
            antithetic=self.antithetic,
            fitness_shaping=self.fitness_shaping,
            optimizer=self.optimizer,
            momentum=self.momentum,
            weight_decay=self.weight_decay,
            forget_best=self.forget_best,
            seed=seed,
            noise_table=make_noise_table(self.noise_table_size, seed),
        )

    def _ask(self) -> np.ndarray | NoiseTablePopulation:
        progress, generation = self._current_progress_remaining, self._n_updates
        self.strategy.sigma = decayed(self.sigma, progress, generation, self.sigma_decay, self.sigma_limit)
        self.strategy.learning_rate = decayed(
            FloatSchedule(self.learning_rate) if callable(self.learning_rate) else self.learning_rate,
            progress,
            generation,
            self.learning_rate_decay,
            self.learning_rate_limit,
        )
        check_positive("sigma", self.strategy.sigma)
        return self.strategy.ask()

    @property
    def best_params(self) -> np.ndarray:
        """:return: Parameters of the best candidate seen (load them with ``policy.load_from_vector``)."""
        return self.strategy.best_params

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
