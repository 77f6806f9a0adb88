"""What one worker of a sharded evaluator runs (in a Ray actor or a worker process): its share of a generation.

A worker owns a VecEnv built from an env config (the arguments of SB3's ``make_vec_env``) and runs its share of
the generation's (candidate, episode) jobs with the local engine, :class:`~sb3_es.evaluation.VecEnvEvaluator`:
there is no second engine. It records what the driver needs to replay the callbacks (the ``dones`` of every vec
step, the infos of the slots whose episode ended) and can *linger*: once its share is done, it signals it and
keeps every slot on the center policy until the driver tells it to stop. The host (Ray, processes) provides only
the transport of these signals.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any, TypedDict

import cloudpickle
import gymnasium as gym
import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv
from typing_extensions import Unpack

from sb3_es.evaluation.base import Generation
from sb3_es.evaluation.network import NetworkSpec
from sb3_es.evaluation.vec_env import VecEnvEvaluator
from sb3_es.strategies.base import check_count
from sb3_es.strategies.noise import noise_rows

#: Env slots of each worker's VecEnv unless ``envs_per_worker`` says otherwise (worker processes and Ray actors).
#: The slots of a worker share one batched forward pass per vec step, so with several slots a worker pays the
#: forward pass and the engine's bookkeeping once per several env steps, and a slot left without a candidate at
#: the tail of a generation costs little (it runs the center policy). Measured with
#: ``python benchmarks/throughput.py --only processes`` (2 workers on a 2-core machine, ARS MlpPolicy, n_delta=8,
#: two runs; docs/benchmarks.md): 1 slot ran at 77%/79% (BipedalWalker-v3) and 48%/48% (Pendulum-v1) of the plain
#: 2-process ``env.step`` loop, 4 slots at 94%/95% and 95%/98%.
DEFAULT_ENVS_PER_WORKER = 4

#: Each sharded evaluator's argument for the replacements of dead workers within a generation (each names its
#: workers its own way): given the other's, an evaluator says which it takes.
RESTARTS_ARGUMENTS = {"ProcessEvaluator": "max_worker_restarts", "RayEvaluator": "max_actor_restarts"}


def make_env_fn(env: str | Callable[..., gym.Env]) -> Callable[..., gym.Env]:
    """
    :param env: Env id or factory.
    :return: A factory taking the env kwargs; for an id, ``gym.make(id, **kwargs)`` as SB3 does for a string env.
    """
    if isinstance(env, str):
        env_id = env

        def make(**kwargs: Any) -> gym.Env:
            try:
                return gym.make(env_id, **kwargs)
            except gym.error.UnregisteredEnv as error:
                raise type(error)(
                    f"{error} (in a worker process). An env registered by your script (gymnasium.register) is not "
                    "registered in workers that do not start as a fork of it (Ray's actors, start_method='spawn'): "
                    "give the id as 'my_package.envs:MyEnv-v0' (gym.make imports my_package.envs first), or pass "
                    "an env factory."
                ) from error

        return make
    return env


class WorkerEnvArgs(TypedDict, total=False):
    """
    The keyword arguments that a sharded evaluator (:class:`~sb3_es.evaluation.processes.ProcessEvaluator`,
    :class:`~sb3_es.evaluation.ray.RayEvaluator`) passes to SB3's ``make_vec_env`` when a worker builds its VecEnv.
    """

    #: Wrapper applied to each env after ``Monitor`` (as ``make_vec_env``).
    wrapper_class: Callable[[gym.Env], gym.Env] | None
    #: Keyword arguments for ``gym.make`` or the env factory.
    env_kwargs: dict[str, Any] | None
    #: Keyword arguments for ``wrapper_class``.
    wrapper_kwargs: dict[str, Any] | None
    #: VecEnv class of each worker (``DummyVecEnv`` by default).
    vec_env_cls: type[VecEnv] | None
    #: Keyword arguments for ``vec_env_cls``.
    vec_env_kwargs: dict[str, Any] | None
    #: Keyword arguments for ``Monitor``.
    monitor_kwargs: dict[str, Any] | None


def env_config(
    env: str | Callable[..., gym.Env],
    envs_per_worker: int,
    restarts_argument: str | None = None,
    **env_args: Unpack[WorkerEnvArgs],
) -> dict[str, Any]:
    """
    Check the env arguments of a sharded evaluator and gather them for :class:`ShareRunner`.

    :param env: Env id or picklable env factory.
    :param envs_per_worker: Env slots of each worker's VecEnv.
    :param restarts_argument: The evaluator's argument for worker replacements (one of
        :data:`RESTARTS_ARGUMENTS`), named when the other evaluator's is given.
    :param env_args: The other keyword arguments of ``make_vec_env`` (see :class:`WorkerEnvArgs`).
    :return: The keyword arguments of ``make_vec_env``, with the env id or factory under ``"env"``.
    """
    if not (isinstance(env, str) or callable(env)):
        raise ValueError(
            f"env={env!r}: pass an env id or a picklable env factory (a function returning a gym.Env), not an env "
            "instance: every worker builds its own envs."
        )
    envs_per_worker = check_count("envs_per_worker", envs_per_worker)
    unknown = sorted(set(env_args) - set(WorkerEnvArgs.__annotations__))
    for evaluator, argument in RESTARTS_ARGUMENTS.items():
        if argument in unknown and restarts_argument is not None:
            raise TypeError(
                f"Unexpected keyword argument {argument}: that is {evaluator}'s; this evaluator's is "
                f"{restarts_argument} (the replacements of dead workers allowed within one generation)."
            )
    if unknown:
        raise TypeError(
            f"Unexpected keyword argument(s) {', '.join(unknown)}: the env arguments of a worker are "
            f"{', '.join(WorkerEnvArgs.__annotations__)} (those of SB3's make_vec_env)."
        )
    for name in ("env_kwargs", "wrapper_kwargs", "vec_env_kwargs", "monitor_kwargs"):
        check_kwargs(name, env_args.get(name))
    wrapper_class = env_args.get("wrapper_class")
    if wrapper_class is not None and not callable(wrapper_class):
        raise TypeError(
            f"wrapper_class={wrapper_class!r}: it must be a gym.Wrapper class, or a function taking the env and "
            "returning the wrapped env (or None for no wrapper)."
        )
    vec_env_cls = env_args.get("vec_env_cls")
    if vec_env_cls is not None and not (isinstance(vec_env_cls, type) and issubclass(vec_env_cls, VecEnv)):
        what = "the VecEnv class itself, not its name" if isinstance(vec_env_cls, str) else "a VecEnv class"
        raise TypeError(
            f"vec_env_cls={vec_env_cls!r}: pass {what} (from stable_baselines3.common.vec_env import DummyVecEnv, "
            "then vec_env_cls=DummyVecEnv), or None for DummyVecEnv."
        )
    config: dict[str, Any] = dict(env=env, n_envs=envs_per_worker, **env_args)
    config["vec_env_cls"] = config.get("vec_env_cls") or DummyVecEnv
    for name, value in config.items():  # every worker gets a copy: refused here, not at the first learn()
        try:
            cloudpickle.dumps(value)
        except Exception as error:
            raise TypeError(
                f"{name}={value!r} does not pickle ({type(error).__name__}: {error}), and every worker gets a copy: "
                "create what does not pickle (a lock, an open file, an env instance, a client) inside the env "
                "factory, or pass a registered env id."
            ) from error
    return config


def check_kwargs(name: str, value: Any) -> dict[str, Any] | None:
    """
    :param name: Argument name, for the message.
    :param value: Keyword arguments for a function (``None`` for none).
    :return: ``value`` as a dict, or ``None``.
    :raises TypeError: Naming ``name`` when ``value`` is not a mapping with string keys (a list of pairs, a
        string), which would fail only where the keywords are passed (in a worker, at the first evaluation).
    """
    if value is None:
        return None
    if not isinstance(value, Mapping):
        raise TypeError(f"{name}={value!r}: it must be a dict of keyword arguments, such as dict(key=value), or None.")
    wrong = [key for key in value if not isinstance(key, str)]
    if wrong:
        raise TypeError(f"{name}={value!r}: its keys must be argument names (strings), not {wrong[0]!r}.")
    return dict(value)


def with_sb3_wrappers(env: VecEnv) -> VecEnv:
    """
    :param env: A worker's VecEnv.
    :return: ``env`` in the VecEnv wrappers SB3 adds to a model's env (``VecTransposeImage`` for channels-last
        images), so that the workers' observations are those the policy was built for.
    """
    return BaseAlgorithm._wrap_env(env, monitor_wrapper=False)


class ShareRunner:
    """
    A worker's VecEnv and engine, and the noise tables it was given.

    :param config: Output of :func:`env_config`.
    """

    def __init__(self, config: dict[str, Any]) -> None:
        config = dict(config)
        env = config.pop("env")
        self.env: VecEnv = with_sb3_wrappers(make_vec_env(make_env_fn(env), **config))
        self.engine = VecEnvEvaluator(self.env)
        self.noise_tables: dict[tuple[int, int], np.ndarray] = {}
        self._clock_start: float | None = None

    def _set_clock(self, clock_start: float) -> None:
        """Measure the episodes' ``t`` from the driver's clock origin: the ``Monitor`` of each slot starts there."""
        if clock_start == self._clock_start:
            return
        # Through any wrapper outside the Monitor, and into the processes of a SubprocVecEnv.
        self.env.env_method("set_wrapper_attr", "t_start", clock_start, force=False)
        self._clock_start = clock_start

    def run(
        self,
        payload: dict[str, Any],
        jobs: np.ndarray,
        seed: int,
        share_done: Callable[[], None] | None = None,
        keep_lingering: Callable[[], bool] | None = None,
    ) -> dict[str, Any]:
        """
        Run the (candidate, episode) jobs of this share, one episode each.

        :param payload: The generation's data: ``network``, ``center``, ``population`` (rows) or ``noise``
            (table key, offsets, scales), ``shaping``, ``max_episode_steps``, ``n_candidates``, ``reset_seeds``
            (the reset seed of each job, or ``None``), ``clock_start`` (the origin of the episodes' ``t``).
        :param jobs: The jobs of this share: job ``j`` is episode ``j // n_candidates`` of candidate
            ``j % n_candidates``.
        :param seed: Env seed of this share.
        :param share_done: If given, the worker lingers: called once when the share is done (not on an error,
            which the driver gets as the call's result), after which every slot runs the center policy while
            ``keep_lingering()`` returns True.
        :param keep_lingering: See ``share_done``.
        :return: The engine's result, the dones and rewards of every vec step, the done slots' infos (without
            ``terminal_observation``) and the timings (in the engine, of which lingering).
        """
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

        linger_start: list[float] = []
        linger: Callable[[], bool] | None = None
        if share_done is not None:
            lingering = keep_lingering or (lambda: False)

            def linger() -> bool:
                if not linger_start:
                    linger_start.append(time.perf_counter())
                    share_done()
                return lingering()

        start = time.perf_counter()
        # An error is not signalled as a done share: the driver, waiting for the shares, gets it at once.
        network: NetworkSpec = payload["network"]
        self._set_clock(payload["clock_start"])
        center = payload["center"]
        candidates = jobs % payload["n_candidates"]
        reset_seeds = None if payload["reset_seeds"] is None else payload["reset_seeds"][jobs][:, None]
        if payload["population"] is not None:
            rows = payload["population"][candidates]
        else:
            key, offsets, scales = payload["noise"]
            rows = noise_rows(self.noise_tables[tuple(key)], center, offsets[candidates], scales[candidates])
        generation = Generation(
            network, rows, center, 1, seed, payload["shaping"], payload["max_episode_steps"], reset_seeds
        )
        result = self.engine.run(generation, record, linger)
        if share_done is not None and not linger_start:
            share_done()
        end = time.perf_counter()
        n_envs = self.env.num_envs
        dones = np.stack(dones_log) if dones_log else np.zeros((0, n_envs), dtype=bool)
        rewards = np.stack(rewards_log) if rewards_log else np.zeros((0, n_envs), dtype=np.float32)
        return {
            "result": result,
            "dones": dones,
            "rewards": rewards,
            "done_infos": done_infos,
            "eval_time": end - start,
            "linger_time": end - linger_start[0] if linger_start else 0.0,
        }
