"""What a host of a sharded evaluator's workers provides (Ray actors, worker processes): the :class:`WorkerPool`."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from sb3_es.strategies.noise import SharedNoiseTable


class WorkerDied(Exception):
    """A worker ended (process killed, node lost, crash in native code) before it returned its share."""


class WorkerPool(ABC):
    """
    The host of a sharded evaluator's workers: each worker owns a VecEnv and runs shares with the local engine.

    Every blocking call takes a timeout (seconds, ``None`` for none) and raises ``TimeoutError`` when it passes.
    """

    #: Number of workers once started (``None`` before, when it is resolved at start).
    size: int | None
    #: Env slots of each worker's VecEnv.
    envs_per_worker: int
    #: True while a generation is in flight (a shared pool is then not released to make room for another).
    busy: bool = False

    @property
    @abstractmethod
    def started(self) -> bool:
        """:return: Whether the workers are running."""

    @abstractmethod
    def start(self) -> None:
        """Create the workers if there are none and wait until they are ready (raise a clear error on timeout)."""

    @abstractmethod
    def close(self) -> None:
        """Stop every worker (a later :meth:`start` creates fresh ones)."""

    @abstractmethod
    def publish(self, payload: dict[str, Any]) -> Any:
        """:return: A handle on the generation's payload, passed to :meth:`submit` (e.g. a Ray object reference)."""

    @abstractmethod
    def submit(
        self, k: int, handle: Any, jobs: np.ndarray, seed: int, token: int | None, table: SharedNoiseTable | None
    ) -> None:
        """
        Start worker ``k`` on a share (sending it the noise table first if it lacks it).

        :param k: Index of the worker.
        :param handle: The generation's payload, as :meth:`publish` returned it.
        :param jobs: The share: indices of the generation's jobs (one candidate's episodes each) the worker runs.
        :param seed: Env seed of this share (its envs are seeded from it, as ``VecEnv.seed``).
        :param table: The noise table the population reads from (``None``: dense rows).
        :param token: The generation's token if the worker should linger (see :class:`~.worker.ShareRunner`).
        :raises WorkerDied: If the worker is dead.
        """

    @abstractmethod
    def wait_share_done(self, ks: Sequence[int], timeout: float | None) -> tuple[int, WorkerDied | None]:
        """
        Wait until one of the lingering workers ``ks`` has finished its share or died.

        :return: The worker, and the error if it died.
        :raises Exception: The error of a worker whose share failed (raised at once).
        """

    @abstractmethod
    def stop_lingering(self, k: int, token: int) -> None:
        """Tell worker ``k`` to end generation ``token``'s lingering."""

    @abstractmethod
    def result(self, k: int, timeout: float | None) -> dict[str, Any]:
        """
        :return: Worker ``k``'s output for its share (see :meth:`~.worker.ShareRunner.run`).
        :raises WorkerDied: If it died; an exception raised in the worker is raised here.
        """

    @abstractmethod
    def replace(self, k: int) -> None:
        """Stop worker ``k`` if it still runs and start a new one in its place."""

    @abstractmethod
    def call(self, fn: Callable[[VecEnv], Any]) -> list[Any]:
        """:return: ``fn(vec_env)`` run in every worker, in worker order."""
