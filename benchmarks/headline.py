"""
The README's headline, measured as a new user would: ``ARS("MlpPolicy", "BipedalWalker-v3", seed=s).learn(1e6)``
with every default, then ``evaluate_policy`` (deterministic, 10 episodes) on a fresh env.

Examples::

    python benchmarks/headline.py --seeds 0 1 2                       # the defaults, three seeds
    python benchmarks/headline.py --seeds 0 --set n_delta=16 reward_clip=[-1,1]   # a variation

Prints one line per seed and the median; writes ``<out>/headline.json``.
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
import yaml
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.utils import get_system_info

import sb3_es


def run(algo: str, policy: str, env_id: str, seed: int, steps: int, episodes: int, kwargs: dict[str, Any]) -> dict:
    """
    Train one model and evaluate it.

    :return: Seed, steps, wall-clock and the evaluation's mean and std.
    """
    start = time.perf_counter()
    model = getattr(sb3_es, algo)(policy, env_id, seed=seed, **kwargs).learn(steps)
    train_s = time.perf_counter() - start
    eval_env = make_vec_env(env_id, n_envs=1, seed=10_000 + seed)
    mean, std = evaluate_policy(model, eval_env, n_eval_episodes=episodes, deterministic=True)
    return {"seed": seed, "env_steps": model.num_timesteps, "train_s": round(train_s, 1), "mean": mean, "std": std}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algo", default="ARS")
    parser.add_argument("--policy", default="MlpPolicy")
    parser.add_argument("--env", default="BipedalWalker-v3")
    parser.add_argument("--steps", type=float, default=1e6)
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--set", nargs="*", default=[], help="KEY=VALUE constructor arguments (values read as YAML)")
    parser.add_argument("--out", default="results/headline")
    args = parser.parse_args()
    torch.set_num_threads(1)
    kwargs = {key: yaml.safe_load(value) for key, value in (item.split("=", 1) for item in args.set)}
    rows = []
    for seed in args.seeds:
        row = run(args.algo, args.policy, args.env, seed, int(args.steps), args.episodes, kwargs)
        rows.append(row)
        print(f"seed {seed}: {row['mean']:.1f} +- {row['std']:.1f} after {row['env_steps']:,} steps, {row['train_s']}s")
    median = float(np.median([row["mean"] for row in rows]))
    print(f"median over {len(rows)} seeds: {median:.1f}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    info = {
        "system": get_system_info(print_info=False)[0],
        "date": time.strftime("%Y-%m-%d %H:%M %Z"),
        "commit": commit,
    }
    record = {"args": vars(args), "kwargs": kwargs, "runs": rows, "median": median, **info}
    (out / "headline.json").write_text(json.dumps(record, indent=2, default=str))


if __name__ == "__main__":
    main()
