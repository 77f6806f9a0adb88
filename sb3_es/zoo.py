"""
rl-baselines3-zoo with the sb3-es algorithms: ``python -m sb3_es.zoo train|enjoy [rl-zoo3 flags]``.

rl-baselines3-zoo has no plugin system; its documented route for outside algorithms is a wrapper
script that adds them to ``rl_zoo3.ALGOS`` and passes a hyperparameter file. This module is that
wrapper:

* :func:`register` adds ``ars``, ``openes``, ``cmaes`` (and ``reinforce`` when it imports) to the
  ``ALGOS`` dict that ``rl_zoo3``, ``rl_zoo3.train``, ``rl_zoo3.exp_manager`` and ``rl_zoo3.enjoy``
  share. ``ars`` then means sb3-es's ARS, not sb3-contrib's.
* :class:`ExperimentManager` (installed as ``rl_zoo3.train.ExperimentManager``) changes rl-zoo's
  behaviour for the sb3-es algorithms only: rl-zoo special-cases ``algo == "ars"`` (a single training
  env, and with ``n_envs > 1`` sb3-contrib's ``AsyncEval`` passed to ``learn()``); sb3-es's ARS instead
  gets an ordinary VecEnv of ``n_envs`` slots and evaluates one candidate per slot, without
  ``AsyncEval``. Float ``learning_rate``/``delta_std`` values stay floats (OpenES decays float
  learning rates; rl-zoo would turn them into constant schedules), and ``sigma: lin_0.1`` works for OpenES.
* :func:`main` runs rl-zoo3's own ``train()``/``enjoy()`` with ``sys.argv`` adjusted: for an sb3-es
  algorithm without ``--conf-file``, ``train`` reads ``benchmarks/hyperparams/<algo>.yml`` (or the
  folder named by ``SB3_ES_HYPERPARAMS``); ``enjoy`` looks in ``-f logs`` unless told otherwise. Every
  other algorithm (``ppo``, ``sac``, ...) runs exactly as with rl-zoo3, with rl-zoo3's hyperparameters.

It also registers the ``dm_control/...`` environments of shimmy, so those ids work with ``--env``.
"""

from __future__ import annotations

import os
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

try:
    import rl_zoo3
    import rl_zoo3.enjoy
    import rl_zoo3.exp_manager
    import rl_zoo3.train
    import rl_zoo3.utils
    from rl_zoo3.exp_manager import ExperimentManager as ZooExperimentManager
    from rl_zoo3.utils import SimpleLinearSchedule
except ImportError as e:  # pragma: no cover - exercised only without the extra
    raise ImportError("sb3_es.zoo needs rl-baselines3-zoo: pip install 'sb3-es[zoo]' (or pip install rl_zoo3).") from e
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecEnv

from sb3_es.cli import ALGOS as SB3_ES_ALGOS
from sb3_es.common.population_algorithm import PopulationAlgorithm

#: Environment variable naming a folder of ``<algo>.yml`` files that replaces :data:`HYPERPARAMS_DIR`.
HYPERPARAMS_ENV_VAR = "SB3_ES_HYPERPARAMS"
#: Default hyperparameter folder: ``benchmarks/hyperparams`` of the source tree (editable installs).
HYPERPARAMS_DIR = Path(__file__).resolve().parent.parent / "benchmarks" / "hyperparams"
#: Keys that rl-zoo turns into schedules and that sb3-es keeps as floats when they are numbers.
_FLOAT_KEYS = ("learning_rate", "delta_std")


def sb3_es_algos() -> dict[str, type[BaseAlgorithm]]:
    """
    The sb3-es algorithms by rl-zoo name (``reinforce`` only when it imports).

    :return: A new dict ``name -> class``.
    """
    return dict(SB3_ES_ALGOS)


def hyperparams_dir() -> Path:
    """
    Folder of the sb3-es hyperparameter files: ``$SB3_ES_HYPERPARAMS`` or :data:`HYPERPARAMS_DIR`.

    :return: The folder (not checked).
    """
    return Path(os.environ.get(HYPERPARAMS_ENV_VAR) or HYPERPARAMS_DIR)


def default_conf_file(algo: str) -> Path:
    """
    The hyperparameter file that ``train`` uses for an sb3-es algorithm when no ``--conf-file`` is given.

    :param algo: Algorithm name (``ars``, ``openes``, ``cmaes``, ``reinforce``).
    :return: Path of ``<folder>/<algo>.yml``.
    """
    path = hyperparams_dir() / f"{algo}.yml"
    if not path.is_file():
        raise FileNotFoundError(
            f"No hyperparameter file {path} for {algo!r}. The files ship with the sb3-es source tree "
            f"(benchmarks/hyperparams/); pass --conf-file PATH or set {HYPERPARAMS_ENV_VAR} to their folder."
        )
    return path


