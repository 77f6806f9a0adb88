"""Callback calls of ``num_envs`` env steps each, whatever the evaluator's vec steps.

SB3's callbacks count calls: ``EvalCallback(eval_freq=k)`` and ``CheckpointCallback(save_freq=k)`` act every ``k``
calls, that is every ``k * training_env.num_envs`` env steps, and rl-zoo divides its ``eval_freq`` by ``n_envs`` for
this. A worker process or Ray actor steps its own env slots (4 by default), and an evaluator passed as an instance can
own any number: :class:`StepCalls` regroups their vec steps into calls of the model env's ``num_envs`` steps, so that
these callbacks act at the env steps they would with the local evaluator.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sb3_es.evaluation.base import StepHook

# One vec step as the evaluator reports it: infos, dones, rewards, new_obs, actions.
_Piece = tuple[list[dict[str, Any]], np.ndarray, np.ndarray, Any, Any]


def _rows(value: Any, start: int, stop: int) -> Any:
    if value is None:
        return None
    if isinstance(value, dict):
        return {key: item[start:stop] for key, item in value.items()}
    return value[start:stop]


def _stack(values: list[Any]) -> Any:
    if any(value is None for value in values):
        return None
    if isinstance(values[0], dict):
        return {key: np.concatenate([value[key] for value in values]) for key in values[0]}
    return np.concatenate(values)


def _split(piece: _Piece, k: int) -> tuple[_Piece, _Piece]:
    """:return: The first ``k`` slots of a vec step, and the others."""
    infos, dones, rewards, new_obs, actions = piece
    n = len(dones)
    head = (infos[:k], dones[:k], rewards[:k], _rows(new_obs, 0, k), _rows(actions, 0, k))
    tail = (infos[k:], dones[k:], rewards[k:], _rows(new_obs, k, n), _rows(actions, k, n))
    return head, tail


class StepCalls:
    """
    A step hook that calls ``hook`` once per ``n_envs`` env steps: the vec steps it receives are cut or joined into
    calls of exactly ``n_envs`` slots, in order; :meth:`flush` hands on what is left at the end of a generation (a
    last call of fewer slots). A vec step of ``n_envs`` slots with nothing pending is passed on as it is.

    Once ``hook`` returns False, the rest of the vec step it came from is not shown and this hook returns False;
    :attr:`dropped` then tells whether env steps were left unshown (the generation is then discarded).

    :param hook: The step hook that counts the steps and calls the callbacks.
    :param n_envs: Env steps per call (the model env's ``num_envs``).
    """

    def __init__(self, hook: StepHook, n_envs: int) -> None:
        self.hook = hook
        self.n_envs = n_envs
        self._pieces: list[_Piece] = []
        self._pending = 0
        self.dropped = False

    def __call__(
        self,
        n_envs: int,
        infos: list[dict[str, Any]],
        dones: np.ndarray,
        rewards: np.ndarray,
        new_obs: Any,
        actions: Any,
    ) -> bool:
        m = self.n_envs
        if n_envs == m and not self._pending:
            return self.hook(n_envs, infos, dones, rewards, new_obs, actions)
        if n_envs % m == 0 and not self._pending:  # the usual case (4 slots per worker): slices, nothing kept
            for start in range(0, n_envs, m):
                stop = start + m
                if not self.hook(
                    m,
                    infos[start:stop],
                    dones[start:stop],
                    rewards[start:stop],
                    _rows(new_obs, start, stop),
                    _rows(actions, start, stop),
                ):
                    self.dropped = stop < n_envs
                    return False
            return True
        self._pieces.append((infos, np.asarray(dones), np.asarray(rewards), new_obs, actions))
        self._pending += n_envs
        while self._pending >= m:
            if not self._call(m):
                self.dropped = self._pending > 0
                self._pieces.clear()
                self._pending = 0
                return False
        return True

    def flush(self) -> bool:
        """
        Show the steps left over (fewer than ``n_envs``) in one last call.

        :return: What the hook returned (True when nothing was left).
        """
        return self._call(self._pending) if self._pending else True

    def _call(self, size: int) -> bool:
        taken: list[_Piece] = []
        needed = size
        while needed:
            n = len(self._pieces[0][1])
            if n <= needed:
                taken.append(self._pieces.pop(0))
                needed -= n
            else:
                head, self._pieces[0] = _split(self._pieces[0], needed)
                taken.append(head)
                needed = 0
        self._pending -= size
        if len(taken) == 1:
            return self.hook(size, *taken[0])
        infos = [info for piece in taken for info in piece[0]]
        dones = np.concatenate([piece[1] for piece in taken])
        rewards = np.concatenate([piece[2] for piece in taken])
        return self.hook(
            size, infos, dones, rewards, _stack([piece[3] for piece in taken]), _stack([piece[4] for piece in taken])
        )
