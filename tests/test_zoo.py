"""rl-baselines3-zoo integration (sb3_es.zoo), the hyperparameter files, benchmarks/compare.py and render.py."""

from __future__ import annotations

import argparse
import csv
import importlib.util
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
import torch
import yaml

pytest.importorskip("rl_zoo3")

import rl_zoo3  # noqa: E402
import rl_zoo3.enjoy  # noqa: E402
import rl_zoo3.exp_manager  # noqa: E402
import rl_zoo3.train  # noqa: E402

from sb3_es import ARS  # noqa: E402
from sb3_es.zoo import (  # noqa: E402
    HYPERPARAMS_DIR,
    ExperimentManager,
    default_conf_file,
    prepare_args,
    register,
    sb3_es_algos,
)

ROOT = Path(__file__).resolve().parent.parent
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
#: Envs whose models are built in the tests (the MuJoCo/dm_control entries are parsed, not built).
QUICK_ENVS = ("BipedalWalker-v3", "Pendulum-v1", "LunarLanderContinuous-v3")
ALGOS = ("ars", "openes", "cmaes", "reinforce")
#: Algorithms whose files have entries for QUICK_ENVS only (pgpe.yml: untested settings, run by the lead).
QUICK_ONLY_ALGOS = ("pgpe",)


def manager(algo: str, env_id: str, folder: Path, n_timesteps: int = 0, **kwargs: Any) -> ExperimentManager:
    """An sb3-es ExperimentManager as rl_zoo3.train builds it, logging under ``folder``."""
    register()
    config = str(default_conf_file(algo)) if algo in sb3_es_algos() else None
    args = argparse.Namespace(algo=algo, env=env_id, env_kwargs=None)
    return ExperimentManager(
        args,
        algo,
        env_id,
        str(folder),
        n_timesteps=n_timesteps,
        eval_freq=-1,
        seed=0,
        log_interval=-1,  # rl_zoo3.train's default (the constructor's 0 would mean "every 0 updates")
        verbose=0,
        config=config,
        **kwargs,
    )


