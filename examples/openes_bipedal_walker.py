"""OpenES on BipedalWalker-v3 with a 40-40 tanh network (2,804 parameters), with TensorBoard logs and a saved model.

Run::

    python examples/openes_bipedal_walker.py --timesteps 5000000 --n-envs 2

The settings follow estool's OpenES: mirrored (antithetic) sampling, centered-rank fitness shaping,
Adam on the mean, L2 weight decay, and a noise level decaying geometrically to a floor. Each env slot
evaluates a different candidate; ``--subproc`` puts each env in its own process. The best candidate
seen is kept in ``model.best_params`` and evaluated at the end next to the mean.
"""

from __future__ import annotations

import argparse
import os

from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv
from torch import nn

from sb3_es import OpenES


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=int, default=5_000_000)
    parser.add_argument("--n-envs", type=int, default=2, help="env slots; each evaluates a different candidate")
    parser.add_argument("--subproc", action="store_true", help="one process per env (SubprocVecEnv)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--population-size", type=int, default=64, help="even (mirrored sampling)")
    parser.add_argument("--sigma", type=float, default=0.1)
    parser.add_argument("--learning-rate", type=float, default=0.01)
    parser.add_argument("--tensorboard-log", default="runs")
    parser.add_argument("--save-path", default="runs/openes_bipedal_walker.zip")
    parser.add_argument("--eval-episodes", type=int, default=10)
    args = parser.parse_args()

    vec_env_cls = SubprocVecEnv if args.subproc else DummyVecEnv
    env = make_vec_env("BipedalWalker-v3", n_envs=args.n_envs, seed=args.seed, vec_env_cls=vec_env_cls)
    model = OpenES(
        "MlpPolicy",
        env,
        population_size=args.population_size,
        sigma=args.sigma,
        sigma_decay=0.999,
        sigma_limit=0.02,
        learning_rate=args.learning_rate,
        weight_decay=0.01,
        policy_kwargs=dict(net_arch=[40, 40], activation_fn=nn.Tanh),
        tensorboard_log=args.tensorboard_log,
        seed=args.seed,
        verbose=1,
    )
    print(f"{model.policy.num_params} parameters, population {model.population_size}")
    model.learn(args.timesteps, progress_bar=True)

    os.makedirs(os.path.dirname(args.save_path) or ".", exist_ok=True)
    model.save(args.save_path)
    print(f"model saved to {args.save_path}; TensorBoard logs in {model.logger.get_dir()}")

    eval_env = make_vec_env("BipedalWalker-v3", n_envs=1, seed=args.seed + 1000)
    mean, std = evaluate_policy(model, eval_env, n_eval_episodes=args.eval_episodes)
    print(f"mean policy: mean return over {args.eval_episodes} episodes: {mean:.1f} +/- {std:.1f}")
    best_fitness = model.strategy.best_fitness
    model.policy.load_from_vector(model.best_params)  # the best candidate seen during training
    mean, std = evaluate_policy(model, eval_env, n_eval_episodes=args.eval_episodes)
    print(f"best candidate (training fitness {best_fitness:.1f}): {mean:.1f} +/- {std:.1f}")
    env.close()
    eval_env.close()


if __name__ == "__main__":
    main()
