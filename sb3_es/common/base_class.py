"""What every sb3-es algorithm adds to SB3's ``BaseAlgorithm``: alias resolution, a name in the save, safe load,
episodes that end and SB3's on-policy logging."""

from __future__ import annotations

import inspect
import io
import numbers
import pathlib
import warnings
from collections.abc import Mapping
from typing import Any, ClassVar, TypeVar

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm, maybe_make_env
from stable_baselines3.common.env_util import is_wrapped
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, Schedule, TensorDict
from stable_baselines3.common.utils import ConstantSchedule, LinearSchedule
from stable_baselines3.common.vec_env import VecEnv

from sb3_es.common.checks import check_policy_kwargs, check_positive, check_seed
from sb3_es.common.save_util import algorithm_name, check_save_file
from sb3_es.evaluation.slot_reset import can_reset_slots
from sb3_es.evaluation.time_limit import env_time_limit
from sb3_es.strategies.base import check_count, parse_number

#: Episode length cap for an env without a time limit, when ``max_episode_steps`` is not given (the length of
#: MuJoCo's and dm_control's episodes).
DEFAULT_MAX_EPISODE_STEPS = 1000

SelfESBaseAlgorithm = TypeVar("SelfESBaseAlgorithm", bound="ESBaseAlgorithm")


def constant_value(value: Any) -> Any:
    """
    A ``ConstantSchedule`` as its number (rl-zoo wraps a number given for ``learning_rate`` or ``delta_std`` in one),
    rl-zoo's ``"lin_X"`` as a linear schedule from ``X`` to 0 (rl-zoo converts it for ``learning_rate`` and
    ``delta_std`` only, not ``sigma``), and a NumPy number as Python's; any other value unchanged. A number and a
    constant schedule differ where an algorithm decays a number (OpenES).

    :param value: A hyperparameter value.
    :return: The number of a constant schedule, a schedule, a Python number, or ``value``.
    """
    value = value.val if isinstance(value, ConstantSchedule) else value
    start = parse_number(value[len("lin_") :]) if isinstance(value, str) and value.startswith("lin_") else None
    if start is not None:  # rl-zoo's linear schedule, for the keys it leaves alone
        return LinearSchedule(start, 0.0, 1.0)  # start * progress_remaining
    return python_number(value)


def python_number(value: Any) -> Any:
    """
    A NumPy number as Python's (SB3's schedules take Python numbers only, and a model keeps and saves those), for
    the hyperparameters that take no schedule.

    :param value: A hyperparameter value.
    :return: ``int`` for a NumPy integer, ``float`` for another real number (``np.float32``, ``Fraction``), or
        ``value`` unchanged.
    """
    if isinstance(value, numbers.Integral) and not isinstance(value, bool | int):
        return int(value)  # NumPy's integers
    if isinstance(value, numbers.Real) and not isinstance(value, numbers.Integral | float):
        return float(value)
    return value


def _as_count(value: Any, annotation: Any) -> Any:
    """:return: ``value``, an ``int`` where the argument is a count (annotated ``int``) and ``value`` a whole float
    (YAML's ``4.0``), as the constructors take it."""
    whole = isinstance(value, float) and value.is_integer()
    return int(value) if whole and annotation in ("int", "int | None") else value


#: Marks a constructor argument that the save does not hold.
_MISSING = object()


