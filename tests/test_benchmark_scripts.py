"""The benchmark scripts without tests of their own (headline, ars_paper, walker_gait, throughput, render, pilot,
cmaes_timing, reinforce_continuous, pair_noise): what they refuse before any work, with the message that says the
fix, and what the headline records."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path
from types import ModuleType

import pytest
import torch

from sb3_es import ARS, PGPE

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def load_registered(name: str) -> ModuleType:
    """:func:`test_zoo.load_script`, the module also registered in ``sys.modules`` (dataclasses need it)."""
    if str(BENCHMARKS) not in sys.path:
        sys.path.append(str(BENCHMARKS))  # the scripts import common as a script does
    spec = importlib.util.spec_from_file_location(f"benchmarks_{name}", BENCHMARKS / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = sys.modules[spec.name] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    ("script", "argv", "message"),
    [
        ("headline", ["--steps", "-5"], "--steps -5: it must be positive"),
        ("headline", ["--set", "n_delta"], "argument --set: 'n_delta' is not KEY=VALUE; give one such as n_delta=16"),
        ("headline", ["--algo", "Foo"], "invalid choice: 'Foo' (choose from 'ARS', 'CMAES', 'OpenES', 'PGPE', "),
        (
            "headline",
            ["--set", "n_deltaa=3"],
            "--set n_deltaa: not a constructor argument of ARS (it takes alive_bonus_offset, common_seeds, delta_std",
        ),
        ("headline", ["--set", "seed=3"], "--set seed: give it with --seeds"),
        # refused before any training: the env, the policy and the values the constructor checks
        ("headline", ["--env", "FooEnv-v0"], "ARS('MlpPolicy', 'FooEnv-v0', ...): Environment `FooEnv` doesn't exist"),
        ("headline", ["--policy", "FooPolicy"], "Policy 'FooPolicy' unknown: ARS's policies are LinearPolicy"),
        ("headline", ["--set", "n_delta=abc"], "n_delta='abc': it must be a whole number"),
        ("headline", ["--set", "n_delta=[1,"], "argument --set: 'n_delta=[1,': '[1,' is not a YAML value"),
        (
            "ars_paper",
            ["--variants", "V1,v2"],
            "argument --variants: unknown variant 'v2'; give V1 or V2, comma-separated",
        ),
        ("ars_paper", ["--max-seconds", "0"], "--max-seconds 0: it must be positive"),
        ("walker_gait", ["model.zip", "--episodes", "0"], "--episodes 0: it must be at least 1"),
        ("walker_gait", ["model.zip"], "model.zip: no such model; give a saved model's .zip file"),
        ("pair_noise", ["model.zip", "Pendulum-v1"], "model.zip: no such model; give a saved model's .zip file"),
        ("walker_gait", ["model.zip", "--algo", "Foo"], "invalid choice: 'Foo' (choose from 'ARS', "),
        ("throughput", ["--seconds", "0", "--warmup", "0"], "--seconds 0: it must be positive"),
        ("throughput", ["--warmup", "-1"], "--warmup -1: it must be 0 or more"),
        ("pilot", ["Foo", "{n_delta: 4}", "--every", "0"], "--every 0: it must be positive; Foo: not an sb3-es class"),
        ("pilot", ["ARS", "{n_delta: 4}"], "'{n_delta: 4}': not JSON"),
        ("cmaes_timing", ["--generations", "0"], "--generations 0: it must be positive"),
        ("reinforce_continuous", ["--workers", "0", "--env", "Foo-v1"], "--workers 0: it must be positive; --env Foo"),
        ("render", ["model.zip", "--out", "b.avi"], "--out b.avi: unsupported output; give a .gif or .mp4 file"),
    ],
)
def test_scripts_refuse_bad_arguments(
    script: str, argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit):
        load_registered(script).main(argv)
    assert message in capsys.readouterr().err


def test_walker_gait_takes_class_names_and_rl_zoo_keys() -> None:
    algorithms = load_registered("walker_gait").ALGORITHMS
    assert algorithms["ARS"] is algorithms["ars_es"] is ARS and algorithms["PGPE"] is algorithms["pgpe"] is PGPE
    assert "ars" not in algorithms  # rl-zoo's "ars" is sb3-contrib's ARS


def test_headline_records_the_commit_of_the_sb3_es_it_ran(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Run from outside the repository, the record names the sb3_es source's commit, not the working directory's."""
    monkeypatch.chdir(tmp_path)
    argv = [
        "--env",
        "CartPole-v1",
        "--steps",
        "100",
        "--seeds",
        "0",
        "--episodes",
        "1",
        "--set",
        "n_delta=1",
        "n_top=1",
    ]
    threads = torch.get_num_threads()
    try:
        load_registered("headline").main([*argv, "--out", str(tmp_path)])
    finally:
        torch.set_num_threads(threads)  # the script uses one thread
    record = json.loads((tmp_path / "headline.json").read_text())
    assert record["commit"] == load_registered("common").source_commit()
    assert record["kwargs"] == {"n_delta": 1, "n_top": 1} and record["runs"][0]["env_steps"] >= 100


@pytest.mark.parametrize(
    ("algo", "settings"), [("PPO", ["n_steps=64", "batch_size=32"]), ("contrib.ARS", ["n_delta=1"])]
)
def test_headline_runs_the_line_with_ppo_and_sb3_contribs_ars(algo: str, settings: list[str], tmp_path: Path) -> None:
    """The same measurement with SB3's PPO and sb3-contrib's ARS, to compare the defaults at one budget."""
    argv = ["--algo", algo, "--env", "CartPole-v1", "--steps", "64", "--seeds", "0", "--episodes", "1"]
    threads = torch.get_num_threads()
    try:
        load_registered("headline").main([*argv, "--set", *settings, "--out", str(tmp_path)])
    finally:
        torch.set_num_threads(threads)
    record = json.loads((tmp_path / "headline.json").read_text())
    assert record["args"]["algo"] == algo and record["runs"][0]["env_steps"] >= 64
