"""The Ray actor of :class:`~sb3_es.evaluation.ray.RayEvaluator`, and its lingering protocol.

An actor wraps a :class:`~sb3_es.evaluation.worker.ShareRunner` (a VecEnv and the local engine). Lingering uses a
second concurrency group: while :meth:`RayWorker.evaluate` runs, the driver calls :meth:`RayWorker.jobs_done`
(returns once the actor's share is done) and then :meth:`RayWorker.stop` (ends the lingering), both in the
``signal`` group, so they run beside ``evaluate``.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from sb3_es.evaluation.ray_session import import_ray
from sb3_es.evaluation.worker import ShareRunner


class RayWorker:
    """
    What a Ray actor runs. Turned into a Ray actor class by :func:`remote_worker_class`.

    :param config: The env config (see :func:`~sb3_es.evaluation.worker.env_config`).
    """

    def __init__(self, config: dict[str, Any]) -> None:
        import torch as th

        th.set_num_threads(1)  # actors share the machine's cores
        self.runner = ShareRunner(config)
        # Per generation token: set when the actor's share is done, and by the driver to end the lingering.
        self._signals: dict[int, tuple[threading.Event, threading.Event]] = {}
        self._signals_lock = threading.Lock()

    def _signal(self, token: int) -> tuple[threading.Event, threading.Event]:
        """:return: The ``(share done, stop lingering)`` events of generation ``token``."""
        with self._signals_lock:
            return self._signals.setdefault(token, (threading.Event(), threading.Event()))

    def jobs_done(self, token: int) -> bool:
        """Wait until this actor's share of generation ``token`` is done (or failed). Runs in the ``signal`` group."""
        return self._signal(token)[0].wait()

    def stop(self, token: int) -> None:
        """End the lingering of generation ``token``: :meth:`evaluate` then returns. Runs in the ``signal`` group."""
        self._signal(token)[1].set()
        with self._signals_lock:
            self._signals.pop(token, None)

    def ready(self) -> int:
        """:return: Number of env slots (used to wait for the actor and check it started)."""
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
            return self.runner.run(payload, jobs, seed)
        share_done, stop = self._signal(token)
        return self.runner.run(payload, jobs, seed, share_done.set, lambda: not stop.is_set())

    def call(self, fn: Callable[[VecEnv], Any]) -> Any:
        """:return: ``fn(vec_env)``, run in the actor."""
        return fn(self.runner.env)


_REMOTE_WORKER: Any = None


def remote_worker_class() -> Any:
    """:return: :class:`RayWorker` as a Ray actor class (``jobs_done`` and ``stop`` in the ``signal`` group)."""
    global _REMOTE_WORKER
    if _REMOTE_WORKER is None:
        _REMOTE_WORKER = import_ray().remote(concurrency_groups={"signal": 2})(RayWorker)
    return _REMOTE_WORKER
