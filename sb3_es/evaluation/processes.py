"""Population evaluation on persistent worker processes of this machine (no extra dependency).

Local processes host the workers of a :class:`~sb3_es.evaluation.sharded.ShardedEvaluator`, as Ray actors do for
:class:`~sb3_es.evaluation.ray.RayEvaluator`: each process owns a VecEnv and runs whole episodes of its share with
the local engine, so a generation costs one round trip per worker, not one per vec step as with ``SubprocVecEnv``.

Transport: one ``multiprocessing`` pipe per worker carries the calls (the generation's payload is pickled once,
with ``cloudpickle`` as SB3's ``SubprocVecEnv`` does for env factories, so lambdas are fine) and the replies; a
shared integer per worker ends the lingering (read at every vec step, without a system call). The worker side is
:mod:`~sb3_es.evaluation.process_worker`.
Workers are started with ``fork`` on Linux (no imports to repeat: startup in well under a second) and ``spawn``
elsewhere; they ignore ``SIGINT`` (the driver stops them on ``KeyboardInterrupt``), exit when the driver's end of
their pipe closes, and are daemons, so that none outlives the driver.
"""

from __future__ import annotations

import contextlib
import gc
import math
import multiprocessing as mp
import os
import pickle
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from multiprocessing.connection import wait
from typing import Any

import cloudpickle
import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import SubprocVecEnv, VecEnv
from typing_extensions import Unpack

from sb3_es.evaluation.pool import WorkerDied, WorkerPool
from sb3_es.evaluation.process_worker import DRIVER_ENDS, raise_remote, worker_main
from sb3_es.evaluation.sharded import ShardedEvaluator, wait_pieces
from sb3_es.evaluation.worker import DEFAULT_ENVS_PER_WORKER, RESTARTS_ARGUMENTS, WorkerEnvArgs, env_config
from sb3_es.strategies.noise import SharedNoiseTable


@contextlib.contextmanager
def _sigint_deferred() -> Iterator[None]:
    """
    Hold back SIGINT (Ctrl-C) in the block and deliver it after, to the handler of before (``KeyboardInterrupt`` by
    default). Outside the main thread, where Python cannot set a handler, nothing is held back.
    """
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or previous is None:
        yield
        return
    received: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if received:
            signal.raise_signal(signal.SIGINT)


def _wait(handles: list[Any], timeout: float | None) -> list[Any]:
    """:return: ``multiprocessing.connection.wait(handles, timeout)``, for any ``timeout`` (``None``, ``math.inf``)."""
    for piece in wait_pieces(timeout):
        ready = wait(handles, piece)
        if ready:
            return ready
    return []


