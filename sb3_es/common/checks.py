"""Clear errors for bad hyperparameters, at construction and, for schedules, at every generation."""

from __future__ import annotations

import inspect
import numbers
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from stable_baselines3.common.type_aliases import Schedule

from sb3_es.strategies.base import check_number, is_number


def check_positive(name: str, value: float | Schedule) -> None:
    """
    Raise a clear error for a non-positive hyperparameter (a schedule is checked at the start of training).

    :param name: Hyperparameter name, for the message.
    :param value: A float or a schedule ``progress_remaining -> value``.
    """
    start = check_number(name, value(1.0) if callable(value) else value)
    if not np.isfinite(start) or start <= 0:
        raise ValueError(f"{name}={start}: it must be a positive number (got {value!r}).")


def check_scheduled_value(name: str, value: Any, progress_remaining: float, allow_zero: bool = False) -> float:
    """
    Raise a clear error when a schedule gives a non-number, or a non-positive (or negative) or non-finite value, during
    training.

    :param name: Hyperparameter name, for the message.
    :param value: The schedule's value now.
    :param progress_remaining: SB3's progress remaining (1 to 0) at which it was evaluated.
    :param allow_zero: Accept 0: a step size (learning rate) that ends at 0 with the training adds nothing to the
        step (an optimizer with momentum coasts on its velocity),
        whereas a noise scale (``sigma``, ``delta_std``) of 0 leaves nothing to explore.
    :return: ``value`` as a float.
    """
    if not is_number(value):
        raise TypeError(
            f"The {name} schedule gave {value!r} at progress_remaining={progress_remaining:.4g}: it must return a "
            "number (a float) for every progress_remaining from 1 to 0."
        )
    value = float(value)
    if not (np.isfinite(value) and (value >= 0 if allow_zero else value > 0)):
        bound, floor = (">= 0", "0.0") if allow_zero else ("> 0", "1e-6")
        reason = "a negative step size steps downhill" if allow_zero else f"{name} must stay positive"
        raise ValueError(
            f"The {name} schedule gave {value:.6g} at progress_remaining={progress_remaining:.4g}: it must stay "
            f"{bound} for all of training ({reason}). Fix the schedule, e.g. clip it: "
            f"lambda progress: max({floor}, schedule(progress))."
        )
    return value


def check_seed(seed: int | None) -> int | None:
    """
    Raise a clear error for a seed that NumPy and torch would refuse deep inside ``set_random_seed``.

    :param seed: The ``seed`` argument of an algorithm.
    :return: The seed as a Python ``int`` (Python's ``random`` refuses a NumPy integer), or ``None``.
    """
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or not 0 <= seed < 2**32:
        raise ValueError(f"seed={seed!r}: it must be an integer in [0, 2**32 - 1], or None for a random seed.")
    return int(seed)


def check_policy_class(algorithm: str, policy_class: Any, base: type, aliases: Iterable[str]) -> None:
    """
    Raise a clear error for a policy class the algorithm cannot train, before building it.

    :param algorithm: The algorithm's name, for the message.
    :param policy_class: The class given (or looked up from an alias).
    :param base: The policy class it must derive from.
    :param aliases: The algorithm's policy names.
    """
    if not (isinstance(policy_class, type) and issubclass(policy_class, base)):
        name = getattr(policy_class, "__name__", repr(policy_class))
        raise TypeError(
            f"{algorithm} needs a {base.__name__} subclass, got {name}: pass one of its policy names "
            f"({', '.join(map(repr, aliases))}) or a subclass of {base.__module__}.{base.__name__}."
        )


def check_policy_kwargs(policy_kwargs: Any) -> None:
    """
    Raise a clear error for ``policy_kwargs`` that is not a mapping (``**`` or ``.get`` would fail without naming it).

    :param policy_kwargs: The ``policy_kwargs`` argument of an algorithm.
    """
    if policy_kwargs is not None and not isinstance(policy_kwargs, Mapping):
        raise TypeError(
            f"policy_kwargs={policy_kwargs!r}: it must be a dict of the policy's keyword arguments, e.g. "
            'dict(net_arch=[64, 64]) (in an rl-zoo hyperparameter file, the string "dict(net_arch=[64, 64])").'
        )


def check_policy_kwarg_names(policy_class: type, policy_kwargs: Mapping[str, Any]) -> None:
    """
    Raise a clear error for ``policy_kwargs`` keys the policy does not take (e.g. ``log_std_init`` copied from
    another algorithm's rl-zoo entry), naming the keys it takes. A policy whose ``__init__`` takes
    ``**kwargs`` is not checked.

    :param policy_class: The policy class.
    :param policy_kwargs: The keyword arguments it will be built with.
    """
    parameters = inspect.signature(policy_class).parameters  # the constructor's, without self
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return
    built = {"observation_space", "action_space", "lr_schedule", "use_baseline"}  # given by the algorithm
    taken = [name for name in parameters if name not in built]
    unknown = sorted(set(policy_kwargs) - set(taken))
    if unknown:
        raise TypeError(
            f"policy_kwargs {unknown}: {policy_class.__name__} takes no such argument. Its arguments are "
            f"{', '.join(taken)}; remove the others (an option of another algorithm's policy, such as PPO's "
            "log_std_init, has no counterpart here)."
        )


def check_module_class(name: str, value: Any, base: type, example: str) -> None:
    """
    Raise a clear error unless ``value`` is a subclass of ``base`` (a class, as SB3's ``policy_kwargs`` take it).

    :param name: The argument's name, for the message.
    :param value: The value given.
    :param base: The class it must derive from.
    :param example: A valid value, for the message.
    """
    if not (isinstance(value, type) and issubclass(value, base)):
        raise TypeError(
            f"{name}={value!r}: pass a subclass of {base.__module__}.{base.__qualname__}, e.g. {name}={example} "
            "(a class, not an instance or a name), as in SB3's policy_kwargs."
        )
