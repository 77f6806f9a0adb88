"""Learning checks with fixed seeds and stated budgets (each runs in well under a minute on 2 cores)."""

from __future__ import annotations

from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_es import ARS


def test_ars_v2_linear_reaches_swimmer_threshold() -> None:
    """ARS paper settings on Swimmer-v5 (seed 959, one of the paper's seeds): the center policy reaches 325.

    Budget: 200k env steps (200 episodes of 1000 steps), evaluated every 20k steps on 5 episodes.
    benchmarks/ars_paper.py runs the same check over more seeds and compares ARS-V1.
    """
    env = make_vec_env("Swimmer-v5", n_envs=2, seed=959)
    eval_env = make_vec_env("Swimmer-v5", n_envs=1, seed=123)
    model = ARS("LinearPolicy", env, n_delta=1, n_top=1, delta_std=0.01, learning_rate=0.02, seed=959)
    evaluations = []
    while model.num_timesteps < 200_000:
        model.learn(20_000, reset_num_timesteps=False)
        mean, _ = evaluate_policy(model, eval_env, n_eval_episodes=5)
        evaluations.append(mean)
    assert max(evaluations) >= 325, evaluations
