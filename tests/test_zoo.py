"""rl-baselines3-zoo with the sb3-es algorithms (sb3_es.zoo), packaged configs, benchmarks/compare.py, render.py."""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import pickle
import re
import shlex
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import optuna
import pytest
import rl_zoo3
import rl_zoo3.hyperparams_opt
import rl_zoo3.train
import yaml
from rl_zoo3.exp_manager import ExperimentManager

from sb3_es import ARS
from sb3_es.common.population_algorithm import PopulationAlgorithm
from sb3_es.zoo import (
    ALGOS,
    HYPERPARAMS_DIR,
    SCRIPTS,
    UsageError,
    default_conf_file,
    main,
    prepare_args,
    register,
)
from sb3_es.zoo.hyperparams_opt import CONVERTERS, SAMPLERS
from sb3_es.zoo.registry import zoo_meaning

ROOT = Path(__file__).resolve().parent.parent
KEYS = tuple(ALGOS)
#: Keys whose files cover every env of ENVS (the others cover QUICK_ENVS), less their REMOVED entries.
FULL_KEYS = ("ars_es", "openes", "cmaes", "reinforce")
#: Envs the files of FULL_KEYS cover.
ENVS = (
    "BipedalWalker-v3",
    "Pendulum-v1",
    "LunarLanderContinuous-v3",
    "Swimmer-v5",
    "Hopper-v5",
    "HalfCheetah-v5",
    "Walker2d-v5",
    "dm_control/walker-walk-v0",
    "dm_control/cheetah-run-v0",
)
#: rl-zoo's ARS envs that ars_es.yml also covers, with the rl-zoo ars.yml entry each one translates.
ARS_ZOO_ENVS = {
    "CartPole-v1": "CartPole-v1",
    "LunarLander-v3": "LunarLander-v3",
    "Acrobot-v1": "Acrobot-v1",
    "MountainCar-v0": "MountainCar-v0",
    "MountainCarContinuous-v0": "MountainCarContinuous-v0",
    "Ant-v5": "Ant-v4",
    "Humanoid-v5": "Humanoid-v4",
    "BipedalWalkerHardcore-v3": "BipedalWalkerHardcore-v3",
}
#: rl-zoo ARS entries that ars_es.yml replaces with its own values (the comment says why and what was measured).
ARS_REPLACED = {"BipedalWalkerHardcore-v3", "LunarLander-v3", "Swimmer-v5", "default"}
#: Envs whose models are built in the tests (the MuJoCo/dm_control entries of every file are parsed, not built).
QUICK_ENVS = ("BipedalWalker-v3", "Pendulum-v1", "LunarLanderContinuous-v3")
#: Entries that failed verification (docs/benchmarks.md, "Verified configs", states the rule): removed from the
#: packaged files, not shipped.
REMOVED = {
    "cmaes": ("Pendulum-v1", "dm_control/walker-walk-v0"),
    "openes": ("Pendulum-v1", "Swimmer-v5", "dm_control/walker-walk-v0"),
    "pgpe": ("Pendulum-v1",),
    "simple_es": ("Pendulum-v1",),
    "reinforce": (
        "Pendulum-v1",
        "Swimmer-v5",
        "Hopper-v5",
        "HalfCheetah-v5",
        "Walker2d-v5",
        "dm_control/cheetah-run-v0",
    ),
}
#: Test-only rl-zoo config files (one per key, a Pendulum-v1 entry with small generations) for the workflow tests:
#: they check the zoo commands, whatever the shipped entries' values.
TEST_CONFIGS = ROOT / "tests" / "data" / "zoo"
#: Constructor arguments that keep a generation (an update) of each algorithm small: benchmarks/zoo_workflow.sh's
#: ``small`` (test_workflow_small_params_fit_the_entries_it_trains checks both).
SMALL = {
    "ars_es": {"n_delta": 2, "n_top": 2},
    "openes": {"population_size": 4},
    "cmaes": {"population_size": 4},
    "pgpe": {"population_size": 4},
    "simple_es": {"population_size": 4},
    "reinforce": {"n_episodes": 2},
}


def manager(
    algo: str,
    env_id: str,
    folder: Path,
    n_timesteps: int = 0,
    manager_cls: type[ExperimentManager] = ExperimentManager,
    **kwargs: Any,
) -> ExperimentManager:
    """rl-zoo's own ExperimentManager (or ``manager_cls``), as rl_zoo3.train builds it, with the packaged file of an
    sb3-es algorithm."""
    register()
    args = argparse.Namespace(algo=algo, env=env_id, env_kwargs=None)
    kwargs.setdefault("config", str(default_conf_file(algo)))
    return manager_cls(
        args,
        algo,
        env_id,
        str(folder),
        n_timesteps=n_timesteps,
        eval_freq=-1,
        seed=0,
        log_interval=-1,  # rl_zoo3.train's default (the constructor's 0 would mean "every 0 updates")
        verbose=0,
        **kwargs,
    )


def shipped_envs(key: str) -> tuple[str, ...]:
    """:return: The env ids the packaged file of ``key`` must have an entry for."""
    return tuple(env_id for env_id in (ENVS if key in FULL_KEYS else QUICK_ENVS) if env_id not in REMOVED.get(key, ()))


def zoo(*args: str) -> None:
    """``python -m sb3_es.zoo ARGS``, in this process."""
    main(list(args))


