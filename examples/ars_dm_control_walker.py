"""ARS on the DeepMind Control Suite's walker-walk, through shimmy (Dict observations are flattened).

Run::

    python examples/ars_dm_control_walker.py --policy LinearPolicy --timesteps 1000000
    python examples/ars_dm_control_walker.py --policy MlpPolicy --layer-norm --timesteps 1000000

A linear policy, or an MLP with layer normalization (the two policies of the ARS walker-walk sketch this
project grew from), both with observation normalization inside the policy (ARS-V2). The linear settings are the
``ars_es.yml`` walker-walk entry's; 1M steps is a short trial (about 650,000 steps scored 32.6 and 43.9): the
entry reached 500 at 14.0M and 19.2M env steps (50 and 42 minutes of one core, docs/benchmarks.md). ARS did not
get the MLP far (best 251.4 in 22.9M steps); PGPE's ``pgpe.yml`` entry is the one that walks with it.
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
    parser.add_argument("--n-envs", type=int, default=2)
    parser.add_argument("--max-episode-steps", type=int, default=1000, help="dm_control's own episode length")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tensorboard-log", default="runs")
    parser.add_argument("--save-path", default=None, help="default: runs/ars_walker_walk_<policy>.zip")
    args = parser.parse_args()

    gym.make(ENV_ID).close()  # fail early with gymnasium's message if dm_control is missing
    env = make_vec_env(ENV_ID, n_envs=args.n_envs, seed=args.seed)
    eval_env = make_vec_env(ENV_ID, seed=args.seed + 1)
    policy_kwargs: dict = {}
    if args.policy == "MlpPolicy":
        policy_kwargs = dict(net_arch=[64, 64], activation_fn=nn.Tanh, layer_norm=args.layer_norm)
    try:
        model = ARS(
            args.policy,
            env,
            n_delta=32,
            n_top=16,
            learning_rate=0.02,
            delta_std=0.03,
            max_episode_steps=args.max_episode_steps,  # dm_control ends episodes itself: said, not warned about
            policy_kwargs=policy_kwargs,
            tensorboard_log=args.tensorboard_log,
            seed=args.seed,
            verbose=1,
        )
        model.learn(args.timesteps, progress_bar=True)
        path = args.save_path or f"runs/ars_walker_walk_{args.policy}.zip"
        model.save(path)
        mean, std = evaluate_policy(model, eval_env, n_eval_episodes=5)
        print(f"mean return over 5 episodes: {mean:.1f} +/- {std:.1f}")
        print(f"model saved to {path}; TensorBoard logs in {model.logger.get_dir()}")
    finally:
        env.close()
        eval_env.close()


if __name__ == "__main__":
    main()
