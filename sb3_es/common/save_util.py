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


def check_save_file(path: str | pathlib.Path | io.BufferedIOBase, algorithm: str) -> dict[str, Any]:
    """
    Check that ``path`` is a readable sb3-es save of ``algorithm`` before SB3 loads it.

    :param path: File or file-like object given to ``load()``.
    :param algorithm: Name of the class that loads it.
    :return: The save's data dictionary.
    """
    try:
        data, params, _ = load_from_zip_file(path, device="cpu")
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
        raise ValueError(
            f"Cannot load {path!r}: it is corrupt or not a Stable-Baselines3 save file ({type(e).__name__}: {e}). "
            "Re-save the model, or load the right file."
        ) from e
    finally:
        if isinstance(path, io.BufferedIOBase):
            path.seek(0)
    if data is None or params is None or "policy" not in params:
        raise ValueError(f"Cannot load {path!r}: the archive has no model data or no policy parameters.")
    saved_by = data.get("_algorithm_name")
    if saved_by != algorithm:
        origin = (
            f"by sb3-es {saved_by}"
            if saved_by
            else f"by {guess_foreign_algorithm(data)} (policy class {data.get('policy_class')!r})"
        )
        hint = f" Load it with {saved_by}.load()." if saved_by else ""
        raise ValueError(f"Cannot load {path!r} with {algorithm}.load(): it was saved {origin}.{hint}")
    return data
