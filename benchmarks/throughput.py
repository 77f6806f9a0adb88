"""
Env-step throughput of sb3-es ARS against sb3-contrib's ARS and a plain ``env.step`` loop.

Command (about 5 minutes on 2 cores with the defaults, 6 with ``--profile``)::

    python benchmarks/throughput.py

The multi-process evaluators alone (worker processes and Ray, 2 workers, against the plain 2-process loop on
BipedalWalker-v3 and Pendulum-v1, with their startup times; about 4 minutes); for each host, one row per
``envs_per_worker`` and one with the evaluator's defaults, as ``evaluator="processes"`` / ``"ray"`` builds it
(labelled ``default``: one worker per CPU, 4 env slots each)::

    python benchmarks/throughput.py --only processes

Options: ``--seconds S`` (timed window of each measurement, default 8), ``--warmup S`` (default 1.5),
``--quick`` (2 s windows, smoke test; ``--seconds 0.5 --warmup 0.2`` for a still shorter one),
``--only bipedal|pendulum|processes``, ``--torch-threads N`` (``th.set_num_threads`` in the main process), ``--profile``
(also print where our engine spends its time per vec step).

Every ARS measurement builds the model and its envs, warms up with a short ``learn()``, then times
``learn(..., reset_num_timesteps=False)`` for a fixed wall time; steps are the difference of
``model.num_timesteps``. A callback ends the timed window (per vec step; for sb3-contrib's
``AsyncEval`` path, whose callbacks run after the generation, at the end of a generation). The plain
loop runs ``env.step(env.action_space.sample())`` (with resets) in N processes for the same time and
sums their rates. All ARS runs: ``MlpPolicy`` ([64, 64]), ``n_delta=8``, other hyperparameters default.

Our "2 processes" configurations are the sharded evaluator with 2 workers, hosted by worker processes
(``ProcessEvaluator``, standard library) or by Ray actors (``RayEvaluator``): each worker runs the batched engine
on its own envs, one round trip per generation. ``SubprocVecEnv`` with 2 envs is also reported: it pays an IPC
round trip on every vec step, which costs more than a BipedalWalker step. The startup time of each sharded
evaluator (workers started and their envs built; for Ray, ``ray.init`` included) is printed too. The Ray rows need
``pip install ray``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import os
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from common import hardware, measure_plain, positive_problems, versions
from sb3_contrib import ARS as ContribARS
from sb3_contrib.common.vec_env import AsyncEval
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv

from sb3_es import ARS
from sb3_es.evaluation.base import ObsStats
from sb3_es.evaluation.network import NetworkSpec
from sb3_es.evaluation.processes import ProcessEvaluator, usable_cpus
from sb3_es.evaluation.sharded import ShardedEvaluator
from sb3_es.evaluation.worker import DEFAULT_ENVS_PER_WORKER

HAVE_RAY = importlib.util.find_spec("ray") is not None

BIPEDAL = "BipedalWalker-v3"
PENDULUM = "Pendulum-v1"
N_DELTA = 8


class _TimeUp(Exception):
    """Raised by :class:`_Deadline` to end a timed ``learn()`` (sb3-contrib ignores ``on_step``'s result)."""


class _Deadline(BaseCallback):
    """
    Stops ``learn()`` once ``seconds`` have passed, checked at every vec step or at the end of a generation.

    :param seconds: Wall time allowed.
    :param per_step: Check at every ``on_step`` (else only in ``on_rollout_end``).
    """

    def __init__(self, seconds: float, per_step: bool = True) -> None:
        super().__init__()
        self.deadline = time.perf_counter() + seconds
        self.per_step = per_step

    def _on_step(self) -> bool:
        if self.per_step and time.perf_counter() >= self.deadline:
            raise _TimeUp
        return True

    def _on_rollout_end(self) -> None:
        if time.perf_counter() >= self.deadline:
            raise _TimeUp


@dataclass
class Result:
    """One measurement."""

    env_id: str
    name: str
    config: str
    steps: int
    seconds: float
    ep_len: float | None = None
    startup: float | None = None

    @property
    def rate(self) -> float:
        return self.steps / self.seconds


def _run_for(model: Any, seconds: float, per_step: bool = True, **learn_kwargs: Any) -> None:
    with contextlib.suppress(_TimeUp):
        model.learn(10**12, callback=_Deadline(seconds, per_step), reset_num_timesteps=False, **learn_kwargs)


def _mean_ep_len(model: Any) -> float | None:
    lengths = [info["l"] for info in model.ep_info_buffer or [] if "l" in info]
    return float(np.mean(lengths)) if lengths else None


def _time_model(
    model: Any, env_id: str, name: str, config: str, seconds: float, warmup: float, per_step: bool = True, **kw: Any
) -> Result:
    _run_for(model, warmup, per_step, **kw)
    start_steps = model.num_timesteps
    start = time.perf_counter()
    _run_for(model, seconds, per_step, **kw)
    elapsed = time.perf_counter() - start
    return Result(env_id, name, config, model.num_timesteps - start_steps, elapsed, _mean_ep_len(model))


def measure_ours(env_id: str, n_envs: int, subproc: bool, seconds: float, warmup: float) -> Result:
    vec_cls = SubprocVecEnv if subproc else DummyVecEnv
    env = make_vec_env(env_id, n_envs=n_envs, seed=0, vec_env_cls=vec_cls)
    try:
        model = ARS("MlpPolicy", env, n_delta=N_DELTA, seed=0)
        config = f"{vec_cls.__name__} n_envs={n_envs} ({n_envs if subproc else 1} proc)"
        return _time_model(model, env_id, "sb3-es ARS", config, seconds, warmup)
    finally:
        env.close()


def measure_ours_sharded(
    host: str, env_id: str, workers: int | None, envs_per_worker: int | None, seconds: float, warmup: float
) -> Result:
    """
    Our ARS with a sharded evaluator: ``workers`` worker processes (``host="processes"``) or Ray actors
    (``host="ray"``), each running ``envs_per_worker`` env slots. The startup is timed separately.

    With ``workers`` and ``envs_per_worker`` both ``None``, the evaluator's defaults (as ``evaluator="processes"`` or
    ``evaluator="ray"`` builds it): the row is labelled ``default``.
    """
    given = {"num_workers": workers, "envs_per_worker": envs_per_worker}
    layout: dict[str, Any] = {key: value for key, value in given.items() if value is not None}
    start = time.perf_counter()
    evaluator: ShardedEvaluator
    if host == "ray":
        import ray

        from sb3_es.evaluation.ray import RayEvaluator

        evaluator = RayEvaluator(env_id, **layout)
    else:
        evaluator = ProcessEvaluator(env_id, **layout)
    try:
        evaluator.start()
        startup = time.perf_counter() - start
        model = ARS("MlpPolicy", env_id, n_delta=N_DELTA, seed=0, evaluator=evaluator)
        name = "Ray" if host == "ray" else "processes"
        n, k = evaluator.pool.size, evaluator.envs_per_worker
        label = f"{name} default: " if not layout else f"{name} "
        config = f"{label}{n} workers x {k} envs ({n} proc)"
        result = _time_model(model, env_id, "sb3-es ARS", config, seconds, warmup, per_step=False)
        result.startup = startup
        return result
    finally:
        evaluator.close()
        if host == "ray":
            ray.shutdown()


def measure_contrib(env_id: str, n_workers: int, seconds: float, warmup: float) -> Result:
    """sb3-contrib's ARS: single process (``n_workers=0``) or ``AsyncEval`` with ``n_workers`` processes."""
    env = make_vec_env(env_id, n_envs=1, seed=0)
    model = ContribARS("MlpPolicy", env, n_delta=N_DELTA, seed=0)
    if n_workers == 0:
        result = _time_model(model, env_id, "sb3-contrib ARS", "single process (DummyVecEnv n_envs=1)", seconds, warmup)
        env.close()
        return result
    async_eval = AsyncEval([partial(make_vec_env, env_id, n_envs=1) for _ in range(n_workers)], model.policy)
    try:
        async_eval.seed(0)  # blocks until the workers have built their envs
        config = f"AsyncEval {n_workers} workers ({n_workers} proc)"
        return _time_model(
            model, env_id, "sb3-contrib ARS", config, seconds, warmup, per_step=False, async_eval=async_eval
        )
    finally:
        async_eval.close()
        env.close()


def measure_plain_loop(env_id: str, n_procs: int, seconds: float, warmup: float) -> Result:
    """The plain step loop in ``n_procs`` processes (:func:`common.measure_plain`), as a table row."""
    plain = measure_plain(env_id, n_procs, seconds, warmup)
    return Result(
        env_id,
        "plain step loop",
        f"{n_procs} proc, gym.make + action_space.sample()",
        round(plain.rate * plain.seconds),
        plain.seconds,
        plain.steps / plain.episodes if plain.episodes else None,
    )


# ---------------------------------------------------------------------------------------------- profile
class _EnvTimer(gym.Wrapper):
    """Accumulates the time spent inside the wrapped env (step and reset, Monitor included)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.busy = 0.0

    def step(self, action: Any) -> Any:
        start = time.perf_counter()
        try:
            return self.env.step(action)
        finally:
            self.busy += time.perf_counter() - start

    def reset(self, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return self.env.reset(**kwargs)
        finally:
            self.busy += time.perf_counter() - start


def profile_ours(env_id: str, n_envs: int, subproc: bool, seconds: float, warmup: float) -> None:
    """
    Print the per-vec-step time of each part of our engine, measured by wrapping its methods (the network spec's
    on the class, the env's and the strategy's on the instance; no change to sb3-es).
    """
    vec_cls = SubprocVecEnv if subproc else DummyVecEnv
    env: VecEnv = make_vec_env(env_id, n_envs=n_envs, seed=0, vec_env_cls=vec_cls, wrapper_class=_EnvTimer)
    model = ARS("MlpPolicy", env, n_delta=N_DELTA, seed=0)
    _run_for(model, warmup)
    timers: dict[str, float] = defaultdict(float)
    calls: dict[str, int] = defaultdict(int)

    def timed(name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                timers[name] += time.perf_counter() - start
                calls[name] += 1

        return wrapper

    def wrap(obj: Any, attr: str, name: str | None = None) -> str | None:
        if not hasattr(obj, attr):
            return None
        setattr(obj, attr, timed(name or attr, getattr(obj, attr)))
        return name or attr

    # The evaluator runs the policy's NetworkSpec (a new one each generation): time its methods on the class.
    originals = {name: getattr(NetworkSpec, name) for name in ("flatten_obs", "normalize", "forward", "__call__")}
    for name, method in originals.items():
        setattr(NetworkSpec, name, timed(name, method))
    flatten = "flatten_obs"
    nested = ["normalize", "forward"]
    wrap(env, "step")
    assert model.strategy is not None
    wrap(model.strategy, "ask", "ask/tell")
    wrap(model.strategy, "tell", "ask/tell")
    reset_busy = [0.0]  # env time spent in the generation-start resets (not part of env.step)
    original_reset = env.reset

    def reset() -> Any:
        before = sum(env.get_attr("busy"))
        try:
            return original_reset()
        finally:
            reset_busy[0] += sum(env.get_attr("busy")) - before

    env.reset = timed("reset", reset)  # type: ignore[method-assign]
    original_add = ObsStats.add
    ObsStats.add = timed("ObsStats.add", original_add)  # type: ignore[method-assign]
    busy_start = sum(env.get_attr("busy"))
    start_steps = model.num_timesteps
    start = time.perf_counter()
    try:
        _run_for(model, seconds)
    finally:
        ObsStats.add = original_add  # type: ignore[method-assign]
        for name, method in originals.items():
            setattr(NetworkSpec, name, method)
    total = time.perf_counter() - start
    busy = sum(env.get_attr("busy")) - busy_start - reset_busy[0]
    env.close()
    vec_steps = calls["step"]
    env_steps = model.num_timesteps - start_steps
    env_compute = busy / (n_envs if subproc else 1)  # per worker when the workers run in parallel
    per_worker = f" (mean per worker, {n_envs} in parallel)" if subproc else ""
    rows = [
        ("NetworkSpec.flatten_obs", timers[flatten]),
        ("ObsStats.add (observation statistics)", timers["ObsStats.add"]),
        ("NetworkSpec.__call__ (batched forward pass)", timers["__call__"]),
        *[(f"- of which NetworkSpec.{name}", timers[name]) for name in nested],
        ("env.step", timers["step"]),
        (f"- of which gym env step + auto-reset + Monitor{per_worker}", env_compute),
        ("- of which VecEnv overhead (copies, IPC, waiting)", timers["step"] - env_compute),
        ("generation start: env.seed + env.reset", timers["reset"]),
        ("strategy ask + tell", timers["ask/tell"]),
    ]
    top_level = sum(v for k, v in timers.items() if k not in nested)
    rows.append(("rest: evaluator loop bookkeeping, callbacks, logging", total - top_level))
    rows.append(("TOTAL", total))
    print(
        f"\n### Profile: sb3-es ARS, {env_id}, {vec_cls.__name__} n_envs={n_envs}: {vec_steps} vec steps, "
        f"{env_steps} env steps, {env_steps / total:.0f} env steps/s\n"
    )
    print("| part | us per vec step | share |")
    print("|---|---:|---:|")
    for name, seconds_spent in rows:
        print(f"| {name} | {1e6 * seconds_spent / vec_steps:.1f} | {100 * seconds_spent / total:.0f}% |")


# ---------------------------------------------------------------------------------------------- report
def _table(results: list[Result], plain: Result | None, contrib: Result | None) -> list[str]:
    lines = ["| env | runner | configuration | env steps | seconds | steps/s | mean ep len | vs plain | vs contrib |"]
    lines.append("|---|---|---|---:|---:|---:|---:|---:|---:|")
    for r in results:
        ep_len = f"{r.ep_len:.0f}" if r.ep_len is not None else "-"
        vs_plain = f"{r.rate / plain.rate:.2f}x" if plain else "-"
        vs_contrib = f"{r.rate / contrib.rate:.2f}x" if contrib else "-"
        lines.append(
            f"| {r.env_id} | {r.name} | {r.config} | {r.steps} | {r.seconds:.1f} | {r.rate:.0f} | {ep_len} "
            f"| {vs_plain} | {vs_contrib} |"
        )
    return lines


def _sharded_checks(env_id: str, procs: list[Result], ray_rows: list[Result], plain2: Result) -> list[str]:
    """:return: The targets of the 2-worker sharded evaluators: >= 90% of the plain 2-process loop, startup < 2 s."""
    checks = []
    for label, rows in (("processes", procs), ("Ray", ray_rows)):
        if not rows:
            continue
        best = max(rows, key=lambda r: r.rate)
        checks.append(
            _check(f"{env_id} ours ({best.config}) / plain loop (2 proc)", 100 * best.rate / plain2.rate, 90, "%")
        )
        checks.append(_startup_check(env_id, label, rows))
    return checks


def _startup_check(env_id: str, label: str, rows: list[Result]) -> str:
    """:return: The slowest startup of the rows: a check (< 2 s) for worker processes, information for Ray."""
    startup = max(r.startup or 0.0 for r in rows)
    if label == "processes":
        return f"{'PASS' if startup < 2 else 'FAIL'}: {env_id} processes startup: {startup:.2f} s (target < 2 s)"
    return f"INFO: {env_id} {label} startup (ray.init and actors): {startup:.2f} s"


def _check(label: str, value: float, target: float, unit: str = "x") -> str:
    verdict = "PASS" if value >= target else "FAIL"
    return f"{verdict}: {label}: {value:.2f}{unit} (target >= {target:g}{unit})"


#: Envs per worker of the sharded rows (2 workers each), per env.
SHARDED_ENVS_PER_WORKER = {BIPEDAL: (1, 2, 4), PENDULUM: (1, 4, 8)}


def sharded_block(env_id: str, host: str, run: Callable[..., Result]) -> tuple[list[Result], list[Result], list[str]]:
    """
    The rows of ``--only processes`` for one env and host: the plain 2-process loop before and after the 2-worker
    sharded evaluator (one row per ``envs_per_worker``), which is compared with their mean, so that a drift of the
    machine during the block shows in the two plain rows instead of in the ratio.

    :return: The evaluator rows, the plain rows, the checks.
    """
    before = run(measure_plain_loop, env_id, 2)
    # The evaluator's defaults (one worker per CPU, DEFAULT_ENVS_PER_WORKER slots) get their own row, labelled
    # "default"; on a 2-CPU machine it replaces the explicit row of the same layout.
    explicit = [k for k in SHARDED_ENVS_PER_WORKER[env_id] if not (k == DEFAULT_ENVS_PER_WORKER and usable_cpus() == 2)]
    rows = [run(measure_ours_sharded, host, env_id, 2, k) for k in explicit]
    rows.append(run(measure_ours_sharded, host, env_id, None, None))
    after = run(measure_plain_loop, env_id, 2)
    plain_rate = (before.rate + after.rate) / 2
    label = "Ray" if host == "ray" else "processes"
    checks = [
        _check(
            f"{env_id} {label} ({r.config}) / plain loop (2 proc, mean of before and after)",
            100 * r.rate / plain_rate,
            90,
            "%",
        )
        for r in rows
    ]
    checks.append(_startup_check(env_id, label, rows))
    return rows, [before, after], checks


def processes_only(run: Callable[..., Result]) -> tuple[list[str], list[str]]:
    """
    ``--only processes``: the 2-worker sharded evaluators (worker processes, then Ray) against the plain 2-process
    loop on BipedalWalker-v3 and Pendulum-v1, and one worker against the plain 1-process loop (the overhead of the
    engine and the transport, without parallelism).

    :return: The table lines and the checks.
    """
    lines: list[str] = []
    checks: list[str] = []
    hosts = ["processes", "ray"] if HAVE_RAY else ["processes"]
    for env_id in (BIPEDAL, PENDULUM):
        results: list[Result] = []
        plain_rows: list[Result] = []
        # Ray last: its daemons (GCS, raylet) keep running until ray.shutdown() and would slow later rows.
        for host in hosts:
            rows, plain, host_checks = sharded_block(env_id, host, run)
            results += rows
            plain_rows += plain
            checks += host_checks
        k = SHARDED_ENVS_PER_WORKER[env_id][-1]
        one = run(measure_ours_sharded, "processes", env_id, 1, k)
        plain1 = run(measure_plain_loop, env_id, 1)
        checks.append(
            f"INFO: {env_id} processes ({one.config}) / plain loop (1 proc): {100 * one.rate / plain1.rate:.0f}%"
        )
        plain2 = Result(env_id, "plain step loop", "2 proc, mean of the rows above", 0, 1.0)
        plain2.steps = round(np.mean([r.rate for r in plain_rows]))
        if lines:
            lines.append("")
        lines += _table([*results, one, *plain_rows, plain1], plain2, None)
    if not HAVE_RAY:
        checks.append("INFO: Ray rows skipped (pip install ray)")
    return lines, checks


def main(argv: list[str] | None = None) -> None:
    """
    Measure, then print the table and the checks.

    :param argv: Arguments (defaults to ``sys.argv[1:]``).
    """
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--seconds", type=float, default=None, help="timed window of each measurement (default 8)")
    parser.add_argument("--warmup", type=float, default=None, help="warm-up learn() / loop before timing (default 1.5)")
    parser.add_argument(
        "--quick", action="store_true", help="2 s windows, 0.5 s warm-up (smoke test; not with --seconds, --warmup)"
    )
    parser.add_argument(
        "--only",
        choices=["bipedal", "pendulum", "processes"],
        help="one environment only, or the 2-worker sharded evaluators against the plain loop on both",
    )
    parser.add_argument("--profile", action="store_true", help="also profile our engine per vec step")
    parser.add_argument(
        "--torch-threads", type=int, default=0, help="th.set_num_threads() in the main process (0: torch's default)"
    )
    args = parser.parse_args(argv)
    problems = positive_problems({"--seconds": args.seconds})
    if args.warmup is not None and not args.warmup >= 0:
        problems.append(f"--warmup {args.warmup:g}: it must be 0 or more")
    if args.quick and (args.seconds is not None or args.warmup is not None):
        problems.append("--quick sets 2 s windows and 0.5 s warm-ups: give it or --seconds/--warmup, not both")
    if problems:
        parser.error("; ".join(problems) + ".")
    if args.torch_threads > 0:
        th.set_num_threads(args.torch_threads)
    load_start = os.getloadavg()[0]
    seconds = 2.0 if args.quick else 8.0 if args.seconds is None else args.seconds
    warmup = 0.5 if args.quick else 1.5 if args.warmup is None else args.warmup

    def run(fn: Callable[..., Result], *fn_args: Any) -> Result:
        result = fn(*fn_args, seconds, warmup)
        print(f"  {result.env_id} | {result.name} | {result.config}: {result.rate:.0f} steps/s", file=sys.stderr)
        return result

    lines: list[str] = []
    checks: list[str] = []
    if args.only == "processes":
        lines, checks = processes_only(run)
    if args.only in (None, "bipedal"):
        plain = run(measure_plain_loop, BIPEDAL, 2)
        ours_sub2 = run(measure_ours, BIPEDAL, 2, True)
        ours = [ours_sub2, run(measure_ours, BIPEDAL, 4, True)]
        ours += [run(measure_ours, BIPEDAL, n, False) for n in (2, 4, 8)]
        ours_procs = [run(measure_ours_sharded, "processes", BIPEDAL, 2, k) for k in (1, 2, 4)]
        ours += ours_procs
        contrib_async = run(measure_contrib, BIPEDAL, 2)
        contrib_single = run(measure_contrib, BIPEDAL, 0)
        plain1 = run(measure_plain_loop, BIPEDAL, 1)
        # Ray last: its daemons (GCS, raylet) keep running until ray.shutdown() and would slow later rows.
        ours_ray = [run(measure_ours_sharded, "ray", BIPEDAL, 2, k) for k in (2, 4)] if HAVE_RAY else []
        ours += ours_ray
        lines += _table([*ours, contrib_async, contrib_single, plain, plain1], plain, contrib_async)
        best = max(ours, key=lambda r: r.rate)
        # "2 processes": the sharded evaluator with 2 workers (each running the batched engine on its own envs);
        # SubprocVecEnv with 2 envs is reported too (it pays an IPC round trip per step).
        two_proc = max(ours_procs, key=lambda r: r.rate)
        checks += [
            _check(
                f"{BIPEDAL} ours ({two_proc.config}) / sb3-contrib ARS (AsyncEval, 2 proc)",
                two_proc.rate / contrib_async.rate,
                3,
            ),
            _check(
                f"{BIPEDAL} ours ({two_proc.config}) / sb3-contrib ARS (single process, its default)",
                two_proc.rate / contrib_single.rate,
                3,
            ),
            *_sharded_checks(BIPEDAL, ours_procs, ours_ray, plain),
            f"INFO: {BIPEDAL} closest to the plain loop: ours {best.config}: {100 * best.rate / plain.rate:.0f}%; "
            f"ours (SubprocVecEnv n_envs=2) / plain loop (2 proc): {100 * ours_sub2.rate / plain.rate:.0f}%",
        ]
    if args.only in (None, "pendulum"):
        ours16 = run(measure_ours, PENDULUM, 16, False)
        ours = [ours16] + [run(measure_ours, PENDULUM, n, False) for n in (1, 4)]
        ours_procs = [run(measure_ours_sharded, "processes", PENDULUM, 2, k) for k in (4, 8)]
        contrib_single = run(measure_contrib, PENDULUM, 0)
        plain1 = run(measure_plain_loop, PENDULUM, 1)
        plain2 = run(measure_plain_loop, PENDULUM, 2)
        ours_ray = [run(measure_ours_sharded, "ray", PENDULUM, 2, 8)] if HAVE_RAY else []
        if lines:
            lines.append("")
        lines += _table([*ours, *ours_procs, *ours_ray, contrib_single, plain1, plain2], plain1, contrib_single)
        checks.append(
            _check(
                f"{PENDULUM} ours (DummyVecEnv n_envs=16) / sb3-contrib ARS (single process)",
                ours16.rate / contrib_single.rate,
                5,
            )
        )
        checks += _sharded_checks(PENDULUM, ours_procs, ours_ray, plain2)

    command = " ".join(["python", *sys.argv])
    print("\n## Throughput: env steps per second\n")
    print(f"- command: `{command}` ({seconds:g} s timed window, {warmup:g} s warm-up per measurement)")
    print(
        f"- hardware: {hardware()}; torch threads={th.get_num_threads()}, 1-min load average {load_start:.1f} at "
        f"start / {os.getloadavg()[0]:.1f} at end"
    )
    print(f"- versions: {versions('sb3-contrib')}")
    if args.only == "processes":
        print("- 'vs plain': ratio to the mean of the plain 2-process loop rows of the same env (measured before and")
        print("  after each host's rows); the sharded rows have 2 workers, except the '1 workers' row and the")
        print("  'default' row: the evaluator's own defaults (one worker per CPU, DEFAULT_ENVS_PER_WORKER slots)\n")
    else:
        print("- 'vs plain': ratio to the plain loop with the same number of processes (BipedalWalker: 2, Pendulum: 1;")
        print("  the checks compare every 2-worker configuration with the plain 2-process loop);")
        print(
            "  'vs contrib': ratio to sb3-contrib's ARS (BipedalWalker: AsyncEval 2 proc, Pendulum: single process)\n"
        )
    print("\n".join(lines))
    print()
    print("\n".join(checks))

    if args.profile:
        if args.only in (None, "bipedal"):
            profile_ours(BIPEDAL, 2, False, seconds, warmup)
            profile_ours(BIPEDAL, 2, True, seconds, warmup)
        if args.only in (None, "pendulum"):
            profile_ours(PENDULUM, 16, False, seconds, warmup)


if __name__ == "__main__":
    main()
