"""Share of a CMA-ES generation spent in the strategy (pycma ask + tell) versus the rollouts.

Setting of the seed document: BipedalWalker-v3, a 40-40 tanh network (2,804 parameters), population 64,
with full and with diagonal (separable) covariance. Run::

    python benchmarks/cmaes_timing.py --generations 4 --n-envs 2

Prints, per covariance choice, the mean per-generation time of ask + tell, the rollout time, and the
strategy's share of the generation's wall time. The target is a share under 10% for the default choice
(``diagonal="auto"``, which picks separable CMA-ES above 1,000 parameters).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from common import hardware, positive_problems, versions
from stable_baselines3.common.env_util import make_vec_env
from torch import nn

from sb3_es import CMAES


def timed(fn: Callable[..., Any], sink: list[float]) -> Callable[..., Any]:
    """
    Wrap ``fn`` so that each call's duration is appended to ``sink``.

    :param fn: Function to time.
    :param sink: List receiving durations in seconds.
    :return: The wrapped function.
    """

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        out = fn(*args, **kwargs)
        sink.append(time.perf_counter() - start)
        return out

    return wrapper


def measure(diagonal: bool | str, generations: int, n_envs: int, seed: int) -> dict[str, float]:
    """
    Run ``generations`` CMA-ES generations and split their wall time.

    :param diagonal: CMAES ``diagonal`` argument.
    :param generations: Generations to time (after one warm-up generation).
    :param n_envs: Env slots (DummyVecEnv).
    :param seed: Random seed.
    :return: Mean seconds per generation for the strategy and the whole generation, and the share.
    """
    env = make_vec_env("BipedalWalker-v3", n_envs=n_envs, seed=seed)
    model = CMAES(
        "MlpPolicy",
        env,
        population_size=64,
        sigma=0.1,
        diagonal=diagonal,
        seed=seed,
        policy_kwargs=dict(net_arch=[40, 40], activation_fn=nn.Tanh),
    )
    assert model.policy.num_params == 2804, model.policy.num_params
    strategy_times: list[float] = []
    generation_times: list[float] = []
    model.strategy.ask = timed(model.strategy.ask, strategy_times)  # type: ignore[method-assign]
    model.strategy.tell = timed(model.strategy.tell, strategy_times)  # type: ignore[method-assign]
    model._run_generation = timed(model._run_generation, generation_times)  # type: ignore[method-assign]
    model.learn(1)  # one generation: warm-up
    strategy_times.clear()
    generation_times.clear()
    for _ in range(generations):
        model.learn(1, reset_num_timesteps=False)
    strategy = float(np.sum(strategy_times)) / generations
    generation = float(np.mean(generation_times))
    env.close()
    return {
        "diagonal": float(model.strategy.diagonal),
        "strategy_s": strategy,
        "rollout_s": generation - strategy,
        "generation_s": generation,
        "share": strategy / generation,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--generations", type=int, default=4)
    parser.add_argument("--n-envs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    problems = positive_problems({"--generations": args.generations, "--n-envs": args.n_envs})
    if problems:
        parser.error("; ".join(problems) + ".")
    print("# CMA-ES strategy vs rollout time, BipedalWalker-v3, 2,804 parameters, population 64")
    print(f"hardware: {hardware()}; n_envs={args.n_envs}; versions: {versions()}")
    print("| covariance | ask+tell s/gen | rollout s/gen | strategy share |")
    print("|---|---|---|---|")
    for label, diagonal in (("full", False), ("diagonal (default: auto)", "auto")):
        row = measure(diagonal, args.generations, args.n_envs, args.seed)
        print(f"| {label} | {row['strategy_s']:.3f} | {row['rollout_s']:.2f} | {100 * row['share']:.1f}% |")
        if diagonal == "auto":
            verdict = "PASS" if row["share"] < 0.10 else "FAIL"
            print(f"{verdict}: strategy share with the default covariance {100 * row['share']:.1f}% (target < 10%)")


if __name__ == "__main__":
    main()
