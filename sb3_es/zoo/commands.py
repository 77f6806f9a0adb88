"""``python -m sb3_es.zoo <command> [rl-zoo arguments]``: rl-zoo's scripts with the sb3-es algorithms registered."""

from __future__ import annotations

import contextlib
import importlib
import inspect
import itertools
import os
import pickle
import runpy
import shlex
import shutil
import sys
import tempfile
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sb3_es.strategies.base import parse_number
from sb3_es.zoo.registry import ALGOS, UsageError, check_algo, config_entry, default_conf_file, is_sb3_es_algo, register

#: rl-zoo's scripts by command, with rl-zoo's own arguments: ``module:function`` is called, a module without a
#: function (rl-zoo keeps those scripts in the module's ``if __name__ == "__main__"`` block) is run as ``__main__``.
SCRIPTS: dict[str, str] = {
    "train": "rl_zoo3.train:train",
    "enjoy": "rl_zoo3.enjoy:enjoy",
    "record_video": "rl_zoo3.record_video",
    "record_training": "rl_zoo3.record_training",
    "push_to_hub": "rl_zoo3.push_to_hub",
    "load_from_hub": "rl_zoo3.load_from_hub",
    "plot_train": "rl_zoo3.plots:plot_train",
    "all_plots": "rl_zoo3.plots:all_plots",
    "plot_from_file": "rl_zoo3.plots:plot_from_file",
}
#: Commands that load one algorithm by ``--algo`` (the plots read folders only).
ALGO_COMMANDS = ("train", "enjoy", "record_video", "record_training", "push_to_hub", "load_from_hub")
#: Commands whose ``-f/--folder`` defaults to rl-zoo's pretrained agents (``rl-trained-agents``, none of them
#: sb3-es's): for sb3-es algorithms the default is ``logs``, where ``train`` writes.
LOGS_DEFAULT_COMMANDS = ("enjoy", "record_video", "record_training")

USAGE = f"""usage: python -m sb3_es.zoo COMMAND [rl-zoo arguments]   (or: sb3-es COMMAND ...)

COMMAND is one of rl-zoo's scripts, run with rl-zoo's own flags: {", ".join(SCRIPTS)}.
The sb3-es algorithms have keys of their own: --algo {", ".join(ALGOS)} (rl-zoo's ars is
sb3-contrib's ARS). For them, train reads the packaged sb3_es/hyperparams/<algo>.yml unless --conf-file is
given, and enjoy, record_video and record_training look in -f logs unless told otherwise.

examples:
  python -m sb3_es.zoo train --algo ars_es --env Pendulum-v1 -tb runs
  python -m sb3_es.zoo train --algo openes --env Pendulum-v1 -optimize --n-trials 20 -n 50000
  python -m sb3_es.zoo enjoy --algo ars_es --env Pendulum-v1
  python -m sb3_es.zoo all_plots -a ars_es ppo -e Pendulum-v1 -f logs
"""


def _option_value(args: Sequence[str], names: Sequence[str], default: str) -> str:
    """
    Value of an option in an argument list (``--name value`` or ``--name=value``), the last one winning.

    :param args: Command-line arguments.
    :param names: The option's spellings, e.g. ``("--algo",)``.
    :param default: Value when absent.
    :return: The value.
    """
    value = default
    for i, arg in enumerate(args):
        flag, sep, inline = arg.partition("=")
        if _spells(flag, names):
            if sep:
                value = inline
            elif i + 1 < len(args):
                value = args[i + 1]
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
        attached = len(short) == 2 and arg.startswith(short) and not arg.startswith("--")  # -f/path
        if attached or _spells(flag, (short, long)):
            return True
    return False


def _spells(flag: str, names: Sequence[str]) -> bool:
    """
    :return: Whether ``flag`` is one of ``names``, or an abbreviation of one as argparse reads it: ``--con`` of
        ``--conf-file``, and ``-con`` of rl-zoo's single-dash long options such as ``-conf``.
    """
    if flag in names:
        return True
    if flag.startswith("--"):
        return len(flag) > 3 and any(n.startswith("--") and n.startswith(flag) for n in names)
    return flag.startswith("-") and len(flag) > 2 and any(len(n) > 2 and n.startswith(flag) for n in names)