def _frozen(value: Any) -> Any:
    """:return: ``value`` with lists as tuples, to compare a value given to ``load()`` with the saved one."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    return tuple(_frozen(v) for v in value) if isinstance(value, (list, tuple)) else value


class ESBaseAlgorithm(BaseAlgorithm):
    """
    Base class of the sb3-es algorithms.

    - Policy aliases are resolved before SB3 sees them: SB3 rejects the alias ``"MlpPolicy"`` for Dict
      observations, which sb3-es policies flatten.
    - The algorithm's name is saved (``_algorithm_name``), so ``load()`` can tell a foreign or mismatched
      file apart and say which class wrote it.
    - ``load()`` and ``set_parameters(path)`` first check the file
      (:func:`~sb3_es.common.save_util.check_save_file`) and raise ``ValueError`` for a corrupt file or
      another algorithm's save; subclasses check their own state in :meth:`_check_save_data`.
    - ``dump_logs`` is SB3's ``OnPolicyAlgorithm.dump_logs`` (``rollout/`` and ``time/`` keys).
    - Every episode ends, so that ``learn()`` returns: an env given by its id that has no time limit is wrapped in
      gymnasium's ``TimeLimit``, and the evaluation cuts any episode at :meth:`episode_step_limit` steps.
    - A hyperparameter given to ``load()`` (also rl-zoo's ``train -i model.zip -params``) with a new value is
      applied to the loaded model (:meth:`_apply_hyperparameters`) when the algorithm can change it in mid-run
      (:attr:`_live_hyperparameters`, and for the population methods their scheduled and strategy-held ones);
      any other new value, and a name the algorithm does not have, is refused with a ``ValueError``.

    :param policy: Policy class or alias.
    :param env: Environment, env id or VecEnv.
    :param learning_rate: Learning rate or schedule (``None`` for algorithms without one).
    :param policy_kwargs: Keyword arguments for the policy.
    :param stats_window_size: Episodes averaged in ``rollout/ep_rew_mean``.
    :param tensorboard_log: TensorBoard log directory.
    :param verbose: Verbosity.
    :param device: Torch device (``"auto"``: see :attr:`_auto_device`).
    :param seed: Random seed.
    :param max_episode_steps: Longest episode, in env steps, that training runs: an episode that reaches it is
        truncated (as by a ``TimeLimit`` inside the ``Monitor``, which records it, except in a ``SubprocVecEnv``).
        ``None``: the env's own ``TimeLimit``, or, for an env without one, ``DEFAULT_MAX_EPISODE_STEPS`` (1000) with
        a warning at ``learn()``.
    """

    #: Constructor arguments that ``load()`` may change by setting the attribute alone: read at every update, or
    #: by SB3 itself (a new ``seed`` seeds the global generators and restarts the algorithm's own random streams, as
    #: SB3 seeds all of PPO's randomness; without one, the saved streams continue).
    _live_hyperparameters: ClassVar[tuple[str, ...]] = (
        "tensorboard_log",
        "verbose",
        "seed",
        "device",
        "policy_kwargs",  # SB3's load() refuses a different value itself
        "max_episode_steps",
    )
    #: What ``device="auto"`` means for this algorithm (SB3: CUDA when available).
    _auto_device: ClassVar[str] = "auto"

    def __init__(
        self,
        policy: str | type[BasePolicy],
        env: GymEnv | str | None,
        learning_rate: float | Schedule | None,
        policy_kwargs: dict[str, Any] | None,
        stats_window_size: int,
        tensorboard_log: str | None,
        verbose: int,
        device: th.device | str,
        seed: int | None,
        max_episode_steps: int | None = None,
        _init_setup_model: bool = True,
    ) -> None:
        if env is None and _init_setup_model:  # SB3 then fails on a missing observation_space
            name = type(self).__name__
            raise ValueError(
                f"{name}(policy, env=None): give an env (an env id such as 'Pendulum-v1', a Gymnasium env or a "
                f"VecEnv), from whose spaces the policy is built. A model without an env comes from {name}.load(path)."
            )
        seed = check_seed(seed)
        check_policy_kwargs(policy_kwargs)
        self._check_live_values({"max_episode_steps": max_episode_steps})
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        #: Length limit of the ``TimeLimit`` added to an env given by its id that had none (not saved).
        self._added_time_limit: int | None = None
        self._warned_time_limit = False
        if isinstance(env, str):
            env = maybe_make_env(env, verbose)
            assert isinstance(env, gym.Env)
            # Looked up at call time, as in evaluation/time_limit.py: rl_zoo3 replaces gymnasium's TimeLimit.
            if not is_wrapped(env, gym.wrappers.TimeLimit):
                self._added_time_limit = self.max_episode_steps or DEFAULT_MAX_EPISODE_STEPS
                env = gym.wrappers.TimeLimit(env, self._added_time_limit)
        if env is not None and hasattr(env, "action_space"):
            self._check_action_space(env.action_space)  # before SB3's bare assertion on Box bounds
        if isinstance(policy, str):
            policy = self._get_policy_from_name(policy)
        super().__init__(
            policy,
            env,
            learning_rate=constant_value(learning_rate),  # type: ignore[arg-type]  # None: it has none
            policy_kwargs=policy_kwargs,
            stats_window_size=check_count("stats_window_size", stats_window_size),
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=self._auto_device if isinstance(device, str) and device == "auto" else device,
            support_multi_env=True,
            seed=seed,
        )
        self._algorithm_name = algorithm_name(type(self))
        self._check_episode_cap()  # now, not at learn()

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_added_time_limit", "_warned_time_limit"]

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        env = self._wrap_env(env, self.verbose)  # as SB3's set_env() does (a VecEnv is left as it is)
        self._check_env(env)  # before anything changes
        super().set_env(env, force_reset)
        # A new env: its own time limit (or the lack of one) counts from now on.
        self._added_time_limit = None
        self._warned_time_limit = False

    def _check_env(self, env: VecEnv | None = None) -> None:
        """
        Refuse settings that cannot run on ``env`` (at ``set_env()`` and ``load()``; override to add checks).

        :param env: A VecEnv about to replace the model's (``None``: the model's own).
        """
        self._check_episode_cap(env)

    def _check_episode_cap(self, env: VecEnv | None = None) -> int | None:
        """
        Refuse a ``max_episode_steps`` above the env's own time limit (at construction, ``load()``, ``set_env()``
        and training).

        :param env: A VecEnv about to replace the model's (``None``: the model's own).
        :return: The env's own time limit (``None``: it has none, or it is the one this model added).
        """
        if env is None and self._added_time_limit is not None:
            return None
        env = env if env is not None else self.env
        limit = env_time_limit(env) if env is not None else None
        cap = self.max_episode_steps
        if limit is not None and cap is not None and cap > limit:
            raise ValueError(
                f"max_episode_steps={cap} is above the env's own time limit ({limit} steps), "
                f"which ends every episode first: pass at most {limit}, or give an env made with the longer "
                f"limit (gym.make(env_id, max_episode_steps={cap}))."
            )
        if env is not None and cap is not None and (limit is None or cap < limit) and not can_reset_slots(env):
            raise ValueError(
                f"max_episode_steps={cap} cuts episodes one env slot at a time, which cannot be done through "
                f"{type(env).__name__} (the VecEnv wrapper would not see the reset). Give each env that time limit "
                f"before wrapping the VecEnv (make_vec_env(env_id, env_kwargs=dict(max_episode_steps={cap}))), "
                "and leave max_episode_steps out."
            )
        return limit

    def episode_step_limit(self) -> int:
        """
        The episode length at which training cuts an episode: ``max_episode_steps`` if given, else the env's
        ``TimeLimit``, else ``DEFAULT_MAX_EPISODE_STEPS``, with a warning (once per model) when the env has no
        time limit of its own.

        :return: The cap, in env steps.
        :raises ValueError: When ``max_episode_steps`` is above the env's own time limit, which ends episodes first.
        """
        limit = self._check_episode_cap()
        if self.max_episode_steps is not None:
            return self.max_episode_steps
        if limit is not None and self._added_time_limit is None:
            return limit
        cap = self._added_time_limit or DEFAULT_MAX_EPISODE_STEPS
        if not self._warned_time_limit:
            self._warned_time_limit = True
            warnings.warn(
                f"The env has no time limit (gymnasium's TimeLimit): {type(self).__name__} ends its episodes at "
                f"{cap} steps, so that every episode of training ends. Pass max_episode_steps= to choose the "
                "limit (and silence this warning), or register the env with max_episode_steps.",
                stacklevel=3,
            )
        return cap

    @classmethod
    def _check_save_data(cls, path: str | pathlib.Path | io.BufferedIOBase, data: dict[str, Any]) -> None:
        """
        Check the algorithm-specific state of a save before loading it (override to add checks).

        :param path: The file, for error messages.
        :param data: The save's data dictionary.
        """

    @staticmethod
    def _check_action_space(action_space: gym.Space) -> None:
        """Raise a clear ``ValueError`` for an action space that the algorithm's policies do not support."""

    def _get_policy_from_name(self, policy_name: str) -> type[BasePolicy]:
        """SB3's lookup in ``policy_aliases``, with an error that lists the names there."""
        if policy_name not in self.policy_aliases:
            hint = (
                " A linear policy is MlpPolicy with policy_kwargs=dict(net_arch=[])."
                if policy_name == "LinearPolicy"
                else ""
            )
            raise ValueError(
                f"Policy {policy_name!r} unknown: {type(self).__name__}'s policies are "
                f"{', '.join(sorted(self.policy_aliases))}, or give a policy class.{hint}"
            )
        return super()._get_policy_from_name(policy_name)

    def dump_logs(self, iteration: int = 0) -> None:
        """
        Write the SB3 ``rollout/`` and ``time/`` keys and dump the logger (SB3's ``OnPolicyAlgorithm.dump_logs``).

        :param iteration: Value of ``time/iterations`` (not logged when 0).
        """
        OnPolicyAlgorithm.dump_logs(self, iteration)  # type: ignore[arg-type]

    def set_parameters(
        self,
        load_path_or_dict: str | TensorDict,
        exact_match: bool = True,
        device: th.device | str = "auto",
    ) -> None:
        """
        Load parameters from a save of the same algorithm, or from a dict of state dicts (see ``get_parameters``).

        :param load_path_or_dict: Path or file-like object of a save, or a dict of state dicts.
        :param exact_match: Whether every parameter of the model must be given.
        :param device: Torch device.
        """
        if isinstance(load_path_or_dict, dict):
            params: dict[str, Any] = load_path_or_dict
        else:
            _, params = check_save_file(load_path_or_dict, type(self), method="set_parameters")
        for name, state in params.items():
            if not isinstance(state, Mapping):  # malformed: SB3's set_parameters names it
                continue
            bad = [key for key, value in state.items() if th.is_tensor(value) and not th.isfinite(value).all()]
            if bad:  # the search would start from them, and fail later with a message about the rewards
                raise ValueError(f"set_parameters(): {name}[{bad[0]!r}] holds NaN or infinite values; nothing was set.")
        super().set_parameters(self._upgrade_saved_params(params), exact_match=exact_match, device=device)

    def _upgrade_saved_params(self, params: dict[str, Any]) -> dict[str, Any]:
        """
        Turn parameters of an older save into the current layout (override where the layout changed).

        :param params: Name of an object -> its state dict, as saved.
        :return: The parameters to load.
        """
        return params

    @classmethod
    def load(  # type: ignore[override]
        cls: type[SelfESBaseAlgorithm],
        path: str | pathlib.Path | io.BufferedIOBase,
        env: GymEnv | None = None,
        device: th.device | str = "auto",
        custom_objects: dict[str, Any] | None = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        **kwargs: Any,
    ) -> SelfESBaseAlgorithm:
        """
        Load a model saved by ``save()``, with everything needed to continue training where it stopped.

        Raises ``ValueError`` for a corrupt file, one saved by another algorithm, a hyperparameter in ``kwargs``
        that the algorithm does not have, or a new value that it cannot apply to a model that has trained.

        :param path: Path or file-like object of the zip archive.
        :param env: Environment to continue training on (optional for ``predict()``).
        :param device: Torch device.
        :param custom_objects: Objects replacing saved ones, as in SB3 (e.g. to skip what cannot be deserialized).
            A hyperparameter there is taken as if given in ``kwargs`` (``kwargs`` wins): applied, or refused where
            ``load()`` cannot change it.
        :param print_system_info: Print the system info of the save and of this machine.
        :param force_reset: Reset the env before training.
        :param kwargs: Hyperparameters to change (constructor arguments or saved attributes); a new value is used
            from the next update on. ``learning_rate=0`` (no update) is accepted here, unlike in the constructor, as
            rl-zoo's ``enjoy`` loads every model with it.
        :return: The loaded model.
        """
        custom_objects = dict(custom_objects or {})
        # As SB3's load() rebuilds learning_rate's schedule from a replaced learning_rate, a hyperparameter replaced
        # here drives training: handled as a change, not left on the model beside a strategy that uses the saved one.
        # One that load() can change (policy_kwargs too: the policy is rebuilt with it before the saved weights are
        # loaded into it, as in SB3) stays in custom_objects as well, so that the file's value, which may not even
        # deserialize here, is never read. One that cannot change is refused as in kwargs when it differs from the
        # saved one (SB3 would set it on the model beside a strategy built with the saved value).
        # (Names of this class's own signature: a subclass whose __init__ takes **kwargs keeps SB3's replacement.)
        changeable = cls._applicable_on_load() & cls._parameters()
        live = {key: custom_objects[key] for key in set(custom_objects) & changeable}
        fixed = (set(custom_objects) & cls._parameters()) - changeable
        replaced = {**live, **{key: custom_objects.pop(key) for key in fixed}}
        data, _ = check_save_file(path, cls, custom_objects)
        cls._check_save_data(path, data)
        signature = inspect.signature(cls.__init__).parameters
        kwargs = {
            key: _as_count(constant_value(value), getattr(signature.get(key), "annotation", None))
            for key, value in {**replaced, **kwargs}.items()
        }
        changed = cls._changed_hyperparameters({k: v for k, v in data.items() if k not in live}, kwargs)
        if isinstance(device, str) and device == "auto":
            device = cls._auto_device
        model = super().load(path, env, device, custom_objects, print_system_info, force_reset, **kwargs)
        # One left out of the save (save(exclude=[...])) is the constructor's default on the model, as in SB3: the
        # state built with the saved value takes that default too, so that the model uses what it shows.
        dropped = changeable - set(kwargs) - set(model._excluded_save_params())
        changed |= {key: signature[key].default for key in dropped if key not in data and f"_{key}" not in data}
        model._apply_hyperparameters(changed)
        # The saved or changed settings against the env given (SB3 built the model with it before restoring them).
        model._check_env()
        return model

    @classmethod
    def _check_live_values(cls, values: dict[str, Any]) -> None:
        """
        Raise a clear error for a bad value of a hyperparameter that ``load()`` may change (the constructor runs the
        same checks); override to check a subclass's own, then call this.

        :param values: ``name -> value``, any subset of the hyperparameters.
        """
        steps = values.get("max_episode_steps")
        if steps is not None:
            check_count("max_episode_steps", steps)
        if "seed" in values:
            check_seed(values["seed"])
        if values.get("learning_rate") is not None:
            check_positive("learning_rate", values["learning_rate"])

    @classmethod
    def _parameters(cls) -> set[str]:
        """:return: The constructor's hyperparameters (its arguments but the policy and the env)."""
        return set(inspect.signature(cls.__init__).parameters) - {"self", "policy", "env", "_init_setup_model"}

    @classmethod
    def _applicable_on_load(cls) -> set[str]:
        """:return: The constructor arguments that ``load()`` can give a new value."""
        return set(cls._live_hyperparameters)

    @classmethod
    def _changed_hyperparameters(cls, data: dict[str, Any], kwargs: dict[str, Any]) -> dict[str, Any]:
        """
        The constructor arguments given to ``load()`` with a value other than the saved one; refuse unknown names
        and new values that the algorithm cannot apply.

        :param data: The save's data dictionary.
        :param kwargs: The keyword arguments given to ``load()``.
        :return: ``name -> new value``.
        """
        parameters = cls._parameters()
        # SB3 saves learning_rate for every algorithm; one without it (CMA-ES, PGPE, SimpleES) would ignore it.
        unknown = sorted((set(kwargs) - parameters - set(data)) | ((set(kwargs) & {"learning_rate"}) - parameters))
        if unknown:
            raise ValueError(
                f"{cls.__name__}.load() got {', '.join(unknown)}, which {cls.__name__} does not have (its "
                f"hyperparameters: {', '.join(sorted(parameters))}). Check the spelling."
            )
        # SB3 saves some constructor arguments under a private name (stats_window_size as _stats_window_size).
        saved = {key: data[key] if key in data else data.get(f"_{key}", _MISSING) for key in kwargs}
        changed = {
            key: value
            for key, value in kwargs.items()
            if key in parameters and (saved[key] is _MISSING or _frozen(value) != _frozen(saved[key]))
        }
        for key, value in changed.items():
            if key not in cls._applicable_on_load():
                before = None if saved[key] is _MISSING else saved[key]
                raise ValueError(
                    f"{cls.__name__}.load({key}={value!r}): the saved model has {key}={before!r}, and "
                    f"{cls.__name__} cannot change {key} once it has trained (the saved state was built with it). "
                    f"Leave {key} out of load() (with rl-zoo's train -i: out of -params and the hyperparameter "
                    "file's entry), or train a new model."
                )
        # learning_rate=0, refused by the constructors, stops the updates of a loaded model (rl-zoo's enjoy gives it).
        cls._check_live_values({key: value for key, value in changed.items() if (key, value) != ("learning_rate", 0)})
        return changed

    def set_random_seed(self, seed: int | None = None) -> None:
        """
        SB3's seeding (Python, NumPy, torch, the action space), and the algorithm's own random streams (the
        strategy's samples and noise table, the evaluation seeds), which SB3's does not reach: training then repeats
        as from a new model with this seed.

        :param seed: The seed (``None``: nothing is seeded).
        """
        seed = check_seed(seed)
        super().set_random_seed(seed)
        if seed is not None:
            self._reseed_streams(seed)

    def _reseed_streams(self, seed: int) -> None:
        """
        Restart the algorithm's own random generators from ``seed`` as a new model starts them (they are saved with
        the model, and a loaded model continues them); nothing before they exist.

        :param seed: The seed.
        """

    def _apply_hyperparameters(self, changed: dict[str, Any]) -> None:
        """
        Apply to the loaded model the hyperparameters that ``load()`` changed (SB3's ``load()`` has set the
        attributes and rebuilt ``lr_schedule``; override to hand them to state built from them).

        :param changed: ``name -> new value``.
        """
        if changed.get("seed") is not None:  # as SB3's load() seeds PPO anew
            self._reseed_streams(changed["seed"])
