"""Population evaluation spread over Ray actors, on one machine or a cluster.

Every actor owns an SB3 ``VecEnv`` and runs its share of the (candidate, episode) jobs with the local engine,
:class:`~sb3_es.evaluation.VecEnvEvaluator` (one batched forward pass per vec step): there is no second engine.
Ray does the scheduling, the transport and the object store; this module only splits the jobs, ships the
generation's data, merges the results, replaces dead actors and replays the callbacks.

What crosses the wire per generation (see ``docs/guide/ray.md``):

* driver -> object store, once (one ``ray.put``): the center, the policy's observation statistics and the
  population as float32 rows (``(n_candidates, num_params)``), or, for a :class:`NoiseTablePopulation`, only
  the per-candidate offsets into a :class:`SharedNoiseTable` and their signed scales. Each node fetches the
  object once; the actors on a node share it (zero-copy).
* driver -> each actor: the object's reference, the candidate index of each of its jobs, and a seed.
* each actor -> driver: returns and lengths of its jobs, its :class:`~sb3_es.evaluation.ObsStats` (count, mean
  and variance, merged with Chan's parallel algorithm), Monitor episode infos, center-policy episodes, and the
  ``dones`` and ``rewards`` of each vec step (for the callback replay).

Sent once per actor (again only if it changes or the actor is replaced): the policy class and its constructor
parameters, and the noise table's object reference.

This module imports without Ray; Ray is imported when a :class:`RayEvaluator` is created.
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import threading
import time
import weakref
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from sb3_es.common.policies import FlatPolicy
from sb3_es.evaluation.base import PopulationEvaluator, PopulationResult, StepHook
from sb3_es.evaluation.shaping import RewardShaping
from sb3_es.evaluation.vec_env import VecEnvEvaluator
from sb3_es.strategies.noise import NoiseTablePopulation, noise_rows

logger = logging.getLogger(__name__)

#: Evaluators that are open; the one that started Ray shuts it down when the last of them closes.
_OPEN_EVALUATORS: weakref.WeakSet[RayEvaluator] = weakref.WeakSet()
_RAY_STARTED_HERE = False


def _import_ray() -> Any:
    """:return: The ``ray`` module, or a clear error explaining how to install it."""
    try:
        import ray
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(
            "RayEvaluator needs Ray: install it with `pip install sb3-es[ray]` (or `pip install ray`)."
        ) from e
    return ray


# ---------------------------------------------------------------------------------------------------- actor side
def _make_env_fn(env: str | Callable[..., gym.Env]) -> Callable[..., gym.Env]:
    """
    :param env: Env id or factory.
    :return: A factory taking the env kwargs; for an id, ``gym.make(id, **kwargs)`` as SB3 does for a string env.
    """
    if isinstance(env, str):
        env_id = env

        def make(**kwargs: Any) -> gym.Env:
            return gym.make(env_id, **kwargs)

        return make
    return env


class _Worker:
    """
    What a Ray actor runs: a VecEnv, a copy of the policy (architecture + frozen observation statistics) and the
    local engine. Turned into a Ray actor class with ``ray.remote`` when the first evaluator starts.
    """

    def __init__(self, env_config: dict[str, Any]) -> None:
        env_config = dict(env_config)
        env = env_config.pop("env")
        self.env: VecEnv = make_vec_env(_make_env_fn(env), **env_config)
        self.evaluator = VecEnvEvaluator(self.env)
        self.policy: FlatPolicy | None = None
        self.noise_tables: dict[tuple[int, int], np.ndarray] = {}
        # Per generation token: set when the actor's share is done, and by the driver to end the lingering.
        self._signals: dict[int, tuple[threading.Event, threading.Event]] = {}
        self._signals_lock = threading.Lock()
        th.set_num_threads(1)

    def _signal(self, token: int) -> tuple[threading.Event, threading.Event]:
        """:return: The ``(share done, stop lingering)`` events of generation ``token``."""
        with self._signals_lock:
            return self._signals.setdefault(token, (threading.Event(), threading.Event()))

    def jobs_done(self, token: int) -> bool:
        """
        Wait until this actor's share of generation ``token`` is done (or failed). Runs in the ``signal``
        concurrency group, beside a running :meth:`evaluate`.
        """
        return self._signal(token)[0].wait()

    def stop(self, token: int) -> None:
        """End the lingering of generation ``token``: :meth:`evaluate` then returns. Runs in the ``signal`` group."""
        self._signal(token)[1].set()
        with self._signals_lock:
            self._signals.pop(token, None)

    def ready(self) -> int:
        """:return: Number of env slots (used to wait for the actor and check it started)."""
        return self.env.num_envs

    def set_policy(self, policy_class: type[FlatPolicy], kwargs: dict[str, Any]) -> int:
        """
        Build the policy from its constructor parameters and check it fits this actor's env.

        :return: Its number of parameters.
        """
        policy = policy_class(**kwargs)
        for name in ("observation_space", "action_space"):
            ours, theirs = getattr(self.env, name), getattr(policy, name)
            if ours != theirs:
                raise ValueError(
                    f"The Ray actor's env has {name} {ours}, but the policy was built for {theirs}: give "
                    "RayEvaluator the same env (and wrappers) as the model."
                )
        self.policy = policy
        return policy.num_params

    def set_noise_table(self, key: tuple[int, int], noise: np.ndarray) -> None:
        """Keep a noise table (a zero-copy view into the object store)."""
        self.noise_tables[tuple(key)] = noise  # type: ignore[index]

    def evaluate(
        self, payload: dict[str, Any], candidates: np.ndarray, seed: int, token: int | None = None
    ) -> dict[str, Any]:
        """
        Evaluate one episode per entry of ``candidates`` (indices into the generation's population).

        :param token: The generation's token, if the actor should linger: once its share is done, it signals
            :meth:`jobs_done` and keeps running the center policy in all slots until :meth:`stop` is called.
        :return: The engine's result, the dones of every vec step, the done slots' infos and the timings (in the
            engine, of which lingering).
        """
        if token is None:
            return {**self._evaluate(payload, candidates, seed, None), "linger_time": 0.0}
        share_done, stop = self._signal(token)
        linger_start: list[float] = []

        def linger() -> bool:
            if not linger_start:
                linger_start.append(time.perf_counter())
                share_done.set()
            return not stop.is_set()

        try:
            output = self._evaluate(payload, candidates, seed, linger)
        finally:
            share_done.set()  # also on an error, so that the driver's wait ends
        output["linger_time"] = time.perf_counter() - linger_start[0] if linger_start else 0.0
        return output

    def _evaluate(
        self, payload: dict[str, Any], candidates: np.ndarray, seed: int, linger: Callable[[], bool] | None
    ) -> dict[str, Any]:
        policy = self.policy
        if policy is None:
            raise RuntimeError("set_policy() must be called before evaluate().")
        # The payload's arrays are read-only views into the object store: copy them into the buffers.
        policy.obs_mean.copy_(th.from_numpy(np.array(payload["obs_mean"])))
        policy.obs_var.copy_(th.from_numpy(np.array(payload["obs_var"])))
        policy.obs_count.fill_(float(payload["obs_count"]))
        center = payload["center"]
        if payload["population"] is not None:
            rows = payload["population"][candidates]
        else:
            key, offsets, scales = payload["noise"]
            rows = noise_rows(self.noise_tables[tuple(key)], center, offsets[candidates], scales[candidates])
        dones_log: list[np.ndarray] = []
        rewards_log: list[np.ndarray] = []
        done_infos: list[tuple[int, int, dict[str, Any]]] = []

        def record(n_envs: int, infos: list[dict[str, Any]], dones: np.ndarray, rewards: np.ndarray, *_: Any) -> bool:
            for slot in np.flatnonzero(dones).tolist():
                info = {k: v for k, v in infos[slot].items() if k != "terminal_observation"}
                done_infos.append((len(dones_log), slot, info))
            dones_log.append(np.array(dones, dtype=bool))
            rewards_log.append(np.array(rewards))
            return True

        start = time.perf_counter()
        result = self.evaluator.evaluate(
            policy, rows, center, 1, seed, record, payload.get("shaping"), payload.get("max_episode_steps"), linger
        )
        eval_time = time.perf_counter() - start
        n_envs = self.env.num_envs
        dones = np.stack(dones_log) if dones_log else np.zeros((0, n_envs), dtype=bool)
        rewards = np.stack(rewards_log) if rewards_log else np.zeros((0, n_envs), dtype=np.float32)
        return {"result": result, "dones": dones, "rewards": rewards, "done_infos": done_infos, "eval_time": eval_time}

    def call(self, fn: Callable[[VecEnv], Any]) -> Any:
        """:return: ``fn(vec_env)``, run in the actor."""
        return fn(self.env)


_REMOTE_WORKER: Any = None


def _remote_worker_class() -> Any:
    global _REMOTE_WORKER
    if _REMOTE_WORKER is None:
        # ``jobs_done`` and ``stop`` are sent to the ``signal`` group, so that they run beside ``evaluate``.
        _REMOTE_WORKER = _import_ray().remote(concurrency_groups={"signal": 2})(_Worker)
    return _REMOTE_WORKER


# ---------------------------------------------------------------------------------------------------- driver side
class RayEvaluator(PopulationEvaluator):
    """
    Evaluates a population on Ray actors, each owning a VecEnv and running its share of the jobs with
    :class:`~sb3_es.evaluation.VecEnvEvaluator` (batched forward pass, as locally).

    The generation's (candidate, episode) jobs, ordered episode by episode as in the local engine, are cut into
    ``num_workers`` contiguous shares of nearly equal size; share ``k`` runs on actor ``k`` with env seed
    ``seed + k * envs_per_worker``, so the env slots of the cluster get the seeds a local VecEnv of
    ``num_workers * envs_per_worker`` envs would get. For envs whose episodes depend only on the reset seed, a
    result does not depend on which actor process runs a share (a replaced actor re-runs it identically), and
    with one worker the results are those of the local engine on a VecEnv of ``envs_per_worker`` envs, bit for
    bit. (Box2D envs such as BipedalWalker keep their physics world across resets, so their episodes also depend,
    slightly, on what the env ran before, locally as remotely.)

    Idle actors: as the local engine's idle slots do, an actor whose share is done keeps all its slots on the
    center policy until every share is done (the driver then tells the actors to stop); the completed episodes
    are reported as center episodes and the steps are counted. So no actor sits idle while another finishes,
    but the number of these extra steps depends on timing: with several workers, ``num_timesteps`` and the
    center returns are not reproducible to the step (the candidates' returns, the observation statistics and
    so the learning are). With one share (one worker, or a single job) there is no lingering.

    Callbacks: remote steps cannot call the driver's callbacks, so when the results are back the step hook is
    replayed once per remote vec step (the actors' steps interleaved, with each actor's ``n_envs``, its real
    ``dones`` and ``rewards`` and, for slots whose episode ended, its infos without ``terminal_observation``; the
    callbacks' ``new_obs`` and ``actions`` are ``None``, as the actors do not send them back): ``num_timesteps``
    grows by exactly the env steps taken and ``on_step()`` is called once per remote vec step. A callback that
    returns False stops the replay there and the generation is discarded, as in the local engine (kept only if
    the stop came at the last replayed step); the remote work of that generation is lost, since a stop request
    takes effect only once the generation's evaluation has returned.

    Fault tolerance: an actor that dies (node lost, process killed, crash in native code) is replaced by a new
    one, which re-runs its share with the same seed; the event is logged (``logging`` warning) and counted in
    :attr:`restarted_actors`. More than ``max_actor_restarts`` replacements within one generation raise an error.
    An exception raised by the env or policy code inside an actor is not retried: it is raised in the driver.

    Ray is started with ``ray.init(**ray_init_kwargs)`` if it is not running yet (pass
    ``ray_init_kwargs=dict(address="auto")`` to join a running cluster, or call ``ray.init`` yourself first).
    Actors are created at the first evaluation and killed by :meth:`close` (also called at exit, by the
    ``with`` statement, and on an error or ``KeyboardInterrupt`` during an evaluation; a later evaluation
    creates fresh actors). Not saved with the model.

    :param env: Env id (``"BipedalWalker-v3"``, or ``"module:EnvId"`` so that actors import the module that
        registers it) or a picklable env factory (a class, function or lambda returning a ``gym.Env``).
    :param num_workers: Number of actors; by default one per CPU available in the Ray cluster.
    :param envs_per_worker: Env slots of each actor's VecEnv.
    :param wrapper_class: Wrapper applied to each env after ``Monitor`` (as ``make_vec_env``).
    :param env_kwargs: Keyword arguments for ``gym.make`` or the factory.
    :param wrapper_kwargs: Keyword arguments for ``wrapper_class``.
    :param vec_env_cls: VecEnv class of each actor (``DummyVecEnv`` by default).
    :param vec_env_kwargs: Keyword arguments for ``vec_env_cls``.
    :param monitor_kwargs: Keyword arguments for ``Monitor``.
    :param num_cpus_per_worker: CPUs reserved by each actor (``ray.remote(num_cpus=...)``).
    :param ray_init_kwargs: Keyword arguments for ``ray.init`` when this evaluator starts Ray.
    :param max_actor_restarts: Actor replacements allowed within one generation.
    """

    def __init__(
        self,
        env: str | Callable[..., gym.Env],
        num_workers: int | None = None,
        envs_per_worker: int = 1,
        wrapper_class: Callable[[gym.Env], gym.Env] | None = None,
        env_kwargs: dict[str, Any] | None = None,
        wrapper_kwargs: dict[str, Any] | None = None,
        vec_env_cls: type[VecEnv] | None = None,
        vec_env_kwargs: dict[str, Any] | None = None,
        monitor_kwargs: dict[str, Any] | None = None,
        num_cpus_per_worker: float = 1.0,
        ray_init_kwargs: dict[str, Any] | None = None,
        max_actor_restarts: int = 3,
    ) -> None:
        _import_ray()
        if not (isinstance(env, str) or callable(env)):
            raise ValueError(
                f"RayEvaluator(env={env!r}): pass an env id or a picklable env factory (a function returning a "
                "gym.Env), not an env instance: every actor builds its own envs."
            )
        if num_workers is not None and (int(num_workers) != num_workers or num_workers < 1):
            raise ValueError(f"num_workers={num_workers}: it must be a positive integer.")
        if int(envs_per_worker) != envs_per_worker or envs_per_worker < 1:
            raise ValueError(f"envs_per_worker={envs_per_worker}: it must be a positive integer.")
        if max_actor_restarts < 0:
            raise ValueError(f"max_actor_restarts={max_actor_restarts}: it must be >= 0.")
        self.env = env
        self.num_workers = None if num_workers is None else int(num_workers)
        self.envs_per_worker = int(envs_per_worker)
        self.num_cpus_per_worker = float(num_cpus_per_worker)
        self.ray_init_kwargs = dict(ray_init_kwargs or {})
        self.max_actor_restarts = int(max_actor_restarts)
        self._env_config: dict[str, Any] = dict(
            env=env,
            n_envs=self.envs_per_worker,
            wrapper_class=wrapper_class,
            env_kwargs=env_kwargs,
            wrapper_kwargs=wrapper_kwargs,
            vec_env_cls=vec_env_cls or DummyVecEnv,
            vec_env_kwargs=vec_env_kwargs,
            monitor_kwargs=monitor_kwargs,
        )
        #: Number of actors replaced after they died, over the evaluator's life.
        self.restarted_actors = 0
        #: Timings of the last generation: ``wall`` (s, whole ``evaluate``), ``eval_times`` (s, each actor's time
        #: inside the engine), ``linger_times`` (s, the part of it spent on the center policy after the actor's
        #: share was done), ``replay`` (s, callback replay), ``n_steps`` (env steps of each actor).
        self.last_timings: dict[str, Any] = {}
        self._actors: list[Any] = []
        self._actor_policy: list[bytes | None] = []
        self._actor_tables: list[set[tuple[int, int]]] = []
        self._noise_refs: dict[tuple[int, int], Any] = {}
        self._token = 0  # generation counter, names the lingering signals
        self._atexit_registered = False

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Start Ray if needed and create the actors (done by the first evaluation otherwise)."""
        global _RAY_STARTED_HERE
        if self._actors:
            return
        ray = _import_ray()
        if not ray.is_initialized():
            ray.init(**{"ignore_reinit_error": True, **self.ray_init_kwargs})
            _RAY_STARTED_HERE = True
        if self.num_workers is None:
            available = float(ray.available_resources().get("CPU", 0.0))
            self.num_workers = max(1, int(available // self.num_cpus_per_worker))
        self._actors = [self._new_actor() for _ in range(self.num_workers)]
        self._actor_policy = [None] * self.num_workers
        self._actor_tables = [set() for _ in range(self.num_workers)]
        _OPEN_EVALUATORS.add(self)
        if not self._atexit_registered:
            atexit.register(self.close)
            self._atexit_registered = True
        try:
            ray.get([actor.ready.remote() for actor in self._actors])
        except BaseException:  # e.g. the env cannot be built: report it, and start afresh next time
            self._kill_actors()
            raise

    def _new_actor(self) -> Any:
        cls = _remote_worker_class()
        return cls.options(num_cpus=self.num_cpus_per_worker, max_restarts=0).remote(self._env_config)

    def close(self) -> None:
        """Kill the actors (and shut Ray down if this evaluator started it and no other evaluator is open)."""
        global _RAY_STARTED_HERE
        self._kill_actors()
        _OPEN_EVALUATORS.discard(self)
        try:
            import ray
        except ImportError:  # pragma: no cover
            return
        if _RAY_STARTED_HERE and not _OPEN_EVALUATORS and ray.is_initialized():
            ray.shutdown()
            _RAY_STARTED_HERE = False

    def _kill_actors(self) -> None:
        if not self._actors:
            return
        import ray

        if ray.is_initialized():
            for actor in self._actors:
                with contextlib.suppress(Exception):  # already dead, or Ray shutting down
                    ray.kill(actor, no_restart=True)
        self._actors = []
        self._actor_policy = []
        self._actor_tables = []
        self._noise_refs = {}

    def __enter__(self) -> RayEvaluator:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ------------------------------------------------------------------ helpers
    def call_workers(self, fn: Callable[[VecEnv], Any]) -> list[Any]:
        """
        Run ``fn(vec_env)`` in every actor (e.g. to read wrapper attributes).

        :param fn: A picklable function of the actor's VecEnv.
        :return: Its results, in actor order.
        """
        self.start()
        ray = _import_ray()
        return ray.get([actor.call.remote(fn) for actor in self._actors])

    def _sync_actor(self, k: int, policy_spec: tuple[bytes, type[FlatPolicy], dict[str, Any]], table: Any) -> None:
        """Send the policy's constructor parameters (and the noise table) to actor ``k`` if it lacks them."""
        ray = _import_ray()
        spec_bytes, policy_class, kwargs = policy_spec
        if self._actor_policy[k] != spec_bytes:
            ray.get(self._actors[k].set_policy.remote(policy_class, kwargs))
            self._actor_policy[k] = spec_bytes
        if table is not None and table.key not in self._actor_tables[k]:
            if table.key not in self._noise_refs:
                self._noise_refs[table.key] = ray.put(table.noise)
            self._actors[k].set_noise_table.remote(table.key, self._noise_refs[table.key])
            self._actor_tables[k].add(table.key)

    def _replace_actor(self, k: int, error: Exception, restarts_this_generation: int) -> None:
        ray = _import_ray()
        if restarts_this_generation > self.max_actor_restarts:
            raise RuntimeError(
                f"Ray actors died {restarts_this_generation} times in one generation (max_actor_restarts="
                f"{self.max_actor_restarts}); last error: {error}"
            ) from error
        with contextlib.suppress(Exception):  # it is dead already
            ray.kill(self._actors[k], no_restart=True)
        self._actors[k] = self._new_actor()
        self._actor_policy[k] = None
        self._actor_tables[k] = set()
        self.restarted_actors += 1
        logger.warning(
            "Ray actor %d died during a generation (%s: %s); replaced it and re-running its %s (%d restarts so far).",
            k,
            type(error).__name__,
            str(error).splitlines()[0] if str(error) else "",
            "share of the candidates",
            self.restarted_actors,
        )

    # ------------------------------------------------------------------ evaluation
    def evaluate(
        self,
        policy: FlatPolicy,
        population: np.ndarray | NoiseTablePopulation,
        center: np.ndarray,
        n_episodes: int,
        seed: int,
        step_hook: StepHook | None = None,
        shaping: RewardShaping | None = None,
        max_episode_steps: int | None = None,
    ) -> PopulationResult:
        start_time = time.perf_counter()
        self.start()
        shape = shaping is not None and not shaping.is_identity
        try:
            outputs, shares = self._run_remote(policy, population, center, n_episodes, seed, shaping, max_episode_steps)
        except BaseException:
            # Unfinished tasks would delay the next generation (and an interrupted run must not leave busy
            # actors behind): start afresh next time.
            self._kill_actors()
            raise
        n_candidates = population.shape[0]
        result = PopulationResult.empty(n_candidates, n_episodes, policy.obs_dim, shaped=shape)
        returns, lengths = result.returns, result.lengths
        for share, output in zip(shares, outputs):
            part: PopulationResult = output["result"]
            candidates, episodes = share % n_candidates, share // n_candidates
            returns[candidates, episodes] = part.returns[:, 0]
            lengths[candidates, episodes] = part.lengths[:, 0]
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
            result.stopped = self._replay(outputs, step_hook)
        end = time.perf_counter()
        self.last_timings = {
            "wall": end - start_time,
            "replay": end - replay_start,
            "eval_times": [output["eval_time"] for output in outputs],
            "linger_times": [output["linger_time"] for output in outputs],
            "n_steps": [output["result"].n_steps for output in outputs],
        }
        return result

    def _run_remote(
        self,
        policy: FlatPolicy,
        population: np.ndarray | NoiseTablePopulation,
        center: np.ndarray,
        n_episodes: int,
        seed: int,
        shaping: RewardShaping | None = None,
        max_episode_steps: int | None = None,
    ) -> tuple[list[dict[str, Any]], list[np.ndarray]]:
        """Run the shares on the actors (replacing dead ones); return their outputs and job indices."""
        ray = _import_ray()
        from ray.exceptions import RayActorError

        n_candidates = population.shape[0]
        n_jobs = n_candidates * n_episodes
        # Job j is (candidate j % n_candidates, episode j // n_candidates): episode by episode, as locally.
        shares = [s for s in np.array_split(np.arange(n_jobs), min(len(self._actors), n_jobs)) if len(s)]
        policy_class = type(policy)
        kwargs = policy._get_constructor_parameters()
        policy_spec = (ray.cloudpickle.dumps((policy_class, kwargs)), policy_class, kwargs)
        table = population.table if isinstance(population, NoiseTablePopulation) else None
        payload: dict[str, Any] = {
            "center": np.asarray(center, dtype=np.float64),
            "obs_mean": policy.obs_mean.cpu().numpy(),
            "obs_var": policy.obs_var.cpu().numpy(),
            "obs_count": float(policy.obs_count.item()),
            "population": None,
            "noise": None,
            "shaping": shaping,
            "max_episode_steps": max_episode_steps,
        }
        if isinstance(population, NoiseTablePopulation):
            payload["noise"] = (population.table.key, np.asarray(population.offsets), np.asarray(population.scales))
        else:
            payload["population"] = np.asarray(population, dtype=np.float32)
        payload_ref = ray.put(payload)
        # With several shares, an actor whose share is done runs the center policy until all shares are done.
        linger = len(shares) > 1
        self._token += 1
        token = self._token
        restarts = 0
        eval_refs: list[Any] = [None] * len(shares)

        def replace(k: int, error: Exception) -> None:
            nonlocal restarts
            restarts += 1
            self._replace_actor(k, error, restarts)

        def submit(k: int, lingering: bool) -> Any:
            """Send share ``k`` to actor ``k`` (replacing it if it is dead); return the reference to wait for."""
            while True:
                try:
                    self._sync_actor(k, policy_spec, table)
                    actor = self._actors[k]
                    seed_k = int(seed) + k * self.envs_per_worker
                    candidates = shares[k] % n_candidates
                    eval_refs[k] = actor.evaluate.remote(payload_ref, candidates, seed_k, token if lingering else None)
                    return actor.jobs_done.options(concurrency_group="signal").remote(token) if lingering else None
                except RayActorError as e:  # died before its share was sent (e.g. while receiving the policy)
                    replace(k, e)

        if linger:
            # Wait until every share is done; a dead actor's share is re-run (with lingering) by its replacement.
            pending = {submit(k, True): k for k in range(len(shares))}
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                k = pending.pop(ready[0])
                try:
                    ray.get(ready[0])
                except RayActorError as e:
                    replace(k, e)
                    pending[submit(k, True)] = k
            for actor in self._actors[: len(shares)]:
                actor.stop.options(concurrency_group="signal").remote(token)
        else:
            submit(0, False)
        outputs: list[dict[str, Any]] = []
        for k in range(len(shares)):
            while True:
                try:
                    outputs.append(ray.get(eval_refs[k]))
                    break
                except RayActorError as e:  # died (while lingering, or alone): re-run its share without lingering
                    replace(k, e)
                    submit(k, False)
        return outputs, shares

    @staticmethod
    def _replay(outputs: Sequence[dict[str, Any]], step_hook: StepHook) -> bool:
        """
        Call the step hook once per remote vec step, the actors' steps interleaved.

        :return: Whether a hook call returned False before the last replayed step (the result is then discarded).
        """
        done_infos: list[dict[int, dict[int, dict[str, Any]]]] = []
        for output in outputs:
            by_step: dict[int, dict[int, dict[str, Any]]] = {}
            for step, slot, info in output["done_infos"]:
                by_step.setdefault(step, {})[slot] = info
            done_infos.append(by_step)
        n_calls = [len(output["dones"]) for output in outputs]
        total = sum(n_calls)
        calls = 0
        for t in range(max(n_calls, default=0)):
            for k, output in enumerate(outputs):
                if t >= n_calls[k]:
                    continue
                dones = output["dones"][t]
                infos: list[dict[str, Any]] = [{} for _ in range(len(dones))]
                for slot, info in done_infos[k].get(t, {}).items():
                    infos[slot] = dict(info)
                calls += 1
                if not step_hook(len(dones), infos, dones, output["rewards"][t], None, None):
                    return calls < total
        return False
