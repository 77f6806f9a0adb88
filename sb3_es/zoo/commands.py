"""``python -m sb3_es.zoo <command> [rl-zoo arguments]``: rl-zoo's scripts with the sb3-es algorithms registered."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import inspect
import os
import pickle
import re
import runpy
import shlex
import shutil
import sys
import tempfile
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

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
    Value of an option in an argument list (``--name value``, ``--name=value``, ``-fVALUE``), the last one winning.

    :param args: Command-line arguments.
    :param names: The option's spellings, e.g. ``("--algo",)``.
    :param default: Value when absent.
    :return: The value.
    """
    value = default
    for i, arg in enumerate(args):
        flag, sep, inline = arg.partition("=")
        if any(_attached(arg, name) for name in names):  # -f/path
            value = arg[2:]
        elif _spells(flag, names):
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
    return any(_attached(arg, short) or _spells(arg.split("=", 1)[0], (short, long)) for arg in args)


def _attached(arg: str, name: str) -> bool:
    """:return: Whether ``arg`` is the two-character option ``name`` with its value attached (``-f/path``)."""
    return len(name) == 2 and len(arg) > 2 and arg.startswith(name) and arg[1] != "-"


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


class _Parsed(Exception):
    """Stops an rl-zoo script at its ``parse_args``, carrying what it parsed."""

    def __init__(self, namespace: argparse.Namespace) -> None:
        super().__init__("parsed")
        self.namespace = namespace


def zoo_arguments(command: str, args: Sequence[str]) -> argparse.Namespace:
    """
    rl-zoo's own reading of a command line: the script of ``command`` runs until its ``parse_args`` (it only builds
    its parser before that), which returns here instead of going on. Every spelling that rl-zoo accepts is read as
    rl-zoo reads it (``-params=k:v``, abbreviations such as ``--hyper``, the last of a repeated option).

    :param command: A key of :data:`SCRIPTS` whose script is a function (``train``, ``plot_from_file``, ...).
    :param args: rl-zoo arguments (after the command).
    :return: The parsed arguments (``-params`` evaluated by rl-zoo's ``StoreDict``).
    """
    module, _, function = SCRIPTS[command].partition(":")
    if not function:
        raise ValueError(f"rl-zoo's {command} is a module, not a function: its arguments cannot be read first.")
    register()  # the sb3-es keys are --algo choices
    script = getattr(importlib.import_module(module), function)
    parse_args = argparse.ArgumentParser.parse_args

    def parse_and_stop(parser: argparse.ArgumentParser, *a: Any, **k: Any) -> argparse.Namespace:
        raise _Parsed(parse_args(parser, *a, **k))

    setattr(argparse.ArgumentParser, "parse_args", parse_and_stop)  # noqa: B010 (mypy refuses assigning a method)
    try:
        with _argv([f"sb3_es.zoo {command}", *args]):
            script()
    except _Parsed as parsed:
        return parsed.namespace
    except (NameError, SyntaxError) as e:  # rl-zoo's StoreDict evaluates each key:value's value as Python
        raise UsageError(
            f"{command}: a key:value's value is not a Python expression ({type(e).__name__}: {e}); rl-zoo evaluates "
            "each one: write a string quoted twice, e.g. -params policy:\"'LinearPolicy'\"."
        ) from e
    finally:
        setattr(argparse.ArgumentParser, "parse_args", parse_args)  # noqa: B010 (the original method back)
    raise RuntimeError(f"{SCRIPTS[command]} returned without parsing its arguments.")


def trial_hyperparams(algo: str, storage: str, study_name: str, trial_id: int) -> dict[str, Any]:
    """
    A trial's keyword arguments as rl-zoo's ``--trial-id`` loads them: rl-zoo's ``ExperimentManager.load_trial``
    (a ``.log`` file as a JournalStorage, anything else as a database URL; the key's converter applied).

    :param algo: rl-zoo key of the study's algorithm.
    :param storage: ``--storage``.
    :param study_name: ``--study-name``.
    :param trial_id: Index of the trial in the study.
    :return: ``keyword -> value``.
    """
    from rl_zoo3.exp_manager import ExperimentManager

    register()  # the sb3-es converters
    loader = cast(ExperimentManager, SimpleNamespace(algo=algo))  # load_trial reads nothing else of the manager
    return ExperimentManager.load_trial(loader, storage, study_name, trial_id)


def _stored_trial(algo: str, storage: str, study_name: str, trial_id: int) -> dict[str, Any]:
    """
    :return: :func:`trial_hyperparams`; a storage file (SQLite URL, ``.log``) that is not there is refused before
        anything opens it (that would create it; rl-zoo then failed on the empty study with a KeyError).
    """
    path = storage.removeprefix("sqlite:///") if storage.startswith("sqlite:///") or storage.endswith(".log") else ""
    if path and not Path(path).is_file():
        raise UsageError(
            f"--storage {storage}: there is no file {path}, so no study {study_name!r} to take trial {trial_id} "
            "from. Give the storage of the -optimize run (its --storage)."
        )
    try:
        return trial_hyperparams(algo, storage, study_name, trial_id)
    except (KeyError, IndexError, ValueError) as e:
        raise UsageError(
            f"--trial-id {trial_id}: cannot load that trial of study {study_name!r} from --storage {storage} "
            f"({type(e).__name__}: {e}). Check the study name, the storage and the trial number (the study's trials "
            "are numbered from 0)."
        ) from e


