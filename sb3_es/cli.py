"""
The ``sb3-es`` command: ``sb3-es quickstart`` (the README's first command, no extra needed) and, for everything
else, rl-zoo's scripts with the sb3-es algorithms: ``sb3-es train|enjoy|record_video|... [rl-zoo arguments]``
is ``python -m sb3_es.zoo ...`` (``[zoo]`` extra).
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import sys
import time
from collections.abc import Sequence
from typing import Any

from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_es import ARS
from sb3_es.common.checks import check_seed

#: The quickstart run: ARS-V2 with a linear policy on Swimmer-v5 (MuJoCo ships with the ``mujoco`` wheel),
#: with the ARS paper's Swimmer settings; seed 959 is one of the paper's seeds.
QUICKSTART: dict[str, Any] = dict(
    env="Swimmer-v5",
    policy="LinearPolicy",
    timesteps=300_000,
    seed=959,
    n_envs=2,
    hyperparams=dict(n_delta=1, n_top=1, delta_std=0.01, learning_rate=0.02),
)

#: Flags of the former ``sb3-es train`` and their rl-zoo equivalents (shown when one is used).
FORMER_FLAGS: dict[str, str] = {
    "--timesteps": "-n N",
    "--log-dir": "-f FOLDER (models and logs) and -tb FOLDER (TensorBoard)",
    "--n-envs": "-params n_envs:N",
    "--subproc": "--vec-env subproc",
    "--policy": "-params policy:\"'NAME'\" (rl-zoo evaluates each value: a name is quoted twice)",
}


def shell_command(name: str) -> str:
    """
    :param name: A console script installed with this Python (``sb3-es``, ``tensorboard``).
    :return: How to run it from this shell: its name when ``PATH`` finds it, else its path beside this Python (the
        venv's ``bin/``, as after ``make train``), quoted for a POSIX shell.
    """
    beside = os.path.join(os.path.dirname(sys.executable), name)
    if shutil.which(name) or not os.path.exists(beside):
        return name
    return shlex.quote(os.path.relpath(beside))


def quickstart(timesteps: int, log_folder: str, seed: int | None) -> tuple[ARS, str, str, float, float]:
    """
    Train :data:`QUICKSTART`, evaluate before and after, save the model, print where the logs and model are.

    :param timesteps: Env steps to train for.
    :param log_folder: Folder of the TensorBoard run and the saved model.
    :param seed: Random seed.
    :return: The model, the TensorBoard run directory, the model path, and the mean return before and after.
    """
    env_id, n_eval_episodes = QUICKSTART["env"], 10
    env = make_vec_env(env_id, n_envs=QUICKSTART["n_envs"], seed=seed)
    # One env per evaluation episode: the episodes run side by side, one batched prediction per step.
    eval_env = make_vec_env(env_id, n_envs=n_eval_episodes, seed=None if seed is None else seed + 10_000)
    model = ARS(
        QUICKSTART["policy"], env, tensorboard_log=log_folder, seed=seed, verbose=1, **QUICKSTART["hyperparams"]
    )
    before, _ = evaluate_policy(model, eval_env, n_eval_episodes=n_eval_episodes)
    start = time.perf_counter()
    model.learn(timesteps, log_interval=10)
    if model.logger.name_to_value:  # generations since the last dump (a run shorter than 10 generations has some)
        model.dump_logs()
    elapsed = time.perf_counter() - start
    after, _ = evaluate_policy(model, eval_env, n_eval_episodes=n_eval_episodes)
    run_dir = model.logger.get_dir() or log_folder
    model_path = os.path.join(log_folder, f"ars_es_{env_id}.zip")
    model.save(model_path)
    env.close()
    eval_env.close()
    folder = shlex.quote(log_folder)
    print(
        f"\nTrained ARS on {env_id} for {model.num_timesteps} env steps in {elapsed:.0f} s\n"
        f"  mean return over {n_eval_episodes} episodes: {before:.1f} before -> {after:.1f} after\n"
        f"  TensorBoard logs: {os.path.abspath(run_dir)}   (view: {shell_command('tensorboard')} --logdir {folder})\n"
        f"  Saved model:      {os.path.abspath(model_path)}   (load: ARS.load(path))\n"
        f"  Next: {shell_command('sb3-es')} train --algo ars_es --env {env_id} -tb {folder}   (rl-zoo's flags, "
        "sb3-es's configs)"
    )
    return model, run_dir, model_path, before, after  # type: ignore[return-value]


def check_former_flags(args: Sequence[str]) -> None:
    """
    Refuse the flags of the former ``sb3-es train`` with their rl-zoo equivalents.

    :param args: Arguments after the command.
    """
    hints = [
        f"{flag} -> {FORMER_FLAGS[flag]}"
        for flag in dict.fromkeys(a.split("=", 1)[0] for a in args)
        if flag in FORMER_FLAGS
    ]
    for i, arg in enumerate(args):  # rl-zoo's --hyperparams takes key:value pairs, not JSON
        value = arg.split("=", 1)[1] if arg.startswith("--hyperparams=") else None
        if arg == "--hyperparams" and i + 1 < len(args):
            value = args[i + 1]
        if value is not None and value.lstrip().startswith("{"):
            hints.append("--hyperparams '{\"key\": value}' -> -params key:value [key:value ...]")
    if hints:
        raise SystemExit(
            "sb3-es now takes rl-zoo's flags (python -m rl_zoo3.train --help lists them): " + "; ".join(hints) + "."
        )


def main(argv: Sequence[str] | None = None) -> None:
    """
    Entry point of the ``sb3-es`` command.

    :param argv: Arguments (defaults to ``sys.argv[1:]``).
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] == ["quickstart"]:
        parser = argparse.ArgumentParser(
            prog="sb3-es quickstart", description="Short real ARS run on Swimmer-v5: TensorBoard logs + saved model."
        )
        parser.add_argument("-n", "--n-timesteps", "--timesteps", type=int, default=QUICKSTART["timesteps"])
        parser.add_argument("-f", "--log-folder", "--log-dir", default="runs", help="TensorBoard run and model")
        parser.add_argument("--seed", type=int, default=QUICKSTART["seed"])
        options = parser.parse_args(args[1:])
        if options.n_timesteps < 1:
            parser.error(f"-n {options.n_timesteps}: give a positive number of env steps.")
        try:
            check_seed(options.seed)  # the algorithms' own check, as a usage error before any env is built
        except ValueError:
            parser.error(f"--seed {options.seed}: give an integer in [0, 2**32 - 1].")
        quickstart(options.n_timesteps, options.log_folder, options.seed)
        return
    if args[:1] == ["train"]:  # the former command's flags (enjoy and the others take --n-envs, as in rl-zoo)
        check_former_flags(args[1:])
    if not args or args[0] in ("-h", "--help"):  # with no command, all of the usage goes to stderr (exit status 2)
        print(
            "usage: sb3-es quickstart [-n N] [-f FOLDER] [--seed S]\n       sb3-es COMMAND [rl-zoo arguments]\n",
            file=sys.stderr if not args else sys.stdout,
        )
    try:
        from sb3_es.zoo.commands import SCRIPTS
        from sb3_es.zoo.commands import main as zoo_main
    except ImportError as e:
        raise SystemExit(f"sb3-es {args[0] if args else '--help'}: {e}\n(sb3-es quickstart works without it.)") from e
    if args and not args[0].startswith("-") and args[0] not in SCRIPTS:
        raise SystemExit(f"Unknown command {args[0]!r}: use quickstart or one of {', '.join(SCRIPTS)}.")
    zoo_main(args)


if __name__ == "__main__":
    main()
