"""The training loop shared by every population method: generations of ask, evaluate, tell, with SB3's
callbacks and logger."""

from __future__ import annotations

import warnings
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback, ConvertCallback
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.vec_env import VecEnv

from sb3_es.common.arguments import base_arguments
from sb3_es.common.base_class import ESBaseAlgorithm
from sb3_es.common.checks import check_positive
from sb3_es.common.evaluator_choice import check_evaluator, check_evaluator_name, resolve_evaluator
from sb3_es.common.policies import FlatPolicy, LinearPolicy, MlpPolicy
from sb3_es.common.progress import StepsProgressBarCallback
from sb3_es.common.remote_monitor import align_clock, write_remote_episodes
from sb3_es.common.step_calls import StepCalls
from sb3_es.common.strategy_algorithm import StrategyAlgorithm, check_noise_table_size, initial_value, make_noise_table
from sb3_es.evaluation import PopulationEvaluator, PopulationResult, RewardShaping
from sb3_es.evaluation.slot_reset import check_common_seeds
from sb3_es.strategies.base import check_count, check_flag

SelfPopulationAlgorithm = TypeVar("SelfPopulationAlgorithm", bound="PopulationAlgorithm")

__all__ = ["PopulationAlgorithm", "check_noise_table_size", "check_positive", "initial_value", "make_noise_table"]


