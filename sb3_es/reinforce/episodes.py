"""The complete episodes of one REINFORCE update: which env slot plays how many, the transitions kept while they
are played, and the discounted returns-to-go of the batch."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class EpisodeBatch:
    """
    The transitions of the complete episodes collected for one update, flattened over time and env slots.

    :param observations: Observations ``(n_steps, ...)`` (a dict of arrays for ``Dict`` spaces).
    :param indices: Action indices taken (what the policy's distribution sampled).
    :param returns: Discounted returns-to-go ``G_t`` (not normalized).
    :param episode_returns: Undiscounted return of each episode in the batch.
    """

    observations: np.ndarray | dict[str, np.ndarray]
    indices: np.ndarray
    returns: np.ndarray
    episode_returns: np.ndarray


def check_rewards(rewards: np.ndarray, dones: np.ndarray, keep: np.ndarray, update: int) -> None:
    """
    Refuse a batch whose episodes have a non-finite reward (it would make every weight NaN).

    :param rewards: Rewards ``(n_steps, n_envs)`` of the vec steps of the update.
    :param dones: Episode ends, same shape.
    :param keep: Which steps belong to the episodes used by the update, same shape.
    :param update: Number of the update (1 for the first of the model), for the message.
    """
    bad = keep & ~np.isfinite(rewards)
    if not bad.any():
        return
    t, slot = (int(k) for k in np.argwhere(bad)[0])
    ends = np.flatnonzero(dones[:t, slot])
    episode = len(ends) + 1
    step = t - (int(ends[-1]) if len(ends) else -1)
    raise ValueError(
        f"Non-finite reward {rewards[t, slot]} at step {step} of episode {episode} (env slot {slot}) in update "
        f"{update}, {int(bad.sum())} such reward(s) in the episodes of this update. The update was not applied: the "
        "parameters are those of the last update. Check the environment's rewards (NaN/inf)."
    )


class EpisodeCollector:
    """
    The episodes of one update as a VecEnv plays them, vec step by vec step.

    The ``n_episodes`` episodes are split in advance between the env slots (slot ``i`` plays ``n_episodes //
    n_envs`` of them, plus one if ``i < n_episodes % n_envs``); a slot's episodes past its share, and any episode
    still running when the last needed one ends, are played but not kept.

    :param n_episodes: Complete episodes per update.
    :param n_envs: Env slots.
    """

    def __init__(self, n_episodes: int, n_envs: int) -> None:
        self.quotas = np.array([n_episodes // n_envs + (i < n_episodes % n_envs) for i in range(n_envs)])
        self.finished = np.zeros(n_envs, dtype=np.int64)
        #: Return and length so far of the episode each slot is playing.
        self.ep_return = np.zeros(n_envs)
        self.ep_length = np.zeros(n_envs, dtype=np.int64)
        self._obs: list[Any] = []
        self._indices: list[np.ndarray] = []
        self._rewards: list[np.ndarray] = []
        self._dones: list[np.ndarray] = []
        self._keep: list[np.ndarray] = []
        self._kept_returns: list[float] = []

    @property
    def complete(self) -> bool:
        """:return: Whether every slot has played its share."""
        return not np.any(self.finished < self.quotas)

    def add(
        self, obs: Any, indices: np.ndarray, rewards: np.ndarray, dones: np.ndarray, infos: list[dict[str, Any]]
    ) -> list[dict[str, Any]]:
        """
        Record one vec step.

        :param obs: The observations the actions were taken on.
        :param indices: The action indices taken.
        :param rewards: The rewards of the step.
        :param dones: The episode ends of the step.
        :param infos: The infos of the step.
        :return: ``{"episode": {"r": ..., "l": ...}}`` for each episode that ended without a ``Monitor`` to report
            it (what was measured here), for SB3's episode buffer.
        """
        keep = self.finished < self.quotas
        self._obs.append(obs)
        self._indices.append(indices)
        self._rewards.append(np.asarray(rewards, dtype=np.float64))
        self._dones.append(np.asarray(dones, dtype=bool))
        self._keep.append(keep)
        self.ep_return += rewards
        self.ep_length += 1
        unmonitored = []
        for i in np.flatnonzero(dones):
            if "episode" not in infos[i]:
                unmonitored.append({"episode": {"r": float(self.ep_return[i]), "l": int(self.ep_length[i])}})
            if keep[i]:
                self._kept_returns.append(float(self.ep_return[i]))
            self.ep_return[i] = 0.0
            self.ep_length[i] = 0
        self.finished += dones
        return unmonitored

    def batch(self, gamma: float, update: int) -> EpisodeBatch:
        """
        :param gamma: Discount factor.
        :param update: Number of the update (1 for the first of the model), for the error on a non-finite reward.
        :return: The kept transitions, with their discounted returns-to-go (episodes cut by a time limit are
            treated like terminated ones: no bootstrapping).
        """
        rewards, dones, keep = np.stack(self._rewards), np.stack(self._dones), np.stack(self._keep)
        check_rewards(rewards, dones, keep, update)
        # The discarded steps (unchecked, possibly non-finite) take no part: a 0 * nan would carry into a kept episode.
        rewards = np.where(keep, rewards, 0.0)
        returns = np.zeros_like(rewards)
        running = np.zeros(rewards.shape[1])
        for t in reversed(range(len(rewards))):
            running = rewards[t] + gamma * np.where(dones[t], 0.0, running)
            returns[t] = running
        if isinstance(self._obs[0], dict):
            observations: np.ndarray | dict[str, np.ndarray] = {
                key: np.stack([o[key] for o in self._obs])[keep] for key in self._obs[0]
            }
        else:
            observations = np.stack(self._obs)[keep]
        return EpisodeBatch(
            observations=observations,
            indices=np.stack(self._indices)[keep],
            returns=returns[keep],
            episode_returns=np.array(self._kept_returns),
        )