def run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """Run a command with this interpreter; fail with its output."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run(
        [sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300, check=False
    )
    assert proc.returncode == 0, f"{args} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


def load_script(name: str) -> ModuleType:
    """Import benchmarks/<name>.py as a module."""
    spec = importlib.util.spec_from_file_location(f"benchmarks_{name}", ROOT / "benchmarks" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ----------------------------------------------------------------------------------------------- registration
def test_register_adds_algorithms_everywhere() -> None:
    ours = register()
    assert {"ars", "openes", "cmaes"} <= set(ours)
    for module in (rl_zoo3, rl_zoo3.train, rl_zoo3.exp_manager, rl_zoo3.enjoy):
        for name, cls in ours.items():
            assert module.ALGOS[name] is cls
    assert rl_zoo3.ALGOS["ars"] is ARS
    assert rl_zoo3.train.ExperimentManager is ExperimentManager
    assert rl_zoo3.ALGOS["ppo"].__module__.startswith("stable_baselines3")


def test_prepare_args_defaults() -> None:
    conf = str(HYPERPARAMS_DIR / "ars.yml")
    assert prepare_args("train", ["--algo", "ars", "--env", "Pendulum-v1"])[-2:] == ["--conf-file", conf]
    assert prepare_args("train", ["--algo=openes"])[-1] == str(HYPERPARAMS_DIR / "openes.yml")
    given = ["--algo", "ars", "-conf", "mine.yml"]
    assert prepare_args("train", given) == given
    assert prepare_args("train", ["--algo", "ars", "--conf-file=mine.yml"]) == ["--algo", "ars", "--conf-file=mine.yml"]
    # rl-zoo's own algorithms keep rl-zoo's own hyperparameters
    assert prepare_args("train", ["--algo", "ppo", "--env", "Pendulum-v1"]) == ["--algo", "ppo", "--env", "Pendulum-v1"]
    assert prepare_args("train", ["--env", "Pendulum-v1"]) == ["--env", "Pendulum-v1"]
    assert prepare_args("enjoy", ["--algo", "ars"])[-2:] == ["-f", "logs"]
    assert prepare_args("enjoy", ["--algo", "ars", "-f", "x"]) == ["--algo", "ars", "-f", "x"]


# ----------------------------------------------------------------------------------------------- YAML files
@pytest.mark.parametrize("algo", ALGOS)
def test_hyperparameter_files_parse(algo: str, tmp_path: Path) -> None:
    path = HYPERPARAMS_DIR / f"{algo}.yml"
    text = path.read_text()
    data = yaml.safe_load(text)
    assert set(ENVS) <= set(data), f"{path} misses {set(ENVS) - set(data)}"
    lines = text.splitlines()
    for env_id in ENVS:
        # each entry is preceded by a comment saying where its values come from
        index = lines.index(f"{env_id}:")
        assert lines[index - 1].startswith("#"), f"{path}: no source comment above {env_id}"
        entry = data[env_id]
        assert entry["policy"] in ("LinearPolicy", "MlpPolicy", "MultiInputPolicy")
        assert entry["n_timesteps"] > 0
        assert "normalize" not in entry  # observation normalization is done by the policies
    if algo not in sb3_es_algos():
        pytest.skip(f"{algo} is not importable")
    for env_id in ENVS:
        # rl-zoo's own parsing and preprocessing (schedules, policy_kwargs strings, n_envs)
        zoo = manager(algo, env_id, tmp_path)
        hyperparams, _ = zoo.read_hyperparameters()
        processed, *_ = zoo._preprocess_hyperparams(hyperparams)
        assert "n_timesteps" not in processed and "n_envs" not in processed
        assert isinstance(processed.get("policy_kwargs", {}), dict)
        if "learning_rate" in processed:
            assert isinstance(processed["learning_rate"], float)  # kept a float (OpenES decays it)


@pytest.mark.parametrize("env_id", QUICK_ENVS)
@pytest.mark.parametrize("algo", ALGOS + QUICK_ONLY_ALGOS)
def test_entries_build_models(algo: str, env_id: str, tmp_path: Path) -> None:
    if algo not in sb3_es_algos():
        pytest.skip(f"{algo} is not importable")
    zoo = manager(algo, env_id, tmp_path)
    result = zoo.setup_experiment()
    assert result is not None
    model, saved = result
    try:
        assert type(model) is sb3_es_algos()[algo]
        assert model.get_env().num_envs == saved.get("n_envs", 1)  # type: ignore[union-attr]
        assert model.device.type == "cpu"
    finally:
        model.get_env().close()  # type: ignore[union-attr]


# ----------------------------------------------------------------------------------------------- ARS special case
def test_ars_n_envs_2_gets_a_vec_env_and_no_async_eval(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def no_async_eval(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("rl-zoo's AsyncEval path was taken for sb3-es's ARS")

    monkeypatch.setattr(rl_zoo3.exp_manager, "AsyncEval", no_async_eval)
    zoo = manager("ars", "Pendulum-v1", tmp_path, n_timesteps=1600)
    result = zoo.setup_experiment()
    assert result is not None
    model, _ = result
    assert zoo.n_envs == 2 and model.get_env().num_envs == 2  # type: ignore[union-attr]
    zoo.learn(model)  # rl-zoo's learn(): would build AsyncEval for "ars" with n_envs > 1
    assert model.num_timesteps >= 1600
    assert zoo.n_envs == 2


def test_optimize_is_refused(tmp_path: Path) -> None:
    zoo = manager("ars", "Pendulum-v1", tmp_path, optimize_hyperparameters=True)
    with pytest.raises(ValueError, match="not supported"):
        zoo.setup_experiment()


# ----------------------------------------------------------------------------------------------- command line
@pytest.fixture(scope="module")
def trained_ars(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``python -m sb3_es.zoo train --algo ars`` on Pendulum-v1 (n_envs: 2 in ars.yml); the log folder."""
    folder = tmp_path_factory.mktemp("zoo")
    run(
        ["-m", "sb3_es.zoo", "train", "--algo", "ars", "--env", "Pendulum-v1", "-n", "2000", "--seed", "0"]
        + ["-f", "logs", "--n-eval-envs", "1", "--eval-freq", "-1", "--verbose", "0"],
        folder,
    )
    return folder


