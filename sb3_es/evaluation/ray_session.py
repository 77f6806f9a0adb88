"""Ray's lifetime in this process, and the actor pools that Ray evaluators share.

* Ray is started (``ray.init``) by the first evaluator that needs it if it is not running, and shut down when the
  last pool is released, only if it was started here.
* Evaluators with the same env config, layout and CPU request share one pool of actors: a seed loop or a
  notebook re-run of ``ARS(..., evaluator="ray")`` reuses the running actors instead of waiting for CPUs that the
  previous model's actors hold. A pool is released (its actors killed) when the last evaluator using it is closed
  or garbage-collected.
* When actors of a new pool do not fit in the free CPUs, idle pools of this process (no generation in flight) are
  stopped to make room; they start again when their evaluator next runs.
* Ray reports the CPUs of started and killed actors a moment late: a pool's start and close return once the report
  shows them (:func:`wait_for_report`), so a new evaluator counts the free CPUs right whatever the timing.

Ray itself is imported only when an evaluator is created.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable
from typing import Any, Protocol

logger = logging.getLogger(__name__)


class SharedPool(Protocol):
    """What the session needs of a pool of actors."""

    busy: bool

    @property
    def started(self) -> bool: ...

    @property
    def cpus(self) -> float:
        """:return: The CPUs its running actors hold."""
        ...

    def close(self) -> None: ...


#: Seconds to wait at most for Ray to report the CPUs of started or killed actors (see :func:`wait_for_report`).
REPORT_TIMEOUT = 10.0

_pools: dict[bytes, SharedPool] = {}
_users: dict[int, int] = {}  # id(pool) -> number of evaluators using it
#: The Ray session started here (see :func:`current_session`) and its ``ray.init`` arguments; ``None`` if Ray was
#: started by the user, or not at all.
_started: tuple[tuple[str, str], dict[str, Any]] | None = None


def import_ray() -> Any:
    """:return: The ``ray`` module, or a clear error explaining how to install it."""
    try:
        import ray
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            "RayEvaluator needs Ray: install sb3-es's [ray] extra (`pip install -e '.[ray]'` in its clone) or "
            "`pip install ray`."
        ) from e
    return ray


def current_session() -> tuple[str, str] | None:
    """
    :return: What identifies the running Ray session (driver node and job ids; a ``ray.shutdown()`` and
        ``ray.init()`` give a new one), or ``None`` if Ray is not running.
    """
    ray = import_ray()
    if not ray.is_initialized():
        return None
    context = ray.get_runtime_context()
    return str(context.get_node_id()), str(context.get_job_id())


def ensure_started(init_kwargs: dict[str, Any]) -> Any:
    """
    Start Ray with ``ray.init(**init_kwargs)`` unless it is running; warn if it runs with other arguments.

    :return: The ``ray`` module.
    """
    global _started
    ray = import_ray()
    session = current_session()
    if session is None:
        ray.init(**{"ignore_reinit_error": True, **init_kwargs})
        _started = (current_session() or ("", ""), dict(init_kwargs))
    elif init_kwargs and (_started is None or _started[0] != session or _started[1] != init_kwargs):
        logger.warning(
            "Ray is already running, so ray_init_kwargs=%r were not applied: the actors run on the running Ray "
            "instance. Call ray.shutdown() first to start Ray with them, or call ray.init(...) yourself before "
            "creating the evaluator.",
            init_kwargs,
        )
    return ray


def acquire(key: bytes, factory: Callable[[], SharedPool]) -> SharedPool:
    """
    :param key: Identifies what the pool runs (env config, layout, CPU request).
    :param factory: Builds a new pool (without starting it) when none has this key.
    :return: The pool for ``key``, now counted as used once more (:func:`release` it).
    """
    pool = _pools.get(key)
    if pool is None:
        pool = _pools[key] = factory()
    _users[id(pool)] = _users.get(id(pool), 0) + 1
    return pool


def release(key: bytes, pool: SharedPool) -> None:
    """
    One evaluator no longer uses ``pool``: when none does, kill its actors, and shut Ray down if it was started
    here and no pool is left. Safe at interpreter exit and from a garbage-collection finalizer.
    """
    global _started
    count = _users.get(id(pool), 0) - 1
    if count > 0:
        _users[id(pool)] = count
        return
    _users.pop(id(pool), None)
    if _pools.get(key) is pool:
        del _pools[key]
    with contextlib.suppress(Exception):  # Ray may be shutting down already
        pool.close()
    if _started is not None and not _pools:
        with contextlib.suppress(Exception):  # only the session started here: not one the user started since
            if current_session() == _started[0]:
                import_ray().shutdown()
        _started = None


def total_cpus() -> float:
    """:return: CPUs of the Ray cluster."""
    return float(import_ray().cluster_resources().get("CPU", 0.0))


def free_cpus() -> float:
    """:return: CPUs that the Ray cluster reports free now (a moment late: see :func:`wait_for_report`)."""
    return float(import_ray().available_resources().get("CPU", 0.0))


def held_cpus() -> float:
    """:return: CPUs that the running actors of this process's pools hold."""
    return sum(pool.cpus for pool in _pools.values() if pool.started)


def wait_for_report(settled: Callable[[float], bool], timeout: float = REPORT_TIMEOUT) -> float:
    """
    Ray reports the CPUs of actors it has just started or killed a moment later (about 0.1 s, longer on a loaded
    machine): wait until the report shows the change, so that the next evaluator counts the free CPUs right.

    :param settled: Whether the free CPUs reported show the change.
    :param timeout: Seconds to wait at most (actors of other drivers may keep the report from settling).
    :return: The CPUs reported free.
    """
    deadline = time.monotonic() + timeout
    free = free_cpus()
    while not settled(free) and time.monotonic() < deadline:
        time.sleep(0.02)
        free = free_cpus()
    return free


def make_room(cpus: float, requester: SharedPool) -> float:
    """
    Stop idle pools of this process (oldest first) until ``cpus`` CPUs are free or none is left to stop.

    :param cpus: CPUs needed.
    :param requester: The pool asking (never stopped).
    :return: The CPUs free afterwards.
    """
    free = free_cpus()
    for pool in list(_pools.values()):
        if free >= cpus:
            break
        if pool is requester or pool.busy or not pool.started:
            continue
        held = pool.cpus
        pool.close()  # returns once Ray reports the CPUs free (or after REPORT_TIMEOUT)
        logger.warning(
            "Stopped %g idle Ray actor CPU(s) of another evaluator in this process to make room for a new one; they "
            "start again when that evaluator next runs (close() evaluators you no longer use).",
            held,
        )
        free = free_cpus()
    return free


def describe_pools() -> str:
    """:return: What this process's pools hold, for error messages."""
    running = [pool for pool in _pools.values() if pool.started]
    if not running:
        return "no other Ray evaluator of this process holds actors"
    held = sum(pool.cpus for pool in running)
    return f"Ray evaluators of this process hold or are starting actors for {held:g} CPU(s) in {len(running)} pool(s)"
