"""The driver side of evaluating a population on several workers, whatever hosts them (Ray actors, processes).

A :class:`ShardedEvaluator` cuts a generation's (candidate, episode) jobs into one share per worker, has every
worker run its share with the local engine (see :mod:`sb3_es.evaluation.worker`), keeps finished workers busy on
the center policy until every share is done (lingering), replaces a worker that dies and re-runs its share, merges
the results (observation statistics by Chan's parallel algorithm), replays the callbacks and records timings. The
host is a :class:`~sb3_es.evaluation.pool.WorkerPool`: it starts the workers and carries the calls and signals,
nothing else.
"""

from __future__ import annotations

import itertools
import logging
import math
import time
import weakref
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from sb3_es.evaluation.base import Generation, PopulationEvaluator, PopulationResult, StepHook
from sb3_es.evaluation.pool import WorkerDied, WorkerPool
from sb3_es.evaluation.replay import replay
from sb3_es.strategies.base import check_count, check_flag, check_number
from sb3_es.strategies.noise import NoiseTablePopulation

logger = logging.getLogger(__name__)

#: Names the lingering signals of each generation (unique in the process, shared pools included).
_TOKENS = itertools.count(1)

#: The longest single wait, in seconds, that the hosts hand to the OS or Ray: ``poll`` refuses more than about 24
#: days (``OverflowError``), Ray's ``wait`` refuses ``math.inf`` and gives up after about 11 days without a timeout.
#: Longer waits are made of such pieces (see :func:`wait_pieces`).
MAX_WAIT = 86400.0


def _remaining(deadline: float | None) -> float | None:
    return None if deadline is None else max(0.0, deadline - time.monotonic())


def wait_pieces(timeout: float | None) -> Iterator[float]:
    """
    Cut a wait of any length into waits that the OS and Ray take.

    :param timeout: Seconds to wait; ``None`` or ``math.inf`` for no limit.
    :return: The timeouts of the pieces, each at most :data:`MAX_WAIT`, the last one ending when ``timeout`` is
        over (without a limit, there is no last one): wait for each in turn, until one ends with something ready.
    """
    deadline = math.inf if timeout is None else time.monotonic() + timeout
    while True:
        remaining = max(0.0, deadline - time.monotonic())
        yield min(remaining, MAX_WAIT)
        if remaining <= MAX_WAIT:
            return


def check_timeout(name: str, value: Any, no_limit: str = "math.inf") -> float:
    """
    :param name: Argument name, for the message.
    :param value: A number of seconds, ``math.inf`` for no limit.
    :param no_limit: What the argument takes for no limit, for the message.
    :return: ``value`` as a float.
    :raises ValueError: Naming ``name`` when ``value`` is not above 0 (``nan`` included); ``TypeError``: no number.
    """
    seconds = check_number(name, value)
    if not seconds > 0:
        raise ValueError(f"{name}={value!r}: give a positive number of seconds ({no_limit} for no limit).")
    return seconds