def register_envs() -> None:
    """Register shimmy's ``dm_control/...`` environments with gymnasium, when shimmy is installed."""
    import gymnasium as gym

    with warnings.catch_warnings():
        # dm_control imports glfw, which warns about a missing X11 DISPLAY on headless machines
        warnings.simplefilter("ignore")
        try:
            import shimmy
        except ImportError:
            return
    gym.register_envs(shimmy)


def is_sb3_es_algo(algo: str) -> bool:
    """
    Whether rl-zoo's ``ALGOS[algo]`` is an sb3-es class (after :func:`register`).

    :param algo: rl-zoo algorithm name.
    :return: True for sb3-es algorithms.
    """
    cls = rl_zoo3.utils.ALGOS.get(algo)
    return cls is not None and cls.__module__.startswith("sb3_es.")


class ExperimentManager(ZooExperimentManager):
    """
    rl-zoo's ``ExperimentManager``, unchanged for other libraries' algorithms; for sb3-es algorithms:

    * the training VecEnv has the configured ``n_envs`` slots (rl-zoo builds a single env for ``ars``);
    * ``learn()`` gets no ``async_eval`` (rl-zoo builds sb3-contrib's ``AsyncEval`` for ``ars`` with
      ``n_envs > 1``): sb3-es evaluates the candidates on the VecEnv's slots itself;
    * numeric ``learning_rate``/``delta_std`` stay floats, ``sigma: lin_<x>`` gives OpenES a linear schedule;
    * ``--device auto`` means the CPU for the population methods (NumPy forward passes);
    * hyperparameter search (``-optimize``) is refused with a clear error (rl-zoo has no sampler for them).
    """

    def _is_sb3_es(self) -> bool:
        return is_sb3_es_algo(self.algo)

    def setup_experiment(self) -> tuple[BaseAlgorithm, dict[str, Any]] | None:
        if self._is_sb3_es():
            if self.optimize_hyperparameters:
                raise ValueError(
                    f"Hyperparameter optimization (-optimize) is not supported for sb3-es's {self.algo!r} through "
                    "sb3_es.zoo: rl-zoo's samplers and its ARS special case (AsyncEval) are written for sb3-contrib."
                )
            cls = rl_zoo3.utils.ALGOS[self.algo]
            if self.device == "auto" and issubclass(cls, PopulationAlgorithm):
                self.device = "cpu"
        return super().setup_experiment()

    def create_envs(self, n_envs: int, eval_env: bool = False, no_log: bool = False) -> VecEnv:
        # The only call with eval_env=False and no_log=False builds the training env; rl-zoo passes
        # n_envs=1 there for "ars" (its AsyncEval runs the slots). Ours runs the candidates on the slots.
        if self._is_sb3_es() and not eval_env and not no_log:
            n_envs = self.n_envs
        return super().create_envs(n_envs, eval_env=eval_env, no_log=no_log)

    def learn(self, model: BaseAlgorithm) -> None:
        if not self._is_sb3_es():
            super().learn(model)
            return
        # rl-zoo builds sb3-contrib's AsyncEval when algo == "ars" and n_envs > 1; n_envs is read nowhere
        # else in learn(), so hiding it there keeps the rest of rl-zoo's learn() (callbacks, interrupt, close).
        n_envs, self.n_envs = self.n_envs, 1
        try:
            super().learn(model)
        finally:
            self.n_envs = n_envs

    def _preprocess_hyperparams(
        self, hyperparams: dict[str, Any]
    ) -> tuple[dict[str, Any], Callable | None, list, Callable | None]:
        if not self._is_sb3_es():
            return super()._preprocess_hyperparams(hyperparams)
        floats = {
            key: float(hyperparams.pop(key))
            for key in _FLOAT_KEYS
            if isinstance(hyperparams.get(key), (int, float)) and not isinstance(hyperparams.get(key), bool)
        }
        if self.algo == "openes" and isinstance(hyperparams.get("sigma"), str):
            hyperparams["sigma"] = parse_schedule(hyperparams["sigma"])
        processed, env_wrapper, callbacks, vec_env_wrapper = super()._preprocess_hyperparams(hyperparams)
        processed.update(floats)
        return processed, env_wrapper, callbacks, vec_env_wrapper


