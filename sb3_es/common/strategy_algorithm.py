"""The model of a population method: a flat policy whose parameters a strategy searches, and the strategy's
hyperparameters (built once, scheduled every generation, changed by ``load()``, upgraded from old saves)."""

from __future__ import annotations

import io
import pathlib
import warnings
from abc import abstractmethod
from collections.abc import Iterable
from typing import Any, ClassVar

import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.type_aliases import Schedule
from stable_baselines3.common.vec_env import VecEnv, unwrap_vec_normalize

from sb3_es.common.base_class import ESBaseAlgorithm
from sb3_es.common.checks import check_policy_class, check_policy_kwarg_names, check_positive, check_scheduled_value
from sb3_es.common.policies import FlatPolicy, check_action_space
from sb3_es.strategies import Strategy
from sb3_es.strategies.base import Population, check_count
from sb3_es.strategies.noise import SharedNoiseTable


def initial_value(value: float | Schedule) -> float:
    """
    :param value: A float or a schedule ``progress_remaining -> value``.
    :return: The value at the start of training (a strategy is built with it; a schedule then takes over).
    """
    return float(value(1.0) if callable(value) else value)


def check_noise_table_size(size: int | None) -> int | None:
    """
    :param size: ``noise_table_size`` of an algorithm: a positive number of float32 values, or ``None``.
    :return: ``size``, once checked.
    """
    return None if size is None else check_count("noise_table_size", size)


def stream_seeds(seed: int | None) -> tuple[np.random.SeedSequence, np.random.SeedSequence]:
    """
    :param seed: The model's seed.
    :return: The seeds of the strategy's random stream (and its noise table) and of the evaluation seeds' stream.
    """
    strategy_seed, env_seed = np.random.SeedSequence(seed).spawn(2)
    return strategy_seed, env_seed


def make_noise_table(size: int | None, seed: np.random.SeedSequence, num_params: int) -> SharedNoiseTable | None:
    """
    Build the shared noise table of a strategy, if one was asked for.

    :param size: Number of float32 values, or ``None`` for no table (directions drawn fresh).
    :param seed: Seed sequence of the strategy (the table's seed is derived from it).
    :param num_params: Size of one perturbation: a clear error at construction for a table smaller than that.
    :return: The table, or ``None``.
    """
    if size is None:
        return None
    table = SharedNoiseTable(size, seed=int(seed.generate_state(1)[0]))
    table.check_fits(num_params)
    return table


