"""
A training-only reward for dm_control walker-walk that pays more for a high torso: ``StandBonus``.

walker-walk pays per step ``stand * (5 * move + 1) / 6``; ``stand`` mixes a torso-height term ``standing`` (1 from
1.2 m up, falling off below) with uprightness. ``StandBonus`` adds ``weight * standing`` to each step's reward, so
that a search which has settled on a fast crouched gait (``benchmarks/walker_gait.py``) gains more by rising. Used
as rl-zoo's ``env_wrapper``, it is applied after SB3's ``Monitor``: the Monitor files, ``rollout/ep_rew_mean`` and
the evaluations stay the task's own reward; only the fitness the search ranks by changes. Example::

    python benchmarks/compare.py --algos pgpe --envs dm_control/walker-walk-v0 ... \\
        --override pgpe:env_wrapper=benchmarks.walker_shaping.StandBonus

(run from the repository root, which must be importable: ``PYTHONPATH=.``).
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
from dm_control.suite import walker
from dm_control.utils import rewards

#: dm_control's walker: the torso height from which ``standing`` pays in full.
STAND_HEIGHT: float = walker._STAND_HEIGHT


def walker_physics(env: gym.Env) -> Any:
    """
    The dm_control physics of a ``dm_control/walker-*`` env made through shimmy (torso height, speed, uprightness).

    :param env: The env, wrapped or not.
    :return: Its ``dm_control.suite.walker.Physics``.
    """
    physics = getattr(getattr(env.unwrapped, "_env", None), "physics", None)
    if not hasattr(physics, "torso_height"):
        raise ValueError(
            f"needs a dm_control walker env made through shimmy (e.g. 'dm_control/walker-walk-v0'), got {env}: "
            f"use it only on those envs."
        )
    return physics


class StandBonus(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """
    Add ``weight * standing`` (dm_control's walker torso-height term, in [0, 1]) to each step's reward.

    :param env: A ``dm_control/walker-*`` env made through shimmy.
    :param weight: The bonus for a torso at full standing height, per step.
    """

    def __init__(self, env: gym.Env, weight: float = 1.0) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, weight=weight)
        gym.Wrapper.__init__(self, env)
        try:
            self._physics = walker_physics(env)
        except ValueError as error:
            raise ValueError(f"StandBonus {error}") from None
        self.weight = weight

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        standing = rewards.tolerance(
            self._physics.torso_height(), bounds=(STAND_HEIGHT, float("inf")), margin=STAND_HEIGHT / 2
        )
        return obs, float(reward) + self.weight * float(standing), terminated, truncated, info
