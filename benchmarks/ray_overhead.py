"""
Throughput of population evaluation on Ray actors against the local engine, and Ray's per-generation overhead.

Command (about 5 minutes on 2 cores with the defaults)::

    python benchmarks/ray_overhead.py

Options: ``--rounds R`` (default 6), ``--turn S`` (minimum seconds of one configuration's turn, default 1.5),
``--plain-seconds S`` (window of the plain step loops, default 6), ``--only bipedal|pendulum``,
``--envs-per-worker 1,2,4``, ``--quick`` (Pendulum only, 2 rounds).

Every configuration trains ``ARS("MlpPolicy", env_id, n_delta=8, seed=0)`` (16 candidates, one episode each;
timed with ``learn(1, reset_num_timesteps=False)``, one generation per call, callbacks and logging included):

* local: the local engine, ``VecEnvEvaluator`` on a ``DummyVecEnv`` of 2 envs, in this process;
* Ray: ``RayEvaluator(env_id, num_workers=W, envs_per_worker=E)`` on a local ``ray.init(num_cpus=2)``, for
  W = 1, 2 and E = 1, 2, 4.

All configurations are built and warmed up (one generation) first, then timed in interleaved rounds: each
round gives every configuration a turn of ``G`` generations (``G`` chosen so that the local engine's turn lasts
about ``--turn`` seconds), so a change in the machine's load (other users) hits every configuration alike.
The actors of idle configurations sleep (each reserves 0.01 CPU so that all of them can exist at once).

Columns: env steps per second; milliseconds per generation; Ray's per-generation overhead, i.e. the
``evaluate()`` wall time minus the evaluation time of the slowest actor (inside ``VecEnvEvaluator``), which
leaves serialization, transport, scheduling, merging and the callback replay (also shown alone); the
imbalance (slowest share minus the mean share: shares are fixed, so an actor whose share is done waits for the
slowest, running the center policy meanwhile, as idle slots of the local engine do). "Same work": with the
same seed, the local engine and Ray with 1 worker x 2 envs run bit-identical generations (checked), so the
difference of their times, taken generation by generation, is everything Ray adds. The plain step loop
(``env.step(action_space.sample())`` in 1 and 2 processes, no policy), measured before and after, is the
machine's ceiling.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch as th
from common import hardware, measure_plain, versions
from stable_baselines3.common.env_util import make_vec_env

from sb3_es import ARS
from sb3_es.evaluation import VecEnvEvaluator

BIPEDAL = "BipedalWalker-v3"
PENDULUM = "Pendulum-v1"
N_DELTA = 8
IDLE_CPU = 0.01


@dataclass
class Row:
    """One configuration and its measurements."""

    env_id: str
    engine: str
    layout: str
    model: Any = None
    evaluator: Any = None
    steps: int = 0
    seconds: float = 0.0
    gen_times: list[float] = field(default_factory=list)
    overheads: list[float] = field(default_factory=list)
    imbalances: list[float] = field(default_factory=list)
    replays: list[float] = field(default_factory=list)

    @property
    def generations(self) -> int:
        return len(self.gen_times)

    @property
    def rate(self) -> float:
        return self.steps / self.seconds if self.seconds else float("nan")

    @property
    def ms_per_gen(self) -> float:
        return 1000 * self.seconds / self.generations if self.generations else float("nan")

    def run(self, generations: int) -> None:
        """Run and time ``generations`` generations."""
        for _ in range(generations):
            steps = self.model.num_timesteps
            start = time.perf_counter()
            self.model.learn(1, reset_num_timesteps=False)
            elapsed = time.perf_counter() - start
            self.seconds += elapsed
            self.steps += self.model.num_timesteps - steps
            self.gen_times.append(elapsed)
            if self.evaluator is not None:
                timings = self.evaluator.last_timings
                slowest = max(timings["eval_times"])
                self.overheads.append(timings["wall"] - slowest)
                shares = np.subtract(timings["eval_times"], timings["linger_times"])
                self.imbalances.append(float(shares.max() - shares.mean()))
                self.replays.append(timings["replay"])


def local_row(env_id: str) -> Row:
    # The engine gets its own VecEnv, reset only by the engine (as an actor's): Box2D envs keep their physics
    # world across resets, so an extra reset (learn() resets the model's env) would change later episodes.
    evaluator = VecEnvEvaluator(make_vec_env(env_id, n_envs=2))
    model = ARS("MlpPolicy", env_id, n_delta=N_DELTA, seed=0, evaluator=evaluator)
    return Row(env_id, "local", "DummyVecEnv n_envs=2, 1 process", model)


def ray_row(env_id: str, workers: int, envs_per_worker: int) -> Row:
    from sb3_es.evaluation.ray import RayEvaluator

    evaluator = RayEvaluator(env_id, num_workers=workers, envs_per_worker=envs_per_worker, num_cpus_per_worker=IDLE_CPU)
    evaluator.start()
    model = ARS("MlpPolicy", env_id, n_delta=N_DELTA, seed=0, evaluator=evaluator)
    plural = "s" if workers > 1 else ""
    return Row(
        env_id,
        "Ray",
        f"{workers} worker{plural} x {envs_per_worker} env{'s' if envs_per_worker > 1 else ''}",
        model,
        evaluator,
    )


def fmt(value: float, digits: int = 0) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:,.{digits}f}"


def benchmark_env(env_id: str, per_worker: list[int], rounds: int, turn: float) -> tuple[list[Row], int]:
    rows = [local_row(env_id)] + [ray_row(env_id, w, e) for w in (1, 2) for e in per_worker]
    try:
        warmup = []
        for row in rows:
            start = time.perf_counter()
            row.model.learn(1)  # untimed: first generation (caches, actors' first task)
            warmup.append(time.perf_counter() - start)
        per_turn = max(1, math.ceil(turn / warmup[0]))
        for r in range(rounds):
            for row in rows:
                row.run(per_turn)
            print(f"{env_id}: round {r + 1}/{rounds} done ({per_turn} generations per turn)", flush=True)
    finally:
        for row in rows:
            if row.evaluator is not None:
                row.evaluator.close()
    return rows, per_turn


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--turn", type=float, default=1.5)
    parser.add_argument("--plain-seconds", type=float, default=6.0)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--only", choices=["bipedal", "pendulum"])
    parser.add_argument("--envs-per-worker", default="1,2,4")
    args = parser.parse_args()
    env_ids = [BIPEDAL, PENDULUM]
    if args.only or args.quick:
        env_ids = [PENDULUM if args.quick or args.only == "pendulum" else BIPEDAL]
    rounds = 2 if args.quick else args.rounds
    plain_seconds = 2.0 if args.quick else args.plain_seconds
    per_worker = [int(x) for x in args.envs_per_worker.split(",")]
    th.set_num_threads(1)
    load = [os.getloadavg()[0]]

    # Plain loops before Ray starts its processes (and again at the end, to see how the load changed).
    plain: dict[tuple[str, int], list[float]] = {}
    for env_id in env_ids:
        for n in (1, 2):
            plain[(env_id, n)] = [measure_plain(env_id, n, plain_seconds).rate]

    import ray

    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    results: dict[str, tuple[list[Row], int]] = {}
    try:
        for env_id in env_ids:
            results[env_id] = benchmark_env(env_id, per_worker, rounds, args.turn)
    finally:
        ray.shutdown()
    for env_id in env_ids:
        for n in (1, 2):
            plain[(env_id, n)].append(measure_plain(env_id, n, plain_seconds).rate)
    load.append(os.getloadavg()[0])

    print()
    print(f"Command: `python {' '.join(sys.argv)}`")
    print(
        f"Hardware: {hardware()}; 1-minute load average {load[0]:.1f} before, {load[1]:.1f} after. "
        f"Versions: {versions('ray')}."
    )
    print(f"ARS MlpPolicy [64, 64], n_delta=8 (16 candidates x 1 episode per generation); {rounds} interleaved rounds.")
    for env_id, (rows, per_turn) in results.items():
        ceiling = float(np.mean(plain[(env_id, 2)]))
        print()
        print(f"**{env_id}** ({rows[0].generations} timed generations per configuration, {per_turn} per turn)")
        print()
        print(
            "| engine | layout | env steps/s | % of plain 2-process loop | ms / generation | Ray overhead ms / gen "
            "(% of gen) | of which callback replay ms | imbalance ms / gen |"
        )
        print("|---|---|---:|---:|---:|---:|---:|---:|")
        for n in (1, 2):
            before, after = plain[(env_id, n)]
            print(
                f"| plain step loop | {n} process{'es' if n > 1 else ''} (before / after) | {fmt(before)} / "
                f"{fmt(after)} | {fmt(100 * np.mean([before, after]) / ceiling)} | - | - | - | - |"
            )
        for row in rows:
            overhead = 1000 * float(np.mean(row.overheads)) if row.overheads else float("nan")
            share = f" ({100 * overhead / row.ms_per_gen:.1f} %)" if row.overheads else ""
            replay = 1000 * float(np.mean(row.replays)) if row.replays else float("nan")
            imbalance = 1000 * float(np.mean(row.imbalances)) if row.imbalances else float("nan")
            print(
                f"| {row.engine} | {row.layout} | {fmt(row.rate)} | {fmt(100 * row.rate / ceiling)} | "
                f"{fmt(row.ms_per_gen)} | {fmt(overhead, 1)}{share} | {fmt(replay, 1)} | {fmt(imbalance, 1)} |"
            )
        twins = [r for r in rows if r.layout == "1 worker x 2 envs"]
        if not twins:  # --envs-per-worker without 2: no Ray layout runs the local row's work
            print("\n(The same-work comparison needs 2 in --envs-per-worker.)")
            continue
        local, twin = rows[0], twins[0]
        same = np.array_equal(local.model.strategy.center, twin.model.strategy.center) and local.steps == twin.steps
        diffs = 1000 * (np.array(twin.gen_times) - np.array(local.gen_times))
        verdict = "bit-identical generations" if same else "NOT identical: check the seeds"
        print()
        print(
            f"Same work, local DummyVecEnv n_envs=2 vs Ray 1 worker x 2 envs ({verdict}):"
            f" {fmt(local.ms_per_gen, 1)} vs {fmt(twin.ms_per_gen, 1)} ms per generation of "
            f"{fmt(local.steps / local.generations)} env steps; Ray adds {fmt(float(np.median(diffs)), 1)} ms per "
            f"generation (median of the per-generation differences; mean {fmt(float(np.mean(diffs)), 1)}), of which "
            f"{fmt(1000 * float(np.mean(twin.overheads)), 1)} ms outside the actor's engine by its timings."
        )


if __name__ == "__main__":
    main()