def _hyperparam_overrides(args: Sequence[str]) -> dict[str, str]:
    """
    The ``-params key:value ...`` of an argument list, unevaluated (the last ``-params`` wins, as in rl-zoo).

    :param args: Command-line arguments.
    :return: ``key -> value`` as written.
    """
    overrides: dict[str, str] = {}
    for i, arg in enumerate(args):
        if _spells(arg, ("-params", "--hyperparams")):
            overrides = {}
            for item in itertools.takewhile(lambda a: not a.startswith("-"), args[i + 1 :]):
                key, _, value = item.partition(":")
                overrides[key] = value
    return overrides


#: The keys whose string values rl-zoo reads as a schedule ``"lin_X"`` (it splits them at ``_``).
SCHEDULE_KEYS = ("learning_rate", "delta_std")


def check_schedule_strings(conf: str, key: str | None, entry: dict[str, Any]) -> None:
    """
    Refuse a number that YAML read as a string (``1e-2``: no dot) under a key that rl-zoo parses as a schedule;
    rl-zoo would fail with "not enough values to unpack", naming no key.

    :param conf: The hyperparameter file.
    :param key: The entry's key in it.
    :param entry: The entry.
    """
    for name in SCHEDULE_KEYS:
        value = entry.get(name)
        number = parse_number(value) if isinstance(value, str) else None  # None for "lin_X", rl-zoo's schedule
        if number is not None:
            with_dot = f"{number:.1e}".replace("e-0", "e-").replace("e+0", "e+")
            raise UsageError(
                f"{conf}, entry {key}: {name}: {value} is read by YAML as the string {value!r} (a number without a "
                f"dot), which rl-zoo cannot parse as {name}: write it with a dot, e.g. {name}: {with_dot}."
            )


#: Keys of a hyperparameter entry that rl-zoo reads itself and does not pass to the algorithm's constructor.
ZOO_KEYS = (
    "n_timesteps",
    "n_envs",
    "normalize",
    "env_wrapper",
    "vec_env_wrapper",
    "frame_stack",
    "callback",
    "env_kwargs",
    "monitor_kwargs",
)


def constructor_names(cls: type[Any]) -> set[str]:
    """:return: What ``cls``'s constructor takes besides the env (rl-zoo builds it): the names an entry may give."""
    return set(inspect.signature(cls.__init__).parameters) - {"self", "env", "_init_setup_model"}


def check_entry_names(conf: str, key: str | None, algo: str, names: Sequence[str]) -> None:
    """
    Refuse a name in the entry (or in ``-params``) that neither the algorithm's constructor nor rl-zoo takes; rl-zoo
    would fail with the constructor's ``TypeError``, naming neither the file nor the valid names.

    :param conf: The hyperparameter file.
    :param key: The entry's key in it.
    :param algo: The algorithm's rl-zoo key.
    :param names: The entry's keys and those of ``-params``.
    """
    cls = ALGOS[algo]
    taken = constructor_names(cls)
    unknown = sorted(set(names) - taken - set(ZOO_KEYS))
    if unknown:
        raise UsageError(
            f"{conf}, entry {key} (with -params): {', '.join(unknown)} is not a hyperparameter of {cls.__name__} "
            f"(--algo {algo}). Its hyperparameters: {', '.join(sorted(taken))}; rl-zoo's own keys: "
            f"{', '.join(ZOO_KEYS)}. Check the spelling."
        )


def check_plot_runs(results_file: str) -> None:
    """
    Refuse an ``all_plots`` results file in which an algorithm has a single run on every env: rl-zoo's
    ``plot_from_file`` skips it, then fails with "min() arg is an empty sequence".

    :param results_file: The ``.pkl`` file (``-i``), written by ``all_plots -o``.
    """
    path = Path(results_file if results_file.endswith(".pkl") else f"{results_file}.pkl")
    if not path.is_file():
        return  # rl-zoo names the missing file
    with path.open("rb") as file:
        results = pickle.load(file)  # the user's own all_plots output, as rl-zoo reads it
    single: dict[str, list[bool]] = {}  # algorithm -> whether each env has a single run (rl-zoo skips those)
    for env, by_algo in results.items():
        for algo, result in by_algo.items() if env != "results_table" else ():
            single.setdefault(algo, []).append(np.ndim(result["last_evals"]) == 0)  # one run: its mean alone
    for algo, flags in single.items():
        if all(flags):
            raise UsageError(
                f"{path}: {algo} has a single run, and plot_from_file needs two runs (seeds) or more per algorithm. "
                "Train more seeds (train --seed S, or compare.py --seeds), then run all_plots again."
            )


