"""ARS on MuJoCo tasks with the ARS paper's settings (its Table 9), against the paper's reward thresholds.

Evaluates the center policy every ``--eval-every`` env steps (5 episodes, deterministic) and reports the
first env-step count (and episode count) at which the evaluation reached the threshold. Run::

    python benchmarks/ars_paper.py --env Swimmer-v5 --steps 300000 --seeds 237,759,959,0 --variants V1,V2
    python benchmarks/ars_paper.py --env HalfCheetah-v5 --steps 5000000 --seeds 0 --variants V2 --eval-every 100000
    python benchmarks/ars_paper.py --env Hopper-v5 --steps 5000000 --seeds 0 --variants V2 --eval-every 100000
    python benchmarks/ars_paper.py --env dm_control/walker-walk-v0 --steps 100000000 --seeds 0 --variants V2 \
        --eval-every 500000 --max-seconds 3600 --n-envs 4 [--policy mlp-ln]

V1 trains without observation normalization, V2 with it (inside the policy). ``--policy linear`` (default) is
the paper's linear policy; ``--policy mlp-ln`` an ``MlpPolicy`` with two hidden layers of 64 units and layer
normalization (as the seed document's best walker-walk policy). ``--max-seconds`` stops a run after that much
wall-clock time.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import gymnasium as gym
import shimmy
from common import PAPER_THRESHOLDS, hardware, positive_problems, step_count, versions
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_es import ARS

#: Paper settings (Table 9, the V1/V2 rows for Swimmer, the V2-t rows for Hopper and HalfCheetah); thresholds:
#: ``common.PAPER_THRESHOLDS``.
PRESETS: dict[str, dict[str, Any]] = {
    "Swimmer-v5": dict(n_delta=1, n_top=1, delta_std=0.01, learning_rate=0.02, alive=0.0),
    "Hopper-v5": dict(n_delta=8, n_top=4, delta_std=0.025, learning_rate=0.01, alive=-1.0),
    "HalfCheetah-v5": dict(n_delta=32, n_top=4, delta_std=0.03, learning_rate=0.02, alive=0.0),
    # Not in the paper: the seed document reports a linear policy near 500 after ~8 hours on a large machine.
    "dm_control/walker-walk-v0": dict(n_delta=32, n_top=16, delta_std=0.03, learning_rate=0.02, alive=0.0),
}


#: ``--variants``: whether the policy normalizes its observations.
VARIANTS = {"V1": False, "V2": True}

#: ``--policy`` choices: policy class and its keyword arguments (observation normalization is set by the variant).
POLICIES: dict[str, tuple[str, dict[str, Any]]] = {
    "linear": ("LinearPolicy", {}),
    "mlp-ln": ("MlpPolicy", dict(net_arch=[64, 64], layer_norm=True)),
}

gym.register_envs(shimmy)  # the dm_control/ ids


def run(
    env_id: str,
    variant: str,
    seed: int,
    steps: int,
    eval_every: int,
    n_envs: int,
    max_seconds: float,
    policy: str = "linear",
) -> dict[str, Any]:
    """
    Train one ARS run and evaluate it periodically.

    :param env_id: A key of :data:`PRESETS`.
    :param variant: A key of :data:`VARIANTS`.
    :param seed: Random seed.
    :param steps: Env-step budget.
    :param eval_every: Env steps between evaluations.
    :param n_envs: Env slots.
    :param max_seconds: Wall-clock limit of the run.
    :param policy: A key of :data:`POLICIES`.
    :return: Summary of the run.
    """
    preset = PRESETS[env_id]
    env = make_vec_env(env_id, n_envs=n_envs, seed=seed)
    eval_env = make_vec_env(env_id, n_envs=1, seed=123)
    policy_class, policy_kwargs = POLICIES[policy]
    model = ARS(
        policy_class,
        env,
        n_delta=preset["n_delta"],
        n_top=preset["n_top"],
        delta_std=preset["delta_std"],
        learning_rate=preset["learning_rate"],
        alive_bonus_offset=preset["alive"],
        seed=seed,
        policy_kwargs=dict(policy_kwargs, normalize_observations=VARIANTS[variant]),
    )
    start = time.perf_counter()
    history: list[tuple[int, int, float]] = []
    episodes = 0
    # one evaluation at least, however short the wall-clock limit
    while not history or (model.num_timesteps < steps and time.perf_counter() - start < max_seconds):
        model.learn(max(min(eval_every, steps - model.num_timesteps), 1), reset_num_timesteps=False)  # not past steps
        episodes = model._n_updates * 2 * preset["n_delta"]  # one episode per candidate
        mean, _ = evaluate_policy(model, eval_env, n_eval_episodes=5)
        history.append((model.num_timesteps, episodes, float(mean)))  # type: ignore[arg-type]
        print(
            f"  {env_id} {variant} seed={seed}: {model.num_timesteps} steps, {episodes} episodes, eval {mean:.0f}",
            file=sys.stderr,
            flush=True,
        )
    first = next(((n, e) for n, e, r in history if r >= PAPER_THRESHOLDS[env_id]), None)
    return {
        "first": first,
        "best": max(r for _, _, r in history),
        "final": history[-1][2],
        "steps": model.num_timesteps,
        "episodes": episodes,
        "seconds": time.perf_counter() - start,
    }


def variant_list(text: str) -> list[str]:
    """
    An ``argparse`` type for ``--variants``: comma-separated keys of :data:`VARIANTS`.

    :param text: The value as typed.
    :return: The variants.
    """
    variants = text.split(",")
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise argparse.ArgumentTypeError(
            f"unknown variant {', '.join(map(repr, unknown))}; give {' or '.join(VARIANTS)}, comma-separated"
        )
    return variants


def seed_list(text: str) -> list[int]:
    """
    An ``argparse`` type for ``--seeds``: comma-separated integers.

    :param text: The value as typed.
    :return: The seeds.
    """
    try:
        return [int(s) for s in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of seeds; give integers such as 0,1,2") from None


def main(argv: list[str] | None = None) -> None:
    """
    Run each variant and seed, printing one table row per run.

    :param argv: Arguments (defaults to ``sys.argv[1:]``).
    """
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", choices=sorted(PRESETS), default="Swimmer-v5")
    parser.add_argument("--steps", type=step_count, default=300_000)
    parser.add_argument("--max-seconds", type=float, default=float("inf"))
    parser.add_argument("--eval-every", type=step_count, default=20_000)
    parser.add_argument("--seeds", type=seed_list, default=[237, 759, 959, 0], help="comma-separated")
    parser.add_argument("--n-envs", type=int, default=2)
    parser.add_argument(
        "--variants", type=variant_list, default=list(VARIANTS), help=f"comma-separated, of {', '.join(VARIANTS)}"
    )
    parser.add_argument("--policy", choices=sorted(POLICIES), default="linear")
    args = parser.parse_args(argv)
    problems = positive_problems(
        {
            "--steps": args.steps,
            "--max-seconds": args.max_seconds,
            "--eval-every": args.eval_every,
            "--n-envs": args.n_envs,
        }
    )
    if problems:
        parser.error("; ".join(problems) + ".")
    print(f"hardware: {hardware()}; versions: {versions()}")
    threshold = PAPER_THRESHOLDS[args.env]
    print(f"command: python {' '.join(sys.argv)}")
    print(f"policy: {args.policy} {POLICIES[args.policy]}")
    print(f"| env | variant | seed | env steps (episodes) to {threshold:g} | best eval | final eval | steps | s |")
    print("|---|---|---|---|---|---|---|---|")
    for variant in args.variants:
        for seed in args.seeds:
            row = run(args.env, variant, seed, args.steps, args.eval_every, args.n_envs, args.max_seconds, args.policy)
            first = "not reached" if row["first"] is None else f"{row['first'][0]} ({row['first'][1]})"
            print(
                f"| {args.env} | {variant} | {seed} | {first} | {row['best']:.0f} | {row['final']:.0f} | "
                f"{row['steps']} | {row['seconds']:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
