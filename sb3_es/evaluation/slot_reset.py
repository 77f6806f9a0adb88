"""Reset one slot of a VecEnv (optionally with a seed) and write its first observation into the step's batch."""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper, VecTransposeImage


def can_reset_slots(env: VecEnv) -> bool:
    """
    :param env: A VecEnv.
    :return: Whether its slots can be reset one at a time (``env_method("reset")``): not through a
        ``VecEnvWrapper`` (a ``VecNormalize`` or ``VecFrameStack`` would not see the reset), except SB3's
        ``VecTransposeImage``, which keeps no state (the first observation is transposed here).
    """
    return not isinstance(env.venv if isinstance(env, VecTransposeImage) else env, VecEnvWrapper)


def check_common_seeds(env: VecEnv) -> None:
    """
    Raise a clear error when common reset seeds cannot be used on ``env`` (see :func:`can_reset_slots`).

    :param env: The VecEnv that evaluates the candidates.
    """
    if not can_reset_slots(env):
        raise ValueError(
            f"Common reset seeds (common_seeds=True) reset each candidate's episode on its own, which cannot be "
            f"done through {type(env).__name__} (the VecEnv wrapper would not see the reset): evaluate on a VecEnv "
            "without VecEnv wrappers (normalize observations with the policy's normalize_observations instead of "
            "VecNormalize), or set common_seeds=False."
        )


def reset_slot(env: VecEnv, slot: int, obs: np.ndarray | dict[str, np.ndarray], seed: int | None = None) -> Any:
    """
    Reset the env of one slot and write its first observation into ``obs`` (in place).

    :param env: The VecEnv (see :func:`can_reset_slots`).
    :param slot: The slot.
    :param obs: The batch of observations returned by the last ``step()`` or ``reset()``.
    :param seed: Seed of the reset (``None``: the env's own random sequence goes on).
    :return: The slot's observation before the reset (a copy).
    """
    kwargs = {} if seed is None else {"seed": int(seed)}
    first_obs, _ = env.env_method("reset", indices=[slot], **kwargs)[0]
    if isinstance(env, VecTransposeImage):
        first_obs = env.transpose_observations(first_obs)
    previous: Any
    if isinstance(obs, dict):
        previous = {key: np.array(value[slot]) for key, value in obs.items()}
        for key, value in obs.items():
            value[slot] = first_obs[key]
    else:
        previous = np.array(obs[slot])
        obs[slot] = first_obs
    return previous
