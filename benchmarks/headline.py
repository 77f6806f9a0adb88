"""
The README's headline, measured as a new user would: ``ARS("MlpPolicy", "BipedalWalker-v3", seed=s).learn(1e6)``
with every default, then ``evaluate_policy`` (deterministic, 10 episodes) on a fresh env.

Examples::

    python benchmarks/headline.py --seeds 0 1 2                       # the defaults, three seeds
    python benchmarks/headline.py --seeds 0 --steps 1e6 3e6 --set reward_clip=[-1,1]   # a variation
    python benchmarks/headline.py --algo PPO --seeds 0 1 2            # the same line with SB3's PPO

Prints one line per seed and budget, and the median at each budget; writes ``<out>/headline.json`` after every seed.
"""

from __future__ import annotations

import argparse
import inspect
import json
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from common import algorithm_classes, read_value, selection_problems, source_commit, step_count, system_info
from sb3_contrib import ARS as ContribARS
from stable_baselines3 import PPO
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

#: ``--algo`` choices: sb3-es's algorithm classes by name, and for comparison SB3's PPO and sb3-contrib's ARS.
ALGORITHMS: dict[str, type[BaseAlgorithm]] = {**algorithm_classes(BaseAlgorithm), "PPO": PPO, "contrib.ARS": ContribARS}
#: Constructor arguments that ``--set`` may not give: the script's own flags set them.
OWN_FLAGS = {"policy": "--policy", "env": "--env", "seed": "--seeds"}


def key_value(text: str) -> tuple[str, Any]:
    """
    An ``argparse`` type for ``--set``: ``KEY=VALUE``, the value read as YAML (:func:`common.read_value`).

    :param text: The item as typed.
    :return: The key and the value.
    """
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"{text!r} is not KEY=VALUE; give one such as n_delta=16")
    try:
        return key, read_value(value)
    except ValueError as e:  # read_value's one-line reason
        raise argparse.ArgumentTypeError(f"{text!r}: {value!r} is not a YAML value ({e})") from e


def set_problems(algo: str, items: list[tuple[str, Any]]) -> list[str]:
    """
    :param algo: A key of :data:`ALGORITHMS`.
    :param items: ``--set`` items.
    :return: What the constructor would refuse with a TypeError, or the script would silently drop: keys it does not
        take, keys the script's own flags set, repeated keys.
    """
    keys = [key for key, _ in items]
    taken = set(inspect.signature(ALGORITHMS[algo].__init__).parameters) - {"self", "_init_setup_model"}
    problems = [f"--set {key}: give it with {OWN_FLAGS[key]}" for key in keys if key in OWN_FLAGS]
    unknown = [key for key in keys if key not in taken]
    if unknown:
        allowed = ", ".join(sorted(taken - set(OWN_FLAGS)))
        problems.append(f"--set {', '.join(unknown)}: not a constructor argument of {algo} (it takes {allowed})")
    repeated = sorted({key for key in keys if keys.count(key) > 1})
    if repeated:
        problems.append(f"--set repeats {repeated}: give each key once")
    return problems


def run(
    algo: str, policy: str, env_id: str, seed: int, budgets: list[int], episodes: int, kwargs: dict[str, Any]
) -> list[dict]:
    """
    Train one model, evaluating it each time ``num_timesteps`` reaches the next budget.

    ``learn(b1)`` then ``learn(b2 - num_timesteps, reset_num_timesteps=False)`` is the run ``learn(b2)`` would
    make (constant hyperparameters), with an evaluation between.

    :return: One row per budget: seed, steps, training wall-clock and the evaluation's mean and std.
    """
    model = ALGORITHMS[algo](policy, env_id, seed=seed, **kwargs)
    rows, train_s = [], 0.0
    for budget in budgets:
        start = time.perf_counter()
        model.learn(max(budget - model.num_timesteps, 1), reset_num_timesteps=model.num_timesteps == 0)
        train_s += time.perf_counter() - start
        eval_env = make_vec_env(env_id, n_envs=1, seed=10_000 + seed)
        mean, std = evaluate_policy(model, eval_env, n_eval_episodes=episodes, deterministic=True)
        rows.append(
            {
                "seed": seed,
                "budget": budget,
                "env_steps": model.num_timesteps,
                "train_s": round(train_s, 1),
                "mean": mean,
                "std": std,
            }
        )
        print(f"seed {seed}: {mean:.1f} +- {std:.1f} after {model.num_timesteps:,} steps, {train_s:.0f}s", flush=True)
    return rows


def main(argv: list[str] | None = None) -> None:
    """
    Train and evaluate each seed, print the medians and write ``headline.json``.

    :param argv: Arguments (defaults to ``sys.argv[1:]``).
    """
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--algo", choices=sorted(ALGORITHMS), default="ARS", help="an sb3-es algorithm class, PPO or contrib.ARS"
    )
    parser.add_argument("--policy", default="MlpPolicy")
    parser.add_argument("--env", default="BipedalWalker-v3")
    parser.add_argument("--steps", nargs="+", type=step_count, default=[1_000_000], help="budgets at which to evaluate")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument(
        "--set",
        nargs="+",
        action="extend",
        type=key_value,
        default=[],
        help="KEY=VALUE constructor arguments, as YAML (repeatable)",
    )
    parser.add_argument("--out", default="results/headline")
    args = parser.parse_args(argv)
    problems = [f"--steps {b}: it must be positive" for b in args.steps if b <= 0]
    if len(set(args.steps)) < len(args.steps):
        problems.append(f"--steps repeats a budget ({' '.join(map(str, args.steps))}): give each once")
    if args.episodes < 1:
        problems.append(f"--episodes {args.episodes}: it must be at least 1")
    problems += selection_problems(args.seeds, [args.env], {}) + set_problems(args.algo, args.set)
    kwargs = dict(args.set)
    if not problems:  # the env and the constructor's own checks (policy, values), before any training
        try:
            ALGORITHMS[args.algo](args.policy, gym.make(args.env), seed=args.seeds[0], **kwargs)
        except (gym.error.Error, ValueError, TypeError, KeyError) as e:
            problems.append(f"{args.algo}({args.policy!r}, {args.env!r}, ...): {str(e).rstrip('.')}")
    if problems:
        parser.error("; ".join(problems) + ".")
    torch.set_num_threads(1)
    budgets = sorted(args.steps)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    # the sb3_es source that ran, wherever the script is run from (None outside a git checkout)
    info = {"system": system_info(), "date": time.strftime("%Y-%m-%d %H:%M %Z"), "commit": source_commit()}
    rows: list[dict] = []
    median: dict[int, float] = {}
    for seed in args.seeds:  # written after every seed: an interrupted run keeps the seeds it finished
        rows += run(args.algo, args.policy, args.env, seed, budgets, args.episodes, kwargs)
        median = {b: float(np.median([r["mean"] for r in rows if r["budget"] == b])) for b in budgets}
        record: dict[str, Any] = {"args": vars(args), "kwargs": kwargs, "runs": rows, "median": median, **info}
        (out / "headline.json").write_text(json.dumps(record, indent=2, default=str))
    for budget in budgets:
        print(f"{budget:,} steps: median over {len(args.seeds)} seeds {median[budget]:.1f}")


if __name__ == "__main__":
    main()