def prepare_args(command: str, args: Sequence[str]) -> list[str]:
    """
    Check ``--algo`` and add the sb3-es defaults to rl-zoo's arguments, saying so.

    For an sb3-es algorithm: ``train`` gets ``--conf-file`` (the packaged file) and a line naming the entry it
    uses, or saying that the env has none and ``default`` is used; ``enjoy``, ``record_video`` and
    ``record_training`` get ``-f logs``. Arguments for other algorithms are returned unchanged.

    :param command: A key of :data:`SCRIPTS`.
    :param args: rl-zoo arguments (after the command).
    :return: The arguments to give rl-zoo.
    """
    args = list(args)
    if command == "plot_from_file":
        check_plot_runs(_option_value(args, ("-i", "--input"), ""))
    if command not in ALGO_COMMANDS:
        return args
    algo = _option_value(args, ("--algo",), "ppo")
    check_algo(algo)
    if not is_sb3_es_algo(algo):
        return args
    if command == "train":
        trial_id = _option_value(args, ("--trial-id",), "")
        storage = _option_value(args, ("--storage",), "")
        study = _option_value(args, ("--study-name",), "")
        # rl-zoo's CSV and "Best trial" print the study's stored names (population_size_pow, ...): the keyword
        # arguments are the key's converter applied to them.
        convert = (
            'python -c "import optuna; from sb3_es.zoo.hyperparams_opt import CONVERTERS; '
            f"print(CONVERTERS['{algo}'](optuna.load_study(study_name='{study or 'STUDY'}', "
            f"storage='{storage or 'STORAGE'}').trials[0].params))\""
        )
        if trial_id and parse_number(trial_id) == 0:
            raise UsageError(
                f"--trial-id {trial_id}: rl-zoo reads a trial id of 0 as no trial and would train with the file's "
                "values. Pass trial 0's keyword arguments with -params key:value instead; they are printed by "
                f"{convert} (an SQLite storage as sqlite:///file.db; rl-zoo opens a .log file as a JournalStorage)."
            )
        if trial_id and not (storage and study):
            raise UsageError(
                f"--trial-id {trial_id} needs --storage and --study-name: without both, rl-zoo loads no trial and "
                "would train with the file's values."
            )
        if not _has_option(args, "-conf", "--conf-file"):
            args += ["--conf-file", str(default_conf_file(algo))]
        conf = _option_value(args, ("-conf", "--conf-file"), "")
        env_id = _option_value(args, ("--env",), "CartPole-v1")
        if trial_id:
            print(f"sb3-es: {algo} on {env_id}: the values of trial {trial_id} of the study replace the file's")
        if conf.endswith((".yml", ".yaml")) and Path(conf).is_file():
            key, entry = config_entry(conf, env_id)
            if key is None:
                raise UsageError(
                    f"{conf} has no {env_id} entry and no 'default' entry, so rl-zoo has no hyperparameters for "
                    f"{algo}: add an entry named {env_id} (or default) to it, e.g. copied from "
                    f"{default_conf_file(algo)}."
                )
            overrides = _hyperparam_overrides(args)
            check_entry_names(conf, key, algo, [*entry, *overrides])
            optimizer = str({**entry, **overrides}.get("optimizer", "clipup")).strip("'\"")
            if (
                algo == "pgpe"
                and optimizer != "clipup"
                and _has_option(args, "-optimize", "--optimize-hyperparameters")
            ):
                raise UsageError(
                    f"-optimize samples PGPE's ClipUp max_speed, which optimizer={optimizer!r} does not take: every "
                    "trial would be refused. Search with ClipUp (leave optimizer out of the entry and -params), then "
                    "tune the other optimizer by hand."
                )
            check_schedule_strings(conf, key, {k: v for k, v in entry.items() if k not in overrides})
            if key == "default":
                used = {**entry, **overrides}
                n_timesteps = _option_value(args, ("-n", "--n-timesteps"), "")
                if n_timesteps.isdigit() and int(n_timesteps) > 0:  # rl-zoo's -n replaces the entry's n_timesteps
                    used["n_timesteps"] = int(n_timesteps)
                print(
                    f"sb3-es: {conf} has no {env_id} entry: {algo} trains with its 'default' entry "
                    f"({', '.join(f'{k}={v}' for k, v in used.items())}, with -params and -n applied), not tuned for "
                    f"{env_id}. Add an entry for {env_id} to a copy of the file (--conf-file) or override values "
                    "with -params key:value."
                )
            elif key is not None:
                print(f"sb3-es: {algo} on {env_id}: hyperparameters from the {env_id} entry of {conf}")
    if command in LOGS_DEFAULT_COMMANDS and not _has_option(args, "-f", "--folder"):
        args += ["-f", "logs"]
    return args


