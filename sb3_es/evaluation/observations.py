"""Observations as the networks see them: one flat float32 vector per observation (SB3's preprocessing)."""

from __future__ import annotations

from typing import TypeVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.preprocessing import get_flattened_obs_dim, preprocess_obs

#: A batch of observations, NumPy or torch.
ObsT = TypeVar("ObsT", np.ndarray, th.Tensor)

#: Observation spaces a network takes, alone or as the entries of a ``Dict``.
FLAT_OBS_SPACES = (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)


def flat_obs_dim(observation_space: spaces.Space) -> int:
    """
    Size of the flattened observation vector, or a clear error for a space that cannot be flattened.

    :param observation_space: A ``Box``, ``Discrete``, ``MultiDiscrete`` or ``MultiBinary`` space, or a ``Dict`` of
        them (e.g. dm_control through shimmy). Discrete entries count one input per value (one-hot).
    :return: Number of scalars in one flattened observation.
    """
    entries = observation_space.spaces.values() if isinstance(observation_space, spaces.Dict) else [observation_space]
    for space in entries:
        if isinstance(space, spaces.MultiDiscrete) and space.nvec.ndim > 1:  # SB3's one-hot takes a 1-D nvec only
            raise ValueError(
                f"Unsupported observation space {space}: a MultiDiscrete with a {space.nvec.ndim}-D nvec "
                f"{space.nvec.shape}; wrap the env with gymnasium.wrappers.FlattenObservation (or give it a 1-D nvec)."
            )
    if isinstance(observation_space, spaces.Dict):
        bad = {k: type(s).__name__ for k, s in observation_space.spaces.items() if not isinstance(s, FLAT_OBS_SPACES)}
        if bad:
            raise ValueError(
                f"Unsupported observation space: Dict entries {bad} are not Box, Discrete, MultiDiscrete or "
                "MultiBinary spaces; wrap the env with gymnasium.wrappers.FlattenObservation."
            )
        return sum(int(get_flattened_obs_dim(s)) for s in observation_space.spaces.values())
    if isinstance(observation_space, FLAT_OBS_SPACES):
        return int(get_flattened_obs_dim(observation_space))
    raise ValueError(
        f"Unsupported observation space {observation_space}: sb3-es policies take Box, Discrete, MultiDiscrete and "
        "MultiBinary observations, or a Dict of them. Wrap the env with gymnasium.wrappers.FlattenObservation "
        "(Tuple, ...) or a TransformObservation that produces a Box."
    )


def counted_from_zero(obs: ObsT, space: spaces.Space) -> ObsT:
    """
    :param obs: A batch of observations of ``space`` (NumPy or torch).
    :param space: Their space.
    :return: For a ``Discrete`` or ``MultiDiscrete`` space with a ``start``, the values counted from 0, as SB3's
        one-hot encoding counts them (``Discrete(3, start=1)`` holds 1, 2, 3); else ``obs`` unchanged.
    """
    if not (isinstance(space, spaces.Discrete | spaces.MultiDiscrete) and np.any(space.start)):
        return obs
    if isinstance(obs, th.Tensor):
        return obs - th.as_tensor(space.start, device=obs.device, dtype=obs.dtype)  # type: ignore[return-value]
    return obs - space.start  # type: ignore[no-any-return]


def _flatten_entry(obs: np.ndarray, space: spaces.Space) -> np.ndarray:
    """
    :param obs: A batch of observations of ``space``.
    :param space: The space: a ``Box`` is flattened; other spaces go through SB3's ``preprocess_obs`` (one-hot).
    :return: ``(n, flat_dim)`` observations.
    """
    obs = counted_from_zero(np.asarray(obs), space)
    if not isinstance(space, spaces.Box):
        obs = preprocess_obs(th.as_tensor(obs), space, normalize_images=False).numpy()  # type: ignore[union-attr]
    return obs.reshape(obs.shape[0], -1)


def flatten_obs(observation_space: spaces.Space, obs: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
    """
    Flatten a batch of observations to ``(n, obs_dim)`` float32 (discrete ones one-hot, as SB3 does).

    :param observation_space: The observation space (``Dict`` entries are concatenated in its key order).
    :param obs: Array, or dict of arrays for ``Dict`` spaces, with a leading batch dimension.
    :return: Flattened observations.
    """
    if isinstance(observation_space, spaces.Dict):
        assert isinstance(obs, dict)
        parts = [_flatten_entry(obs[key], subspace) for key, subspace in observation_space.spaces.items()]
        return np.concatenate(parts, axis=1).astype(np.float32, copy=False)
    return _flatten_entry(obs, observation_space).astype(np.float32, copy=False)  # type: ignore[arg-type]