def run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """Run a command with this interpreter and this tree's sb3_es; fail with its output."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run(
        [sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=900, check=False
    )
    assert proc.returncode == 0, f"{args} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


def load_script(name: str) -> ModuleType:
    """Import benchmarks/<name>.py as a module (with benchmarks/ on ``sys.path``, as when it runs as a script)."""
    if str(ROOT / "benchmarks") not in sys.path:
        sys.path.append(str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location(f"benchmarks_{name}", ROOT / "benchmarks" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ----------------------------------------------------------------------------------------------- own names
def test_register_uses_rl_zoo_registries_only() -> None:
    ours = register()
    assert set(ours) == set(KEYS) and "ars_es" in ours
    for key, cls in ours.items():
        assert rl_zoo3.ALGOS[key] is cls
        assert rl_zoo3.hyperparams_opt.HYPERPARAMS_SAMPLER[key] is SAMPLERS[key]
        assert rl_zoo3.hyperparams_opt.HYPERPARAMS_CONVERTER[key] is CONVERTERS[key]
    # rl-zoo's own algorithms and machinery are left alone: "ars" is still sb3-contrib's ARS
    assert rl_zoo3.ALGOS["ars"].__module__.startswith("sb3_contrib")
    assert rl_zoo3.ALGOS["ppo"].__module__.startswith("stable_baselines3")
    assert rl_zoo3.train.ExperimentManager is ExperimentManager
    assert ExperimentManager.__module__ == "rl_zoo3.exp_manager"
    assert all(cls.__module__.startswith("sb3_es.") for cls in ours.values())


@pytest.mark.parametrize("key", KEYS)
def test_every_key_has_a_config_and_a_sampler(key: str) -> None:
    assert key not in ("ars", "ppo", "sac", "td3", "a2c", "dqn", "ddpg", "qrdqn", "tqc", "trpo", "ppo_lstm", "crossq")
    data = yaml.safe_load(default_conf_file(key).read_text())
    assert "default" in data
    assert key in SAMPLERS and key in CONVERTERS


@pytest.mark.parametrize("key", ["learning_rate", "delta_std"])
def test_a_schedule_key_that_yaml_read_as_a_string_is_named(key: str, tmp_path: Path) -> None:
    # YAML reads 1e-2 (no dot) as a string, which rl-zoo splits as "lin_X" without naming the key
    conf = tmp_path / "ars_es.yml"
    conf.write_text(f"Pendulum-v1:\n  policy: 'LinearPolicy'\n  {key}: 1e-2\n")
    with pytest.raises(
        UsageError, match=rf"entry Pendulum-v1: {key}: 1e-2 is read by YAML as the string .*{key}: 1.0e-2"
    ):
        prepare_args("train", ["--algo", "ars_es", "--env", "Pendulum-v1", "-conf", str(conf)])
    # -params replaces the file's value before rl-zoo reads it: nothing to refuse
    prepare_args("train", ["--algo", "ars_es", "--env", "Pendulum-v1", "-conf", str(conf), "-params", f"{key}:0.01"])
    conf.write_text(f"Pendulum-v1:\n  policy: 'LinearPolicy'\n  {key}: lin_1.0e-2\n")
    prepare_args("train", ["--algo", "ars_es", "--env", "Pendulum-v1", "-conf", str(conf)])  # a schedule is fine


@pytest.mark.parametrize("key", KEYS)
def test_every_packaged_entry_names_only_what_the_algorithm_or_rl_zoo_takes(key: str) -> None:
    for env_id in yaml.safe_load(default_conf_file(key).read_text()):
        prepare_args("train", ["--algo", key, "--env", env_id])  # check_entry_names would raise UsageError


def test_a_misspelled_hyperparameter_is_named_with_the_valid_ones(tmp_path: Path) -> None:
    # rl-zoo would pass it on, and the constructor's TypeError names neither the file nor the valid names
    train = ["train", "--algo", "ars_es", "--env", "Pendulum-v1"]
    with pytest.raises(UsageError, match=r"n_dleta is not a hyperparameter of ARS .*: .*n_delta, .*Check the spelling"):
        prepare_args(train[0], [*train[1:], "-params", "n_dleta:4"])
    conf = tmp_path / "mine.yml"
    conf.write_text("Pendulum-v1:\n  policy: 'LinearPolicy'\n  delta_stdd: 0.03\n  n_envs: 2\n")
    with pytest.raises(UsageError, match=rf"{conf}, entry Pendulum-v1 .*: delta_stdd is not a hyperparameter of ARS"):
        prepare_args(train[0], [*train[1:], "-conf", str(conf)])
    conf.write_text("CartPole-v1:\n  policy: 'LinearPolicy'\n")
    with pytest.raises(UsageError, match=rf"{conf} has no Pendulum-v1 entry and no 'default' entry"):
        prepare_args(train[0], [*train[1:], "-conf", str(conf)])


def test_plot_from_file_with_a_single_run_is_refused_with_the_fix(tmp_path: Path) -> None:
    # rl-zoo's plot_from_file skips an algorithm with one run (its last_evals is then a number), then fails with
    # "min() arg is an empty sequence"
    results = {"results_table": {}, "Pendulum-v1": {"ARS_ES-logs": {"last_evals": np.float64(-1600.0)}}}
    (tmp_path / "all_plots.pkl").write_bytes(pickle.dumps(results))
    with pytest.raises(UsageError, match=r"ARS_ES-logs has a single run on Pendulum-v1, and plot_from_file needs two"):
        prepare_args("plot_from_file", ["-i", str(tmp_path / "all_plots"), "--rliable"])
    results["HalfCheetah-v5"] = {"ARS_ES-logs": {"last_evals": np.array([3000.0, 3100.0])}}  # two runs on one env
    (tmp_path / "all_plots.pkl").write_bytes(pickle.dumps(results))
    assert prepare_args("plot_from_file", ["-i", str(tmp_path / "all_plots.pkl")]) == [
        "-i",
        str(tmp_path / "all_plots.pkl"),
    ]


def test_plot_from_file_checks_only_what_rl_zoo_plots(tmp_path: Path) -> None:
    # rl-zoo plots the keys of the first env less --skip-keys (only --keep-keys), the envs less --skip-envs (only
    # --keep-envs), with --merge files merged in: a single-run algorithm left out of those is no failure
    one, two = {"last_evals": np.float64(-1600.0)}, {"last_evals": np.array([-900.0, -950.0])}
    results = {"results_table": {}, "Pendulum-v1": {"ARS_ES-logs": two, "PPO-logs": two, "REINFORCE-logs": one}}
    results["CartPole-v1"] = {"ARS_ES-logs": one, "PPO-logs": one, "REINFORCE-logs": one}
    (tmp_path / "ap.pkl").write_bytes(pickle.dumps(results))
    for given in (
        ["--skip-keys", "REINFORCE-logs"],
        ["--skip-k=REINFORCE-logs"],  # argparse's abbreviation and = form, as rl-zoo reads them
        ["--keep-keys", "ARS_ES-logs", "PPO-logs"],
    ):
        prepare_args("plot_from_file", ["-i", str(tmp_path / "ap"), *given])
    single = r"REINFORCE-logs has a single run on Pendulum-v1, CartPole-v1, .* --skip-keys REINFORCE-logs"
    with pytest.raises(UsageError, match=single):
        prepare_args("plot_from_file", ["-i", str(tmp_path / "ap")])
    with pytest.raises(UsageError, match=r"ARS_ES-logs has a single run on CartPole-v1, and"):
        prepare_args(
            "plot_from_file", ["-i", str(tmp_path / "ap"), "--skip-keys", "REINFORCE-logs", "-skip", "Pendulum-v1"]
        )
    with pytest.raises(UsageError, match=r"--keep-envs Acrobot-v1 leaves no env to plot \(the file's envs: Pendulum"):
        prepare_args("plot_from_file", ["-i", str(tmp_path / "ap"), "--keep-envs", "Acrobot-v1"])
    # a merged file brings REINFORCE's second run on Pendulum-v1
    merged = {"results_table": {}, "Pendulum-v1": {"REINFORCE-logs": two}}
    (tmp_path / "more.pkl").write_bytes(pickle.dumps(merged))
    prepare_args("plot_from_file", ["-i", str(tmp_path / "ap.pkl"), "--merge", str(tmp_path / "more.pkl")])


def optuna_study(algo: str, storage_name: str, study_name: str, n_trials: int) -> list[dict[str, Any]]:
    """
    A study of ``n_trials`` finished trials with ``algo``'s sampler, in ``storage_name`` opened as rl-zoo opens it (a
    ``.log`` file as a JournalStorage, else a database URL).

    :return: Each trial's sampled keyword arguments.
    """
    storage: Any = storage_name
    if storage_name.endswith(".log"):
        storage = optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(storage_name))
    study = optuna.create_study(storage=storage, study_name=study_name, sampler=optuna.samplers.RandomSampler(seed=0))
    sampled = []
    for _ in range(n_trials):
        trial = study.ask()
        sampled.append(SAMPLERS[algo](trial, 0, 1, {}))
        study.tell(trial, 1.0)
    return sampled


@pytest.mark.parametrize("storage", ["sqlite:///study.db", "study.log"])
def test_trial_id_0_prints_a_command_that_prints_its_params(
    storage: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # rl-zoo reads --trial-id 0 as no trial; the refusal's command prints trial 0's keyword arguments as -params,
    # with this interpreter, from a database URL or a .log journal file (rl-zoo's two kinds of --storage)
    monkeypatch.chdir(tmp_path)
    (sampled, _) = optuna_study("cmaes", storage, "s", 2)
    train = ["--algo", "cmaes", "--env", "CartPole-v1", "--storage", storage, "--study-name", "s", "--trial-id", "0"]
    with pytest.raises(UsageError, match="--trial-id 0: rl-zoo reads a trial id of 0 as no trial") as refused:
        prepare_args("train", train)
    message = str(refused.value)
    command = shlex.split(message[message.rindex(" ", 0, message.index(" -c ")) + 1 :])
    printed = shlex.split(run(command[1:3], tmp_path).stdout)
    assert command[0] == sys.executable and len(command) == 3  # the interpreter that runs sb3_es.zoo
    # trial 0's values as rl-zoo's --trial-id would load them (ExperimentManager.load_trial), the sampler's
    assert printed[0] == "-params" and eval_params(printed[1:]) == sampled
    assert manager("cmaes", "CartPole-v1", tmp_path).load_trial(storage, "s", 0) == sampled
    assert "--conf-file" in prepare_args("train", [*train[:4], *printed])  # -params takes them


def eval_params(items: list[str]) -> dict[str, Any]:
    """:return: ``-params key:value ...`` as rl-zoo's ``StoreDict`` reads them."""
    return {key: eval(value) for key, _, value in (item.partition(":") for item in items)}


