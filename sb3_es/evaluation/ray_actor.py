"""The Ray actor of :class:`~sb3_es.evaluation.ray.RayEvaluator`, and its lingering protocol.

An actor wraps a :class:`~sb3_es.evaluation.worker.ShareRunner` (a VecEnv and the local engine). Lingering uses a
second concurrency group: while :meth:`RayWorker.evaluate` runs, the driver calls :meth:`RayWorker.jobs_done`
(returns once the actor's share is done, or once the evaluation ended without it) and :meth:`RayWorker.stop`
(ends the lingering), both in the ``signal`` group, so they run beside ``evaluate``. Ray does not order calls of
different groups: ``stop`` and ``jobs_done`` may run before ``evaluate`` starts or after it returned, and the
protocol holds either way.

A ``SystemExit`` or ``KeyboardInterrupt`` raised by the env or policy code is carried to the driver as an
:class:`EnvExit`: Ray would take the first for the actor's own exit (a dead actor, replaced and its share re-run
until ``max_actor_restarts``, the error lost) and the second for a cancellation (``TaskCancelledError``).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from sb3_es.evaluation.ray_session import import_ray
from sb3_es.evaluation.worker import ShareRunner


class EnvExit(Exception):
    """
    A ``SystemExit`` or ``KeyboardInterrupt`` raised by the env or policy code in an actor, as an exception Ray
    sends back as it does any other (the driver raises :attr:`error` again).

    :param error: The exception raised.
    """

    def __init__(self, error: BaseException) -> None:
        super().__init__(error)
        self.error = error


@contextlib.contextmanager
def _carrying_exits() -> Iterator[None]:
    """Raise a ``SystemExit`` or ``KeyboardInterrupt`` of the block as an :class:`EnvExit`."""
    try:
        yield
    except (SystemExit, KeyboardInterrupt) as e:
        raise EnvExit(e) from e


class _Generation:
    """The signals of one generation in one actor."""

    def __init__(self) -> None:
        #: Set when the share is done, or when the evaluation ended without it (an error).
        self.over = threading.Event()
        #: Whether the share was done.
        self.share_done = False
        #: Set by the driver to end (or prevent) the lingering.
        self.stop = threading.Event()

    def done(self) -> None:
        self.share_done = True
        self.over.set()


class RayWorker:
    """
    What a Ray actor runs. Turned into a Ray actor class by :func:`remote_worker_class`.

    :param config: The env config (see :func:`~sb3_es.evaluation.worker.env_config`).
    """

    def __init__(self, config: dict[str, Any]) -> None:
        import torch as th

        th.set_num_threads(1)  # actors share the machine's cores
        # An error here is raised by ready(): raised by __init__, Ray reports an ActorDiedError (the type is lost).
        self._start_error: Exception | None = None
        try:
            with _carrying_exits():
                self.runner = ShareRunner(config)
        except Exception as e:
            self._start_error = e
        self._generations: dict[int, _Generation] = {}
        # The latest generation token whose evaluation has returned (the driver's tokens grow): signals for it or an
        # earlier one come too late and are answered at once.
        self._finished = 0
        self._lock = threading.Lock()

    def _generation(self, token: int) -> _Generation | None:
        """:return: The signals of generation ``token``, or ``None`` if its evaluation has returned."""
        with self._lock:
            if token <= self._finished:
                return None
            return self._generations.setdefault(token, _Generation())

    def jobs_done(self, token: int) -> bool:
        """
        Wait until this actor's share of generation ``token`` is done, or its evaluation ended. Runs in the
        ``signal`` group.

        :return: Whether the share was done (``False``: the evaluation failed, or already returned; its result
            tells).
        """
        generation = self._generation(token)
        if generation is None:
            return False
        generation.over.wait()
        return generation.share_done

    def stop(self, token: int) -> None:
        """
        End the lingering of generation ``token`` (prevent it, if the share is not done yet): :meth:`evaluate` then
        returns once the share is done. Runs in the ``signal`` group.
        """
        generation = self._generation(token)
        if generation is not None:
            generation.stop.set()

    def ready(self) -> int:
        """
        :return: Number of env slots (used to wait for the actor and check it started).
        :raises Exception: The error that building the env raised (e.g. ``gymnasium.error.NameNotFound``).
        """
        if self._start_error is not None:
            raise self._start_error
        return self.runner.env.num_envs

    def set_noise_table(self, key: tuple[int, int], noise: np.ndarray) -> None:
        """Keep a noise table (a zero-copy view into the object store)."""
        self.runner.noise_tables[tuple(key)] = noise  # type: ignore[index]

    def evaluate(
        self, payload: dict[str, Any], jobs: np.ndarray, seed: int, token: int | None = None
    ) -> dict[str, Any]:
        """
        Run a share (see :meth:`~sb3_es.evaluation.worker.ShareRunner.run`).

        :param token: The generation's token, if the actor should linger: once its share is done, it signals
            :meth:`jobs_done` and keeps running the center policy in all slots until :meth:`stop` is called.
        """
        if token is None:
            with _carrying_exits():
                return self.runner.run(payload, jobs, seed)
        generation = self._generation(token)
        if generation is None:
            raise RuntimeError(f"generation {token} was evaluated already by this actor")
        try:
            with _carrying_exits():
                return self.runner.run(payload, jobs, seed, generation.done, lambda: not generation.stop.is_set())
        finally:
            with self._lock:
                self._finished = max(self._finished, token)
                for old in [t for t in self._generations if t <= self._finished]:
                    self._generations.pop(old).over.set()  # a waiting jobs_done() returns

    def call(self, fn: Callable[[VecEnv], Any]) -> Any:
        """:return: ``fn(vec_env)``, run in the actor."""
        with _carrying_exits():
            return fn(self.runner.env)


_REMOTE_WORKER: Any = None


def remote_worker_class() -> Any:
    """:return: :class:`RayWorker` as a Ray actor class (``jobs_done`` and ``stop`` in the ``signal`` group)."""
    global _REMOTE_WORKER
    if _REMOTE_WORKER is None:
        _REMOTE_WORKER = import_ray().remote(concurrency_groups={"signal": 2})(RayWorker)
    return _REMOTE_WORKER
