"""CMA-ES on BipedalWalker-v3 with a 40-40 tanh network (2,804 parameters), checkpoints and resume.

Run::

    python examples/cmaes_bipedal_walker.py --timesteps 5000000 --n-envs 2

Continue a run from a checkpoint (or from the final save) for 1M more steps::

    python examples/cmaes_bipedal_walker.py --timesteps 1000000 \\
        --resume runs/cmaes_checkpoints/cmaes_bipedal_walker_1000000_steps.zip

(a checkpoint's name gives the env steps at which it was saved, a multiple of ``--n-envs`` at or past each
``--checkpoint-freq``: list the folder). The policy is the network of the estool-style sketch this project grew
from: 24 observations, two hidden layers of 40 tanh units,
4 tanh-squashed actions, i.e. 24*40+40 + 40*40+40 + 40*4+4 = 2,804 parameters. With ``--diagonal auto``
(the default) a policy this size uses separable CMA-ES (diagonal covariance, ``CMAES.DIAGONAL_THRESHOLD``);
``--diagonal false`` forces the full 2,804 x 2,804 covariance matrix (much slower per generation). What
solves BipedalWalker-v3 here is the ``cmaes.yml`` entry instead: a linear policy with each step's reward clipped to
[-1, 1] in the fitness (307.1 over 100 episodes, docs/benchmarks.md).

Checkpoints: SB3's ``CheckpointCallback`` saves the model, with the CMA-ES state, every
``--checkpoint-freq`` env steps. A checkpoint usually falls inside a generation; resuming from it
restarts that generation (the parameters are those of the last completed update).
"""

from __future__ import annotations

import argparse
import os

from stable_baselines3.common.callbacks import CheckpointCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv
from torch import nn

from sb3_es import CMAES

DIAGONAL = {"auto": "auto", "true": True, "false": False}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=int, default=5_000_000, help="env steps to train (more, when resuming)")
    parser.add_argument("--n-envs", type=int, default=2, help="env slots; each evaluates a different candidate")
    parser.add_argument("--subproc", action="store_true", help="one process per env (SubprocVecEnv)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--population-size", type=int, default=64)
    parser.add_argument("--sigma", type=float, default=0.1, help="initial step size")
    parser.add_argument("--diagonal", choices=sorted(DIAGONAL), default="auto", help="covariance: auto/true/false")
    parser.add_argument("--tensorboard-log", default="runs")
    parser.add_argument("--save-path", default="runs/cmaes_bipedal_walker.zip")
    parser.add_argument("--checkpoint-dir", default="runs/cmaes_checkpoints")
    parser.add_argument("--checkpoint-freq", type=int, default=500_000, help="env steps between checkpoints")
    parser.add_argument("--resume", metavar="PATH", help="load this save or checkpoint and continue training it")
    parser.add_argument("--eval-episodes", type=int, default=10)
    args = parser.parse_args()

    vec_env_cls = SubprocVecEnv if args.subproc else DummyVecEnv
    env = make_vec_env("BipedalWalker-v3", n_envs=args.n_envs, seed=args.seed, vec_env_cls=vec_env_cls)
    if args.resume:
        # Hyperparameters, the CMA-ES state (mean, step size, covariance, random state) and the
        # observation statistics come from the file; the command-line hyperparameters are ignored.
        model = CMAES.load(args.resume, env=env, tensorboard_log=args.tensorboard_log)
        print(f"resuming {args.resume} at {model.num_timesteps} steps")
    else:
        model = CMAES(
            "MlpPolicy",
            env,
            sigma=args.sigma,
            population_size=args.population_size,
            diagonal=DIAGONAL[args.diagonal],
            policy_kwargs=dict(net_arch=[40, 40], activation_fn=nn.Tanh),
            tensorboard_log=args.tensorboard_log,
            seed=args.seed,
            verbose=1,
        )
    covariance = "diagonal" if model.strategy.diagonal else "full"
    print(f"{model.policy.num_params} parameters, population {model.strategy.population_size}, {covariance} covariance")

    # save_freq counts vec steps (callback calls), each of which is n_envs env steps.
    checkpoint = CheckpointCallback(
        save_freq=max(args.checkpoint_freq // args.n_envs, 1),
        save_path=args.checkpoint_dir,
        name_prefix="cmaes_bipedal_walker",
        verbose=1,
    )
    model.learn(args.timesteps, callback=checkpoint, reset_num_timesteps=not args.resume, progress_bar=True)

    os.makedirs(os.path.dirname(args.save_path) or ".", exist_ok=True)
    model.save(args.save_path)
    print(f"model saved to {args.save_path} (resume with --resume {args.save_path})")
    print(f"checkpoints in {args.checkpoint_dir}; TensorBoard logs in {model.logger.get_dir()}")
    if model.strategy.stopped:
        print(f"pycma's stop conditions ended training: {model.strategy.last_stop}")

    eval_env = make_vec_env("BipedalWalker-v3", n_envs=1, seed=args.seed + 1000)
    mean, std = evaluate_policy(model, eval_env, n_eval_episodes=args.eval_episodes)
    print(f"mean return over {args.eval_episodes} episodes: {mean:.1f} +/- {std:.1f}")
    env.close()
    eval_env.close()


if __name__ == "__main__":
    main()
