"""Per-step reward shaping of the training fitness (the logged returns stay the env's raw reward)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from sb3_es.strategies.base import is_number, yaml_string_hint


def _finite_number(value: Any) -> bool:
    """:return: Whether ``value`` is a finite real number (not a bool, not a string)."""
    return is_number(value) and math.isfinite(value)


@dataclass(frozen=True)
class RewardShaping:
    """
    Transform applied to each step's reward when summing a candidate's *fitness*, never to the logged returns.

    In this order: the reward of a step that *terminated* the episode (not a time-limit truncation) is replaced
    by ``terminal_reward``; the result is clipped to ``reward_clip``; ``alive_bonus_offset`` is added.

    * ``terminal_reward=0`` is estool's BipedalWalker fitness (Ha 2017, ``simulate()`` maps the -100 fall
      penalty to 0), so that a candidate that walks and then falls outranks one that stands still.
    * ``reward_clip=(-1, 1)`` is the per-step clipping of the ARS implementations that solve BipedalWalker and
      of Atari DQN (Mnih et al. 2015): one large penalty cannot dominate the ranking.
    * ``alive_bonus_offset`` (ARS paper, Mania et al. 2018) removes a per-step survival bonus, e.g. -1 on Hopper.

    :param reward_clip: ``(low, high)`` bounds for each step's reward, or ``None``.
    :param terminal_reward: Reward given instead of the env's on a terminating step, or ``None``.
    :param alive_bonus_offset: Added to every step's reward.
    """

    reward_clip: tuple[float, float] | None = None
    terminal_reward: float | None = None
    alive_bonus_offset: float = 0.0

    @classmethod
    def create(
        cls,
        reward_clip: Sequence[float] | None = None,
        terminal_reward: float | None = None,
        alive_bonus_offset: float = 0.0,
    ) -> RewardShaping:
        """
        Validate user input (e.g. a YAML list for ``reward_clip``) and build the shaping.

        :return: The shaping.
        """
        clip: tuple[float, float] | None = None
        if reward_clip is not None:
            values: list[Any] = []
            if isinstance(reward_clip, np.ndarray):
                values = reward_clip.ravel().tolist()
            elif isinstance(reward_clip, Sequence) and not isinstance(reward_clip, str):
                values = list(reward_clip)
            finite = all(_finite_number(v) for v in values)
            if len(values) != 2 or not finite or values[0] >= values[1]:
                hint = next(filter(None, map(yaml_string_hint, values)), "")
                raise ValueError(
                    f"reward_clip={reward_clip!r}: give two finite numbers (low, high) with low < high, e.g. "
                    f"reward_clip=(-1, 1), or None for no clipping{hint}."
                )
            clip = (float(values[0]), float(values[1]))
        if terminal_reward is not None and not _finite_number(terminal_reward):
            raise ValueError(
                f"terminal_reward={terminal_reward!r}: give a finite number, or None to keep the env's"
                f"{yaml_string_hint(terminal_reward)}."
            )
        if not _finite_number(alive_bonus_offset):
            raise ValueError(
                f"alive_bonus_offset={alive_bonus_offset!r}: give a finite number (0 for none)"
                f"{yaml_string_hint(alive_bonus_offset)}."
            )
        return cls(clip, None if terminal_reward is None else float(terminal_reward), float(alive_bonus_offset))

    @property
    def is_identity(self) -> bool:
        """:return: Whether the fitness is the raw return."""
        return self.reward_clip is None and self.terminal_reward is None and self.alive_bonus_offset == 0.0

    def __call__(self, rewards: np.ndarray, dones: np.ndarray, infos: Sequence[dict[str, Any]]) -> np.ndarray:
        """
        :param rewards: One vec step's rewards ``(n_envs,)``.
        :param dones: Its dones (SB3 VecEnv: terminated or truncated).
        :param infos: Its infos (``"TimeLimit.truncated"`` marks a truncation).
        :return: The shaped rewards, float64.
        """
        shaped = np.asarray(rewards, dtype=np.float64)
        if self.terminal_reward is not None and np.any(dones):
            terminated = [bool(d) and not info.get("TimeLimit.truncated", False) for d, info in zip(dones, infos)]
            shaped = np.where(terminated, self.terminal_reward, shaped)
        if self.reward_clip is not None:
            shaped = np.clip(shaped, *self.reward_clip)
        return shaped + self.alive_bonus_offset
