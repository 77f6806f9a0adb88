"""The model's ``Monitor`` file gets the episodes that worker processes or Ray actors ran.

With ``evaluator="processes"`` or ``"ray"`` the model's own envs run no episode, so their ``Monitor`` CSV files
(which rl-zoo's ``plot_train`` reads) would stay empty; the driver writes the workers' episodes to the first one.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecEnvWrapper

from sb3_es.evaluation import PopulationEvaluator, VecEnvEvaluator


def write_remote_episodes(
    env: VecEnv | None, evaluator: PopulationEvaluator, ep_infos: Sequence[dict[str, Any]]
) -> None:
    """
    Write the candidates' episodes run elsewhere to the ``Monitor`` file of the model's first env, if it has one.

    :param env: The model's VecEnv.
    :param evaluator: The evaluator that ran the generation (nothing is written for the model's own VecEnv).
    :param ep_infos: The episodes (the workers' ``Monitor`` infos: ``r``, ``l``, ``t``).
    """
    if env is None or (isinstance(evaluator, VecEnvEvaluator) and evaluator.env is env):
        return
    venv = env
    while isinstance(venv, VecEnvWrapper):
        venv = venv.venv
    if not isinstance(venv, DummyVecEnv):  # another process's Monitor cannot be written from here
        return
    writer = venv.get_attr("results_writer", indices=[0])[0] if venv.has_attr("results_writer") else None
    if writer is None:
        return
    for info in ep_infos:
        writer.write_row(info)
