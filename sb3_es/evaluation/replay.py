"""The callback replay of a sharded evaluator: the workers' vec steps shown to the driver's step hook.

Remote steps cannot call the driver's callbacks while they run; each worker logs the ``dones`` and ``rewards`` of
its vec steps and the infos of the slots whose episode ended (see :class:`~sb3_es.evaluation.worker.ShareRunner`),
and the driver replays them once the generation's results are back.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sb3_es.evaluation.base import StepHook


def replay(outputs: Sequence[dict[str, Any]], step_hook: StepHook) -> bool:
    """
    Call the step hook once per remote vec step, the workers' steps interleaved (each with its ``n_envs``, its
    real ``dones`` and ``rewards`` and, for slots whose episode ended, its infos without ``terminal_observation``;
    ``new_obs`` and ``actions`` are ``None``: the workers do not send them back).

    :param outputs: The workers' outputs (:meth:`~sb3_es.evaluation.worker.ShareRunner.run`), in worker order.
    :param step_hook: The driver's step hook.
    :return: Whether a hook call returned False before the last replayed step (the result is then discarded).
    """
    done_infos: list[dict[int, dict[int, dict[str, Any]]]] = []
    for output in outputs:
        by_step: dict[int, dict[int, dict[str, Any]]] = {}
        for step, slot, info in output["done_infos"]:
            by_step.setdefault(step, {})[slot] = info
        done_infos.append(by_step)
    # Rows as lists of arrays up front: the loop below runs once per remote vec step.
    steps = [list(zip(output["dones"], output["rewards"])) for output in outputs]
    total = sum(len(rows) for rows in steps)
    calls = 0
    for t in range(max((len(rows) for rows in steps), default=0)):
        for rows, ended in zip(steps, done_infos):
            if t >= len(rows):
                continue
            dones, rewards = rows[t]
            n_envs = len(dones)
            infos: list[dict[str, Any]] = [{} for _ in range(n_envs)]
            if t in ended:
                for slot, info in ended[t].items():
                    infos[slot] = dict(info)
            calls += 1
            if not step_hook(n_envs, infos, dones, rewards, None, None):
                return calls < total
    return False
