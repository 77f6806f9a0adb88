"""
Training-only changes of dm_control walker-walk: ``StandBonus`` (a reward that pays more for a high torso) and
``UprightStart`` (a share of the episodes starts standing).

walker-walk pays per step ``stand * (5 * move + 1) / 6``; ``stand`` mixes a torso-height term ``standing`` (1 from
1.2 m up, falling off below) with uprightness. ``StandBonus`` adds ``weight * standing`` to each step's reward, so
that a search which has settled on a fast crouched gait (``benchmarks/walker_gait.py``) gains more by rising. Used
as rl-zoo's ``env_wrapper``, it is applied after SB3's ``Monitor``: the Monitor files, ``rollout/ep_rew_mean`` and
the evaluations stay the task's own reward; only the fitness the search ranks by changes. Example::

    python benchmarks/compare.py --algos pgpe --envs dm_control/walker-walk-v0 ... \\
        --override pgpe:env_wrapper=benchmarks.walker_shaping.StandBonus

(run from the repository root, which must be importable: ``PYTHONPATH=.``).

``UprightStart`` changes where episodes start, so it must stay out of the evaluation env, which rl-zoo's
``env_wrapper`` would also wrap: give it to ``benchmarks/compare.py --train-wrapper`` instead::

    python benchmarks/compare.py --algos pgpe --envs dm_control/walker-walk-v0 ... \\
        --train-wrapper '{benchmarks.walker_shaping.UprightStart: {probability: 0.5}}'
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from dm_control.suite import walker
from dm_control.utils import rewards
from shimmy.utils.dm_env import dm_obs2gym_obs

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


class UprightStart(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """
    Start a share of the episodes standing upright, instead of from dm_control's random pose (often lying).

    At reset, with probability ``probability`` (drawn from the task's own seeded random state), the walker is put
    upright at rest: torso at its standing height, its angle and every leg joint uniform in ``[-noise, noise]``
    radians (within the joints' limits). The other episodes start as the task's own.

    :param env: A ``dm_control/walker-*`` env made through shimmy.
    :param probability: The share of episodes that start upright.
    :param noise: Half-width of the uniform draw of the torso angle and the joint angles, in radians.
    """

    def __init__(self, env: gym.Env, probability: float = 0.5, noise: float = 0.1) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, probability=probability, noise=noise)
        gym.Wrapper.__init__(self, env)
        if not 0 <= probability <= 1 or noise < 0:
            raise ValueError(
                f"UprightStart(probability={probability}, noise={noise}): give a probability in [0, 1] and a "
                "noise >= 0."
            )
        try:
            self._physics = walker_physics(env)
        except ValueError as error:
            raise ValueError(f"UprightStart {error}") from None
        self._task = env.unwrapped._env.task  # type: ignore[attr-defined]
        self.probability = probability
        self.noise = noise

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        random = self._task.random
        if random.uniform() < self.probability:
            physics = self._physics
            # rootz, rootx, rooty, then the six leg joints: upright is 0 for each, as in the model file.
            angles = random.uniform(-self.noise, self.noise, size=physics.model.nq - 2)
            limited = physics.model.jnt_limited[2:].astype(bool)
            low, high = physics.model.jnt_range[2:].T
            angles[limited] = np.clip(angles[limited], low[limited], high[limited])
            with physics.reset_context():
                physics.data.qpos[:] = 0.0
                physics.data.qpos[2:] = angles
                physics.data.qvel[:] = 0.0
            obs = dm_obs2gym_obs(self._task.get_observation(physics))
        return obs, info