def trial_params_command(algo: str, storage: str, study_name: str, trial_id: int) -> str:
    """
    A shell command that prints a trial's keyword arguments as ``-params key:value ...``: this interpreter runs
    what rl-zoo's ``ExperimentManager.load_trial`` does (a ``.log`` file opened as a JournalStorage, anything else
    as a database URL; the key's converter applied to the stored values).

    :param algo: rl-zoo key of the study's algorithm.
    :param storage: ``--storage``.
    :param study_name: ``--study-name``.
    :param trial_id: Index of the trial in the study.
    :return: The command, for a POSIX shell.
    """
    opened = repr(storage)
    if storage.endswith(".log"):
        opened = f"optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend({storage!r}))"
    code = (
        "import optuna, shlex; from sb3_es.zoo.hyperparams_opt import CONVERTERS; "
        f"kwargs = CONVERTERS[{algo!r}](optuna.load_study(study_name={study_name!r}, storage={opened})"
        f".trials[{int(trial_id)}].params); "
        "print(shlex.join(['-params', *(f'{k}:{v!r}' for k, v in kwargs.items())]))"
    )
    quoted = re.sub(r'([\\"$`])', r"\\\1", code)  # in double quotes: the code's own quotes stay readable
    return f'{shlex.quote(sys.executable)} -c "{quoted}"'


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


def _load_results(results_file: str) -> dict[str, Any] | None:
    """:return: An ``all_plots -o`` pickle without its ``results_table`` (``None`` if absent: rl-zoo names it)."""
    path = Path(results_file)
    if not path.is_file():
        return None
    with path.open("rb") as file:
        results = pickle.load(file)  # the user's own all_plots output, as rl-zoo reads it
    results.pop("results_table", None)
    return dict(results)


