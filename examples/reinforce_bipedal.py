"""REINFORCE on BipedalWalker-v3 with 3 torque levels per joint (a joint categorical over 3**4 = 81 actions).

Run::

    python examples/reinforce_bipedal.py --timesteps 2000000 --n-envs 4

Each of the 4 joint torques is discretized into the levels ``-1, 0, 1`` and the policy is one categorical
over the 81 combinations, as in the classic "learning to walk with policy gradients" notebook; pass
``--factorized`` for an independent categorical per joint instead. The env slots collect the episodes of
an update in parallel. TensorBoard logs go under ``--tensorboard-log`` (``tensorboard --logdir runs``).
Vanilla REINFORCE learns slowly on this task: expect the walker to stop falling well before it walks.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch as th
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_es.reinforce import REINFORCE


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=int, default=2_000_000, help="env steps to train for")
    parser.add_argument("--n-envs", type=int, default=4, help="env slots collecting episodes in parallel")
    parser.add_argument("--n-episodes", type=int, default=16, help="episodes per update")
    parser.add_argument("--n-bins", type=int, default=3, help="torque levels per joint")
    parser.add_argument("--factorized", action="store_true", help="one categorical per joint instead of 81 actions")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tensorboard-log", default="runs")
    parser.add_argument("--save-path", default="runs/reinforce_bipedal_walker.zip")
    args = parser.parse_args()

    th.set_num_threads(1)  # small MLPs: one thread is fastest
    env = make_vec_env("BipedalWalker-v3", n_envs=args.n_envs, seed=args.seed)
    model = REINFORCE(
        "MlpPolicy",
        env,
        learning_rate=3e-3,
        n_episodes=args.n_episodes,
        gamma=0.99,
        normalize_returns=True,
        use_baseline=True,
        max_grad_norm=1.0,
        policy_kwargs=dict(n_bins=args.n_bins, joint=not args.factorized, net_arch=[64, 64]),
        tensorboard_log=args.tensorboard_log,
        seed=args.seed,
        verbose=1,
    )
    print(f"{model.policy.n_actions} discrete actions ({'factorized' if args.factorized else 'joint'} categorical)")
    model.learn(args.timesteps, progress_bar=True)
    Path(args.save_path).parent.mkdir(parents=True, exist_ok=True)
    model.save(args.save_path)
    eval_env = make_vec_env("BipedalWalker-v3", seed=args.seed + 1)
    for deterministic in (False, True):
        mean, std = evaluate_policy(model, eval_env, n_eval_episodes=10, deterministic=deterministic)
        print(f"mean return over 10 episodes (deterministic={deterministic}): {mean:.1f} +/- {std:.1f}")
    print(f"model saved to {args.save_path}; TensorBoard logs in {model.logger.get_dir()}")


if __name__ == "__main__":
    main()