@contextlib.contextmanager
def _argv(argv: list[str]) -> Iterator[None]:
    """
    Give rl-zoo's script its arguments: rl-zoo's scripts read ``sys.argv`` (as ``python -m rl_zoo3.cli`` does).

    :param argv: The full ``sys.argv`` for the script.
    """
    saved = sys.argv
    sys.argv = argv
    try:
        yield
    finally:
        sys.argv = saved


@contextlib.contextmanager
def _subprocess_path() -> Iterator[None]:
    """
    rl-zoo's ``record_training`` runs ``python -m rl_zoo3.record_video`` and ``ffmpeg`` by name, in new processes.
    Put first on ``PATH`` a ``python`` that runs that module through this entry point (this interpreter, the
    sb3-es keys registered) and, when no ``ffmpeg`` is installed, imageio-ffmpeg's binary (``[zoo]`` extra).
    """
    with tempfile.TemporaryDirectory(prefix="sb3_es_zoo_") as folder:
        python = shlex.quote(sys.executable)
        shim = Path(folder) / "python"
        shim.write_text(
            "#!/bin/sh\n"
            'if [ "$1" = "-m" ] && [ "$2" = "rl_zoo3.record_video" ]; then\n'
            f'  shift 2; exec {python} -m sb3_es.zoo record_video "$@"\n'
            "fi\n"
            f'exec {python} "$@"\n'
        )
        shim.chmod(0o755)
        if shutil.which("ffmpeg") is None:
            with contextlib.suppress(ImportError, RuntimeError):
                import imageio_ffmpeg

                os.symlink(imageio_ffmpeg.get_ffmpeg_exe(), Path(folder) / "ffmpeg")
        saved = os.environ.get("PATH", "")
        os.environ["PATH"] = folder + os.pathsep + saved
        try:
            yield
        finally:
            os.environ["PATH"] = saved


def run(command: str, args: Sequence[str]) -> None:
    """
    Run one of rl-zoo's scripts with the sb3-es algorithms registered and the sb3-es defaults added.

    :param command: A key of :data:`SCRIPTS`.
    :param args: rl-zoo arguments (after the command).
    """
    if command not in SCRIPTS:
        raise UsageError(f"Unknown command {command!r}: use one of {', '.join(SCRIPTS)}.")
    register()
    args = prepare_args(command, args)
    paths = _subprocess_path() if command == "record_training" else contextlib.nullcontext()
    module, _, function = SCRIPTS[command].partition(":")
    with _argv([f"sb3_es.zoo {command}", *args]), paths:
        if function:
            getattr(importlib.import_module(module), function)()
        else:
            with warnings.catch_warnings():  # rl-zoo imports some of these modules itself; running them is intended
                warnings.filterwarnings("ignore", "'rl_zoo3.* found in sys.modules", RuntimeWarning)
                runpy.run_module(module, run_name="__main__", alter_sys=False)


def main(argv: Sequence[str] | None = None) -> None:
    """
    Entry point: ``python -m sb3_es.zoo COMMAND [rl-zoo arguments]``.

    :param argv: Arguments after the program name (defaults to ``sys.argv[1:]``).
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(USAGE)
        return
    try:
        run(args[0], args[1:])
    except UsageError as e:
        raise SystemExit(str(e) if args[0] in SCRIPTS else f"{e}\n\n{USAGE}") from e
