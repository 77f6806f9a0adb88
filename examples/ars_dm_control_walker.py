"""ARS on the DeepMind Control Suite's walker-walk, through shimmy (Dict observations are flattened).

Run::

    python examples/ars_dm_control_walker.py --policy LinearPolicy --timesteps 1000000
    python examples/ars_dm_control_walker.py --policy MlpPolicy --layer-norm --timesteps 1000000

As in the seed document: a linear policy, or an MLP with layer normalization, both with observation
normalization inside the policy (ARS-V2).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import shimmy  # noqa: F401  (registers the dm_control/ environments)
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from torch import nn

from sb3_es import ARS

ENV_ID = "dm_control/walker-walk-v0"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--policy", choices=["LinearPolicy", "MlpPolicy"], default="LinearPolicy")
    parser.add_argument("--layer-norm", action="store_true", help="LayerNorm after each hidden layer (MlpPolicy)")
    parser.add_argument("--timesteps", type=int, default=1_000_000)
    parser.add_argument("--n-envs", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tensorboard-log", default="runs")
    parser.add_argument("--save-path", default=None, help="default: runs/ars_walker_walk_<policy>.zip")
    args = parser.parse_args()

    gym.make(ENV_ID).close()  # fail early with gymnasium's message if dm_control is missing
    env = make_vec_env(ENV_ID, n_envs=args.n_envs, seed=args.seed)
    policy_kwargs: dict = {}
    if args.policy == "MlpPolicy":
        policy_kwargs = dict(net_arch=[64, 64], activation_fn=nn.Tanh, layer_norm=args.layer_norm)
    model = ARS(
        args.policy,
        env,
        n_delta=32,
        n_top=16,
        learning_rate=0.02,
        delta_std=0.03,
        policy_kwargs=policy_kwargs,
        tensorboard_log=args.tensorboard_log,
        seed=args.seed,
        verbose=1,
    )
    model.learn(args.timesteps, progress_bar=True)
    path = args.save_path or f"runs/ars_walker_walk_{args.policy}.zip"
    model.save(path)
    mean, std = evaluate_policy(model, make_vec_env(ENV_ID, seed=args.seed + 1), n_eval_episodes=5)
    print(f"mean return over 5 episodes: {mean:.1f} +/- {std:.1f}")
    print(f"model saved to {path}; TensorBoard logs in {model.logger.get_dir()}")


if __name__ == "__main__":
    main()
