"""The ``sb3-es`` command: ``quickstart`` (the README's first command) and rl-zoo's scripts with rl-zoo's flags."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Any

import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from sb3_es import ARS, REINFORCE
from sb3_es.cli import main
from sb3_es.zoo.registry import UsageError


def test_quickstart_writes_logs_and_model(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    main(["quickstart", "-n", "4000", "-f", str(tmp_path)])  # two generations, fewer than its log interval
    out = capsys.readouterr().out
    run_dir = tmp_path / "ARS_ES_1"
    model_path = tmp_path / "ars_es_Swimmer-v5.zip"
    assert str(model_path.resolve()) in out and f"TensorBoard logs: {run_dir.resolve()}" in out
    assert ARS.load(model_path).num_timesteps >= 4000
    (events,) = run_dir.glob("events.out.tfevents.*")
    scalars = EventAccumulator(str(events)).Reload().Tags()["scalars"]
    assert "rollout/ep_rew_mean" in scalars  # a short run's TensorBoard file is not empty


def test_quickstart_former_option_names(tmp_path: Path) -> None:
    main(["quickstart", "--timesteps", "2000", "--log-dir", str(tmp_path), "--seed", "0"])  # docs and Makefile
    assert ARS.load(tmp_path / "ars_es_Swimmer-v5.zip").num_timesteps >= 2000


def test_commands_forward_to_the_zoo(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    main(
        [
            *("train", "--algo", "reinforce", "--env", "CartPole-v1", "-n", "1000", "--seed", "0"),
            *("-params", "n_episodes:4", "n_envs:2", "--eval-freq", "-1", "--verbose", "0"),
        ]
    )
    model = REINFORCE.load(tmp_path / "logs" / "reinforce" / "CartPole-v1_1" / "CartPole-v1.zip")
    assert model.n_episodes == 4 and model.num_timesteps >= 1000 and model.get_env() is None
    # rl-zoo's enjoy has --n-envs, which the former train flags' check must leave to it
    observations: list[tuple[int, ...]] = []
    predict = REINFORCE.predict

    def spy(self: REINFORCE, observation: Any, *args: Any, **kwargs: Any) -> Any:
        observations.append(observation.shape)
        return predict(self, observation, *args, **kwargs)

    monkeypatch.setattr(REINFORCE, "predict", spy)
    capsys.readouterr()
    main(["enjoy", "--algo", "reinforce", "--env", "CartPole-v1", "--no-render", "-n", "50", "--n-envs", "2"])
    assert f"Loading {Path('logs', 'reinforce', 'CartPole-v1_1', 'CartPole-v1.zip')}" in capsys.readouterr().out
    assert observations == [(2, 4)] * 50  # the trained model acted 50 steps on 2 envs


@pytest.mark.parametrize(
    "args, hint",
    [
        (["--timesteps", "1000"], "--timesteps -> -n N"),
        (["--log-dir", "runs"], "--log-dir -> -f FOLDER"),
        (["--hyperparams", '{"n_episodes": 4}'], "-params key:value"),
        (["--n-envs", "4", "--subproc"], "--n-envs -> -params n_envs:N; --subproc -> --vec-env subproc"),
        (["--policy", "LinearPolicy"], "--policy -> -params policy:\"'NAME'\""),
    ],
)
def test_former_train_flags_say_what_to_use(args: list[str], hint: str) -> None:
    with pytest.raises(SystemExit, match=hint):
        main(["train", "--algo", "reinforce", "--env", "CartPole-v1", *args])


def test_unknown_algorithm(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:  # rl-zoo's own argparse error
        main(["train", "--algo", "nope", "--env", "CartPole-v1"])
    assert stop.value.code == 2
    assert "argument --algo: invalid choice: 'nope'" in capsys.readouterr().err


def test_quickstart_refuses_a_budget_below_one(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["quickstart", "-n", "-5"])
    assert "-n -5: give a positive number of env steps" in capsys.readouterr().err


@pytest.mark.parametrize("seed", ["-1", "4294967296"])
def test_quickstart_refuses_a_seed_out_of_range(seed: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["quickstart", "-n", "100", "--seed", seed])
    assert stop.value.code == 2  # a usage error, before any env is built
    assert f"--seed {seed}: give an integer in [0, 2**32 - 1]" in capsys.readouterr().err


def test_abbreviated_and_attached_options_are_read_as_rl_zoo_reads_them(tmp_path: Path) -> None:
    from sb3_es.zoo.commands import prepare_args

    args = prepare_args("train", ["--alg", "ars_es", "--env", "CartPole-v1"])
    assert args[-2] == "--conf-file" and args[-1].endswith("ars_es.yml")  # the packaged file, as with --algo
    (tmp_path / "ars_es").mkdir()
    assert prepare_args("enjoy", ["--algo", "ars_es", "--env", "CartPole-v1", f"-f{tmp_path}"])[-1] == f"-f{tmp_path}"
    with pytest.raises(UsageError, match=rf"no folder {tmp_path}/x/ars_es \(-f {tmp_path}/x\)"):  # -fPATH read too
        prepare_args("enjoy", ["--algo", "ars_es", "--env", "CartPole-v1", f"-f{tmp_path}/x"])
    with pytest.raises(UsageError, match="--algo ars is sb3-contrib's ARS"):
        prepare_args("train", ["--alg", "ars", "--env", "CartPole-v1"])
    # rl-zoo's single-dash long options are abbreviated too: the user's file is kept
    mine = tmp_path / "mine.yml"
    mine.write_text("Pendulum-v1:\n  n_timesteps: 1000\n  policy: 'LinearPolicy'\n")
    assert prepare_args("train", ["--algo", "ars_es", "--env", "Pendulum-v1", "-con", str(mine)])[-2:] == [
        "-con",
        str(mine),
    ]


def test_trial_id_0_is_refused_and_a_trial_id_is_said(capsys: pytest.CaptureFixture[str]) -> None:
    from sb3_es.zoo.commands import prepare_args

    study = ["--storage", "sqlite:///s.db", "--study-name", "s"]
    for zero in ("0", "00"):  # argparse reads both as 0
        with pytest.raises(UsageError, match=rf"--trial-id {zero}: rl-zoo reads a trial id of 0 as no trial") as info:
            prepare_args("train", ["--algo", "openes", "--env", "CartPole-v1", *study, "--trial-id", zero])
        # the keyword arguments, not the study's stored names (population_size_pow, ...), which -params refuses
        assert "CONVERTERS['openes'](optuna.load_study(study_name='s', storage='sqlite:///s.db')" in str(info.value)
    with pytest.raises(UsageError, match=r"--trial-id 3 needs --storage and --study-name: without both, rl-zoo"):
        prepare_args("train", ["--algo", "openes", "--env", "CartPole-v1", "--trial-id", "3", *study[:2]])
    with pytest.raises(UsageError, match=r"--storage sqlite:///s.db: there is no file s.db, so no study 's'"):
        prepare_args("train", ["--algo", "openes", "--env", "CartPole-v1", *study, "--trial-id=3"])
    # with the study there, the line naming the trial's values: tests/test_zoo.py


def test_a_pgpe_search_with_another_optimizer_than_clipup_is_refused() -> None:
    # the sampler draws ClipUp's max_speed, which PGPE refuses with Adam: every trial would fail
    from sb3_es.zoo.commands import prepare_args

    search = ["--algo", "pgpe", "--env", "CartPole-v1", "-optimize", "-params", "optimizer:'adam'"]
    with pytest.raises(UsageError, match=r"-optimize samples PGPE's ClipUp max_speed, which optimizer='adam' does"):
        prepare_args("train", [*search, "center_learning_rate:0.01"])
    prepare_args("train", search[:-3])  # the entry's ClipUp


def test_quickstart_prints_commands_that_run_from_this_shell(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # after `make train` the venv's bin/ is not on PATH: "sb3-es train ..." was "command not found"; a folder with a
    # space broke both printed commands
    folder = tmp_path / "q s"
    monkeypatch.setenv("PATH", "/nonexistent")
    main(["quickstart", "-n", "2000", "-f", str(folder)])
    out = capsys.readouterr().out
    next_line = next(line for line in out.splitlines() if "Next:" in line)
    command = next_line.split("Next: ", 1)[1].split(" train ", 1)[0]
    assert command != "sb3-es" and Path(shlex.split(command)[0]).name == "sb3-es"
    assert Path(shlex.split(command)[0]).resolve() == (Path(sys.executable).parent / "sb3-es").resolve()
    assert f"-tb {shlex.quote(str(folder))}" in next_line and f"--logdir {shlex.quote(str(folder))})" in out


def test_an_unknown_command_names_quickstart_too() -> None:
    with pytest.raises(SystemExit, match=r"Unknown command 'bogus': use quickstart or one of train, enjoy"):
        main(["bogus"])


def test_help_shows_the_quickstart_usage_even_without_rl_zoo(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    for name in [name for name in sys.modules if name.startswith(("sb3_es.zoo", "rl_zoo3"))]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "rl_zoo3", None)  # not installed
    with pytest.raises(SystemExit, match=r"^sb3-es --help: .*pip install -c constraints.txt -e '.\[zoo\]'"):
        main(["--help"])
    assert capsys.readouterr().out.startswith("usage: sb3-es quickstart")


def test_no_command_is_a_usage_error_and_help_is_not(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:  # as argparse does with a missing command: usage on stderr, status 2
        main([])
    assert exited.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith("usage: sb3-es quickstart") and "python -m sb3_es.zoo COMMAND" in captured.err
    main(["--help"])
    captured = capsys.readouterr()
    assert captured.err == "" and "python -m sb3_es.zoo COMMAND" in captured.out