def test_train_command_writes_model(trained_ars: Path) -> None:
    run_dir = trained_ars / "logs" / "ars" / "Pendulum-v1_1"
    assert (run_dir / "Pendulum-v1.zip").is_file()
    # two monitor files: one VecEnv with 2 slots (rl-zoo's ARS path would have a single training env)
    assert sorted(p.name for p in run_dir.glob("*.monitor.csv")) == ["0.monitor.csv", "1.monitor.csv"]
    config = yaml.load((run_dir / "Pendulum-v1" / "config.yml").read_text(), Loader=yaml.UnsafeLoader)
    assert dict(config)["n_envs"] == 2
    model = ARS.load(run_dir / "Pendulum-v1.zip")
    assert model.num_timesteps >= 2000


def test_enjoy_command(trained_ars: Path) -> None:
    proc = run(
        ["-m", "sb3_es.zoo", "enjoy", "--algo", "ars", "--env", "Pendulum-v1", "--no-render", "-n", "250"], trained_ars
    )
    assert "Episode Reward" in proc.stdout


def test_ppo_through_the_same_entry_point(tmp_path: Path) -> None:
    proc = run(
        ["-m", "sb3_es.zoo", "train", "--algo", "ppo", "--env", "Pendulum-v1", "-n", "64", "--seed", "0"]
        + ["-f", "logs", "--eval-freq", "-1", "--verbose", "0", "--num-threads", "1"]
        + ["-params", "n_steps:32", "batch_size:32", "n_epochs:1", "n_envs:2"],
        tmp_path,
    )
    assert f"{Path(rl_zoo3.__file__).parent / 'hyperparams' / 'ppo.yml'}" in proc.stdout  # rl-zoo's own file
    assert (tmp_path / "logs" / "ppo" / "Pendulum-v1_1" / "Pendulum-v1.zip").is_file()


# ----------------------------------------------------------------------------------------------- benchmarks
def test_compare_tiny_budget(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    compare = load_script("compare")
    out = tmp_path / "cmp"
    threads = torch.get_num_threads()  # compare.py sets 1 thread (its default): restore it for the other tests
    try:
        report = compare.main(
            ["--algos", "ars", "ppo", "--envs", "Pendulum-v1", "--seeds", "0", "--steps", "1600", "--eval-freq", "800"]
            + ["--eval-episodes", "1", "--out", str(out), "--threshold", "Pendulum-v1=-2000"]
            + ["--override", "ppo:n_steps=64", "ppo:batch_size=64", "ppo:n_epochs=1", "ppo:n_envs=2"]
        )
    finally:
        torch.set_num_threads(threads)
    tb = out / "tb" / "Pendulum-v1"
    assert (tb / "ARS_1").is_dir() and (tb / "PPO_1").is_dir()
    assert list((tb / "ARS_1").glob("events.out.tfevents.*"))
    for algo in ("ars", "ppo"):
        with (out / "runs" / "Pendulum-v1" / algo / "seed0" / "eval.csv").open() as f:
            rows = list(csv.DictReader(f))
        assert float(rows[0]["env_steps"]) == 0  # evaluation before training
        assert float(rows[-1]["env_steps"]) >= 1600  # and at the end
        assert len(rows) >= 3
    assert (out / "plots" / "Pendulum-v1.png").stat().st_size > 10_000
    text = report.read_text()
    assert "| ARS | 1 (0) |" in text and "| PPO | 1 (0) |" in text
    assert "time to return ≥ -2000" in text
    assert (out / "configs" / "ppo-Pendulum-v1.yml").is_file()
    # the report can be redrawn from the files alone
    assert compare.main(["--out", str(out), "--report-only"]).is_file()


def test_render_gif(trained_ars: Path, tmp_path: Path) -> None:
    pytest.importorskip("imageio")
    pytest.importorskip("pygame")
    model = trained_ars / "logs" / "ars" / "Pendulum-v1_1" / "Pendulum-v1.zip"
    out = tmp_path / "pendulum.gif"
    proc = run([str(ROOT / "benchmarks" / "render.py"), str(model), "--out", str(out), "--steps", "8"], tmp_path)
    assert "ARS on Pendulum-v1" in proc.stdout  # algorithm and env found from the save and rl-zoo's files
    import imageio.v3 as iio

    assert iio.imread(out).shape[0] == 9  # first frame + one per step
