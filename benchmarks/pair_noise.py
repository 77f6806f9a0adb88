"""
How much of a mirrored pair's return difference comes from the starting states: the case for ``common_seeds``.

Around the center of a saved model, ``--pairs`` mirrored candidates ``center +/- sigma * eps`` (``sigma``: a PGPE
model's standard deviations, or ``--sigma``) each run ``--episodes`` episodes with the evaluator's reset
seeds: both members of a pair from the same starting states (common random numbers, as ``common_seeds=True``
does), then from different ones (every episode its own seed). For each pair, the variance over episodes of the
difference ``R(center + d) - R(center - d)`` is what the strategy's update sees as noise. Example (the shipped
walker-walk model)::

    python benchmarks/pair_noise.py benchmarks/trained/pgpe_walker_walk_mlp_ln.zip dm_control/walker-walk-v0

Prints the two variances, their ratio and the correlation of the pair's returns; writes nothing.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym
import numpy as np
import shimmy
from common import algorithm_classes, load_model, positive_problems, system_info
from stable_baselines3.common.env_util import make_vec_env

from sb3_es.common.population_algorithm import PopulationAlgorithm
from sb3_es.evaluation import VecEnvEvaluator

gym.register_envs(shimmy)  # the dm_control/ ids

#: ``--algo`` choices: sb3-es's population algorithms by class name (REINFORCE has no population).
ALGORITHMS: dict[str, type[PopulationAlgorithm]] = algorithm_classes(PopulationAlgorithm)


def main(argv: list[str] | None = None) -> None:
    """
    Print the variances of a pair's return difference from common and from separate starting states.

    :param argv: Arguments (defaults to ``sys.argv[1:]``).
    """
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", help="a saved model (zip) of a population algorithm")
    parser.add_argument("--algo", choices=sorted(ALGORITHMS), default="PGPE", help="its class in sb3_es (default PGPE)")
    parser.add_argument("env", help="env id")
    parser.add_argument("--pairs", type=int, default=16, help="mirrored pairs (default 16)")
    parser.add_argument("--episodes", type=int, default=10, help="episodes per candidate (default 10)")
    parser.add_argument("--sigma", type=float, default=None, help="perturbation scale (default: a PGPE model's stdevs)")
    parser.add_argument("--n-envs", type=int, default=8, help="env slots (default 8)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    problems = [
        f"{flag} {value}: it must be at least 1"
        for flag, value in (("--pairs", args.pairs), ("--n-envs", args.n_envs))
        if value < 1
    ]
    problems += positive_problems({"--sigma": args.sigma})
    if args.episodes < 2:
        problems.append(f"--episodes {args.episodes}: it must be at least 2 (the variance over episodes needs two)")
    if args.sigma is None and args.algo != "PGPE":
        problems.append(
            f"--sigma is needed for a {args.algo} model (only PGPE keeps a standard deviation per parameter)"
        )
    if problems:
        parser.error("; ".join(problems) + ".")

    model: Any = load_model(parser, ALGORITHMS[args.algo], args.model)
    strategy: Any = model.strategy  # a PGPE model's keeps the standard deviations
    center = np.asarray(strategy.center)
    sigma = np.asarray(strategy.stdev) if args.sigma is None else args.sigma
    rng = np.random.default_rng(args.seed)
    directions = sigma * rng.standard_normal((args.pairs, center.size))
    population = np.concatenate([center + directions, center - directions])
    evaluator = VecEnvEvaluator(make_vec_env(args.env, n_envs=args.n_envs, seed=args.seed))
    common = np.tile(1000 + np.arange(args.episodes), (2 * args.pairs, 1))  # pair members: the same states
    separate = 1000 + np.arange(2 * args.pairs * args.episodes).reshape(2 * args.pairs, args.episodes)
    print(f"{args.model}: {model.num_timesteps:,} steps, {center.size} parameters, mean sigma {np.mean(sigma):.4g}")
    variances = {}
    for name, seeds in (("common", common), ("separate", separate)):
        start = time.perf_counter()
        returns = evaluator.evaluate(model.policy, population, center, args.episodes, args.seed, reset_seeds=seeds)
        plus, minus = returns.returns[: args.pairs], returns.returns[args.pairs :]
        variances[name] = float((plus - minus).var(axis=1, ddof=1).mean())
        correlation = np.mean([np.corrcoef(p, m)[0, 1] for p, m in zip(plus, minus)])
        print(
            f"{name:>8} starting states: return {returns.returns.mean():.1f} (std over episodes "
            f"{returns.returns.std(axis=1).mean():.1f}), var of the pair difference {variances[name]:.0f}, "
            f"correlation of the pair's returns {correlation:.2f} ({time.perf_counter() - start:.0f} s)"
        )
    print(f"ratio separate / common: {variances['separate'] / variances['common']:.2f}")
    print(system_info())


if __name__ == "__main__":
    main()
