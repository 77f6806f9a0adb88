"""The command line: ``sb3-es quickstart`` (the README's first command) and ``sb3-es train``."""

from __future__ import annotations

from pathlib import Path

import pytest

from sb3_es import ARS, REINFORCE
from sb3_es.cli import main


def test_quickstart_writes_logs_and_model(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    main(["quickstart", "--timesteps", "4000", "--log-dir", str(tmp_path)])
    out = capsys.readouterr().out
    assert (tmp_path / "ARS_1").is_dir() and any((tmp_path / "ARS_1").iterdir())
    model_path = tmp_path / "ars_Swimmer-v5.zip"
    assert str(model_path.resolve()) in out and "TensorBoard logs" in out
    assert ARS.load(model_path).num_timesteps >= 4000


def test_train_any_algorithm(tmp_path: Path) -> None:
    main(
        [
            "train",
            *("--algo", "reinforce", "--env", "CartPole-v1", "--timesteps", "1000", "--n-envs", "2"),
            *("--log-dir", str(tmp_path), "--seed", "0", "--hyperparams", '{"n_episodes": 4}'),
        ]
    )
    model = REINFORCE.load(tmp_path / "reinforce_CartPole-v1.zip")
    assert model.n_episodes == 4 and model.num_timesteps >= 1000
    assert (tmp_path / "REINFORCE_1").is_dir()


def test_unknown_algorithm(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="Unknown algorithm 'nope'"):
        main(["train", "--algo", "nope", "--env", "CartPole-v1", "--log-dir", str(tmp_path)])
