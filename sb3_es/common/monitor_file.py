"""The model's ``Monitor`` file gets the episodes that no ``Monitor`` of the model's envs wrote.

A ``Monitor`` writes an episode when it ends in its env's ``step()``. With ``evaluator="processes"`` or ``"ray"`` the
model's own envs run no episode, and an episode that sb3-es cuts at ``max_episode_steps`` (an env without a time
limit, or a cap below the env's own) ends outside the env: without this, their rows would be missing from the
``Monitor`` CSV files that SB3's ``load_results`` and rl-zoo's ``plot_train`` read.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecEnvWrapper


def unmonitored(ep_infos: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """
    :param ep_infos: Episode infos of the model's own envs: a ``Monitor``'s ``info["episode"]``, or what sb3-es
        measured (``r``, ``l``) for an episode that no ``Monitor`` reported.
    :return: The latter (a ``Monitor``'s info always has its time, ``t``).
    """
    return [info for info in ep_infos if "t" not in info]


def write_episodes(env: VecEnv | None, ep_infos: Sequence[dict[str, Any]]) -> None:
    """
    Append episodes to the ``Monitor`` file of the model's first env, if it has one and lives in this process (a
    ``DummyVecEnv``). An episode without a time (``t``) gets the time since that ``Monitor`` started.

    :param env: The model's VecEnv.
    :param ep_infos: The episodes (``r``, ``l`` and, from a worker's ``Monitor``, ``t``).
    """
    if env is None or not ep_infos:
        return
    venv = env
    while isinstance(venv, VecEnvWrapper):
        venv = venv.venv
    if not isinstance(venv, DummyVecEnv):  # another process's Monitor cannot be written from here
        return
    writer = venv.get_attr("results_writer", indices=[0])[0] if venv.has_attr("results_writer") else None
    if writer is None:
        return
    elapsed = round(time.time() - venv.get_attr("t_start", indices=[0])[0], 6)
    for info in ep_infos:
        writer.write_row(info if "t" in info else {**info, "t": elapsed})