def parse_schedule(value: str) -> SimpleLinearSchedule:
    """
    Parse rl-zoo's schedule notation ``lin_<initial value>`` (linear decay to zero).

    :param value: The string, e.g. ``"lin_0.02"``.
    :return: The schedule.
    """
    kind, _, initial = value.partition("_")
    if kind != "lin" or not initial:
        raise ValueError(f"Unsupported schedule {value!r}: use lin_<initial value>, e.g. lin_0.02.")
    return SimpleLinearSchedule(float(initial))


def register() -> dict[str, type[BaseAlgorithm]]:
    """
    Add the sb3-es algorithms to rl-zoo (``ars`` replaces sb3-contrib's ARS) and install :class:`ExperimentManager`.

    Idempotent. Also registers shimmy's ``dm_control`` environments.

    :return: The algorithms registered.
    """
    register_envs()
    ours = sb3_es_algos()
    # rl_zoo3, rl_zoo3.train, rl_zoo3.exp_manager and rl_zoo3.enjoy all import the one dict of rl_zoo3.utils;
    # update every module's reference anyway in case a version copies it.
    for module in (rl_zoo3.utils, rl_zoo3, rl_zoo3.train, rl_zoo3.exp_manager, rl_zoo3.enjoy):
        algos = getattr(module, "ALGOS", None)
        if isinstance(algos, dict):
            algos.update(ours)
    rl_zoo3.train.ExperimentManager = ExperimentManager  # type: ignore[misc]
    return ours


def _option_value(args: Sequence[str], name: str, default: str) -> str:
    """
    Value of a long option in an argument list (``--name value`` or ``--name=value``), last one winning.

    :param args: Command-line arguments.
    :param name: Option, e.g. ``"--algo"``.
    :param default: Value when absent.
    :return: The value.
    """
    value = default
    for i, arg in enumerate(args):
        if arg == name and i + 1 < len(args):
            value = args[i + 1]
        elif arg.startswith(name + "="):
            value = arg.split("=", 1)[1]
    return value


def _has_option(args: Sequence[str], short: str, long: str) -> bool:
    """
    Whether an option is present, including argparse's unambiguous abbreviations of the long form.

    :param args: Command-line arguments.
    :param short: Short form (e.g. ``"-conf"``).
    :param long: Long form (e.g. ``"--conf-file"``).
    :return: True if given.
    """
    for arg in args:
        flag = arg.split("=", 1)[0]
        if flag == short or (flag.startswith("--") and len(flag) > 3 and long.startswith(flag)):
            return True
    return False


def prepare_args(command: str, args: Sequence[str]) -> list[str]:
    """
    Add sb3-es defaults to rl-zoo3 arguments: ``--conf-file`` for ``train``, ``-f logs`` for ``enjoy``.

    Only for sb3-es algorithms; arguments for other algorithms are returned unchanged.

    :param command: ``"train"`` or ``"enjoy"``.
    :param args: rl-zoo3 arguments (without the command).
    :return: The arguments to give rl-zoo3.
    """
    args = list(args)
    algo = _option_value(args, "--algo", "ppo")
    if algo not in SB3_ES_ALGOS:
        return args
    if command == "train" and not _has_option(args, "-conf", "--conf-file"):
        args += ["--conf-file", str(default_conf_file(algo))]
    if command == "enjoy" and not _has_option(args, "-f", "--folder"):
        args += ["-f", "logs"]
    return args


USAGE = """usage: python -m sb3_es.zoo {train,enjoy} [rl-zoo3 arguments]

  train  rl_zoo3.train with the sb3-es algorithms (ars, openes, cmaes, reinforce) and rl-zoo's own
         (ppo, sac, ...). sb3-es algorithms read benchmarks/hyperparams/<algo>.yml unless --conf-file is given.
  enjoy  rl_zoo3.enjoy; for sb3-es algorithms the default folder is -f logs.

example: python -m sb3_es.zoo train --algo ars --env BipedalWalker-v3 -n 200000 --seed 0 -P
"""


def main(argv: Sequence[str] | None = None) -> None:
    """
    Entry point: ``python -m sb3_es.zoo train|enjoy [rl-zoo3 arguments]``.

    :param argv: Arguments after the program name (defaults to ``sys.argv[1:]``).
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(USAGE)
        return
    command, rest = args[0], args[1:]
    commands: dict[str, Callable[[], None]] = {"train": rl_zoo3.train.train, "enjoy": rl_zoo3.enjoy.enjoy}
    if command not in commands:
        raise SystemExit(f"Unknown command {command!r}: use one of {sorted(commands)}.\n\n{USAGE}")
    register()
    sys.argv = [f"{Path(sys.argv[0]).name} {command}", *prepare_args(command, rest)]
    commands[command]()


if __name__ == "__main__":
    main()
