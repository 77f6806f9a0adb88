"""REINFORCE with discretized actions improves clearly on a continuous-control task.

Command (the numbers in ``docs/modules/reinforce.md``)::

    python benchmarks/reinforce_continuous.py --env LunarLanderContinuous-v3 --timesteps 100000 --seeds 0 1 2

For each seed: REINFORCE with 3 levels per action dimension (a joint categorical over ``3 ** 2 = 9``
actions on LunarLanderContinuous: main engine off/off/full, side engines left/off/right), a value
baseline, ``n_envs`` env slots collecting the episodes of an update in parallel. The policy is evaluated
on ``--eval-episodes`` episodes of a separate env before training (random initialization, close to
uniform over the levels) and after ``--timesteps`` env steps, both with sampled actions (the stochastic
policy that REINFORCE optimizes) and with the mode of the distribution. Seeds run in parallel processes
(``--workers``), each with one torch thread. Prints one line per seed, the means over seeds and the
wall-clock time.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from common import env_id_problems, positive_problems, selection_problems, step_count


def run_seed(config: dict[str, Any]) -> dict[str, Any]:
    """
    Train and evaluate one seed.

    :param config: The command line arguments as a dict, plus ``seed``.
    :return: Returns before/after training and the training time.
    """
    import torch as th
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.evaluation import evaluate_policy

    from sb3_es.reinforce import REINFORCE

    th.set_num_threads(1)
    seed = config["seed"]
    env = make_vec_env(config["env"], n_envs=config["n_envs"], seed=seed)
    model = REINFORCE(
        "MlpPolicy",
        env,
        learning_rate=config["learning_rate"],
        n_episodes=config["n_episodes"],
        gamma=config["gamma"],
        use_baseline=not config["no_baseline"],
        policy_kwargs=dict(n_bins=config["n_bins"], joint=not config["factorized"], net_arch=[64, 64]),
        seed=seed,
        device="cpu",
    )
    eval_env = make_vec_env(config["env"], n_envs=1, seed=10_000 + seed)

    def evaluate(deterministic: bool) -> float:
        mean, _ = evaluate_policy(model, eval_env, n_eval_episodes=config["eval_episodes"], deterministic=deterministic)
        return float(np.mean(mean))

    before = {"stochastic": evaluate(False), "deterministic": evaluate(True)}
    start = time.perf_counter()
    model.learn(config["timesteps"])
    train_s = time.perf_counter() - start
    after = {"stochastic": evaluate(False), "deterministic": evaluate(True)}
    return dict(
        seed=seed,
        before=before,
        after=after,
        train_s=train_s,
        num_timesteps=model.num_timesteps,
        n_actions=model.policy.n_actions,
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="LunarLanderContinuous-v3", help="Box action space env id")
    parser.add_argument("--timesteps", type=step_count, default=100_000, help="env steps per seed")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--n-envs", type=int, default=8, help="env slots per seed")
    parser.add_argument("--n-episodes", type=int, default=8, help="episodes per update")
    parser.add_argument("--n-bins", type=int, default=3, help="levels per action dimension")
    parser.add_argument("--factorized", action="store_true", help="one categorical per dimension (default: joint)")
    parser.add_argument("--learning-rate", type=float, default=1e-2)
    parser.add_argument("--gamma", type=float, default=0.99)
    parser.add_argument("--no-baseline", action="store_true", help="plain REINFORCE, without the value baseline")
    parser.add_argument("--eval-episodes", type=int, default=10)
    parser.add_argument("--workers", type=int, default=2, help="seeds trained in parallel processes")
    args = parser.parse_args(argv)
    flags = ("--timesteps", "--n-envs", "--n-episodes", "--n-bins", "--learning-rate", "--eval-episodes", "--workers")
    problems = positive_problems({flag: getattr(args, flag[2:].replace("-", "_")) for flag in flags})
    problems += selection_problems(args.seeds, [args.env], {})
    problems += env_id_problems("--env", [args.env])
    if problems:
        parser.error("; ".join(problems) + ".")

    configs = [dict(vars(args), seed=seed) for seed in args.seeds]
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(run_seed, configs))
    wall_s = time.perf_counter() - start

    form = "factorized" if args.factorized else "joint"
    print(
        f"REINFORCE on {args.env}: {args.n_bins} levels per dimension ({form}, {results[0]['n_actions']} logits), "
        f"baseline={not args.no_baseline}, lr={args.learning_rate}, {args.n_envs} env slots, "
        f"{args.n_episodes} episodes per update, {args.timesteps} env steps per seed"
    )
    print(f"mean return over {args.eval_episodes} evaluation episodes (stochastic policy / mode of the policy):")
    for r in results:
        print(
            f"  seed {r['seed']}: before {r['before']['stochastic']:8.1f} / {r['before']['deterministic']:8.1f}   "
            f"after {r['after']['stochastic']:8.1f} / {r['after']['deterministic']:8.1f}   "
            f"({r['num_timesteps']} steps, {r['train_s']:.0f} s)"
        )
    for mode in ("stochastic", "deterministic"):
        before = np.array([r["before"][mode] for r in results])
        after = np.array([r["after"][mode] for r in results])
        print(
            f"  mean over {len(results)} seeds ({mode}): before {before.mean():.1f} +/- {before.std():.1f}, "
            f"after {after.mean():.1f} +/- {after.std():.1f}"
        )
    print(f"wall-clock: {wall_s:.0f} s ({args.workers} worker processes)")


if __name__ == "__main__":
    main()