def check_plot_runs(plot_args: argparse.Namespace) -> None:
    """
    Refuse a ``plot_from_file`` in which an algorithm it plots has a single run on every env it plots: rl-zoo skips
    those, then fails with "min() arg is an empty sequence". The algorithms and envs are rl-zoo's (its
    ``plot_from_file``): ``--merge`` files merged into the input's envs, the keys of its first env less
    ``--skip-keys`` (and only ``--keep-keys`` if given), its envs less ``--skip-envs`` (only ``--keep-envs``).

    :param plot_args: ``plot_from_file``'s arguments, as rl-zoo parses them (:func:`zoo_arguments`).
    """
    name = plot_args.input or ""
    name = name if name.endswith(".pkl") else f"{name}.pkl"  # as rl-zoo reads -i
    results = _load_results(name)
    if not results:
        return  # rl-zoo names the missing file
    for merged_name in plot_args.merge:
        merged = _load_results(merged_name)
        if merged is None:
            return
        for env, by_algo in results.items():
            by_algo.update(merged.get(env, {}))
    keys = [key for key in next(iter(results.values())) if key not in plot_args.skip_keys]
    if plot_args.keep_keys:
        keys = [key for key in keys if key in plot_args.keep_keys]
    envs = [env for env in results if env not in plot_args.skip_envs]
    if plot_args.keep_envs:
        envs = [env for env in envs if env in plot_args.keep_envs]
    if keys and not envs:
        given = (("--skip-envs", plot_args.skip_envs), ("--keep-envs", plot_args.keep_envs))
        filters = " ".join(f"{flag} {' '.join(values)}" for flag, values in given if values)
        raise UsageError(
            f"{name}: {filters} leaves no env to plot (the file's envs: {', '.join(results)}), and rl-zoo would fail "
            "with 'min() arg is an empty sequence': keep at least one of them."
        )
    for key in keys:
        if any(key not in results[env] for env in envs):
            continue  # rl-zoo's KeyError names it
        # one run: all_plots stores its mean alone, a number, and rl-zoo skips that env for the key
        if all(np.ndim(results[env][key]["last_evals"]) == 0 for env in envs):
            raise UsageError(
                f"{name}: {key} has a single run on {', '.join(envs)}, and plot_from_file needs two runs (seeds) or "
                f"more per algorithm. Train more seeds (train --seed S, or compare.py --seeds), then run all_plots "
                f"again; or leave {key} out with --skip-keys {key}."
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
        check_plot_runs(zoo_arguments(command, args))
    if command not in ALGO_COMMANDS:
        return args
    algo = _option_value(args, ("--algo",), "ppo")
    check_algo(algo)
    if not is_sb3_es_algo(algo):
        return args
    if command == "train":
        train_args = zoo_arguments(command, args)
        trial_id: int | None = train_args.trial_id
        storage, study = train_args.storage, train_args.study_name
        if trial_id == 0:
            convert = trial_params_command(algo, storage or "STORAGE", study or "STUDY", 0)
            raise UsageError(
                f"--trial-id {_option_value(args, ('--trial-id',), '0')}: rl-zoo reads a trial id of 0 as no trial and "
                "would train with the file's values. Pass trial 0's keyword arguments with -params key:value instead; "
                f"this command prints them: {convert}"
            )
        if trial_id is not None and not (storage and study):
            raise UsageError(
                f"--trial-id {trial_id} needs --storage and --study-name: without both, rl-zoo loads no trial and "
                "would train with the file's values."
            )
        trial = _stored_trial(algo, storage, study, trial_id) if trial_id is not None else {}
        conf: str | None = train_args.conf_file
        if conf is None:
            conf = str(default_conf_file(algo))
            args += ["--conf-file", conf]
        env_id = train_args.env
        if trial_id is not None:
            values = f": {', '.join(f'{k}={v}' for k, v in trial.items())}" if trial else " (and -params replaces them)"
            print(f"sb3-es: {algo} on {env_id}: the values of trial {trial_id} of the study replace the file's{values}")
        if conf.endswith((".yml", ".yaml")) and not Path(conf).is_file():
            raise UsageError(f"--conf-file {conf}: no such file.")
        if conf.endswith((".yml", ".yaml")):
            key, entry = config_entry(conf, env_id)
            if key is None:
                raise UsageError(
                    f"{conf} has no {env_id} entry and no 'default' entry, so rl-zoo has no hyperparameters for "
                    f"{algo}: add an entry named {env_id} (or default) to it, e.g. copied from "
                    f"{default_conf_file(algo)}."
                )
            overrides: dict[str, Any] = train_args.hyperparams or {}
            check_entry_names(conf, key, algo, [*entry, *overrides])
            used = {**entry, **trial, **overrides}  # rl-zoo's order (ExperimentManager.read_hyperparameters)
            optimizer = str(used.get("optimizer", "clipup")).strip("'\"")
            if algo == "pgpe" and optimizer != "clipup" and train_args.optimize_hyperparameters:
                raise UsageError(
                    f"-optimize samples PGPE's ClipUp max_speed, which optimizer={optimizer!r} does not take: every "
                    "trial would be refused. Search with ClipUp (leave optimizer out of the entry and -params), then "
                    "tune the other optimizer by hand."
                )
            check_schedule_strings(conf, key, {k: v for k, v in entry.items() if k not in {**trial, **overrides}})
            if key == "default":
                if train_args.n_timesteps > 0:  # rl-zoo's -n replaces the entry's n_timesteps
                    used["n_timesteps"] = train_args.n_timesteps
                applied = "with -params and -n applied"
                if trial_id is not None:
                    applied = (
                        f"with trial {trial_id}'s values, -params and -n applied"
                        if trial
                        else f"with -params and -n applied; trial {trial_id}'s values replace those it sets"
                    )
                print(
                    f"sb3-es: {conf} has no {env_id} entry: {algo} trains with its 'default' entry "
                    f"({', '.join(f'{k}={v}' for k, v in used.items())}, {applied}), not tuned for "
                    f"{env_id}. Add an entry for {env_id} to a copy of the file (--conf-file) or override values "
                    "with -params key:value."
                )
            elif key is not None:
                print(f"sb3-es: {algo} on {env_id}: hyperparameters from the {env_id} entry of {conf}")
    if command in LOGS_DEFAULT_COMMANDS:
        if not _has_option(args, "-f", "--folder"):
            args += ["-f", "logs"]
        folder = Path(_option_value(args, ("-f", "--folder"), "logs")) / algo
        # rl-zoo: an AssertionError traceback (but for its rl-trained-agents folder, which it downloads; -h asks only)
        asks_help = any(arg in ("-h", "--help") for arg in args)
        if not folder.is_dir() and "rl-trained-agents" not in str(folder) and not asks_help:
            raise UsageError(
                f"{command}: no folder {folder} (-f {folder.parent}): train first (sb3-es train --algo {algo} "
                f"--env ENV -f {folder.parent}), or give the folder that holds {algo}/ with -f."
            )
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
    if command == "push_to_hub":
        try:
            importlib.import_module(SCRIPTS[command].partition(":")[0])
        except ImportError as e:  # rl-zoo 2.9's push_to_hub imports a function huggingface_sb3 no longer has
            raise UsageError(
                f"push_to_hub: rl-zoo's script cannot be imported ({e}): a known mismatch of rl-zoo3 and "
                "huggingface_sb3 versions, for every algorithm, PPO included (docs/guide/zoo.md, Share)."
            ) from e
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
    if args[:1] in (["-h"], ["--help"]):
        print(USAGE)
        return
    if not args:  # a usage error, as argparse treats a missing command (exit status 2)
        print(USAGE, file=sys.stderr)
        raise SystemExit(2)
    try:
        run(args[0], args[1:])
    except UsageError as e:
        raise SystemExit(str(e) if args[0] in SCRIPTS else f"{e}\n\n{USAGE}") from e