class ProcessPool(WorkerPool):
    """
    Worker processes running a :class:`~sb3_es.evaluation.worker.ShareRunner` each.

    :param config: Env config of every worker.
    :param num_workers: Number of processes.
    :param start_method: ``multiprocessing`` start method.
    :param start_timeout: Seconds to wait for a worker to build its envs (``math.inf``: no limit).
    """

    def __init__(self, config: dict[str, Any], num_workers: int, start_method: str, start_timeout: float) -> None:
        self.config = cloudpickle.dumps(config)  # env factories may be lambdas
        self.size = self.num_workers = num_workers
        self.envs_per_worker = int(config["n_envs"])
        self.start_timeout = start_timeout
        self._ctx: Any = mp.get_context(start_method)
        self.processes: list[Any] = []
        self._conns: list[Any] = []
        self._stops: list[Any] = []
        self._tables: list[set[tuple[int, int]]] = []
        self._known_tables: dict[tuple[int, int], SharedNoiseTable] = {}
        self._inbox: dict[int, tuple[Any, ...]] = {}  # a share's reply received while waiting for "done"
        self._owner = os.getpid()  # the process that starts the workers: the only one that may stop them

    @property
    def started(self) -> bool:
        return bool(self.processes)

    def start(self) -> None:
        if self.processes:
            return
        # A model dropped in a reference cycle (a loop over seeds) keeps its workers until the garbage collector runs:
        # collected here, its pool closes its workers now, in this process, instead of being copied into the new
        # workers by the fork, where its finalizer would run on processes that are not their children.
        gc.collect()
        self._owner = os.getpid()
        n = self.num_workers
        self.processes, self._conns = [None] * n, [None] * n
        self._stops = [self._ctx.RawValue("q", 0) for _ in range(n)]
        self._tables = [set() for _ in range(n)]
        try:
            for k in range(n):
                self._spawn(k)
            deadline = time.monotonic() + self.start_timeout
            for k in range(n):
                self._wait_ready(k, deadline)
        except BaseException:
            self.close()
            raise

    def _spawn(self, k: int) -> None:
        driver_end, worker_end = self._ctx.Pipe()
        tables = list(self._known_tables.values())
        process = self._ctx.Process(
            target=worker_main,
            args=(worker_end, self.config, self._stops[k], tables),
            name=f"sb3-es-worker-{k}",
            daemon=True,
        )
        DRIVER_ENDS.add(driver_end)
        process.start()
        worker_end.close()
        self.processes[k], self._conns[k] = process, driver_end
        self._tables[k] = set(self._known_tables)

    def _wait_ready(self, k: int, deadline: float) -> None:
        try:
            kind, *rest = self._receive(k, max(0.0, deadline - time.monotonic()))
        except TimeoutError as e:
            raise RuntimeError(
                f"Worker process {k} did not build its envs within start_timeout={self.start_timeout:g} s "
                "(raise start_timeout for envs that are slow to build)."
            ) from e
        except WorkerDied as e:
            raise RuntimeError(f"Worker process {k} ended while building its envs ({e}).") from e
        if kind == "error":
            raise_remote(*rest)

    def _receive(self, k: int, timeout: float | None) -> tuple[Any, ...]:
        """:return: Worker ``k``'s next message. :raises WorkerDied: if it ended; ``TimeoutError``."""
        conn, process = self._conns[k], self.processes[k]
        if not _wait([conn, process.sentinel], timeout):
            raise TimeoutError(f"worker process {k} did not reply within {timeout} s")
        try:
            if conn.poll():
                return tuple(cloudpickle.loads(conn.recv_bytes()))
        except (EOFError, OSError):
            pass
        process.join(1.0)
        raise WorkerDied(f"worker process {process.pid} ended with exit code {process.exitcode}")

    def close(self) -> None:
        processes, conns = self.processes, self._conns
        # Forgotten first: a close cut short (a second Ctrl-C) leaves no worker or unread reply for the next start.
        self.processes, self._conns, self._stops, self._tables, self._inbox = [], [], [], [], {}
        if os.getpid() != self._owner:  # a copy inherited by a forked process: the workers are not its children
            return
        with _sigint_deferred():  # a Ctrl-C while the workers are stopped is raised once they all are
            for process, conn in zip(processes, conns, strict=True):
                if process is not None:
                    if process.is_alive():
                        process.kill()  # SIGKILL: a worker may be in the middle of an episode, or stuck in the env
                    process.join(5.0)
                if conn is not None:
                    conn.close()
                    DRIVER_ENDS.discard(conn)

    def publish(self, payload: dict[str, Any]) -> Any:
        return cloudpickle.dumps(payload, protocol=pickle.HIGHEST_PROTOCOL)

    def _send(self, k: int, message: tuple[str, Any]) -> None:
        try:
            self._conns[k].send(message)
        except (BrokenPipeError, ConnectionResetError, EOFError) as e:
            raise WorkerDied(f"worker process {self.processes[k].pid} is gone ({type(e).__name__})") from e

    def submit(
        self, k: int, handle: Any, jobs: np.ndarray, seed: int, token: int | None, table: SharedNoiseTable | None
    ) -> None:
        if table is not None:
            self._known_tables[table.key] = table
            if table.key not in self._tables[k]:
                self._send(k, ("table", table))  # pickled as its size and seed: rebuilt in the worker
                self._tables[k].add(table.key)
        self._inbox.pop(k, None)
        self._send(k, ("run", (handle, jobs, seed, token)))

    def wait_share_done(self, ks: Sequence[int], timeout: float | None) -> tuple[int, WorkerDied | None]:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            for k in ks:
                if k in self._inbox:
                    return k, None
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            handles = {self._conns[k]: k for k in ks} | {self.processes[k].sentinel: k for k in ks}
            ready = _wait(list(handles), remaining)
            if not ready:
                raise TimeoutError(f"no worker process finished its share within {timeout} s")
            k = handles[ready[0]]
            try:
                message = self._receive(k, 0)
            except WorkerDied as e:
                return k, e
            if message[0] == "done":
                return k, None
            if message[0] == "error":  # the share failed: raised at once, not once the other shares are done
                raise_remote(*message[1:])
            self._inbox[k] = message  # its result came with no "done"

    def stop_lingering(self, k: int, token: int) -> None:
        self._stops[k].value = token

    def result(self, k: int, timeout: float | None) -> dict[str, Any]:
        deadline = None if timeout is None else time.monotonic() + timeout
        message = self._inbox.pop(k, None)
        while message is None or message[0] == "done":
            message = self._receive(k, None if deadline is None else max(0.0, deadline - time.monotonic()))
        if message[0] == "error":
            raise_remote(*message[1:])
        return message[1]

    def replace(self, k: int) -> None:
        process = self.processes[k]
        if process.is_alive():
            process.kill()
        process.join(5.0)
        self._conns[k].close()
        DRIVER_ENDS.discard(self._conns[k])
        self._inbox.pop(k, None)
        self._stops[k] = self._ctx.RawValue("q", 0)
        self._spawn(k)
        self._wait_ready(k, time.monotonic() + self.start_timeout)

    def call(self, fn: Callable[[VecEnv], Any]) -> list[Any]:
        message = ("call", cloudpickle.dumps(fn))
        sent: list[int] = []
        failure: Exception | None = None
        for k in range(self.num_workers):
            try:
                self._send(k, message)
            except WorkerDied as e:
                failure = e
                break
            sent.append(k)
        results = []
        for k in sent:  # every reply is read, also after an error, so that none is left over for the next call
            try:
                results.append(self.result(k, None))
            except Exception as e:
                failure = failure or e
        if failure is not None:
            raise failure
        return results


