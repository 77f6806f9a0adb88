"""
The README's headline, measured as a new user would: ``ARS("MlpPolicy", "BipedalWalker-v3", seed=s).learn(1e6)``
with every default, then ``evaluate_policy`` (deterministic, 10 episodes) on a fresh env.

Examples::

    python benchmarks/headline.py --seeds 0 1 2                       # the defaults, three seeds
    python benchmarks/headline.py --seeds 0 --steps 1e6 3e6 --set reward_clip=[-1,1]   # a variation

Prints one line per seed and budget, and the median at each budget; writes ``<out>/headline.json``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from common import read_value, step_count, system_info
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

import sb3_es


def run(
    algo: str, policy: str, env_id: str, seed: int, budgets: list[int], episodes: int, kwargs: dict[str, Any]
) -> list[dict]:
    """
    Train one model, evaluating it each time ``num_timesteps`` reaches the next budget.

    ``learn(b1)`` then ``learn(b2 - num_timesteps, reset_num_timesteps=False)`` is the run ``learn(b2)`` would
    make (constant hyperparameters), with an evaluation between.

    :return: One row per budget: seed, steps, training wall-clock and the evaluation's mean and std.
    """
    model = getattr(sb3_es, algo)(policy, env_id, seed=seed, **kwargs)
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algo", default="ARS")
    parser.add_argument("--policy", default="MlpPolicy")
    parser.add_argument("--env", default="BipedalWalker-v3")
    parser.add_argument("--steps", nargs="+", type=step_count, default=[1_000_000], help="budgets at which to evaluate")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument(
        "--set", nargs="+", action="extend", default=[], help="KEY=VALUE constructor arguments, as YAML (repeatable)"
    )
    parser.add_argument("--out", default="results/headline")
    args = parser.parse_args()
    torch.set_num_threads(1)
    kwargs = {key: read_value(value) for key, value in (item.split("=", 1) for item in args.set)}
    budgets = sorted(args.steps)
    rows = [
        row
        for seed in args.seeds
        for row in run(args.algo, args.policy, args.env, seed, budgets, args.episodes, kwargs)
    ]
    median = {}
    for budget in budgets:
        at = [row["mean"] for row in rows if row["budget"] == budget]
        median[budget] = float(np.median(at))
        print(f"{budget:,} steps: median over {len(at)} seeds {median[budget]:.1f}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    info = {"system": system_info(), "date": time.strftime("%Y-%m-%d %H:%M %Z"), "commit": commit}
    record: dict[str, Any] = {"args": vars(args), "kwargs": kwargs, "runs": rows, "median": median, **info}
    (out / "headline.json").write_text(json.dumps(record, indent=2, default=str))


if __name__ == "__main__":
    main()
