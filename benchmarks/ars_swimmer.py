"""ARS on Swimmer-v5 with the ARS paper's settings (n_delta=1, n_top=1, delta_std=0.01, learning_rate=0.02).

Compares ARS-V1 (no observation normalization) and ARS-V2 (normalization inside the policy) over seeds,
evaluating the center policy every ``--eval-every`` env steps (5 episodes, deterministic). Run::

    python benchmarks/ars_swimmer.py --steps 300000 --seeds 237,759,959,0

Prints, per variant and seed, the first env-step count at which the evaluation reached the paper's
threshold (325), the best and the final evaluation, and the wall-clock time.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_es import ARS

THRESHOLD = 325.0


def run(variant: str, seed: int, steps: int, eval_every: int, n_envs: int) -> dict[str, object]:
    """
    Train one ARS run and evaluate it periodically.

    :param variant: ``"V1"`` or ``"V2"``.
    :param seed: Random seed.
    :param steps: Env-step budget.
    :param eval_every: Env steps between evaluations.
    :param n_envs: Env slots.
    :return: Summary of the run.
    """
    env = make_vec_env("Swimmer-v5", n_envs=n_envs, seed=seed)
    eval_env = make_vec_env("Swimmer-v5", n_envs=1, seed=123)
    model = ARS(
        "LinearPolicy",
        env,
        n_delta=1,
        n_top=1,
        delta_std=0.01,
        learning_rate=0.02,
        seed=seed,
        policy_kwargs=dict(normalize_observations=variant == "V2"),
    )
    start = time.perf_counter()
    history: list[tuple[int, float]] = []
    while model.num_timesteps < steps:
        model.learn(eval_every, reset_num_timesteps=False)
        mean, _ = evaluate_policy(model, eval_env, n_eval_episodes=5)
        history.append((model.num_timesteps, float(mean)))  # type: ignore[arg-type]
    first = next((n for n, r in history if r >= THRESHOLD), None)
    return {
        "first": first,
        "best": max(r for _, r in history),
        "final": history[-1][1],
        "seconds": time.perf_counter() - start,
        "episodes_to_threshold": None if first is None else first // 1000,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=300_000)
    parser.add_argument("--eval-every", type=int, default=20_000)
    parser.add_argument("--seeds", default="237,759,959,0")
    parser.add_argument("--n-envs", type=int, default=2)
    parser.add_argument("--variants", default="V1,V2")
    args = parser.parse_args()
    print(f"hardware: {os.cpu_count()} CPUs, {platform.processor() or platform.machine()}")
    print("| variant | seed | env steps to 325 (episodes) | best eval | final eval | wall-clock s |")
    print("|---|---|---|---|---|---|")
    for variant in args.variants.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            row = run(variant, seed, args.steps, args.eval_every, args.n_envs)
            first = "not reached" if row["first"] is None else f"{row['first']} ({row['episodes_to_threshold']})"
            print(
                f"| {variant} | {seed} | {first} | {row['best']:.0f} | {row['final']:.0f} | {row['seconds']:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