def default_start_method() -> str:
    """:return: ``"fork"`` on Linux (fast start, nothing to import again), else ``"spawn"``."""
    return "fork" if sys.platform.startswith("linux") else "spawn"


def usable_cpus(cgroup_root: str = "/sys/fs/cgroup") -> int:
    """
    :param cgroup_root: Where Linux shows the control groups.
    :return: The CPUs this process may run on, at most its container's CPU quota (``docker --cpus``, a Kubernetes
        CPU limit), rounded up.
    """
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    quota = cgroup_cpu_quota(cgroup_root)
    return max(1, min(cpus, math.ceil(quota))) if quota is not None else cpus


def cgroup_cpu_quota(root: str = "/sys/fs/cgroup") -> float | None:
    """:return: The CPU quota of this process's control group (cgroup v2 or v1) in CPUs, or ``None`` if none."""
    try:
        with open(os.path.join(root, "cpu.max")) as f:  # v2: "max 100000" or "<quota> <period>"
            quota, period = f.read().split()[:2]
        return None if quota == "max" else int(quota) / int(period)
    except (OSError, ValueError):
        pass
    try:
        with open(os.path.join(root, "cpu", "cpu.cfs_quota_us")) as f:  # v1: -1 for none
            quota_us = int(f.read())
        with open(os.path.join(root, "cpu", "cpu.cfs_period_us")) as f:
            period_us = int(f.read())
        return quota_us / period_us if quota_us > 0 and period_us > 0 else None
    except (OSError, ValueError):
        return None


