"""Command line: ``sb3-es quickstart`` (the README's first command) and ``sb3-es train``."""

from __future__ import annotations

import argparse
import json
import os
import time
from typing import Any

from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

from sb3_es import ARS, CMAES, PGPE, REINFORCE, OpenES, SimpleES

#: Algorithms reachable from the command line, by lower-case name.
ALGOS: dict[str, type[BaseAlgorithm]] = {
    "ars": ARS,
    "openes": OpenES,
    "cmaes": CMAES,
    "pgpe": PGPE,
    "simple_es": SimpleES,
    "reinforce": REINFORCE,
}

#: The quickstart run: ARS-V2 with a linear policy on Swimmer-v5 (MuJoCo ships with the ``mujoco`` wheel),
#: with the ARS paper's Swimmer settings; seed 959 is one of the paper's seeds.
QUICKSTART: dict[str, Any] = dict(
    algo="ars",
    env="Swimmer-v5",
    policy="LinearPolicy",
    timesteps=300_000,
    seed=959,
    n_envs=2,
    hyperparams=dict(n_delta=1, n_top=1, delta_std=0.01, learning_rate=0.02),
)


def train(
    algo: str,
    env_id: str,
    policy: str,
    timesteps: int,
    n_envs: int,
    hyperparams: dict[str, Any],
    log_dir: str,
    seed: int | None,
    subproc: bool = False,
    n_eval_episodes: int = 10,
    log_interval: int = 10,
) -> tuple[BaseAlgorithm, str, str, float, float]:
    """
    Train ``algo`` on ``env_id``, evaluate before and after, save the model.

    :param algo: Algorithm name (key of :data:`ALGOS`).
    :param env_id: Gymnasium env id.
    :param policy: Policy alias.
    :param timesteps: Env steps to train for.
    :param n_envs: Number of env slots.
    :param hyperparams: Keyword arguments for the algorithm.
    :param log_dir: Directory for TensorBoard logs and the saved model.
    :param seed: Random seed.
    :param subproc: Use ``SubprocVecEnv`` (one process per env) instead of ``DummyVecEnv``.
    :param n_eval_episodes: Evaluation episodes before and after training.
    :param log_interval: Generations between two log dumps (stdout and TensorBoard).
    :return: The model, the TensorBoard run directory, the model path, and the mean return before and after.
    """
    if algo not in ALGOS:
        raise ValueError(f"Unknown algorithm {algo!r}; choose one of {sorted(ALGOS)}.")
    vec_env_cls = SubprocVecEnv if subproc else DummyVecEnv
    env = make_vec_env(env_id, n_envs=n_envs, seed=seed, vec_env_cls=vec_env_cls)
    eval_env = make_vec_env(env_id, n_envs=1, seed=None if seed is None else seed + 10_000)
    model = ALGOS[algo](policy, env, tensorboard_log=log_dir, seed=seed, verbose=1, **hyperparams)
    before, _ = evaluate_policy(model, eval_env, n_eval_episodes=n_eval_episodes)
    start = time.perf_counter()
    model.learn(timesteps, log_interval=log_interval)
    elapsed = time.perf_counter() - start
    after, _ = evaluate_policy(model, eval_env, n_eval_episodes=n_eval_episodes)
    run_dir = model.logger.get_dir() or log_dir
    model_path = os.path.join(log_dir, f"{algo}_{env_id.replace('/', '-')}.zip")
    model.save(model_path)
    env.close()
    eval_env.close()
    print(
        f"\nTrained {type(model).__name__} on {env_id} for {model.num_timesteps} env steps in {elapsed:.0f} s\n"
        f"  mean return over {n_eval_episodes} episodes: {before:.1f} before -> {after:.1f} after\n"
        f"  TensorBoard logs: {os.path.abspath(run_dir)}   (view: tensorboard --logdir {log_dir})\n"
        f"  Saved model:      {os.path.abspath(model_path)}   (load: {type(model).__name__}.load(path))"
    )
    return model, run_dir, model_path, before, after  # type: ignore[return-value]


def main(argv: list[str] | None = None) -> None:
    """
    Entry point of the ``sb3-es`` command.

    :param argv: Arguments (defaults to ``sys.argv[1:]``).
    """
    parser = argparse.ArgumentParser(prog="sb3-es", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    quick = sub.add_parser("quickstart", help="short real ARS run on Swimmer-v5: TensorBoard logs + saved model")
    quick.add_argument("--timesteps", type=int, default=QUICKSTART["timesteps"])
    quick.add_argument("--log-dir", default="runs")
    quick.add_argument("--seed", type=int, default=QUICKSTART["seed"])
    run = sub.add_parser("train", help="train one algorithm on one env id")
    run.add_argument("--algo", required=True)
    run.add_argument("--env", required=True)
    run.add_argument("--policy", default="MlpPolicy")
    run.add_argument("--timesteps", type=int, default=100_000)
    run.add_argument("--n-envs", type=int, default=1)
    run.add_argument("--subproc", action="store_true", help="one process per env (SubprocVecEnv)")
    run.add_argument("--hyperparams", default="{}", help="JSON dict, e.g. '{\"n_delta\": 8}'")
    run.add_argument("--log-dir", default="runs")
    run.add_argument("--seed", type=int, default=None)
    args = parser.parse_args(argv)
    if args.command == "quickstart":
        train(
            QUICKSTART["algo"],
            QUICKSTART["env"],
            QUICKSTART["policy"],
            args.timesteps,
            QUICKSTART["n_envs"],
            QUICKSTART["hyperparams"],
            args.log_dir,
            args.seed,
        )
    else:
        train(
            args.algo.lower(),
            args.env,
            args.policy,
            args.timesteps,
            args.n_envs,
            json.loads(args.hyperparams),
            args.log_dir,
            args.seed,
            subproc=args.subproc,
        )


if __name__ == "__main__":
    main()
