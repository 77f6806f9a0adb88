"""Each script in ``examples/`` runs end to end as its docstring says (train, save, evaluate, print where the model
and the TensorBoard logs are), shrunk to one generation of 20-step episodes."""

from __future__ import annotations

import re
import runpy
import sys
from collections.abc import Iterator
from pathlib import Path

import gymnasium as gym
import pytest
import shimmy  # noqa: F401  (registers the dm_control/ envs, whose episodes are shortened below)
import torch as th

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: Per script, the arguments that make it small (its own defaults train for hours).
SMALL_ARGUMENTS = {
    "ars_bipedal_walker.py": ["--n-envs", "2"],
    "ars_dm_control_walker.py": ["--n-envs", "2", "--policy", "MlpPolicy", "--layer-norm", "--max-episode-steps", "20"],
    "cmaes_bipedal_walker.py": ["--population-size", "4", "--eval-episodes", "1", "--checkpoint-freq", "40"],
    "openes_bipedal_walker.py": ["--population-size", "4", "--eval-episodes", "1"],
    "reinforce_bipedal.py": ["--n-envs", "2", "--n-episodes", "2"],
}
EPISODE_STEPS = 20


@pytest.fixture
def short_episodes(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Every example env ends its episodes after ``EPISODE_STEPS`` steps (gym.make's TimeLimit); torch threads kept."""
    for env_id in ("BipedalWalker-v3", "dm_control/walker-walk-v0"):
        monkeypatch.setattr(gym.registry[env_id], "max_episode_steps", EPISODE_STEPS)
    threads = th.get_num_threads()
    yield
    th.set_num_threads(threads)


def run_example(name: str, *arguments: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "argv", [name, *arguments])
    runpy.run_path(str(EXAMPLES / name), run_name="__main__")


def test_every_example_is_run() -> None:
    assert sorted(SMALL_ARGUMENTS) == sorted(path.name for path in EXAMPLES.glob("*.py"))


@pytest.mark.parametrize("name", sorted(SMALL_ARGUMENTS))
@pytest.mark.usefixtures("short_episodes")
def test_example_trains_saves_and_says_where(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    save_path = tmp_path / "model.zip"
    common = ["--timesteps", "1", "--tensorboard-log", str(tmp_path / "tb"), "--save-path", str(save_path)]
    run_example(name, *common, *SMALL_ARGUMENTS[name], monkeypatch=monkeypatch)
    out = capsys.readouterr().out
    assert save_path.is_file()
    assert re.search(r"mean return over \d+ episodes.*: -?\d+\.\d \+/- \d+\.\d", out), out
    logs = re.search(r"TensorBoard logs in (\S+)", out)
    assert logs is not None and Path(logs[1]).is_relative_to(tmp_path / "tb"), out
    assert list(Path(logs[1]).glob("events.out.tfevents.*")), out
    if name == "cmaes_bipedal_walker.py":  # its docstring's resume command goes on from the save
        assert list((tmp_path / "runs" / "cmaes_checkpoints").glob("cmaes_bipedal_walker_*_steps.zip"))
        run_example(name, *common, "--resume", str(save_path), monkeypatch=monkeypatch)
        assert re.search(r"resuming .*model\.zip at \d+ steps", capsys.readouterr().out)
