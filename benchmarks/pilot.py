"""
A quick pilot of one sb3-es configuration through the Python API (no rl-zoo): train on a wall-clock budget,
evaluate the deterministic policy every ``--every`` env steps on 10 episodes, stop at the first mean at or above
``--threshold`` and save that model. Used to try hyperparameters before a config goes into a YAML file.

Example (the CMA-ES BipedalWalker-v3 pilot of ``docs/benchmarks.md``, one core)::

    taskset -c 0 python benchmarks/pilot.py CMAES '{"population_size": 32, "sigma": 0.05, "reward_clip": [-1, 1]}' \\
        --seconds 480 --every 250000 --out results/pilot/cma

Training env: ``make_vec_env(env, n_envs, seed=seed)``; evaluation env: one env seeded ``1000 + seed``. The budget
is checked at evaluations, so a run ends at the first evaluation past it. Prints one line per evaluation; writes
``<out>_hit.zip`` at the threshold and ``<out>_end.zip`` when training stops. Then check a saved model over 100
episodes with ``--check <zip>``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from common import env_id_problems, positive_problems, step_count
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import VecEnv

import sb3_es


class EvalUntil(BaseCallback):
    """Evaluate every ``every`` steps; stop at ``threshold`` (saving the model) or after ``seconds`` of training."""

    def __init__(self, eval_env: VecEnv, every: int, seconds: float, threshold: float, out: str) -> None:
        super().__init__()
        self.eval_env, self.every, self.seconds, self.threshold, self.out = eval_env, every, seconds, threshold, out
        self.train_seconds = 0.0
        self.next_eval = every
        self.best = -np.inf
        self.started = time.perf_counter()

    def _on_step(self) -> bool:
        if self.num_timesteps < self.next_eval:
            return True
        self.train_seconds += time.perf_counter() - self.started
        self.next_eval += self.every
        mean, std = evaluate_policy(self.model, self.eval_env, n_eval_episodes=10, deterministic=True)
        assert isinstance(mean, float)
        self.best = max(self.best, float(mean))
        print(
            f"{self.num_timesteps:>10d} steps {self.train_seconds:7.0f}s eval {mean:7.1f} +- {std:5.1f} "
            f"best {self.best:.1f}",
            flush=True,
        )
        if mean >= self.threshold:
            self.model.save(f"{self.out}_hit.zip")
            return False
        self.started = time.perf_counter()
        return self.train_seconds <= self.seconds


def check(algo: str, path: str, env_id: str, episodes: int) -> None:
    """Evaluate a saved model over ``episodes`` deterministic episodes on ``make_vec_env(env_id, seed=2026)``."""
    model = getattr(sb3_es, algo).load(path, device="cpu")
    env = make_vec_env(env_id, n_envs=1, seed=2026)
    rewards, _ = evaluate_policy(model, env, n_eval_episodes=episodes, deterministic=True, return_episode_rewards=True)
    returns = np.asarray(rewards)
    print(f"{path}: {returns.mean():.1f} +- {returns.std():.1f} (min {returns.min():.1f}, n={len(returns)})")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("algo", help="sb3-es class name: ARS, OpenES, CMAES, PGPE, SimpleES")
    parser.add_argument("kwargs", nargs="?", default="{}", help="constructor arguments as JSON")
    parser.add_argument("--env", default="BipedalWalker-v3")
    parser.add_argument("--policy", default="LinearPolicy")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-envs", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=480, help="training wall-clock budget")
    parser.add_argument("--every", type=step_count, default=250_000, help="env steps between evaluations")
    parser.add_argument("--threshold", type=float, default=300)
    parser.add_argument("--out", default="results/pilot/run", help="prefix of the saved models")
    parser.add_argument("--check", metavar="ZIP", help="only evaluate this saved model over --check-episodes")
    parser.add_argument("--check-episodes", type=int, default=100)
    args = parser.parse_args(argv)
    counts = {"--n-envs": args.n_envs, "--seconds": args.seconds, "--every": args.every}
    problems = positive_problems({**counts, "--check-episodes": args.check_episodes})
    if not hasattr(sb3_es, args.algo):
        problems.append(f"{args.algo}: not an sb3-es class; give ARS, OpenES, CMAES, PGPE or SimpleES")
    try:
        kwargs = json.loads(args.kwargs)  # a JSON list for reward_clip is fine: the algorithm validates it
    except json.JSONDecodeError as e:
        problems.append(f"{args.kwargs!r}: not JSON ({e}); give the arguments as '{{\"n_delta\": 16}}'")
    problems += env_id_problems("--env", [args.env])
    if problems:
        parser.error("; ".join(problems) + ".")
    if args.check:
        check(args.algo, args.check, args.env, args.check_episodes)
        return
    env = make_vec_env(args.env, n_envs=args.n_envs, seed=args.seed)
    eval_env = make_vec_env(args.env, n_envs=1, seed=1000 + args.seed)
    model = getattr(sb3_es, args.algo)(args.policy, env, seed=args.seed, **kwargs)
    model.learn(10**10, callback=EvalUntil(eval_env, args.every, args.seconds, args.threshold, args.out))
    model.save(f"{args.out}_end.zip")


if __name__ == "__main__":
    main()