class StrategyAlgorithm(ESBaseAlgorithm):
    """
    What a population method keeps between generations, and saves: its :class:`~sb3_es.common.policies.FlatPolicy`
    (whose parameters are the strategy's center), its strategy (built by :meth:`_make_strategy`) and the random
    generator of the evaluation seeds. The training loop that uses them is
    :class:`~sb3_es.common.population_algorithm.PopulationAlgorithm`, whose ``__init__`` sets the attributes
    read here (``zero_policy``, ``seed``, ...).
    """

    policy: FlatPolicy
    strategy: Strategy | None
    _env_rng: np.random.Generator | None
    zero_policy: bool
    #: Hyperparameters that may be SB3 schedules: each names an attribute of the algorithm (a float or a
    #: schedule ``progress_remaining -> value``) and the strategy attribute of the same name. The strategy is
    #: built with the starting value; a schedule is then evaluated, checked and written into the strategy at
    #: the start of every generation (the one place where anything outside a strategy changes it).
    scheduled_hyperparameters: ClassVar[tuple[str, ...]] = ()
    #: Hyperparameters the strategy keeps under the same name and that ``load()`` may change: the strategy checks
    #: the new values (``Strategy.check_settings``) and uses them from the next generation on.
    strategy_hyperparameters: ClassVar[tuple[str, ...]] = ()
    _check_action_space = staticmethod(check_action_space)

    def _setup_model(self) -> None:
        if self.learning_rate is not None:
            self._setup_lr_schedule()  # SB3's lr_schedule attribute, as in SB3; _ask() applies the schedule
        BaseAlgorithm.set_random_seed(self, self.seed)  # not _reseed_streams: a loaded model continues its own
        check_policy_class(self._algorithm_name, self.policy_class, FlatPolicy, self.policy_aliases)
        check_policy_kwarg_names(self.policy_class, self.policy_kwargs)
        policy = self.policy_class(self.observation_space, self.action_space, **self.policy_kwargs)
        assert isinstance(policy, FlatPolicy)  # checked above
        self.policy = policy.to(self.device)
        if self.strategy is None:  # a loaded model brings its strategy (and its random state)
            center = self.policy.parameters_to_vector()
            if self.zero_policy:
                center[self.policy.output_layer_slice()] = 0.0
            self.strategy = self._make_strategy(center, stream_seeds(self.seed)[0])
        elif self.strategy.restored_legacy_state:
            self._upgrade_legacy_strategy()
            self.strategy.state_version = self.strategy.STATE_VERSION
        # A new model's stream of evaluation seeds; a loaded one brings its own, unless it was left out of the save
        # (save(exclude=["_env_rng"])): then a new one, as SB3 does without _last_obs.
        if self._env_rng is None:
            self._env_rng = np.random.default_rng(stream_seeds(self.seed)[1])
        self.policy.load_from_vector(self.strategy.center)
        self._warn_double_normalization(self.env)

    def _check_env(self, env: VecEnv | None = None) -> None:
        super()._check_env(env)
        if env is not None:
            self._warn_double_normalization(env)

    def _warn_double_normalization(self, env: VecEnv | None) -> None:
        """Warn when a ``VecNormalize`` and the policy both normalize the observations."""
        policy = getattr(self, "policy", None)
        normalize = None if env is None else unwrap_vec_normalize(env)
        if normalize is not None and normalize.norm_obs and policy is not None and policy.normalize_observations:
            warnings.warn(
                "The env is wrapped in VecNormalize(norm_obs=True) and the policy normalizes observations itself "
                "(normalize_observations=True, ARS-V2), so they are normalized twice. Keep one: "
                "VecNormalize(norm_obs=False) (in an rl-zoo file, drop the normalize key), or "
                "policy_kwargs=dict(normalize_observations=False).",
                UserWarning,
                stacklevel=2,
            )

    def _reseed_streams(self, seed: int) -> None:
        if self.strategy is not None:  # the constructor's seeding, from ``seed``
            strategy_seed, env_seed = stream_seeds(seed)
            self.strategy.reseed(strategy_seed)
            table = self.strategy.noise_table  # drawn from the strategy's seed too
            if table is not None:
                self.strategy.noise_table = make_noise_table(table.size, strategy_seed, self.strategy.num_params)
            self._env_rng = np.random.default_rng(env_seed)

    @abstractmethod
    def _make_strategy(self, center: np.ndarray, seed: np.random.SeedSequence) -> Strategy:
        """
        Build the strategy.

        :param center: Initial parameters.
        :param seed: Seed for the strategy's random generator.
        :return: The strategy.
        """

    def _upgrade_legacy_strategy(self) -> None:
        """
        A strategy saved before version 2 had hyperparameters that the algorithm overwrote every generation:
        give it the algorithm's values (a schedule is applied at the next generation anyway).
        """
        for name in self.scheduled_hyperparameters:
            value = getattr(self, name)
            if not callable(value):
                setattr(self.strategy, name, float(value))

    @classmethod
    def _applicable_on_load(cls) -> set[str]:
        return super()._applicable_on_load() | set(cls.scheduled_hyperparameters) | set(cls.strategy_hyperparameters)

    def _apply_hyperparameters(self, changed: dict[str, Any]) -> None:
        """
        Hand the loaded strategy the hyperparameters that ``load()`` changed: a number for a scheduled one (a
        schedule is written into it at every generation anyway) and the strategy-held ones; the strategy checks
        them. The others (:attr:`_live_hyperparameters`) are read from the model at every generation.

        :param changed: ``name -> new value``.
        """
        super()._apply_hyperparameters(changed)
        assert self.strategy is not None
        for name, value in changed.items():
            if name in self.scheduled_hyperparameters and not callable(value):
                if name != "learning_rate":  # checked by load() already, with its "no update" 0
                    check_positive(name, value)
                setattr(self.strategy, name, float(value))
            elif name in self.strategy_hyperparameters:
                setattr(self.strategy, name, value)
        self.strategy.check_settings()

    def _ask(self) -> Population:
        """
        Move the center to weights written into the policy since the last generation, write this generation's
        value of every scheduled hyperparameter into the strategy, then ask it.

        :return: The candidates ``(population_size, num_params)``.
        """
        assert self.strategy is not None
        self._follow_policy_weights(self.strategy)
        progress = self._current_progress_remaining
        for name in self.scheduled_hyperparameters:
            schedule = getattr(self, name)
            if callable(schedule):
                # A step size may reach 0 (no update); a noise scale (sigma, delta_std) must stay positive.
                value = check_scheduled_value(name, schedule(progress), progress, allow_zero=name == "learning_rate")
                setattr(self.strategy, name, value)
        return self.strategy.ask()

    @property
    def best_params(self) -> np.ndarray:
        """
        :return: Parameters of the best candidate seen (with ``forget_best``, of the latest generation); its
            fitness is ``strategy.best_fitness``. Load them with ``policy.load_from_vector``; training and
            ``save()`` then go on from them.
        """
        assert self.strategy is not None
        return self.strategy.best_params

    def save(
        self,
        path: str | pathlib.Path | io.BufferedIOBase,
        exclude: Iterable[str] | None = None,
        include: Iterable[str] | None = None,
    ) -> None:
        """
        SB3's ``save()``, with the strategy as it stands between generations (``Strategy.without_pending``): a
        save from a callback in the middle of a generation leaves out the candidates asked, which a loaded model
        asks afresh (CMA-ES keeps them and asks them again: pycma's ``ask()`` uses up state).
        """
        strategy = self.strategy
        if strategy is not None:
            # The saved center is the policy's weights. Moved on the model's strategy, not on the shallow snapshot,
            # whose set_center could write into state it shares with the model's (the optimizers' parameter tensor).
            self._follow_policy_weights(strategy)
            self.strategy = strategy.without_pending()
        try:
            super().save(path, exclude, include)
        finally:
            self.strategy = strategy

    def set_parameters(
        self,
        load_path_or_dict: str | dict[str, th.Tensor],
        exact_match: bool = True,
        device: th.device | str = "auto",
    ) -> None:
        super().set_parameters(load_path_or_dict, exact_match=exact_match, device=device)
        assert self.strategy is not None
        self._follow_policy_weights(self.strategy)

    def _follow_policy_weights(self, strategy: Strategy) -> None:
        """
        Move ``strategy``'s center to the policy's weights where they were written into the policy from outside
        (``set_parameters``, ``policy.load_from_vector(model.best_params)``, ``policy.load_state_dict``), so
        that training and ``save()`` go on from the weights the policy has, as with SB3's own algorithms.

        :param strategy: The strategy (or a saved snapshot of it) whose center follows the policy.
        """
        vector = self.policy.parameters_to_vector()
        if not np.array_equal(vector.astype(np.float32), strategy.center.astype(np.float32)):
            strategy.set_center(vector)

    @classmethod
    def _check_save_data(cls, path: str | pathlib.Path | io.BufferedIOBase, data: dict[str, Any]) -> None:
        if "strategy" not in data:
            raise ValueError(
                f"Cannot load {path!r}: it holds no strategy state (saved with save(exclude=['strategy'])?), so "
                "training could not continue where it stopped. Save the model without excluding it; for the policy "
                "alone, use set_parameters(path) on a new model."
            )
        if not isinstance(data["strategy"], Strategy):
            raise ValueError(
                f"Cannot load {path!r}: the saved strategy state could not be read (the file is damaged or was "
                "written by an incompatible version), so training could not continue where it stopped."
            )
