"""Population evaluation spread over Ray actors, on one machine or a cluster.

Ray hosts the workers of a :class:`~sb3_es.evaluation.sharded.ShardedEvaluator`: each actor
(:mod:`~sb3_es.evaluation.ray_actor`) owns an SB3 ``VecEnv`` and runs its share of the (candidate, episode) jobs
with the local engine. Ray does the scheduling, the transport and the object store; this module only moves the
generation's data and signals, and turns a dead actor into a :class:`~sb3_es.evaluation.pool.WorkerDied`.
Ray's lifetime and the actor pools that evaluators share are in :mod:`~sb3_es.evaluation.ray_session`.

Per generation the driver puts the generation's data (network spec, center, population rows or noise-table
offsets, reset seeds) once in the object store and sends each actor its jobs' indices (candidate and episode)
and a seed; each actor sends back its share's results, its observation statistics and its vec steps' ``dones``
and ``rewards`` (what crosses the wire, with sizes: ``docs/guide/ray.md``). This module imports without Ray;
Ray is imported when a :class:`RayEvaluator` is created. (About 300 lines: the actor pool and the evaluator are
documented for users who run Ray clusters.)
"""

from __future__ import annotations

import contextlib
import functools
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv
from typing_extensions import Unpack

from sb3_es.evaluation import ray_session
from sb3_es.evaluation.pool import WorkerDied, WorkerPool
from sb3_es.evaluation.ray_actor import EnvExit, remote_worker_class
from sb3_es.evaluation.ray_session import import_ray
from sb3_es.evaluation.sharded import ShardedEvaluator, wait_pieces
from sb3_es.evaluation.worker import (
    DEFAULT_ENVS_PER_WORKER,
    RESTARTS_ARGUMENTS,
    WorkerEnvArgs,
    check_kwargs,
    env_config,
)
from sb3_es.strategies.base import check_positive_number
from sb3_es.strategies.noise import SharedNoiseTable


def _died(error: Exception) -> WorkerDied:
    message = str(error).splitlines()[0] if str(error) else ""
    return WorkerDied(f"{type(error).__name__}: {message}")


def _get(refs: Any) -> Any:
    """
    :return: ``ray.get(refs)``; a ``SystemExit`` or ``KeyboardInterrupt`` of the env code in an actor (an
        :class:`~sb3_es.evaluation.ray_actor.EnvExit`) is raised as itself, with Ray's error (the actor's traceback)
        as its cause.
    """
    from ray.exceptions import RayTaskError

    try:
        return import_ray().get(refs)
    except RayTaskError as e:
        if isinstance(e.cause, EnvExit):
            raise e.cause.error from e
        raise


def _wait(refs: list[Any], num_returns: int, timeout: float | None) -> tuple[list[Any], list[Any]]:
    """
    :return: ``ray.wait(refs, num_returns=num_returns, timeout=timeout)``, for any ``timeout`` (``None`` or
        ``math.inf``: no limit; Ray refuses ``math.inf``, and ends a wait without a timeout after about 11 days).
    """
    ray = import_ray()
    ready: list[Any] = []
    not_ready = list(refs)
    for piece in wait_pieces(timeout):
        ready, not_ready = ray.wait(refs, num_returns=num_returns, timeout=piece)
        if len(ready) >= num_returns:
            break
    return ready, not_ready