@pytest.mark.parametrize("spelling", ["-params=", "--hyperparams=", "--hyperparams", "--hyper", "-param", "-params"])
def test_every_spelling_of_params_is_checked(spelling: str, capsys: pytest.CaptureFixture[str]) -> None:
    # rl-zoo's argparse takes -params=k:v and abbreviations: each is checked and shown in the default entry's line
    def params(item: str) -> list[str]:
        return [spelling + item] if spelling.endswith("=") else [spelling, item]

    train = ["--algo", "openes", "--env", "CartPole-v1", "-n", "400"]
    with pytest.raises(UsageError, match=r"sigmaa is not a hyperparameter of OpenES"):
        prepare_args("train", [*train, *params("sigmaa:0.1")])
    prepare_args("train", [*train, *params("population_size:6")])
    out = capsys.readouterr().out
    assert "trains with its 'default' entry (n_timesteps=400, " in out and "population_size=6," in out


def test_trial_id_line_shows_the_values_rl_zoo_trains_with(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = f"sqlite:///{tmp_path / 'study.db'}"
    optuna_study("openes", url, "s", 2)
    train = ["--algo", "openes", "--env", "CartPole-v1", "--storage", url, "--study-name", "s", "--trial-id", "1"]
    for params in ([], ["-params", "population_size:6"]):
        prepare_args("train", [*train, *params])
        out = capsys.readouterr().out
        (line,) = [line for line in out.splitlines() if "trains with its 'default' entry" in line]
        assert "with trial 1's values, -params and -n applied" in line
        # rl-zoo's own reading: the entry, the trial's values over it, -params over both
        zoo_manager = manager(
            "openes",
            "CartPole-v1",
            tmp_path,
            storage=url,
            study_name="s",
            trial_id=1,
            hyperparams=eval_params(params[1:]),
        )
        hyperparams = zoo_manager.read_hyperparameters()[0]
        capsys.readouterr()
        shown = dict(item.split("=", 1) for item in line.split("(", 1)[1].split(", with trial")[0].split(", "))
        assert shown == {k: str(v) for k, v in hyperparams.items()}
    assert "population_size=6" in line
    with pytest.raises(UsageError, match=r"--trial-id 5: cannot load that trial of study 's' .*IndexError"):
        prepare_args("train", [*train[:-1], "5"])
    # a storage file that is not there is refused and not created (opening it would; rl-zoo then failed with a
    # KeyError traceback)
    missing = f"sqlite:///{tmp_path / 'none.db'}"
    with pytest.raises(UsageError, match=rf"--storage {missing}: there is no file .*none.db, so no study 's'"):
        prepare_args("train", [*train[:4], "--storage", missing, *train[6:]])
    assert not (tmp_path / "none.db").exists()


def test_missing_files_and_folders_are_said_before_rl_zoo_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # rl-zoo: a FileNotFoundError and an AssertionError traceback
    monkeypatch.chdir(tmp_path)
    with pytest.raises(UsageError, match=r"--conf-file /nonexistent.yml: no such file"):
        prepare_args("train", ["--algo", "ars_es", "--env", "Pendulum-v1", "-conf", "/nonexistent.yml"])
    for command in ("enjoy", "record_video", "record_training"):
        with pytest.raises(UsageError, match=rf"{command}: no folder logs/ars_es \(-f logs\): train first"):
            prepare_args(command, ["--algo", "ars_es", "--env", "Swimmer-v5"])
    assert prepare_args("enjoy", ["--algo", "ars_es", "--env", "Swimmer-v5", "-h"])[-2:] == ["-f", "logs"]  # help
    (tmp_path / "runs" / "ars_es").mkdir(parents=True)
    assert prepare_args("enjoy", ["--algo", "ars_es", "--env", "Swimmer-v5", "-f", "runs"])[-2:] == ["-f", "runs"]


def test_push_to_hub_that_rl_zoo_cannot_import_says_so_in_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rl_zoo3.push_to_hub", None)  # as with rl-zoo3 2.9.2 and huggingface_sb3 3.2
    with pytest.raises(SystemExit, match=r"^push_to_hub: rl-zoo's script cannot be imported .*PPO included"):
        zoo("push_to_hub", "-h")


@pytest.mark.parametrize("command", ["train", "enjoy", "record_video", "push_to_hub", "load_from_hub"])
def test_old_ars_key_is_refused_with_the_new_one(command: str) -> None:
    with pytest.raises(UsageError, match=r"--algo ars is sb3-contrib's ARS in rl-zoo; sb3-es's ARS is --algo ars_es"):
        prepare_args(command, ["--algo", "ars", "--env", "Pendulum-v1"])
    with pytest.raises(SystemExit, match="--algo ars_es"):
        zoo(command, "--algo", "ars", "--env", "Pendulum-v1")


def test_tensorboard_run_name_is_not_sb3_contribs(tmp_path: Path) -> None:
    ARS("LinearPolicy", "Pendulum-v1", n_delta=1, tensorboard_log=str(tmp_path)).learn(400)
    assert [p.name for p in tmp_path.iterdir()] == ["ARS_ES_1"]


# ----------------------------------------------------------------------------------------------- packaged configs
def entry_comments(path: Path) -> dict[str, str]:
    """:return: ``entry -> the comment lines right above it`` for each top-level entry of a YAML file."""
    lines = path.read_text().splitlines()
    comments = {}
    for index, line in enumerate(lines):
        if re.fullmatch(r"[^\s#][^:]*:\s*", line):
            start = index
            while start > 0 and lines[start - 1].startswith("#"):
                start -= 1
            comments[line.rstrip(": ")] = " ".join(lines[start:index])
    return comments


@pytest.mark.parametrize("algo", KEYS)
def test_hyperparameter_files_parse(algo: str, tmp_path: Path) -> None:
    path = HYPERPARAMS_DIR / f"{algo}.yml"
    assert path.parent == ROOT / "sb3_es" / "hyperparams"
    text = path.read_text()
    data = yaml.safe_load(text)
    envs = shipped_envs(algo)
    assert set(envs) <= set(data), f"{path} misses {set(envs) - set(data)}"
    # an entry that failed verification is removed, not shipped
    assert not set(REMOVED.get(algo, ())) & set(data), f"{path} ships a removed entry"
    assert "FAILED verification" not in text and "kept only because" not in text
    comments = entry_comments(path)
    for env_id in envs:
        # each entry is preceded by a comment saying where its values come from and what a run measured
        comment = comments[env_id]
        assert comment, f"{path}: no source comment above {env_id}"
        assert "untested" not in comment, f"{path}: {env_id} is shipped unmeasured"
        entry = data[env_id]
        assert entry["policy"] in ("LinearPolicy", "MlpPolicy", "MultiInputPolicy")
        assert entry["n_timesteps"] > 0
        assert "normalize" not in entry  # observation normalization is done by the policies
    for env_id in envs:
        # rl-zoo's own parsing and preprocessing (schedules, policy_kwargs strings, n_envs)
        zoo_manager = manager(algo, env_id, tmp_path)
        hyperparams, _ = zoo_manager.read_hyperparameters()
        processed, *_ = zoo_manager._preprocess_hyperparams(hyperparams)
        assert "n_timesteps" not in processed and "n_envs" not in processed
        assert isinstance(processed.get("policy_kwargs", {}), dict)


def test_ars_file_covers_rl_zoos_ars_envs() -> None:
    path = HYPERPARAMS_DIR / "ars_es.yml"
    comments = entry_comments(path)
    ours = yaml.safe_load(path.read_text())
    theirs = yaml.safe_load((Path(rl_zoo3.__file__).parent / "hyperparams" / "ars.yml").read_text())
    for env_id, zoo_id in ARS_ZOO_ENVS.items():
        # the comment block above the entry says whether a run checked it (docs/benchmarks.md, "Verified configs")
        comment = comments[env_id]
        status = ("Verified 20", "Measured 20")
        assert any(word in comment for word in status), f"{env_id}: the comment must say one of {status}"
        if env_id in ARS_REPLACED:
            assert "replaces rl-zoo's" in comment and ours[env_id] != theirs[zoo_id]
            continue
        assert "benchmarks/verify_configs.py" in comment, f"{env_id}: a measured entry gives its command"
        entry, source = ours[env_id], theirs[zoo_id]
        for key in ("n_timesteps", "policy", "learning_rate", "delta_std", "n_delta", "n_top", "alive_bonus_offset"):
            if key in source:
                assert entry[key] == source[key], (env_id, key)
        assert entry.get("zero_policy", True) == source.get("zero_policy", True)
        if "normalize" not in source:  # rl-zoo without VecNormalize: no observation normalization (ARS-V1)
            assert "normalize_observations=False" in entry["policy_kwargs"]
        if "net_arch" in str(source.get("policy_kwargs")):
            assert source["policy_kwargs"].split("net_arch=")[1] in entry["policy_kwargs"]


@pytest.mark.parametrize("algo", KEYS)
def test_every_packaged_entry_states_what_was_measured(algo: str) -> None:
    # the rule of the files' headers: the comment above each entry gives its measured result, date and command
    comments = entry_comments(HYPERPARAMS_DIR / f"{algo}.yml")
    assert set(comments) == set(yaml.safe_load((HYPERPARAMS_DIR / f"{algo}.yml").read_text()))
    for entry, comment in comments.items():
        assert re.search(r"\b20\d\d-\d\d-\d\d\b", comment), f"{algo}.yml {entry}: no date in {comment!r}"
        assert re.search(r"python (benchmarks|-m)", comment), f"{algo}.yml {entry}: no command in {comment!r}"


@pytest.mark.parametrize(
    "algo, env_id",
    [(algo, env_id) for algo in KEYS for env_id in QUICK_ENVS if env_id in shipped_envs(algo)]
    + [("ars_es", env_id) for env_id in ARS_ZOO_ENVS],
)
def test_entries_build_models(algo: str, env_id: str, tmp_path: Path) -> None:
    zoo_manager = manager(algo, env_id, tmp_path)
    result = zoo_manager.setup_experiment()
    assert result is not None
    model, saved = result
    try:
        assert type(model) is ALGOS[algo]
        # rl-zoo's n_envs: one VecEnv whose slots evaluate different candidates (no "ars" special case)
        assert model.get_env().num_envs == saved.get("n_envs", 1)  # type: ignore[union-attr]
        if isinstance(model, PopulationAlgorithm):
            assert model.device.type == "cpu"  # rl-zoo passes device="auto"
        if "learning_rate" in saved:  # rl-zoo makes a ConstantSchedule of it; the model keeps the number
            assert model.learning_rate == saved["learning_rate"]
    finally:
        model.get_env().close()  # type: ignore[union-attr]


def test_default_fallback_is_logged(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    for folder in ("logs", "x"):
        (tmp_path / folder / "cmaes").mkdir(parents=True)  # what enjoy loads from (missing: refused)
    args = prepare_args("train", ["--algo", "openes", "--env", "CartPole-v1"])
    assert args[-2:] == ["--conf-file", str(HYPERPARAMS_DIR / "openes.yml")]
    out = capsys.readouterr().out
    assert "has no CartPole-v1 entry: openes trains with its 'default' entry" in out
    assert "n_timesteps=1000000.0" in out
    # the values it trains with: -params and -n replace the entry's
    args = ["--algo", "openes", "--env", "CartPole-v1", "-params", "population_size:8", "n_envs:4", "-n", "5000"]
    prepare_args("train", args)
    out = capsys.readouterr().out
    assert "population_size=8" in out and "n_envs=4" in out and "n_timesteps=5000," in out
    assert "Add an entry for CartPole-v1" in out
    prepare_args("train", ["--algo", "ars_es", "--env", "CartPole-v1"])
    assert "from the CartPole-v1 entry" in capsys.readouterr().out
    # rl-zoo's own algorithms keep rl-zoo's own files and defaults
    assert prepare_args("train", ["--algo", "ppo", "--env", "Pendulum-v1"]) == ["--algo", "ppo", "--env", "Pendulum-v1"]
    assert prepare_args("enjoy", ["--algo", "cmaes"])[-2:] == ["-f", "logs"]
    assert prepare_args("enjoy", ["--algo", "cmaes", "--folder=x"]) == ["--algo", "cmaes", "--folder=x"]
    given = ["--algo", "ars_es", "--env", "Pendulum-v1", "-conf", str(HYPERPARAMS_DIR / "ars_es.yml")]
    assert prepare_args("train", given) == given


def test_wheel_ships_the_configs(tmp_path: Path) -> None:
    source = tmp_path / "src"
    shutil.copytree(ROOT / "sb3_es", source / "sb3_es", ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, source / name)
    run(["-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", str(source), "-w", str(tmp_path)], tmp_path)
    (wheel,) = tmp_path.glob("sb3_es-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    for key in KEYS:
        assert f"sb3_es/hyperparams/{key}.yml" in names
    assert "sb3_es/zoo/__main__.py" in names


def test_zoo_extra_has_rl_zoos_plot_dependencies() -> None:
    pyproject = (ROOT / "pyproject.toml").read_text()
    for extra in ("zoo", "dev"):
        match = re.search(rf"^{extra} = \[(.*?)\]$", pyproject, re.MULTILINE | re.DOTALL)
        assert match is not None, extra
        assert '"rl_zoo3[plots]' in match.group(1), extra  # seaborn, pandas, scipy, rliable
        assert '"moviepy' in match.group(1), extra  # record_video
    pins = (ROOT / "constraints.txt").read_text()
    for package in ("seaborn", "pandas", "rliable", "scipy"):
        assert re.search(rf"^{package}==", pins, re.MULTILINE), package
    import rl_zoo3.plots  # noqa: F401  (imports seaborn, pandas, pytablewriter, scipy)


# ----------------------------------------------------------------------------------------------- every zoo command
@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """
    ``train`` of every sb3-es algorithm on Pendulum-v1 with its test-only config (small generations, two
    evaluations); the folder.
    """
    folder = tmp_path_factory.mktemp("zoo")
    for key in KEYS:
        zoo(
            *("train", "--algo", key, "--env", "Pendulum-v1", "-n", "800", "--seed", "0", "-f", str(folder / "logs")),
            *("-tb", str(folder / "tb"), "--eval-freq", "400", "--eval-episodes", "2", "--verbose", "0"),
            *("--num-threads", "1", "-conf", str(TEST_CONFIGS / f"{key}.yml")),
        )
    return folder


@pytest.mark.parametrize("key", KEYS)
def test_train_uses_the_given_config_file(runs: Path, key: str) -> None:
    # the runs above trained with the test-only file and its Pendulum-v1 entry, not the packaged file
    saved = runs / "logs" / key / "Pendulum-v1_1" / "Pendulum-v1" / "config.yml"
    config = yaml.load(saved.read_text(), Loader=yaml.UnsafeLoader)
    entry = yaml.safe_load((TEST_CONFIGS / f"{key}.yml").read_text())["Pendulum-v1"]
    assert {k: v for k, v in dict(config).items() if k in entry} == entry


@pytest.mark.parametrize("key", KEYS)
def test_train_writes_rl_zoos_layout(runs: Path, key: str) -> None:
    run_dir = runs / "logs" / key / "Pendulum-v1_1"
    model = ALGOS[key].load(run_dir / "Pendulum-v1.zip")
    assert model.num_timesteps >= 800
    evaluations = np.load(run_dir / "evaluations.npz")
    assert len(evaluations["timesteps"]) >= 2 and evaluations["results"].shape[1] == 2
    # one VecEnv with n_envs: 2 slots (rl-zoo's "ars" path would have a single training env)
    assert sorted(p.name for p in run_dir.glob("*.monitor.csv")) == ["0.monitor.csv", "1.monitor.csv"]
    config = yaml.load((run_dir / "Pendulum-v1" / "config.yml").read_text(), Loader=yaml.UnsafeLoader)
    assert dict(config)["n_envs"] == 2
    tb_name = {"ars_es": "ARS_ES_1"}.get(key, f"{ALGOS[key].__name__}_1")
    assert (runs / "tb" / "Pendulum-v1" / tb_name).is_dir()


def test_eval_freq_counts_env_steps_with_worker_processes(tmp_path: Path) -> None:
    """rl-zoo divides --eval-freq by n_envs, since SB3's EvalCallback counts calls: with worker processes, whose vec
    steps are of 4 slots, the evaluations still come every --eval-freq env steps."""
    zoo(
        *("train", "--algo", "ars_es", "--env", "Pendulum-v1", "-n", "2000", "--seed", "0", "-f", str(tmp_path)),
        *("--eval-freq", "400", "--eval-episodes", "1", "--verbose", "0", "--num-threads", "1"),
        *("-conf", str(TEST_CONFIGS / "ars_es.yml"), "-params", "evaluator:'processes'"),
    )
    timesteps = np.load(tmp_path / "ars_es" / "Pendulum-v1_1" / "evaluations.npz")["timesteps"]
    assert len(timesteps) >= 5 and timesteps.tolist() == list(range(400, 400 * len(timesteps) + 1, 400))


@pytest.mark.parametrize("key", KEYS)
def test_enjoy(runs: Path, key: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(runs)  # enjoy's default folder for sb3-es algorithms: logs
    zoo("enjoy", "--algo", key, "--env", "Pendulum-v1", "--no-render", "-n", "250", "--verbose", "1")
    out = capsys.readouterr().out
    assert f"logs/{key}/Pendulum-v1_1/Pendulum-v1.zip" in out and "Episode Reward" in out


@pytest.mark.parametrize("key", KEYS)
def test_record_video(runs: Path, key: str, tmp_path: Path) -> None:
    zoo(
        "record_video", "--algo", key, "--env", "Pendulum-v1", "-f", str(runs / "logs"), "-n", "20", "-o", str(tmp_path)
    )
    (video,) = tmp_path.glob("*.mp4")
    assert video.name.startswith(f"final-model-{key}-Pendulum-v1") and video.stat().st_size > 1000


def test_record_training(runs: Path, tmp_path: Path) -> None:
    # rl-zoo runs `python -m rl_zoo3.record_video` (once per model: the final one only here) and ffmpeg in new
    # processes, which must know the sb3-es keys
    run_dir = tmp_path / "logs" / "ars_es" / "Pendulum-v1_1"
    shutil.copytree(runs / "logs" / "ars_es" / "Pendulum-v1_1", run_dir, ignore=shutil.ignore_patterns("best_model*"))
    out = tmp_path / "videos"
    run(["-m", "sb3_es.zoo", "record_training", "--algo", "ars_es", "--env", "Pendulum-v1"]
        + ["-f", str(tmp_path / "logs"), "-n", "20", "-o", str(out)], tmp_path)  # fmt: skip
    assert (out / "training.mp4").stat().st_size > 1000


def test_all_plots_and_plot_train(runs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pickle = tmp_path / "results"
    zoo("all_plots", "-a", *KEYS, "-e", "Pendulum-v1", "-f", str(runs / "logs"), "--no-display", "-o", str(pickle))
    table = capsys.readouterr().out
    for key in KEYS:
        assert key.upper() in table
    assert "0.0 +/- 0.0" not in table  # every run was found and read
    assert pickle.with_suffix(".pkl").is_file()
    from matplotlib import pyplot as plt

    for key in KEYS:
        plt.close("all")
        zoo("plot_train", "-a", key, "-e", "Pendulum-v1", "-f", str(runs / "logs"), "-w", "2")
        assert plt.get_figlabels() == ["Training Episodic Reward"]
        (axes,) = plt.gcf().axes
        (curve,) = axes.get_lines()  # the run's smoothed episode returns, read from its monitor files
        assert curve.get_label() == "Pendulum-v1_1"
        rewards = np.asarray(curve.get_ydata())
        assert len(rewards) >= 2 and np.all(np.isfinite(rewards)) and np.all(rewards < 0), key
    plt.close("all")


def test_push_to_hub_uses_the_sb3_es_name(runs: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import huggingface_hub

    hf_push = importlib.import_module("huggingface_sb3.push_to_hub")  # the package exports a function of that name
    if not hasattr(hf_push, "generate_metadata"):
        # rl-zoo3 2.9.2's push_to_hub imports generate_metadata, which sb3-team-hf-integration 3.2 calls
        # _generate_metadata: rl-zoo's push_to_hub does not import at all there, for any algorithm
        monkeypatch.setattr(hf_push, "generate_metadata", hf_push._generate_metadata, raising=False)

    seen: dict[str, Any] = {}

    def create_repo(self: Any, repo_id: str, **kwargs: Any) -> None:
        seen["repo_id"] = repo_id
        raise ConnectionAbortedError("no network in the tests")

    monkeypatch.setattr(huggingface_hub.HfApi, "create_repo", create_repo)
    monkeypatch.chdir(runs)
    with pytest.raises(ConnectionAbortedError):
        zoo("push_to_hub", "--algo", "ars_es", "--env", "Pendulum-v1", "-f", "logs", "-orga", "someone", "--no-render")
    assert seen["repo_id"] == "someone/ars_es-Pendulum-v1"


def test_load_from_hub_uses_the_sb3_es_name(runs: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import huggingface_sb3

    run_dir = runs / "logs" / "ars_es" / "Pendulum-v1_1"
    metrics = tmp_path / "train_eval_metrics.zip"
    with zipfile.ZipFile(metrics, "w") as archive:
        archive.write(run_dir / "evaluations.npz", "evaluations.npz")
    files = {
        "ars_es-Pendulum-v1.zip": run_dir / "Pendulum-v1.zip",
        "config.yml": run_dir / "Pendulum-v1" / "config.yml",
        "args.yml": run_dir / "Pendulum-v1" / "args.yml",
        "env_kwargs.yml": run_dir / "Pendulum-v1" / "config.yml",
        "train_eval_metrics.zip": metrics,
    }
    asked: list[tuple[str, str]] = []

    def load_from_hub(repo_id: str, filename: str) -> str:
        asked.append((repo_id, filename))
        if filename not in files:
            from requests.exceptions import HTTPError

            raise HTTPError(f"{filename} not in the fake hub")
        return str(files[filename])

    monkeypatch.setattr(huggingface_sb3, "load_from_hub", load_from_hub)
    zoo("load_from_hub", "--algo", "ars_es", "--env", "Pendulum-v1", "-f", str(tmp_path / "logs"), "-orga", "someone")
    assert asked[0] == ("someone/ars_es-Pendulum-v1", "ars_es-Pendulum-v1.zip")
    model = ARS.load(tmp_path / "logs" / "ars_es" / "Pendulum-v1_1" / "Pendulum-v1.zip")
    assert model.num_timesteps >= 800


def test_ppo_through_the_same_entry_point(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    zoo(
        *("train", "--algo", "ppo", "--env", "Pendulum-v1", "-n", "64", "--seed", "0", "-f", str(tmp_path / "logs")),
        *("--eval-freq", "-1", "--verbose", "0", "--num-threads", "1"),
        *("-params", "n_steps:32", "batch_size:32", "n_epochs:1", "n_envs:2"),
    )
    assert f"{Path(rl_zoo3.__file__).parent / 'hyperparams' / 'ppo.yml'}" in capsys.readouterr().out
    assert (tmp_path / "logs" / "ppo" / "Pendulum-v1_1" / "Pendulum-v1.zip").is_file()


def test_continuing_applies_new_values(runs: Path, tmp_path: Path) -> None:
    trained = runs / "logs" / "ars_es" / "Pendulum-v1_1" / "Pendulum-v1.zip"
    assert ARS.load(trained).delta_std == 0.1  # the Pendulum-v1 entry of the test-only file
    zoo(
        *("train", "--algo", "ars_es", "--env", "Pendulum-v1", "-i", str(trained), "-n", "400", "--seed", "1"),
        *("-f", str(tmp_path / "logs"), "--eval-freq", "-1", "--verbose", "0"),
        *("-conf", str(TEST_CONFIGS / "ars_es.yml")),
        *("-params", "delta_std:0.05", "n_delta:1", "n_top:1"),
    )
    model = ARS.load(tmp_path / "logs" / "ars_es" / "Pendulum-v1_1" / "Pendulum-v1.zip")
    assert model.delta_std == 0.05 and model.strategy.delta_std == 0.05  # the value the last generation used
    assert model.strategy.n_delta == 1 and model.num_timesteps >= 400  # (rl-zoo restarts the step count)
    assert not np.array_equal(model.strategy.center, ARS.load(trained).strategy.center)  # trained on from there


# ----------------------------------------------------------------------------------------------- hyperparameter search
@pytest.mark.parametrize("key", KEYS)
def test_optimize_two_trials(key: str, tmp_path: Path) -> None:
    # CartPole-v1 for the population methods (short episodes whatever the sampled population), Pendulum-v1 for
    # REINFORCE (Box actions: n_bins is sampled). The budget, evaluated every half of it, is at most a generation or
    # two of the largest sampled population, so that it is evaluated a few times, not every few hundred steps.
    env_id, steps = ("Pendulum-v1", "400") if key == "reinforce" else ("CartPole-v1", "2000")
    extra = ["-params", "n_episodes:2"] if key == "reinforce" else []
    zoo(
        *("train", "--algo", key, "--env", env_id, "-optimize", "--n-trials", "2", "-n", steps),
        *("--n-evaluations", "2", "--eval-episodes", "1", "--no-optim-plots", "-f", str(tmp_path), "--seed", "0"),
        *("--n-startup-trials", "1", "--verbose", "0", "--num-threads", "1", *extra),
    )
    (report,) = (tmp_path / key).glob("report_*.csv")
    lines = report.read_text().splitlines()
    assert len(lines) == 3  # header + 2 trials
    sampled = {"ars_es": "n_delta_pow", "cmaes": "sigma", "pgpe": "stdev_init", "reinforce": "n_bins"}
    sampled.update(openes="population_size_pow", simple_es="elite_fraction")
    assert f"params_{sampled[key]}" in lines[0]


@pytest.mark.parametrize(
    "algo, env_id", [(algo, env_id) for algo in KEYS for env_id in QUICK_ENVS if env_id in shipped_envs(algo)]
)
def test_every_entry_builds_with_the_samplers_extreme_values(algo: str, env_id: str, tmp_path: Path) -> None:
    """A sampled value with an entry's other settings is a model the trial trains (rl-zoo's objective builds it
    outside its error handling, so one refused combination ends the whole search)."""
    zoo_manager = manager(algo, env_id, tmp_path, optimize_hyperparameters=True)
    assert zoo_manager.setup_experiment() is None
    probe = optuna.create_study().ask()
    SAMPLERS[algo](probe, zoo_manager.n_actions, zoo_manager.n_envs, {})
    for end in ("low", "high"):
        fixed = {
            name: distribution.choices[0 if end == "low" else -1]
            if isinstance(distribution, optuna.distributions.CategoricalDistribution)
            else getattr(distribution, end)
            for name, distribution in probe.distributions.items()
        }
        kwargs = {
            **zoo_manager._hyperparams,
            **SAMPLERS[algo](optuna.trial.FixedTrial(fixed), zoo_manager.n_actions, 1, {}),
        }
        env = zoo_manager.create_envs(zoo_manager.n_envs, no_log=True)
        try:
            ALGOS[algo](env=env, seed=None, verbose=0, **kwargs)
        finally:
            env.close()


def test_pruning_on_evaluations(tmp_path: Path) -> None:
    zoo_manager = manager("openes", "CartPole-v1", tmp_path, n_timesteps=4000, optimize_hyperparameters=True)
    zoo_manager.n_evaluations = 4
    assert zoo_manager.setup_experiment() is None
    sampler = optuna.samplers.RandomSampler(seed=0)
    study = optuna.create_study(sampler=sampler, direction="maximize", pruner=optuna.pruners.ThresholdPruner(lower=1e9))
    study.optimize(zoo_manager.objective, n_trials=1)
    (trial,) = study.trials
    assert trial.state == optuna.trial.TrialState.PRUNED
    assert list(trial.intermediate_values) == [1]  # stopped at its first evaluation (of 4 or more)
    kept = optuna.create_study(sampler=sampler, direction="maximize", pruner=optuna.pruners.NopPruner())
    kept.optimize(zoo_manager.objective, n_trials=1)
    # every 1,000 env steps until learn() ends, within one generation past 4,000 steps
    assert kept.trials[0].state == optuna.trial.TrialState.COMPLETE
    assert len(kept.trials[0].intermediate_values) >= 4


# ----------------------------------------------------------------------------------------------- benchmarks
def test_compare_writes_rl_zoos_layout(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    compare = load_script("compare")
    out = tmp_path / "cmp"
    # generations of 1,600 env steps (ARS, the file's Pendulum-v1 entry: n_delta 4) and 800 (CMA-ES: its file's
    # default entry, population 4 by --override): 2,000 steps take 3,200 and 2,400, each within one generation of
    # the budget
    report = compare.main(
        ["--algos", "ars_es", "cmaes", "--envs", "Pendulum-v1", "--seeds", "0", "1", "--steps", "2000"]
        + ["--eval-freq", "800", "--eval-episodes", "2", "--out", str(out), "--threshold", "Pendulum-v1=-2000"]
        + ["--override", "cmaes:population_size=4"]
    )
    for algo, steps in (("ars_es", 3200), ("cmaes", 2400)):
        for seed in (0, 1):
            folder = out / "logs" / algo / f"Pendulum-v1_1_seed{seed}"
            evaluations = np.load(folder / "evaluations.npz")
            # the start, the grid points below the budget, the end: as many evaluations for both algorithms
            assert evaluations["timesteps"].tolist() == [0, 800, 1600, steps]
            assert ALGOS[algo].load(folder / "Pendulum-v1.zip").num_timesteps == steps
    assert (out / "tb" / "Pendulum-v1" / "ARS_ES_1").is_dir() and (out / "tb" / "Pendulum-v1" / "CMAES_2").is_dir()
    assert (out / "plots" / "Pendulum-v1-wallclock.png").stat().st_size > 10_000
    text = report.read_text()
    assert "| ars_es (ARS) | 2 (0, 1) | 3,200 |" in text and "| cmaes (CMAES) | 2 (0, 1) | 2,400 |" in text
    assert "time to return ≥ -2000" in text and "--rliable --iqm" in text
    assert compare.main(["--out", str(out), "--report-only"]).is_file()  # redrawn from the files alone
    # rl-zoo's plots read the runs: learning curves, results table, rliable's IQM and bootstrap intervals
    capsys.readouterr()
    pickle = tmp_path / "all_plots"
    zoo(
        "all_plots",
        "-a",
        "ars_es",
        "cmaes",
        "-e",
        "Pendulum-v1",
        "-f",
        str(out / "logs"),
        "--no-display",
        "-o",
        str(pickle),
    )
    table = capsys.readouterr().out
    assert "ARS_ES" in table and "CMAES" in table and "0.0 +/- 0.0" not in table
    figure = tmp_path / "iqm.png"
    zoo("plot_from_file", "-i", f"{pickle}.pkl", "--rliable", "--iqm", "-o", str(figure), "--format", "png")
    assert "Computing bootstrap CI" in capsys.readouterr().out and figure.stat().st_size > 10_000


def test_compare_runs_sb3_contribs_ars_under_its_rl_zoo_key(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cmp"
    load_script("compare").main(
        ["--algos", "ars", "--envs", "Pendulum-v1", "--steps", "1000", "--eval-freq", "0", "--out", str(out)]
    )
    assert "--algos ars is sb3-contrib's ARS (rl-zoo's key, with rl-zoo's hyperparameters); sb3-es's is ars_es." in (
        capsys.readouterr().out
    )
    assert zoo_meaning("ars") == "sb3-contrib's ARS" and zoo_meaning("no_such_key") is None
    model = rl_zoo3.ALGOS["ars"].load(out / "logs" / "ars" / "Pendulum-v1_1_seed0" / "Pendulum-v1.zip")
    assert type(model).__module__.startswith("sb3_contrib") and model.num_timesteps >= 1000
    assert "n_delta" in (out / "configs" / "ars-Pendulum-v1.yml").read_text()  # rl-zoo's ars.yml entry


def test_compare_confirms_a_threshold_before_stopping(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    compare = load_script("compare")
    out = tmp_path / "cmp"
    # any policy scores above -2000 on Pendulum-v1: the start evaluation reaches it, 3 more episodes confirm it
    compare.main(
        ["--algos", "ars_es", "--envs", "Pendulum-v1", "--steps", "20000", "--eval-freq", "800", "--out", str(out)]
        + ["--eval-episodes", "2", "--threshold", "Pendulum-v1=-2000", "--stop-at-threshold"]
        + ["--confirm-episodes", "3", "--eval-envs", "2"]
    )
    folder = out / "logs" / "ars_es" / "Pendulum-v1_1_seed0"
    summary = json.loads((folder / "summary.json").read_text())
    (confirmation,) = summary["confirmations"]
    assert summary["eval_envs"] == 2 and np.load(folder / "evaluations.npz")["results"].shape == (2, 2)  # start and end
    assert summary["confirm_episodes"] == 3 and confirmation["env_steps"] == 0 and confirmation["mean_return"] > -2000
    assert summary["env_steps"] < 20000 and (folder / "confirmed_model.zip").is_file()
    text = (out / "results.md").read_text()
    assert "1/1 seeds; confirmed on 3 episodes" in text
    # the progress output says what the confirmation gave, when it happens
    printed = capsys.readouterr().out
    assert "3 confirmation episodes at 0 steps: " in printed and "(confirmed; threshold -2000)" in printed
    with pytest.raises(SystemExit, match="add it, with --threshold"):
        compare.main(["--algos", "ars_es", "--steps", "10", "--confirm-episodes", "3", "--out", str(out)])
    # An evaluation at which the time budget runs out is confirmed too (it used to end the run unconfirmed: a miss).
    out = tmp_path / "cmp_budget"
    compare.main(
        ["--algos", "ars_es", "--envs", "Pendulum-v1", "--seconds", "0.000001", "--eval-freq", "0", "--out", str(out)]
        + ["--eval-episodes", "2", "--threshold", "Pendulum-v1=-2000", "--stop-at-threshold"]
        + ["--confirm-episodes", "3", "--eval-envs", "2"]
    )
    summary = json.loads((out / "logs" / "ars_es" / "Pendulum-v1_1_seed0" / "summary.json").read_text())
    assert (
        len(summary["confirmations"]) == 1 and "1/1 seeds; confirmed on 3 episodes" in (out / "results.md").read_text()
    )
    # A run that ends below the threshold has its final model confirmed too (a policy whose episodes vary much can
    # hold it over many episodes while its last evaluation, on few, fell short); Pendulum-v1 never pays above 0.
    out = tmp_path / "cmp_final"
    capsys.readouterr()
    compare.main(
        ["--algos", "ars_es", "--envs", "Pendulum-v1", "--steps", "1000", "--eval-freq", "400", "--out", str(out)]
        + ["--eval-episodes", "2", "--threshold", "Pendulum-v1=1", "--stop-at-threshold"]
        + ["--confirm-episodes", "3", "--eval-envs", "2"]
    )
    summary = json.loads((out / "logs" / "ars_es" / "Pendulum-v1_1_seed0" / "summary.json").read_text())
    (confirmation,) = summary["confirmations"]
    assert confirmation["env_steps"] == summary["env_steps"] >= 1000 and confirmation["mean_return"] < 0
    assert "0/1 seeds" in (out / "results.md").read_text()
    assert "(not confirmed; threshold 1)" in capsys.readouterr().out


def test_compare_saves_the_vecnormalize_statistics_with_each_checkpoint(tmp_path: Path) -> None:
    """``last_model.zip`` comes with the training env's VecNormalize statistics where rl-zoo reads them back, so
    that ``--continue-from`` a run stopped before its end (rl-zoo writes them only at the end) keeps them."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    compare = load_script("compare")
    env = VecNormalize(make_vec_env("Pendulum-v1", n_envs=2))
    model = ARS("LinearPolicy", env, n_delta=2, seed=0, policy_kwargs=dict(normalize_observations=False))
    path = tmp_path / "Pendulum-v1" / "vecnormalize.pkl"
    recorder = compare.RecordingEvalCallback(
        VecNormalize(make_vec_env("Pendulum-v1", n_envs=1), training=False),
        eval_freq=400,
        n_eval_episodes=1,
        log_path=str(tmp_path),
        budget_seconds=None,
        progress=compare.Progress("test", None, None),
        vecnormalize_path=str(path),
    )
    model.learn(800, callback=recorder)
    saved = VecNormalize.load(str(path), make_vec_env("Pendulum-v1", n_envs=2))
    assert (tmp_path / "last_model.zip").is_file() and saved.obs_rms.count == env.obs_rms.count > 800


def test_compare_train_wrapper_wraps_the_training_envs_only(tmp_path: Path) -> None:
    compare = load_script("compare")
    zoo_manager = manager("ars_es", "Pendulum-v1", tmp_path, manager_cls=compare.TrainingWrapperManager)
    zoo_manager.train_wrapper = compare.parse_train_wrapper(
        "{gymnasium.wrappers.ClipReward: {min_reward: -0.5, max_reward: 0.5}}"
    )
    result = zoo_manager.setup_experiment()
    assert result is not None
    train_env, eval_env = result[0].get_env(), zoo_manager.create_envs(1, eval_env=True)
    assert train_env is not None
    # the same start state and action: the training env's reward is clipped, the evaluation env's is Pendulum's own
    train_env.seed(3)
    eval_env.seed(3)
    train_env.reset()
    eval_env.reset()
    action = np.array([[2.0]], dtype=np.float32)
    (raw,) = eval_env.step(action)[1]
    trained = train_env.step(np.repeat(action, train_env.num_envs, axis=0))[1][0]
    assert raw < -0.5 and trained == pytest.approx(-0.5)
    with pytest.raises(SystemExit, match="give an importable wrapper class"):
        compare.parse_train_wrapper("no_such_module.Wrapper")


def test_render_gif(runs: Path, tmp_path: Path) -> None:
    model = runs / "logs" / "ars_es" / "Pendulum-v1_1" / "Pendulum-v1.zip"
    out = tmp_path / "pendulum.gif"
    proc = run([str(ROOT / "benchmarks" / "render.py"), str(model), "--out", str(out), "--steps", "8"], tmp_path)
    assert "ARS on Pendulum-v1" in proc.stdout  # algorithm and env found from the save and rl-zoo's files
    import imageio.v3 as iio

    assert iio.imread(out).shape[0] == 9  # first frame + one per step
    # rl-zoo's --env-kwargs (args.yml) apply as in training; the video ends at the episode's last step, not on the
    # next episode's first frame (the env has reset after the last step)
    folder = tmp_path / "run"
    shutil.copytree(model.parent, folder)
    args_file = folder / "Pendulum-v1" / "args.yml"
    saved = yaml.load(args_file.read_text(), Loader=yaml.UnsafeLoader)
    saved["env_kwargs"] = {"max_episode_steps": 20}
    args_file.write_text(yaml.dump(saved))
    render = str(ROOT / "benchmarks" / "render.py")
    run([render, str(folder / model.name), "--out", str(out), "--steps", "50"], tmp_path)
    assert iio.imread(out).shape[0] == 20  # first frame + steps 1 to 19


# ----------------------------------------------------------------------------------------------- docs
def test_docs_walk_through_the_workflow() -> None:
    guide = (ROOT / "docs" / "guide" / "zoo.md").read_text()
    for command in ("train", "enjoy", "record_video", "record_training", "push_to_hub", "load_from_hub", "-optimize"):
        assert command in guide
    assert "all_plots" in guide and "plot_from_file" in guide
    # the script that runs the workflow from a built wheel runs every command, and the guide shows its commands
    script = (ROOT / "benchmarks" / "zoo_workflow.sh").read_text()
    ran = set(re.findall(r"^\s*(?:MPLBACKEND=Agg )?zoo (\w+)", script, re.MULTILINE))
    ran |= set(re.findall(r"/sb3-es\" (\w+)", script))
    assert {"train", "enjoy", "record_video", "record_training", "plot_train", "all_plots", "plot_from_file"} <= ran
    assert ran <= set(SCRIPTS) and "-optimize --n-trials 2" in script
    section = guide.split("## The whole workflow from a built wheel")[1]
    for command in ran:
        assert re.search(rf"(python -m sb3_es\.zoo|sb3-es) {command} ", section), command
    assert "-optimize --n-trials 2" in section and "PLACEHOLDER" not in guide and "WORKFLOW_RUN" not in guide
    # which curve to hold against PPO
    assert "`rollout/ep_rew_mean` averages the perturbed candidates" in guide
    assert "`eval/mean_reward`" in guide


def test_workflow_small_params_fit_the_entries_it_trains(tmp_path: Path) -> None:
    """benchmarks/zoo_workflow.sh trains every key on Pendulum-v1 with ``-params $(small KEY)``: with the packaged
    entry it uses (every ars_es entry, should Pendulum-v1's change), those values build a model (``n_top`` at most
    ``n_delta``, a population that fits ``n_envs``, ...)."""
    script = (ROOT / "benchmarks" / "zoo_workflow.sh").read_text()
    body = script.split("small() {")[1].split("\n}\n")[0]
    cases = dict(re.findall(r'^\s*([\w*]+)\) echo "([^"]*)" ;;', body, re.MULTILINE))
    for key in KEYS:
        params = cases.get(key, cases["*"])
        assert eval_params(params.split()) == SMALL[key], key
        data = yaml.safe_load(default_conf_file(key).read_text())
        entries = list(data) if key == "ars_es" else ["Pendulum-v1" if "Pendulum-v1" in data else "default"]
        for entry in entries:
            conf = tmp_path / f"{key}.yml"
            values = {k: v for k, v in data[entry].items() if k != "max_episode_steps"}  # the entry's env's episodes
            conf.write_text(yaml.safe_dump({"Pendulum-v1": values}))
            zoo_manager = manager(key, "Pendulum-v1", tmp_path, config=str(conf), hyperparams=dict(SMALL[key]))
            result = zoo_manager.setup_experiment()
            assert result is not None, (key, entry)
            result[0].get_env().close()  # type: ignore[union-attr]
    assert f"`{cases['ars_es']}` for `ars_es`" in (ROOT / "docs" / "guide" / "zoo.md").read_text()  # its $SMALL


#: ``(algorithm, hyperparameter)``: every value that takes a schedule (rl-zoo converts ``lin_X`` for
#: ``learning_rate`` and ``delta_std`` itself, and hands ``sigma`` on as the string).
SCHEDULED = [
    ("ars_es", "learning_rate"),
    ("ars_es", "delta_std"),
    ("openes", "learning_rate"),
    ("openes", "sigma"),
    ("simple_es", "sigma"),
    ("reinforce", "learning_rate"),
]


@pytest.mark.parametrize(("algo", "name"), SCHEDULED, ids=[f"{algo}-{name}" for algo, name in SCHEDULED])
def test_lin_strings_are_linear_schedules(algo: str, name: str) -> None:
    policy = "MlpPolicy" if algo == "reinforce" else "LinearPolicy"
    model = ALGOS[algo](policy, "Pendulum-v1", **{name: "lin_0.1"})
    schedule = getattr(model, name)
    assert callable(schedule) and schedule(1.0) == pytest.approx(0.1) and schedule(0.25) == pytest.approx(0.025)


@pytest.mark.parametrize("value", ["abc", "1 +"])
def test_a_params_value_that_is_not_python_is_said_in_one_line(value: str) -> None:
    # rl-zoo evaluates each value: a NameError or SyntaxError traceback
    with pytest.raises(
        UsageError, match=r"^train: a key:value's value is not a Python expression \((Name|Syntax)Error"
    ):
        prepare_args("train", ["--algo", "ars_es", "--env", "Pendulum-v1", "-params", f"n_delta:{value}"])