class PopulationAlgorithm(StrategyAlgorithm):
    """
    Base class of the population methods (ARS, OpenES, CMA-ES, PGPE, SimpleES): an algorithm is mostly its
    strategy. Each one adds its strategy's hyperparameters to the parameters below (documented here once) and
    builds its strategy (:meth:`~sb3_es.common.strategy_algorithm.StrategyAlgorithm._make_strategy`).

    Each generation: scheduled hyperparameters are written into the strategy (``scheduled_hyperparameters``),
    the strategy proposes candidates (``ask``), the evaluator runs them on the
    environment (one batched forward pass per vec step, SB3 callbacks once per ``num_envs`` env steps), their
    fitness goes back to the strategy (``tell``), the observation statistics are updated, and the
    policy takes the strategy's new center.

    Fitness of a candidate: its mean return over ``n_eval_episodes`` episodes, each step's reward first
    shaped by ``terminal_reward``, ``reward_clip`` and ``alive_bonus_offset`` (see
    :class:`~sb3_es.evaluation.RewardShaping`). The shaping changes the fitness only: the logged
    ``rollout/ep_rew_mean``, the center returns, Monitor files and ``EvalCallback`` see the env's raw reward.
    A non-finite fitness raises an error naming the candidate and leaves the parameters unchanged.

    :param policy: Policy class or alias (``"MlpPolicy"``, ``"LinearPolicy"``).
    :param env: Environment, env id, or VecEnv. Every env slot evaluates a different candidate.
    :param learning_rate: Step size (float or schedule) of ARS and OpenES, its meaning their own; the algorithms
        without one (CMA-ES, PGPE, SimpleES) take no such argument and pass ``None``.
    :param n_eval_episodes: Episodes per candidate.
    :param common_seeds: Common random numbers: the candidates that the strategy compares with each other start
        their episodes from the same states (the same reset seed for the e-th episode of each): the two members of
        each mirrored pair (ARS, OpenES, PGPE; as estool does), the whole population otherwise (CMA-ES, SimpleES).
        Their fitness differences then come from their parameters, not from their starting states. Each candidate
        episode is then reset on its own (the VecEnv cannot be a ``VecEnvWrapper`` such as ``VecNormalize``).
    :param alive_bonus_offset: Added to the fitness once per step, to cancel alive bonuses.
    :param reward_clip: ``(low, high)``: clip each step's reward to this range in the fitness (``None``: no clipping).
    :param terminal_reward: In the fitness, the reward of a step that terminates an episode (a fall, not a time
        limit) is replaced by this value, e.g. ``0`` to cancel BipedalWalker's -100 fall penalty (``None``: keep it).
    :param zero_policy: Start with the output layer at zero (the action does not depend on the observation);
        hidden layers keep the policy's random initialization, so that an MLP learns from the first step. A
        linear policy then starts all-zero, as in the ARS paper. ``False`` keeps the whole initialization.
    :param policy_kwargs: Keyword arguments for the policy.
    :param stats_window_size: Number of episodes averaged in ``rollout/ep_rew_mean``.
    :param tensorboard_log: TensorBoard log directory.
    :param seed: Seed for the strategy, the environments and torch.
    :param verbose: 0 none, 1 training information, 2 debug.
    :param device: Torch device; the CPU is the right choice for small policies, and what ``"auto"`` means here
        (rl-zoo passes ``"auto"``): the candidates' forward passes are NumPy.
    :param max_episode_steps: Longest episode training runs (see :class:`~sb3_es.common.base_class.ESBaseAlgorithm`):
        ``None`` takes the env's ``TimeLimit``, or 1000 steps with a warning for an env without one.
    :param evaluator: Who runs the candidates: ``"local"`` (the model's VecEnv, in this process),
        ``"processes"`` (worker processes of this machine, one per CPU, see
        :class:`~sb3_es.evaluation.processes.ProcessEvaluator`), ``"ray"`` (Ray actors, one per available CPU, see
        :class:`~sb3_es.evaluation.ray.RayEvaluator`) or a :class:`~sb3_es.evaluation.PopulationEvaluator`
        instance. ``"processes"`` and ``"ray"`` build their workers' envs from ``env``: an env id, or a VecEnv whose
        envs ``gym.make`` made (their wrappers are rebuilt from the Gymnasium specs). Not saved with the model.
    :param noise_table_size: (ARS, OpenES and SimpleES, whose strategies draw Gaussian directions; not a parameter of
        this base class) Read the perturbations from a shared noise table of this many float32 values (e.g.
        ``2**24``) instead of drawing them fresh, so that a Ray evaluator sends an offset per candidate rather than a
        parameter vector; offsets are drawn independently (OpenAI's ES), so keep the table far larger than a
        generation's perturbations. ``None`` (default) draws them fresh.
    :param _init_setup_model: Whether to build the model at construction.
    """

    _live_hyperparameters: ClassVar[tuple[str, ...]] = (
        *ESBaseAlgorithm._live_hyperparameters,
        "n_eval_episodes",
        "common_seeds",
        "alive_bonus_offset",
        "reward_clip",
        "terminal_reward",
        "evaluator",
    )
    _auto_device: ClassVar[str] = "cpu"
    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MlpPolicy,
        "LinearPolicy": LinearPolicy,
        "MultiInputPolicy": MlpPolicy,
    }

    def __init__(
        self,
        policy: str | type[FlatPolicy],
        env: GymEnv | str | None,
        learning_rate: float | Schedule | None = None,
        n_eval_episodes: int = 1,
        common_seeds: bool = False,
        alive_bonus_offset: float = 0.0,
        zero_policy: bool = True,
        reward_clip: tuple[float, float] | None = None,
        terminal_reward: float | None = None,
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
        # Env id, for evaluator="processes" or "ray" (each worker builds its envs from it); not saved.
        self._env_id = env if isinstance(env, str) else None
        super().__init__(**base_arguments(super().__init__, locals()))
        self._check_live_values({"n_eval_episodes": n_eval_episodes})
        # As ESBaseAlgorithm keeps it (a constant schedule's number, ...); None only where the algorithm has no
        # learning rate of its own (a scheduled one must be given).
        if self.learning_rate is not None or "learning_rate" in self.scheduled_hyperparameters:
            check_positive("learning_rate", self.learning_rate)
        self.n_eval_episodes = int(n_eval_episodes)
        self.common_seeds = check_flag("common_seeds", common_seeds)
        shaping = RewardShaping.create(reward_clip, terminal_reward, alive_bonus_offset)
        self.alive_bonus_offset = shaping.alive_bonus_offset
        self.reward_clip = shaping.reward_clip
        self.terminal_reward = shaping.terminal_reward
        self.zero_policy = check_flag("zero_policy", zero_policy)
        self.strategy = None
        self._env_rng = None
        check_evaluator(evaluator, self._env_id, self.env)
        self.evaluator = evaluator
        self._check_common_seeds()
        self._evaluator: PopulationEvaluator | None = None
        self._stop_training = False

    def _check_common_seeds(self, env: VecEnv | None = None) -> None:
        """
        With ``common_seeds`` and the local evaluator, refuse a VecEnv whose slots cannot be reset one at a time
        (now, not at the first generation).

        :param env: A VecEnv about to replace the model's (``None``: the model's own).
        """
        env = env if env is not None else self.env
        if self.common_seeds and self.evaluator == "local" and env is not None:
            check_common_seeds(env)

    def _check_env(self, env: VecEnv | None = None) -> None:
        super()._check_env(env)
        self._check_common_seeds(env)
        if isinstance(self.evaluator, str) and self.evaluator != "local":  # the workers can rebuild the env
            env_id, env = (None, env) if env is not None else (getattr(self, "_env_id", None), self.env)
            if env is not None or env_id is not None:
                check_evaluator(self.evaluator, env_id, env)

    @classmethod
    def _check_live_values(cls, values: dict[str, Any]) -> None:
        check_count("n_eval_episodes", values.get("n_eval_episodes", 1))
        check_flag("common_seeds", values.get("common_seeds", False))
        if "evaluator" in values:
            check_evaluator_name(values["evaluator"])
        super()._check_live_values(values)

    @property
    def reward_shaping(self) -> RewardShaping:
        """:return: The per-step reward shaping of the fitness, from the current hyperparameters."""
        return RewardShaping.create(
            getattr(self, "reward_clip", None), getattr(self, "terminal_reward", None), self.alive_bonus_offset
        )

    def _apply_hyperparameters(self, changed: dict[str, Any]) -> None:
        shaping = self.reward_shaping  # checks reward_clip, terminal_reward and alive_bonus_offset
        self.reward_clip, self.terminal_reward = shaping.reward_clip, shaping.terminal_reward
        self.alive_bonus_offset = shaping.alive_bonus_offset
        super()._apply_hyperparameters(changed)

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "evaluator", "_evaluator", "_env_id"]

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        """
        Train on ``env`` from now on. Worker processes or Ray actors that the model built (``evaluator="processes"``
        or ``"ray"``) are closed and rebuilt from the new env's Gymnasium specs at the next ``learn()``; an evaluator
        instance passed as ``evaluator=`` keeps its own envs.

        :param env: The new environment (same spaces and number of envs).
        :param force_reset: Reset the env before the next ``learn()``.
        """
        env = self._wrap_env(env, self.verbose)
        super().set_env(env, force_reset)  # checks that the workers can rebuild the env, before anything changes
        if isinstance(self.evaluator, str) and self.evaluator != "local":
            self._env_id = None
            self.close()

    def close(self) -> None:
        """
        Stop the worker processes or Ray actors that the model built for ``evaluator="processes"`` or ``"ray"``
        (they idle between ``learn()`` calls, and would stop only when the model is garbage-collected or at exit);
        the next ``learn()`` starts new ones. An evaluator instance passed as ``evaluator=`` is its owner's to close,
        and the env is closed with ``model.env.close()``, as in SB3.
        """
        if self.evaluator in ("processes", "ray") and self._evaluator is not None:
            self._evaluator.close()
            self._evaluator = None

    # ------------------------------------------------------------------ training
    def _init_callback(self, callback: MaybeCallback, progress_bar: bool = False) -> BaseCallback:
        if progress_bar:  # SB3's bar counts num_envs per call; a generation's last call can stand for fewer
            if callback is None or isinstance(callback, list):
                callbacks = callback or []
            else:  # a callback, or a function as SB3 takes it
                callbacks = [callback if isinstance(callback, BaseCallback) else ConvertCallback(callback)]
            callback = [*callbacks, StepsProgressBarCallback()]
        return super()._init_callback(callback, progress_bar=False)

    def _get_evaluator(self) -> PopulationEvaluator:
        self._evaluator = resolve_evaluator(self.evaluator, getattr(self, "_env_id", None), self.env, self._evaluator)
        align_clock(self.env, self._evaluator)
        return self._evaluator

    def learn(
        self: SelfPopulationAlgorithm,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "run",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfPopulationAlgorithm:
        """
        Train for at least ``total_timesteps`` env steps.

        Training stops at a generation's end: the generation during which ``num_timesteps`` reaches
        ``total_timesteps`` is completed and applied (so the run can overshoot by up to one generation), and no
        further one is started; nothing (strategy, observation statistics, the env's ``VecNormalize``) changes
        after it. With ``verbose >= 1`` the size of a generation is printed at the start.

        :param total_timesteps: Env steps to train for.
        :param callback: Callback(s) called at every vec step; returning False stops training at once
            (the interrupted generation is discarded, the parameters stay those of the last update).
        :param log_interval: Number of generations between two log dumps.
        :param tb_log_name: Name of the TensorBoard run.
        :param reset_num_timesteps: Whether to reset ``num_timesteps`` (False to continue a run).
        :param progress_bar: Display a progress bar (tqdm and rich).
        :return: The trained model.
        """
        evaluator = self._get_evaluator()
        total_timesteps, callback = self._setup_learn(
            total_timesteps, callback, reset_num_timesteps, tb_log_name, progress_bar
        )
        iteration = 0  # generations of this learn() call, as SB3's on-policy algorithms count them
        callback.on_training_start(locals(), globals())
        self._stop_training = False
        if self.verbose >= 1:
            print(self._generation_size_message(total_timesteps))
        while self.num_timesteps < total_timesteps and not self._stop_training:
            self._update_current_progress_remaining(self.num_timesteps, total_timesteps)
            if not self._run_generation(evaluator, callback):
                break
            self._n_updates += 1
            self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")  # as SB3's PPO
            iteration += 1
            if log_interval is not None and iteration % log_interval == 0:
                self.dump_logs(iteration)
        if total_timesteps > 0:  # as PPO's: 0 (or less) at the end; learn(0) runs nothing and returns, as PPO's
            self._update_current_progress_remaining(self.num_timesteps, total_timesteps)
        callback.on_training_end()
        return self

    def _generation_size_message(self, total_timesteps: int) -> str:
        """
        :param total_timesteps: The ``learn()`` target.
        :return: What a generation costs, and where ``learn()`` stops.
        """
        max_steps = self.episode_step_limit()
        size = getattr(self.strategy, "population_size", None)
        if size is None:
            episodes = f"its candidates x {self.n_eval_episodes} episode(s)"
        else:
            n = int(size) * self.n_eval_episodes
            episodes = (
                f"{size} candidates x {self.n_eval_episodes} episode(s) = {n} episodes, at most "
                f"{n * max_steps} env steps of candidates"
            )
        return (
            f"{type(self).__name__}: a generation evaluates {episodes} (episodes last at most {max_steps} steps; "
            f"env slots left idle at its end run the center policy, and those steps count in num_timesteps too). "
            f"learn() stops at the end of the generation "
            f"during which num_timesteps reaches {total_timesteps}, so it can overshoot by up to one generation."
        )

    def _run_generation(self, evaluator: PopulationEvaluator, callback: BaseCallback) -> bool:
        """
        Ask, evaluate, tell. Returns False when a callback stopped training before the generation ended.

        :param evaluator: Who runs the candidates.
        :param callback: The callbacks.
        :return: Whether the generation was completed and applied.
        """
        assert self.strategy is not None and self._env_rng is not None
        population = self._ask()
        seed = int(self._env_rng.integers(2**31 - 1))
        reset_seeds = self._reset_seeds(len(population))
        callback.on_rollout_start()

        def step_hook(
            n_envs: int, infos: list[dict[str, Any]], dones: np.ndarray, rewards: np.ndarray, new_obs: Any, actions: Any
        ) -> bool:
            self.num_timesteps += n_envs
            callback.update_locals(
                {
                    "env": self.env,
                    "infos": infos,
                    "dones": dones,
                    "n_envs": n_envs,
                    "rewards": rewards,
                    "new_obs": new_obs,
                    "actions": actions,
                    "clipped_actions": actions,  # PPO's name for what the env took, which actions already is
                }
            )
            if not callback.on_step():
                self._stop_training = True
            return not self._stop_training

        # Calls of the model env's num_envs steps, as SB3's callbacks count them, whatever the evaluator's slots.
        calls = StepCalls(step_hook, self.n_envs)
        result = evaluator.evaluate(
            self.policy.network_spec(),
            population,
            self.strategy.center,
            self.n_eval_episodes,
            seed,
            calls,
            self.reward_shaping,
            max_episode_steps=self.episode_step_limit(),
            reset_seeds=reset_seeds,
        )
        # As SB3's collect_rollouts: a stop on any step, the generation's last included, discards the generation
        # (no on_rollout_end, no update), so that the model returned is the one the callback judged.
        if result.stopped or calls.dropped or not calls.flush() or self._stop_training:
            return False
        self._record_episodes(result)  # before on_rollout_end, so that callbacks see this generation's episodes
        callback.on_rollout_end()
        stats = result.obs_stats
        if stats.n_nonfinite and self.policy.normalize_observations:
            warnings.warn(
                f"{stats.n_nonfinite} of the {stats.n_nonfinite + stats.count} observations of this generation had "
                "NaN or infinite values: they were left out of the observation statistics (check the env).",
                stacklevel=2,
            )
        fitness = result.fitness_returns.mean(axis=1)
        for key, value in self.strategy.tell(fitness).items():
            self.logger.record(f"train/{key}", value)
        if self.policy.normalize_observations:
            self.policy.update_obs_rms(*stats.moments())
        self.policy.load_from_vector(self.strategy.center)
        self._record_generation(result, fitness)
        return True

    def _reset_seeds(self, n_candidates: int) -> np.ndarray | None:
        """
        :param n_candidates: Size of the population asked.
        :return: With ``common_seeds``, the reset seed of each candidate's episodes ``(n_candidates,
            n_eval_episodes)``, shared within the strategy's seed groups; otherwise ``None``.
        """
        if not getattr(self, "common_seeds", False):  # models saved before common_seeds: off
            return None
        assert self.strategy is not None and self._env_rng is not None
        groups = self.strategy.seed_groups(n_candidates)
        group_seeds = self._env_rng.integers(2**31 - 1, size=(int(groups.max()) + 1, self.n_eval_episodes))
        return group_seeds[groups]

    def _record_episodes(self, result: PopulationResult) -> None:
        """
        Add the generation's candidate episodes to the episode buffers (and to the Monitor files, for episodes run
        in other processes).

        :param result: The evaluation results.
        """
        assert self.ep_success_buffer is not None
        self._update_info_buffer([{"episode": info} for info in result.ep_infos])
        if self._evaluator is not None:
            write_remote_episodes(self.env, self._evaluator, result.ep_infos)
        self.ep_success_buffer.extend(result.successes)

    def _record_generation(self, result: PopulationResult, fitness: np.ndarray) -> None:
        """
        Record this generation's statistics.

        :param result: The evaluation results.
        :param fitness: The fitness given to the strategy.
        """
        self.logger.record("rollout/candidate_return_mean", float(result.returns.mean()))
        self.logger.record("rollout/candidate_return_max", float(result.returns.mean(axis=1).max()))
        self.logger.record("rollout/fitness_mean", float(fitness.mean()))
        self.logger.record("rollout/fitness_std", float(fitness.std()))
        if result.center_returns:
            self.logger.record("rollout/center_return", float(np.mean(result.center_returns)))
