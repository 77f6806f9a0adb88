"""The YAML comment ``benchmarks/verify_configs.py --comments`` writes for an entry: its figures and its command."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_zoo import load_script


def result(seed: int, hit: int | None, commit: str | None = "abc1234") -> dict[str, Any]:
    """One seed's result as ``seed_results`` gives it."""
    return {
        "status": "done",
        "seed": seed,
        "steps": 1_200_000,
        "seconds": 150.0,
        "first": -100.0,
        "final": 250.5,
        "best": 260.25,
        "hit_steps": hit,
        "hit_seconds": None if hit is None else 42.0,
        "budget_steps": 2_000_000,
        "budget_seconds": 150.0,
        "date": "2026-11-25 01:33 UTC",
        "commit": commit,
        "eval_freq": 100_000,
        "eval_episodes": 10,
        "eval_envs": 5,
    }


def test_comment_states_each_seed_and_the_command() -> None:
    comment = load_script("verify_configs").comment
    text = comment("ars_es", "Hopper-v5", 300.0, [result(0, 800_000), result(1, None)], n_timesteps=7_000_000)
    lines = text.splitlines()
    assert all(line.startswith("#") for line in lines)
    assert all(len(line) <= 120 for line in lines[:-1])  # the command is one line, however long
    joined = " ".join(line.lstrip("# ") for line in lines)
    assert "Measured 2026-11-25 (abc1234;" in joined
    assert "seed 0 reached 300 at 800,000 steps (42 s)" in joined
    assert "seed 1 went from -100.0 to best 260.2, final 250.5 (1,200,000 steps, 150 s)" in joined
    assert "300 reached by 1 of 2" in joined
    command = "python benchmarks/verify_configs.py --algos ars_es --envs Hopper-v5 --seeds 0 1 --max-seconds 150"
    # the budget below the entry's n_timesteps is part of the command that reproduces the figures
    assert lines[-1] == f"#   {command} --max-steps 2000000 --eval-envs 5"


def test_comment_without_threshold_or_commit() -> None:
    comment = load_script("verify_configs").comment
    text = comment("cmaes", "dm_control/cheetah-run-v0", None, [result(0, None, commit=None)], n_timesteps=2_000_000)
    assert "commit not recorded" in text and "reached by" not in text
    assert text.splitlines()[-1].endswith("--seeds 0 --max-seconds 150 --eval-envs 5")


def test_comment_states_an_eval_freq_other_than_the_envs_default() -> None:
    """A run with ``--eval-freq`` is reproduced only with it; the env's default frequency is left out."""
    script = load_script("verify_configs")
    assert script.eval_freq_for("BipedalWalker-v3") == script.DEFAULT_EVAL_FREQ != 100_000
    text = script.comment("simple_es", "BipedalWalker-v3", 300.0, [result(0, None)], n_timesteps=2_000_000)
    assert "10 evaluation episodes every 100,000 steps" in " ".join(line.lstrip("# ") for line in text.splitlines())
    assert text.splitlines()[-1].endswith("--seeds 0 --max-seconds 150 --eval-freq 100000 --eval-envs 5")
    default = {**result(0, None), "eval_freq": script.DEFAULT_EVAL_FREQ}
    text = script.comment("simple_es", "BipedalWalker-v3", 300.0, [default], n_timesteps=2_000_000)
    assert "--eval-freq" not in text


def test_comment_states_the_evaluation_episodes_the_runs_used() -> None:
    comment = load_script("verify_configs").comment
    text = comment("ars_es", "Hopper-v5", 300.0, [{**result(0, None), "eval_episodes": 20}], n_timesteps=2_000_000)
    assert "20 evaluation episodes every 100,000 steps" in " ".join(line.lstrip("# ") for line in text.splitlines())
    assert text.splitlines()[-1].endswith("--max-seconds 150 --eval-episodes 20 --eval-envs 5")
    assert "--eval-episodes" not in comment("ars_es", "Hopper-v5", 300.0, [result(0, None)], n_timesteps=2_000_000)


def test_threshold_of_a_dm_control_env_without_one_is_none() -> None:
    """dm_control ids are registered (by shimmy) before their spec is read; cheetah-run has no threshold."""
    threshold_for = load_script("verify_configs").threshold_for
    assert threshold_for("dm_control/cheetah-run-v0", {}) is None
    assert threshold_for("dm_control/cheetah-run-v0", {"dm_control/cheetah-run-v0": 700.0}) == 700.0


def test_seeds_run_with_other_settings_are_reported_apart() -> None:
    """A seed run again with another budget (``--skip-existing`` keeps the others) gets its own statement and
    command, and the table row names each budget with its seeds, instead of seed 0's budget for every seed."""
    script = load_script("verify_configs")
    longer = [{**result(seed, None), "budget_seconds": 900.0, "seconds": 734.0} for seed in (1, 2)]
    text = script.comment("ars_es", "Hopper-v5", 300.0, [result(0, 800_000), *longer], n_timesteps=7_000_000)
    commands = [line for line in text.splitlines() if line.startswith("#   python")]
    assert [command.split("--seeds ")[1].split(" --")[0] for command in commands] == ["0", "1 2"]
    assert "--max-seconds 150" in commands[0] and "--max-seconds 900" in commands[1]
    joined = " ".join(line.lstrip("# ") for line in text.splitlines())
    assert "or 900 s of training" in joined and "(1,200,000 steps, 734 s)" in joined
    row = script.table([("ars_es", "Hopper-v5", 300.0, [result(0, 800_000), *longer])]).splitlines()[-1]
    assert "| 2,000,000 steps or 150 s (s0); 2,000,000 steps or 900 s (s1, s2) |" in row