class RayActorPool(WorkerPool):
    """
    Ray actors running :class:`~sb3_es.evaluation.ray_actor.RayWorker`, shared by the evaluators of one config.

    :param config: Env config of every actor.
    :param num_workers: Number of actors, or ``None`` for one per CPU free in the cluster at start.
    :param num_cpus_per_worker: CPUs reserved by each actor.
    :param init_kwargs: Keyword arguments for ``ray.init`` if Ray is not running.
    :param start_timeout: Seconds to wait for actors to start (``math.inf``: no limit).
    """

    def __init__(
        self,
        config: dict[str, Any],
        num_workers: int | None,
        num_cpus_per_worker: float,
        init_kwargs: dict[str, Any],
        start_timeout: float,
    ) -> None:
        self.config = config
        self.requested = num_workers
        self.size = num_workers
        self.envs_per_worker = int(config["n_envs"])
        self.num_cpus_per_worker = num_cpus_per_worker
        self.init_kwargs = init_kwargs
        self.start_timeout = start_timeout
        self.actors: list[Any] = []
        #: The Ray session the actors run in (see :func:`~sb3_es.evaluation.ray_session.current_session`).
        self._session: tuple[str, str] | None = None
        self._tables: list[set[tuple[int, int]]] = []
        self._noise_refs: dict[tuple[int, int], Any] = {}
        self._eval_refs: dict[int, Any] = {}
        self._done_refs: dict[int, Any] = {}

    @property
    def started(self) -> bool:
        return bool(self.actors)

    @property
    def cpus(self) -> float:
        """:return: The CPUs its running actors hold."""
        return len(self.actors) * self.num_cpus_per_worker

    def start(self) -> None:
        if self.actors and self._session == ray_session.current_session():
            return
        if self.actors:  # Ray was shut down (and maybe started again) since: those actors are gone
            self.close()
        ray_session.ensure_started(self.init_kwargs)
        self._session = ray_session.current_session()
        per_actor = self.num_cpus_per_worker
        if self.requested is None:  # one actor per free CPU (making room if an idle evaluator holds them all)
            free = ray_session.free_cpus()
            if free < per_actor:
                free = ray_session.make_room(per_actor, self)
            self.size = max(1, int(free // per_actor))
        else:
            self.size = self.requested
            ray_session.make_room(self.size * per_actor, self)
            total = ray_session.total_cpus()
            if self.size * per_actor > total + 1e-6:
                warnings.warn(
                    f"num_workers={self.size} Ray actors of num_cpus_per_worker={per_actor:g} CPU(s) need "
                    f"{self.size * per_actor:g} CPUs and the Ray cluster has {total:g} in all: they start only if "
                    f"the cluster grows, else the first evaluation fails after start_timeout={self.start_timeout:g} s. "
                    f"Ask for less (num_workers=, or num_cpus_per_worker={total / self.size:g}).",
                    stacklevel=2,
                )
        self.actors = [self._new_actor() for _ in range(self.size)]
        self._tables = [set() for _ in range(self.size)]
        try:
            self._wait_ready(self.actors)
        except BaseException:  # e.g. the env cannot be built: report it, and start afresh next time
            self.close()
            raise
        # Return once Ray counts the new actors, so that a new evaluator does not see their CPUs as free.
        total = ray_session.total_cpus()
        ray_session.wait_for_report(lambda free: free <= total - ray_session.held_cpus() + 1e-6)

    def _new_actor(self) -> Any:
        cls = remote_worker_class()
        return cls.options(num_cpus=self.num_cpus_per_worker, max_restarts=0).remote(self.config)

    def _wait_ready(self, actors: Sequence[Any]) -> None:
        refs = [actor.ready.remote() for actor in actors]
        ready, not_ready = _wait(refs, len(refs), self.start_timeout)
        _get(ready)  # raises an actor's construction error (e.g. an unknown env id)
        if not_ready:
            raise RuntimeError(
                f"Ray could not start {len(not_ready)} of {len(refs)} actor(s) within start_timeout="
                f"{self.start_timeout:g} s: each needs {self.num_cpus_per_worker:g} CPU(s) and the cluster has "
                f"{ray_session.free_cpus():g} of {ray_session.total_cpus():g} free now, the actors that are starting "
                f"included ({ray_session.describe_pools()}; actors of other drivers count too). Close evaluators you "
                "no longer use (evaluator.close()), or ask for less (num_workers=, num_cpus_per_worker=); if the "
                "CPUs were free, the actors were slow to start (imports, env construction on a loaded machine): "
                "raise start_timeout."
            )

    def close(self) -> None:
        if self.actors:
            ray = import_ray()
            if self._session is not None and self._session == ray_session.current_session():  # else: gone
                free_before, held = ray_session.free_cpus(), self.cpus
                for actor in self.actors:
                    with contextlib.suppress(Exception):  # already dead, or Ray shutting down
                        ray.kill(actor, no_restart=True)
                # ray.kill returns at once: wait (a little) until the actors are gone and Ray reports their CPUs
                # free, so that the next evaluator of this process counts them when close() returns.
                with contextlib.suppress(Exception):
                    refs = [actor.ready.remote() for actor in self.actors]
                    ray.wait(refs, num_returns=len(refs), timeout=ray_session.REPORT_TIMEOUT)
                    total = ray_session.total_cpus()
                    ray_session.wait_for_report(lambda free: free >= min(total, free_before + held) - 1e-6)
        self.actors = []
        self._session = None
        self._tables = []
        self._noise_refs = {}
        self._eval_refs = {}
        self._done_refs = {}

    def publish(self, payload: dict[str, Any]) -> Any:
        return import_ray().put(payload)

    def submit(
        self, k: int, handle: Any, jobs: np.ndarray, seed: int, token: int | None, table: SharedNoiseTable | None
    ) -> None:
        from ray.exceptions import RayActorError

        ray = import_ray()
        actor = self.actors[k]
        try:
            if table is not None and table.key not in self._tables[k]:
                if table.key not in self._noise_refs:
                    self._noise_refs[table.key] = ray.put(table.noise)
                actor.set_noise_table.remote(table.key, self._noise_refs[table.key])
                self._tables[k].add(table.key)
            self._eval_refs[k] = actor.evaluate.remote(handle, jobs, seed, token)
            if token is not None:
                self._done_refs[k] = actor.jobs_done.options(concurrency_group="signal").remote(token)
        except RayActorError as e:
            raise _died(e) from e

    def wait_share_done(self, ks: Sequence[int], timeout: float | None) -> tuple[int, WorkerDied | None]:
        from ray.exceptions import RayActorError

        # The share's result too: an evaluation that failed before the share began (its arguments could not be
        # unpickled in the actor) never signals the share done; its error is raised here.
        refs = {self._done_refs[k]: k for k in ks} | {self._eval_refs[k]: k for k in ks}
        ready, _ = _wait(list(refs), 1, timeout)
        if not ready:
            raise TimeoutError(f"no Ray actor finished its share within {timeout} s")
        k = refs[ready[0]]
        try:
            if _get(ready[0]) is False:  # the evaluation ended without the share done: its error is raised here
                _get(self._eval_refs[k])
        except RayActorError as e:
            return k, _died(e)
        return k, None

    def stop_lingering(self, k: int, token: int) -> None:
        self.actors[k].stop.options(concurrency_group="signal").remote(token)

    def result(self, k: int, timeout: float | None) -> dict[str, Any]:
        from ray.exceptions import RayActorError

        ready, _ = _wait([self._eval_refs[k]], 1, timeout)
        if not ready:
            raise TimeoutError(f"Ray actor {k} did not return its share within {timeout} s")
        try:
            return _get(ready[0])
        except RayActorError as e:
            raise _died(e) from e

    def replace(self, k: int) -> None:
        with contextlib.suppress(Exception):  # it is dead already
            import_ray().kill(self.actors[k], no_restart=True)
        self.actors[k] = self._new_actor()
        self._tables[k] = set()
        self._wait_ready([self.actors[k]])

    def call(self, fn: Callable[[VecEnv], Any]) -> list[Any]:
        return _get([actor.call.remote(fn) for actor in self.actors])


class RayEvaluator(ShardedEvaluator):
    """
    Evaluates a population on Ray actors, each owning a VecEnv and running its share of the jobs with
    :class:`~sb3_es.evaluation.VecEnvEvaluator` (batched forward pass, as locally).

    Shares and seeds, lingering, the callback replay and fault tolerance are those of
    :class:`~sb3_es.evaluation.sharded.ShardedEvaluator` (see there); a dead actor is counted in
    :attr:`restarted_actors`, at most ``max_actor_restarts`` times per generation. An exception raised by the env
    or policy code in an actor is raised in the driver (a ``SystemExit`` or ``KeyboardInterrupt`` as itself, with
    Ray's error, holding the actor's traceback, as its cause).

    Ray is started with ``ray.init(**ray_init_kwargs)`` if it is not running yet (pass
    ``ray_init_kwargs=dict(address="auto")`` to join a running cluster, or call ``ray.init`` yourself first).
    Actors are created at the first evaluation and waited for at most ``start_timeout`` seconds (an error then
    names what holds the CPUs). Evaluators with the same arguments share their actors (a seed loop reuses them);
    the actors are killed when the last evaluator using them is closed (:meth:`close`, the ``with`` statement) or
    garbage-collected, or at exit, and on an error or ``KeyboardInterrupt`` during an evaluation (a later
    evaluation creates fresh actors). When new actors do not fit in the free CPUs, idle actors of other evaluators
    of this process are stopped to make room (they restart when used). Not saved with the model.

    :param env: Env id (``"BipedalWalker-v3"``, or ``"module:EnvId"`` so that actors import the module that
        registers it) or a picklable env factory (a class, function or lambda returning a ``gym.Env``).
    :param num_workers: Number of actors; by default one per CPU available in the Ray cluster.
    :param envs_per_worker: Env slots of each actor's VecEnv; by default
        :data:`~sb3_es.evaluation.worker.DEFAULT_ENVS_PER_WORKER` (4), as for worker processes: the slots share one
        batched forward pass per vec step.
    :param num_cpus_per_worker: CPUs reserved by each actor (``ray.remote(num_cpus=...)``).
    :param ray_init_kwargs: Keyword arguments for ``ray.init`` when this evaluator starts Ray.
    :param max_actor_restarts: Actor replacements allowed within one generation.
    :param start_timeout: Seconds to wait for actors to start (at the first evaluation, and for a replacement);
        ``math.inf`` for no limit.
    :param generation_timeout: Seconds a generation may take (``None`` or ``math.inf``: no limit); see
        :class:`~sb3_es.evaluation.sharded.ShardedEvaluator`.
    :param linger: Whether finished actors run the center policy while the others finish their shares (``False``
        makes ``num_timesteps`` reproducible, at the cost of idle actors); see
        :class:`~sb3_es.evaluation.sharded.ShardedEvaluator`.
    :param env_args: ``make_vec_env``'s other arguments for each actor's VecEnv: ``wrapper_class``, ``env_kwargs``,
        ``wrapper_kwargs``, ``vec_env_cls`` (``DummyVecEnv`` by default), ``vec_env_kwargs``, ``monitor_kwargs``
        (see :class:`~sb3_es.evaluation.worker.WorkerEnvArgs`).
    """

    worker_name = "Ray actor"
    workers_name = "Ray actors"
    restarts_argument = RESTARTS_ARGUMENTS["RayEvaluator"]

    def __init__(
        self,
        env: str | Callable[..., gym.Env],
        num_workers: int | None = None,
        envs_per_worker: int = DEFAULT_ENVS_PER_WORKER,
        *,
        num_cpus_per_worker: float = 1.0,
        ray_init_kwargs: dict[str, Any] | None = None,
        max_actor_restarts: int = 3,
        start_timeout: float = 120.0,
        generation_timeout: float | None = None,
        linger: bool = True,
        **env_args: Unpack[WorkerEnvArgs],
    ) -> None:
        import_ray()
        config = env_config(env, envs_per_worker, self.restarts_argument, **env_args)
        super().__init__(config, num_workers, start_timeout, max_actor_restarts, generation_timeout, linger)
        self.num_cpus_per_worker = check_positive_number("num_cpus_per_worker", num_cpus_per_worker)
        self.ray_init_kwargs = check_kwargs("ray_init_kwargs", ray_init_kwargs) or {}

    @property
    def num_workers(self) -> int | None:
        """:return: Number of actors (``None`` until started when it is one per available CPU)."""
        if self._pool is not None and self._pool.size is not None:
            return self._pool.size
        return self._num_workers

    @property
    def restarted_actors(self) -> int:
        """:return: Number of actors replaced after they died, over the evaluator's life."""
        return self.restarted_workers

    @property
    def max_actor_restarts(self) -> int:
        """:return: Actor replacements allowed within one generation."""
        return self.max_restarts

    @property
    def _actors(self) -> list[Any]:
        """:return: The running actors (empty before the start and after :meth:`close`)."""
        return list(self._pool.actors) if isinstance(self._pool, RayActorPool) else []

    def _acquire_pool(self) -> tuple[WorkerPool, Callable[[], None]]:
        ray = import_ray()
        settings = (self._env_config, self._num_workers, self.num_cpus_per_worker, self.ray_init_kwargs)
        try:
            key = ray.cloudpickle.dumps((*settings, self.start_timeout))
        except Exception as e:
            raise ValueError(
                f"RayEvaluator(env={self.env!r}, ...): the env and wrapper arguments must be picklable (each actor "
                f"builds its own envs from them): {e}"
            ) from e

        def new_pool() -> RayActorPool:
            return RayActorPool(*settings, self.start_timeout)

        pool = ray_session.acquire(key, new_pool)
        assert isinstance(pool, RayActorPool)
        return pool, functools.partial(ray_session.release, key, pool)

    def __enter__(self) -> RayEvaluator:
        self.start()
        return self
