"""The YAML comment ``benchmarks/verify_configs.py --comments`` writes for an entry: its figures and its command."""

from __future__ import annotations

from typing import Any

from test_zoo import load_script


def result(seed: int, hit: int | None, commit: str | None = "abc1234") -> dict[str, Any]:
    """One seed's result as ``seed_results`` gives it."""
    return {
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