def fake_run(folder: Path, seed: int, means: list[float] | None, error: bool = False) -> Path:
    """
    A compare.py run folder of ars_es on CartPole-v1 under ``folder``: a finished run (``summary.json`` and
    ``evaluations.npz``, one evaluation per mean, every 1,000 steps) unless ``means`` is None, an ``error.txt`` if
    ``error``.
    """
    run = folder / "logs" / "ars_es" / f"CartPole-v1_1_seed{seed}"
    run.mkdir(parents=True)
    if error:
        (run / "error.txt").write_text("Traceback ...\nRuntimeError: boom\n")
    if means is not None:
        steps = [1000 * (i + 1) for i in range(len(means))]
        np.savez(run / "evaluations.npz", results=np.array(means)[:, None], timesteps=np.array(steps))
        fields = {"budget_steps": 5000, "budget_seconds": None, "eval_freq": 1000, "eval_episodes": 10}
        summary = {"seed": seed, "env_steps": steps[-1], "train_seconds": 9.0, "eval_train_seconds": [3.0] * len(means)}
        summary |= {
            "command": "c",
            "date": "2026-12-01 10:00 UTC",
            "commit": "abc1234",
            "eval_envs": 1,
            "hardware": "h",
        }
        (run / "summary.json").write_text(json.dumps({**summary, **fields}))
    return run


def test_failed_and_missing_seeds_are_counted_and_only_the_requested_ones_reported(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A seed that failed under compare.py's --keep-going (its error.txt, no result) counts as failed, a requested seed
    without a run as not run, and a seed that was not requested is left out; a failed seed fails the script."""
    folder = tmp_path / "ars_es" / "CartPole-v1"
    fake_run(folder, 0, [20.0, 480.0], error=True)  # an error.txt from an earlier try does not hide a result
    failed = fake_run(folder, 1, None, error=True)
    fake_run(folder, 3, [500.0])  # not in --seeds
    argv = ["--table-only", "--comments", "--algos", "ars_es", "--envs", "CartPole-v1", "--seeds", "2", "1", "0"]
    with pytest.raises(
        SystemExit, match=f"ars_es CartPole-v1 seed 1 failed, see {re.escape(str(failed / 'error.txt'))}.$"
    ):
        load_script("verify_configs").main([*argv, "--out", str(tmp_path)])
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("| ars_es | CartPole-v1"))
    assert row.startswith("| ars_es | CartPole-v1 | 475 | 0, 1, 2 | 5,000 steps | 20.0, -, - |")
    assert f"| s0: 2,000; s1: failed, see {failed / 'error.txt'}; s2: not run | 3, -, - | 1/3 |" in row
    assert "# Not counted above: seed 1 failed, seed 2 not run." in out
    assert "475 reached by 1 of 1" in out and "seed 3" not in out and "s3" not in out


def test_a_failed_compare_run_is_named_in_the_table_and_fails_the_script(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """compare.py refuses --eval-episodes 0: the row says so and where its output is, and the script exits 1."""
    argv = [
        "--algos",
        "ars_es",
        "--envs",
        "CartPole-v1",
        "--seeds",
        "0",
        "--eval-episodes",
        "0",
        "--out",
        str(tmp_path),
    ]
    log = tmp_path / "ars_es" / "CartPole-v1" / "compare.log"
    message = f"compare.py failed (exit status 1), see {log}"
    with pytest.raises(SystemExit, match=f"^verify_configs.py: ars_es CartPole-v1: {re.escape(message)}.$"):
        load_script("verify_configs").main(argv)
    out = capsys.readouterr().out
    assert f"| ars_es | CartPole-v1 | 475 | | | | {message} | | |" in out
    assert "--eval-episodes 0: it must be positive" in out  # compare.py's output, shown as it came
    assert log.read_text().startswith("$ ") and "--eval-episodes 0: it must be positive" in log.read_text()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--threshold", "CartPole-v1=abc"], r"--threshold 'CartPole-v1=abc': use ENV_ID=VALUE with a number"),
        (["--eval-freq", "0"], r"--eval-freq 0: it must be positive"),
    ],
)
def test_bad_thresholds_and_eval_frequencies_are_refused(extra: list[str], message: str, tmp_path: Path) -> None:
    with pytest.raises(SystemExit, match=message):
        load_script("verify_configs").main(["--table-only", "--envs", "CartPole-v1", "--out", str(tmp_path), *extra])


def test_eval_freq_reads_exponent_form(tmp_path: Path) -> None:
    """--eval-freq takes step counts as --max-steps and compare.py do (2e4)."""
    argv = ["--table-only", "--algos", "ars_es", "--envs", "CartPole-v1", "--eval-freq", "2e4", "--out", str(tmp_path)]
    assert "| ars_es | CartPole-v1 | 475 | | | | not run | | |" in load_script("verify_configs").main(argv)