class ProcessEvaluator(ShardedEvaluator):
    """
    Evaluates a population on persistent worker processes of this machine, each owning a VecEnv and running its
    share of the jobs with :class:`~sb3_es.evaluation.VecEnvEvaluator` (whole episodes inside the worker).

    Same driver as :class:`~sb3_es.evaluation.ray.RayEvaluator` (:class:`~sb3_es.evaluation.sharded.ShardedEvaluator`):
    shares, seeds (share ``k`` uses ``seed + k * envs_per_worker``), lingering, callback replay, replacement of a
    worker that dies (its share re-run), exact merge of the observation statistics. With a given seed and
    ``num_workers``, the candidates' returns and so the parameters are reproducible (not with a scheduled
    hyperparameter, which follows ``num_timesteps``, unless ``linger=False``); ``num_timesteps`` also counts
    the center-policy steps of lingering workers, which depend on timing (``linger=False`` makes them
    reproducible too, at the cost of idle workers at the end of each generation). An env that ``reset(seed=...)``
    does not restore completely (BipedalWalker-v3 keeps its Box2D world) is reproducible only with ``linger=False``.

    An exception raised by the env in a worker (``SystemExit`` and ``KeyboardInterrupt`` too: the workers ignore
    ``SIGINT``, so those come from the env's code) is raised in the driver with the worker's traceback as its cause;
    an error or ``KeyboardInterrupt`` during a generation kills the workers (fresh ones start at the next
    evaluation). The workers are stopped by :meth:`close`, the ``with`` statement, garbage collection of the
    evaluator, or the driver's exit. Not saved with the model.

    :param env: Env id or a picklable env factory (a class, function or lambda returning a ``gym.Env``; with the
        ``spawn`` start method it must be importable).
    :param num_workers: Number of worker processes; by default one per CPU this process may use.
    :param envs_per_worker: Env slots of each worker's VecEnv; by default
        :data:`~sb3_es.evaluation.worker.DEFAULT_ENVS_PER_WORKER` (4): the slots share one batched forward pass per
        vec step (with one slot, two workers ran at 77% of a plain 2-process step loop on BipedalWalker-v3 and 48% on
        Pendulum-v1; with four, at 94-98%).
    :param start_method: ``multiprocessing`` start method; by default ``"fork"`` on Linux, else ``"spawn"``.
    :param max_worker_restarts: Worker replacements allowed within one generation.
    :param start_timeout: Seconds to wait for a worker to build its envs (``math.inf``: no limit).
    :param generation_timeout: Seconds a generation may take (``None`` or ``math.inf``: no limit).
    :param linger: Whether a worker whose share is done runs the center policy until every share is done.
    :param env_args: ``make_vec_env``'s other arguments for each worker's VecEnv: ``wrapper_class``, ``env_kwargs``,
        ``wrapper_kwargs``, ``vec_env_cls`` (``DummyVecEnv`` by default), ``vec_env_kwargs``, ``monitor_kwargs``
        (see :class:`~sb3_es.evaluation.worker.WorkerEnvArgs`).
    """

    worker_name = "worker process"
    workers_name = "worker processes"
    restarts_argument = RESTARTS_ARGUMENTS["ProcessEvaluator"]

    def __init__(
        self,
        env: str | Callable[..., gym.Env],
        num_workers: int | None = None,
        envs_per_worker: int = DEFAULT_ENVS_PER_WORKER,
        *,
        start_method: str | None = None,
        max_worker_restarts: int = 3,
        start_timeout: float = 60.0,
        generation_timeout: float | None = None,
        linger: bool = True,
        **env_args: Unpack[WorkerEnvArgs],
    ) -> None:
        vec_env_cls = env_args.get("vec_env_cls")
        if isinstance(vec_env_cls, type) and issubclass(vec_env_cls, SubprocVecEnv):
            raise ValueError(
                "vec_env_cls=SubprocVecEnv: worker processes are daemons and cannot start env processes of their "
                "own. Each worker is a process already: ask for more of them (num_workers=) and leave vec_env_cls "
                "to its default (DummyVecEnv)."
            )
        config = env_config(env, envs_per_worker, self.restarts_argument, **env_args)
        super().__init__(config, num_workers, start_timeout, max_worker_restarts, generation_timeout, linger)
        start_method = start_method or default_start_method()
        if start_method not in mp.get_all_start_methods():
            raise ValueError(f"start_method={start_method!r}: use one of {mp.get_all_start_methods()}.")
        self.start_method = start_method
        #: Number of worker processes.
        self.num_workers = self._num_workers or usable_cpus()

    @property
    def _workers(self) -> list[Any]:
        """:return: The running worker processes (empty before the start and after :meth:`close`)."""
        return list(self._pool.processes) if isinstance(self._pool, ProcessPool) else []

    def _acquire_pool(self) -> tuple[WorkerPool, Callable[[], None]]:
        pool = ProcessPool(self._env_config, self.num_workers, self.start_method, self.start_timeout)
        return pool, pool.close

    def __enter__(self) -> ProcessEvaluator:
        self.start()
        return self
