"""The model's ``Monitor`` file gets the episodes that worker processes or Ray actors ran.

With ``evaluator="processes"`` or ``"ray"`` the model's own envs run no episode, so their ``Monitor`` CSV files
(which rl-zoo's ``plot_train`` reads) would stay empty; the driver writes the workers' episodes to the first one,
their time ``t`` measured from that ``Monitor``'s start.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from sb3_es.evaluation import PopulationEvaluator, VecEnvEvaluator
from sb3_es.evaluation.sharded import ShardedEvaluator


def _first_monitor_env(env: VecEnv | None) -> DummyVecEnv | None:
    """:return: The model's ``DummyVecEnv`` if its envs have a ``Monitor`` (another process's cannot be written)."""
    venv = None if env is None else env.unwrapped  # inside VecNormalize & co.
    if isinstance(venv, DummyVecEnv) and venv.has_attr("results_writer"):
        return venv
    return None


def align_clock(env: VecEnv | None, evaluator: PopulationEvaluator) -> None:
    """
    Have the workers measure their episodes' time from the start of the model's first ``Monitor``, as the model's
    own envs would (their own start differs, and a replaced worker's would start again).

    :param env: The model's VecEnv.
    :param evaluator: The evaluator about to run a ``learn()`` call's generations.
    """
    venv = _first_monitor_env(env)
    if venv is not None and isinstance(evaluator, ShardedEvaluator):
        evaluator.clock_start = float(venv.get_attr("t_start", indices=[0])[0])


def write_remote_episodes(
    env: VecEnv | None, evaluator: PopulationEvaluator, ep_infos: Sequence[dict[str, Any]]
) -> None:
    """
    Write the candidates' episodes run elsewhere to the ``Monitor`` file of the model's first env, if it has one.

    :param env: The model's VecEnv.
    :param evaluator: The evaluator that ran the generation (nothing is written for the model's own VecEnv).
    :param ep_infos: The episodes (the workers' ``Monitor`` infos: ``r``, ``l``, ``t``; see :func:`align_clock`).
    """
    if isinstance(evaluator, VecEnvEvaluator) and evaluator.env is env:
        return
    venv = _first_monitor_env(env)
    writer = None if venv is None else venv.get_attr("results_writer", indices=[0])[0]
    if writer is None:
        return
    for info in ep_infos:
        writer.write_row(info)
