"""Checks run before SB3 loads a save file: clear errors for corrupt files and other algorithms' saves."""

from __future__ import annotations

import io
import json
import pathlib
import pickle
import zipfile
from typing import Any

from stable_baselines3.common.save_util import load_from_zip_file

#: Attributes that identify the algorithm of a save made by Stable-Baselines3 or sb3-contrib.
_FOREIGN_MARKERS = (
    ("clip_range", "PPO"),
    ("exploration_schedule", "DQN"),
    ("target_policy_noise", "TD3"),
    ("target_entropy", "SAC"),
    ("n_delta", "sb3-contrib's ARS"),
    ("gae_lambda", "A2C"),
)


def guess_foreign_algorithm(data: dict[str, Any]) -> str:
    """
    Name the algorithm that most likely wrote a save that sb3-es did not write.

    :param data: The save's data dictionary.
    :return: A description such as ``"PPO"`` or ``"another library or algorithm"``.
    """
    for key, name in _FOREIGN_MARKERS:
        if key in data:
            return name
    return "another library or algorithm"


def check_save_file(
    path: str | pathlib.Path | io.BufferedIOBase,
    algorithm: type,
    custom_objects: dict[str, Any] | None = None,
    method: str = "load",
) -> tuple[dict[str, Any], dict[str, Any]]:
    """
    Check that ``path`` is a readable sb3-es save of ``algorithm`` before SB3 loads it.

    :param path: File or file-like object given to ``load()`` or ``set_parameters()``.
    :param algorithm: The class that loads it (it loads the saves of its sb3-es base classes, and those of its
        subclasses, which save under their sb3-es algorithm's name).
    :param custom_objects: Objects replacing saved ones (as in SB3's ``load``): they are not deserialized.
    :param method: ``"load"`` or ``"set_parameters"``, for the error messages.
    :return: The save's data dictionary and its parameters (state dicts on the CPU).
    """
    try:
        data, params, _ = load_from_zip_file(path, device="cpu", custom_objects=custom_objects)
    except (
        zipfile.BadZipFile,
        ValueError,
        KeyError,
        EOFError,
        json.JSONDecodeError,
        RuntimeError,
        OSError,
        pickle.UnpicklingError,
        ImportError,
        AttributeError,
    ) as e:
        if isinstance(e, FileNotFoundError):
            raise
        if isinstance(e, ModuleNotFoundError):
            raise ValueError(
                f"Cannot load {path!r}: it holds an object of module {e.name!r}, which cannot be imported here ({e}). "
                "Install or import that module first, or replace the object with custom_objects (e.g. "
                "custom_objects={'policy_kwargs': {...}})."
            ) from e
        raise ValueError(
            f"Cannot load {path!r}: it is corrupt or not a Stable-Baselines3 save file ({type(e).__name__}: {e}). "
            "Re-save the model, or load the right file."
        ) from e
    finally:
        if isinstance(path, io.BufferedIOBase):
            path.seek(0)
    if data is None or params is None or "policy" not in params:
        raise ValueError(
            f"Cannot load {path!r}: the archive has no model data or no policy parameters, so it is corrupt (e.g. "
            "truncated) or not a Stable-Baselines3 save file. Re-save the model, or load the right file."
        )
    saved_by = data.get("_algorithm_name")
    if saved_by not in {c.__name__ for c in algorithm.__mro__}:
        origin = (
            f"by sb3-es {saved_by}"
            if saved_by
            else f"by {guess_foreign_algorithm(data)} (policy class {data.get('policy_class')!r})"
        )
        if not saved_by:
            hint = ""
        elif method == "load":
            hint = f" Load it with {saved_by}.load()."
        else:
            hint = (
                f" To use its weights anyway, pass them as a dict: "
                f"model.{method}({{'policy': {saved_by}.load(path).policy.state_dict()}})."
            )
        raise ValueError(f"Cannot load {path!r} with {algorithm.__name__}.{method}(): it was saved {origin}.{hint}")
    return data, params


def algorithm_name(cls: type) -> str:
    """
    :param cls: An sb3-es algorithm class, or a user's subclass of one.
    :return: The name of its sb3-es algorithm, which its saves record (so that the algorithm loads them too).
    """
    return next(c.__name__ for c in cls.__mro__ if c.__module__.startswith("sb3_es."))