class ShardedEvaluator(PopulationEvaluator, ABC):
    """
    Evaluates a population on the workers of a :class:`WorkerPool`, each running its share with the local engine.

    Shares: the generation's (candidate, episode) jobs, ordered episode by episode as in the local engine, are cut
    into ``num_workers`` contiguous shares of nearly equal size; share ``k`` runs on worker ``k`` with env seed
    ``seed + k * envs_per_worker``, so the env slots get the seeds a local VecEnv of ``num_workers *
    envs_per_worker`` envs would get. For envs whose episodes depend only on the reset seed, a result does not
    depend on which process runs a share (a replaced worker re-runs it identically), and with one worker the
    results are the local engine's, bit for bit. (Box2D envs such as BipedalWalker keep their physics world across
    resets, so their episodes also depend, slightly, on what the env ran before, locally as remotely.)

    Lingering: as the local engine's idle slots do, a worker whose share is done keeps its slots on the center
    policy until every share is done (the driver then tells the workers to stop); the completed episodes are
    reported as center episodes and the steps counted. So no worker idles at the end of a generation, but these
    extra steps depend on timing: with several workers, ``num_timesteps`` and the center returns are not
    reproducible to the step (the candidates' returns, the observation statistics and so the parameters are, for
    envs whose episodes depend only on the reset seed and without a scheduled hyperparameter, which follows
    ``num_timesteps``; on BipedalWalker the lingering steps change later episodes).
    ``linger=False`` makes the step counts reproducible too, at the cost of idle workers. One share never lingers.

    Callbacks: remote steps cannot call the driver's callbacks, so when the results are back the step hook is
    replayed once per remote vec step (see :func:`~sb3_es.evaluation.replay.replay`; the algorithm regroups those
    steps into calls of its env's ``num_envs``: :class:`~sb3_es.common.step_calls.StepCalls`): ``num_timesteps``
    grows by exactly the env steps taken. A callback that returns False stops the replay there and the generation is
    discarded, as in the local engine (kept only if the stop came at the last replayed step); the remote work of that
    generation is lost.

    Faults: a worker that dies (process killed, node lost, crash in native code) is replaced and its share re-run
    with the same seed; the event is logged (``logging`` warning) and counted in :attr:`restarted_workers`; more
    than ``max_restarts`` replacements in one generation raise an error. An exception raised by the env or policy
    code in a worker (``SystemExit`` and ``KeyboardInterrupt`` too) is not retried: it is raised here. An error or
    ``KeyboardInterrupt`` during a generation stops the workers (fresh ones start at the next evaluation).

    :param config: The workers' env config (see :func:`~sb3_es.evaluation.worker.env_config`).
    :param num_workers: Number of workers (``None``: the host's default).
    :param start_timeout: Seconds to wait for workers to start; ``math.inf`` for no limit.
    :param max_restarts: Worker replacements allowed within one generation.
    :param generation_timeout: Seconds a generation may take before the workers are stopped and ``TimeoutError``
        is raised; ``None`` (or ``math.inf``, kept as ``None``) for no limit. The start of a replacement for a dead
        worker is not counted (it is bounded by ``start_timeout``).
    :param linger: Whether finished workers run the center policy while the others finish their shares.
    """

    #: How the workers are named in messages, one and several.
    worker_name = "worker"
    workers_name = "workers"
    #: The constructor argument that sets ``max_restarts`` (named in messages).
    restarts_argument = "max_restarts"

    def __init__(
        self,
        config: dict[str, Any],
        num_workers: int | None,
        start_timeout: float,
        max_restarts: int = 3,
        generation_timeout: float | None = None,
        linger: bool = True,
    ) -> None:
        if num_workers is not None:
            num_workers = check_count("num_workers", num_workers)
        start_timeout = check_timeout("start_timeout", start_timeout)
        max_restarts = check_count(self.restarts_argument, max_restarts, minimum=0)
        if generation_timeout is not None:
            generation_timeout = check_timeout("generation_timeout", generation_timeout, "None or math.inf")
            if math.isinf(generation_timeout):
                generation_timeout = None
        self._env_config = config
        #: The env id or factory the workers build their envs from.
        self.env = config["env"]
        self.envs_per_worker = int(config["n_envs"])
        self._num_workers = num_workers
        self.start_timeout = start_timeout
        self.max_restarts = max_restarts
        self.generation_timeout = generation_timeout
        self.linger = check_flag("linger", linger)
        #: Number of workers replaced after they died, over the evaluator's life.
        self.restarted_workers = 0
        #: Wall-clock origin (``time.time()``) of the workers' ``Monitor``: an episode's ``t`` is measured from it. The
        #: evaluator's creation by default; an algorithm sets its own env's ``Monitor`` start, so that the episodes it
        #: writes to that ``Monitor``'s file share its clock (fresh and replaced workers too; Ray actors on other
        #: machines add their clock's offset from the driver's).
        self.clock_start = time.time()
        #: Timings of the last generation: ``wall`` (s, whole ``evaluate``), ``eval_times`` (s, each worker's time
        #: inside the engine), ``linger_times`` (s, the part of it spent on the center policy after the worker's
        #: share was done), ``replay`` (s, callback replay), ``n_steps`` (env steps of each worker).
        self.last_timings: dict[str, Any] = {}
        self._pool: WorkerPool | None = None
        self._release: weakref.finalize | None = None

    # ------------------------------------------------------------------ lifecycle
    @abstractmethod
    def _acquire_pool(self) -> tuple[WorkerPool, Callable[[], None]]:
        """:return: The pool to run on, and how to release it (a function that must not refer to this evaluator)."""

    @property
    def pool(self) -> WorkerPool:
        """:return: The worker pool (acquired at the first use; released by :meth:`close` or garbage collection)."""
        if self._pool is None:
            pool, release = self._acquire_pool()
            self._pool = pool
            # Released when this evaluator is closed or garbage-collected, or at exit: nothing keeps it alive.
            self._release = weakref.finalize(self, release)
        return self._pool

    def start(self) -> None:
        """Start the workers (done by the first evaluation otherwise)."""
        self.pool.start()

    def close(self) -> None:
        """Release the workers (a later evaluation starts them again)."""
        if self._release is not None:
            self._release()
        self._pool = None
        self._release = None

    def __enter__(self) -> ShardedEvaluator:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def call_workers(self, fn: Callable[[VecEnv], Any]) -> list[Any]:
        """
        Run ``fn(vec_env)`` in every worker (e.g. to read wrapper attributes).

        :param fn: A picklable function of the worker's VecEnv.
        :return: Its results, in worker order.
        """
        self.start()
        try:
            return self.pool.call(fn)
        except BaseException:  # unread replies would be taken for the next generation's: start afresh
            self.pool.close()
            raise

    # ------------------------------------------------------------------ evaluation
    def _evaluate(self, generation: Generation, step_hook: StepHook | None) -> PopulationResult:
        start_time = time.perf_counter()
        pool = self.pool
        try:
            pool.busy = True
            pool.start()
            outputs, shares = self._run_shares(pool, generation)
        except BaseException:
            # Unfinished shares would delay the next generation (and an interrupted run must not leave busy
            # workers behind): start afresh next time.
            pool.close()
            raise
        finally:
            pool.busy = False
        n_candidates = generation.n_candidates
        result = generation.empty_result()
        for share, output in zip(shares, outputs):
            part: PopulationResult = output["result"]
            candidates, episodes = share % n_candidates, share // n_candidates
            result.returns[candidates, episodes] = part.returns[:, 0]
            result.lengths[candidates, episodes] = part.lengths[:, 0]
            if result.shaped_returns is not None:
                result.shaped_returns[candidates, episodes] = part.fitness_returns[:, 0]
            result.obs_stats.merge(part.obs_stats)
            result.n_steps += part.n_steps
            result.ep_infos.extend(part.ep_infos)
            result.successes.extend(part.successes)
            result.center_returns.extend(part.center_returns)
            result.center_lengths.extend(part.center_lengths)
        replay_start = time.perf_counter()
        if step_hook is not None:
            result.stopped = replay(outputs, step_hook)
        end = time.perf_counter()
        self.last_timings = {
            "wall": end - start_time,
            "replay": end - replay_start,
            "eval_times": [output["eval_time"] for output in outputs],
            "linger_times": [output["linger_time"] for output in outputs],
            "n_steps": [output["result"].n_steps for output in outputs],
        }
        return result

    def _run_shares(self, pool: WorkerPool, generation: Generation) -> tuple[list[dict[str, Any]], list[np.ndarray]]:
        """Run the shares on the workers (replacing dead ones); return their outputs and job indices."""
        assert pool.size is not None
        n_candidates, population, seed = generation.n_candidates, generation.population, generation.seed
        n_jobs = n_candidates * generation.n_episodes
        # Job j is (candidate j % n_candidates, episode j // n_candidates): episode by episode, as locally.
        shares = [s for s in np.array_split(np.arange(n_jobs), min(pool.size, n_jobs)) if len(s)]
        payload: dict[str, Any] = {
            "network": generation.network,
            "center": np.asarray(generation.center, dtype=np.float64),
            "population": None,
            "noise": None,
            "shaping": generation.shaping,
            "max_episode_steps": generation.max_episode_steps,
            "n_candidates": n_candidates,
            "clock_start": self.clock_start,
            # Reset seed of job j (None: the slots' own sequences).
            "reset_seeds": None if generation.reset_seeds is None else np.asarray(generation.reset_seeds).T.ravel(),
        }
        table = None
        if isinstance(population, NoiseTablePopulation):
            table = population.table
            payload["noise"] = (table.key, np.asarray(population.offsets), np.asarray(population.scales))
        else:
            payload["population"] = np.asarray(population, dtype=np.float32)
        handle = pool.publish(payload)
        deadline = None if self.generation_timeout is None else time.monotonic() + self.generation_timeout
        token = next(_TOKENS)
        restarts = 0

        def replace(k: int, error: WorkerDied) -> None:
            nonlocal restarts, deadline
            restarts += 1
            started = time.monotonic()
            self._replace(pool, k, error, restarts)
            if deadline is not None:  # the replacement's start is bounded by start_timeout, not counted here
                deadline += time.monotonic() - started

        def submit(k: int, lingering: bool) -> None:
            while True:
                try:
                    seed_k = int(seed) + k * pool.envs_per_worker
                    pool.submit(k, handle, shares[k], seed_k, token if lingering else None, table)
                    return
                except WorkerDied as e:  # died before its share was sent
                    replace(k, e)

        try:
            # With several shares, a worker whose share is done runs the center policy until all shares are done.
            linger = self.linger and len(shares) > 1
            for k in range(len(shares)):
                submit(k, linger)
            pending = set(range(len(shares))) if linger else set()
            # After a death, no worker lingers: center-policy steps, counted in num_timesteps, would fill the
            # replacement's start-up time and its re-run of the share. Each is told so at once (a worker still running
            # its share then stops when it is done), and again when its share is done (the replacement, and a Ray
            # actor that got the signal before its share began).
            a_worker_died = False
            while pending:
                k, error = pool.wait_share_done(sorted(pending), _remaining(deadline))
                if error is None:
                    pending.discard(k)
                    if a_worker_died:
                        pool.stop_lingering(k, token)
                    continue
                a_worker_died = True
                for j in range(len(shares)):
                    if j != k:
                        pool.stop_lingering(j, token)
                replace(k, error)  # its share is re-run by its replacement
                submit(k, True)
            if linger:
                for k in range(len(shares)):
                    pool.stop_lingering(k, token)
            outputs: list[dict[str, Any]] = []
            for k in range(len(shares)):
                while True:
                    try:
                        outputs.append(pool.result(k, _remaining(deadline)))
                        break
                    except WorkerDied as e:  # died while lingering, or alone: re-run its share without lingering
                        replace(k, e)
                        submit(k, False)
        except TimeoutError as e:
            raise TimeoutError(
                f"The {self.workers_name} did not finish the generation within generation_timeout="
                f"{self.generation_timeout} s: an episode may never end (an env without a time limit?) or a "
                f"{self.worker_name} is stuck in the env. The {self.workers_name} were stopped."
            ) from e
        return outputs, shares

    def _replace(self, pool: WorkerPool, k: int, error: WorkerDied, restarts_this_generation: int) -> None:
        if restarts_this_generation > self.max_restarts:
            raise RuntimeError(
                f"{self.workers_name.capitalize()} died {restarts_this_generation} times in one generation "
                f"({self.restarts_argument}={self.max_restarts}); last error: {error}"
            ) from error
        pool.replace(k)
        self.restarted_workers += 1
        logger.warning(
            "%s %d died during a generation (%s); replaced it and re-running its share of the candidates "
            "(%d restarts so far).",
            self.worker_name.capitalize(),
            k,
            error,
            self.restarted_workers,
        )
