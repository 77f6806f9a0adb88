"""
``benchmarks/compare.py``'s own logic: the race measure (median time to a threshold, a missing seed counting as its
budget), the reading of ``--override`` values, a run trained on from a saved model (``--continue-from``), and the
flags the benchmark scripts refuse rather than ignore.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from test_zoo import load_script

from sb3_es import ARS


def run(
    seed: int, evaluations: list[tuple[float, float]], train_seconds: float, budget: float | None
) -> dict[str, Any]:
    """A run summary as ``load_runs`` gives it: ``(training wall-clock, mean return)`` per evaluation."""
    rows = [{"wall_s": wall, "mean_return": ret, "env_steps": 0.0} for wall, ret in evaluations]
    return {"seed": seed, "train_seconds": train_seconds, "budget_seconds": budget, "rows": rows}


@pytest.fixture(scope="module")
def time_to_threshold() -> Any:
    return load_script("compare").time_to_threshold


def test_median_over_seeds_counts_a_miss_as_its_budget(time_to_threshold: Any) -> None:
    runs = [
        run(0, [(0.0, -90.0), (1959.0, 300.8)], 1959.0, 4200.0),
        run(1, [(0.0, -90.0), (2700.0, 291.8)], 2700.0, 2700.0),
        run(2, [(0.0, -90.0), (1028.0, 302.5)], 1028.0, 2700.0),
    ]
    assert time_to_threshold(runs, 300.0) == "1,959 s median (1,959 / >2,700 / 1,028 s; 2/3 seeds)"


def test_a_median_that_is_a_budget_is_a_lower_bound(time_to_threshold: Any) -> None:
    runs = [
        run(0, [(2176.0, 295.5)], 2176.0, 2400.0),  # ended at its step budget first: counts as its wall-clock budget
        run(1, [(2700.0, 280.0)], 2700.0, 2700.0),
        run(2, [(900.0, 310.0)], 900.0, 2700.0),
    ]
    assert time_to_threshold(runs, 300.0) == ">2,400 s median (>2,400 / >2,700 / 900 s; 1/3 seeds)"
    # a run with no wall-clock budget (stopped by hand) counts as the training time it had
    assert time_to_threshold([run(0, [(1500.0, -49.8)], 1500.0, None)], 300.0).startswith(">1,500 s median")


def test_a_confirmed_race_counts_the_first_confirmation(time_to_threshold: Any) -> None:
    # seed 0: the 10-episode hit at 500 s falls short over 100 episodes (291.0); the one at 700 s confirms
    first = run(0, [(0.0, -90.0), (500.0, 305.0), (700.0, 310.0)], 700.0, 1200.0)
    first.update(
        confirm_episodes=100,
        confirmations=[{"wall_s": 500.0, "mean_return": 291.0}, {"wall_s": 700.0, "mean_return": 301.0}],
    )
    # seed 1: hit on 10 episodes, never confirmed: a miss at its budget
    second = run(1, [(0.0, -90.0), (900.0, 300.5)], 1200.0, 1200.0)
    second.update(confirm_episodes=100, confirmations=[{"wall_s": 900.0, "mean_return": 280.0}])
    cell = time_to_threshold([first, second], 300.0)
    assert cell == ">950 s median (700 / >1,200 s; 1/2 seeds; confirmed on 100 episodes)"
    # Reported at another threshold than the one the run confirmed (recorded as stop_at): its evaluations count.
    first["stop_at"] = 300.0
    cell = time_to_threshold([first], 250.0)
    assert cell == "500 s median (500 s; 1/1 seeds; s0 confirmed at 300, so its evaluations count)"


def test_overrides_read_yaml_values_and_exponent_numbers() -> None:
    parse_overrides = load_script("compare").parse_overrides
    overrides = parse_overrides(
        ["pgpe:n_timesteps=5e7", "pgpe:stdev_init=0.05", "ars_es:learning_rate=1e-3", "ars_es:policy=MlpPolicy"]
        + ["ars_es:reward_clip=[-1, 1]", "ars_es:zero_policy=false", "ppo:learning_rate=lin_3e-4"]
    )
    # YAML 1.1 reads 5e7 and 1e-3 as strings, which rl-zoo's int(n_timesteps) would reject
    assert overrides["pgpe"] == {"n_timesteps": 5e7, "stdev_init": 0.05}
    assert overrides["ars_es"] == {
        "learning_rate": 1e-3,
        "policy": "MlpPolicy",
        "reward_clip": [-1, 1],
        "zero_policy": False,
    }
    assert overrides["ppo"] == {"learning_rate": "lin_3e-4"}
    with pytest.raises(SystemExit, match="use ALGO:KEY=VALUE"):
        parse_overrides(["n_timesteps=5e7"])


@pytest.mark.parametrize("text", ["2000000", "2_000_000", "2e6", "2.0E6"])
def test_step_counts_read_exponent_form(text: str) -> None:
    assert load_script("compare").step_count(text) == 2_000_000


@pytest.mark.parametrize(
    ("text", "message"),
    [("1.5", "not a whole number"), ("2.5e-1", "not a whole number"), ("2M", "not a step count")],
)
def test_compare_refuses_step_counts_that_are_not_whole(
    text: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit):
        load_script("compare").main(["--algos", "ars_es", "--envs", "CartPole-v1", "--steps", text])
    assert f"argument --steps: '{text}' is {message}" in capsys.readouterr().err


def test_a_run_again_into_the_same_folder_replaces_its_tensorboard_run(tmp_path: Any) -> None:
    args = ["--algos", "ars_es", "--envs", "CartPole-v1", "--seeds", "0", "--steps", "200", "--eval-freq", "0"]
    for _ in range(2):
        load_script("compare").main([*args, "--override", "ars_es:n_delta=2", "ars_es:n_top=2", "--out", str(tmp_path)])
    summary = json.loads((tmp_path / "logs" / "ars_es" / "CartPole-v1_1_seed0" / "summary.json").read_text())
    runs = [path.name for path in (tmp_path / "tb" / "CartPole-v1").iterdir()]
    assert runs == [Path(summary["tensorboard_dir"]).name]


def test_a_run_continues_from_its_last_model(tmp_path: Any) -> None:
    main = load_script("compare").main
    common = ["--algos", "ars_es", "--envs", "CartPole-v1", "--seeds", "0", "--eval-freq", "1000"]
    common += ["--eval-episodes", "1", "--override", "ars_es:n_delta=2", "ars_es:n_top=2"]
    main([*common, "--steps", "2000", "--out", str(tmp_path / "first")])
    first = tmp_path / "first" / "logs" / "ars_es" / "CartPole-v1_1_seed0"
    saved = json.loads((first / "summary.json").read_text())["env_steps"]
    checkpoint = first / "last_model.zip"
    assert ARS.load(checkpoint).num_timesteps == saved  # saved at the last evaluation, the end of training

    main([*common, "--steps", "2000", "--out", str(tmp_path / "second"), "--continue-from", str(checkpoint)])
    second = json.loads((tmp_path / "second" / "logs" / "ars_es" / "CartPole-v1_1_seed0" / "summary.json").read_text())
    assert second["continued_from"] == {"model": str(checkpoint.resolve()), "env_steps": saved}
    assert second["eval_timesteps"][0] == saved  # the step count goes on, and so does the evaluation grid
    assert second["eval_timesteps"][1] == (saved // 1000 + 1) * 1000
    assert saved + 2000 <= second["env_steps"] < saved + 4000
    report = (tmp_path / "second" / "results.md").read_text()  # the run's start and end, not its end twice
    assert f"- Runs: first started {second['started']}, last ended {second['date']}" in report

    with pytest.raises(SystemExit, match="no such model; give a saved model's .zip file"):
        main([*common, "--steps", "10", "--out", str(tmp_path / "third"), "--continue-from", str(first / "none.zip")])
    with pytest.raises(SystemExit, match="lies in the run folder .* give another --out"):
        main([*common, "--steps", "2000", "--out", str(tmp_path / "first"), "--continue-from", str(checkpoint)])
    # a run that cannot load its model leaves the finished run it would replace as it was
    before = sorted(path.name for path in first.iterdir())
    pendulum = tmp_path / "pendulum.zip"
    ARS("LinearPolicy", "Pendulum-v1").save(pendulum)
    with pytest.raises(SystemExit, match=r"ars_es cannot load it \(ValueError: Observation spaces do not match"):
        main([*common, "--steps", "10", "--out", str(tmp_path / "first"), "--continue-from", str(pendulum)])
    assert sorted(path.name for path in first.iterdir()) == before and "summary.json" in before
    assert [path.name for path in (tmp_path / "first").iterdir() if path.name.startswith(".")] == []
    with pytest.raises(SystemExit, match="one algorithm, env and seed"):
        main([*common[:5], "0", "1", *common[6:], "--steps", "10", "--continue-from", str(checkpoint)])


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--steps", "0"], r"--steps 0: it must be positive"),
        (["--steps", "100", "--seconds", "-1", "--eval-freq", "-5"], r"--seconds -1.0: .*--eval-freq -5: it must be 0"),
        (["--steps", "100", "--eval-episodes", "0"], r"--eval-episodes 0: it must be positive"),
        (["--steps", "100", "--seeds", "0", "0"], r"--seeds repeats \[0\]"),
        (["--steps", "100", "--envs", "CartPole-v1", "CartPole-v1"], r"--envs repeats \['CartPole-v1'\]"),
        (["--steps", "100", "--algos", "ars_es", "ars_es"], r"--algos repeats \['ars_es'\]"),
        (["--steps", "100", "--threshold", "CartPol-v1=400"], r"--threshold for \['CartPol-v1'\], which --envs"),
        (["--steps", "100", "--stop-at-threshold"], r"--stop-at-threshold stops at a --threshold"),
        (["--steps", "100", "--override", "ppo:n_steps=64"], r"--override for \['ppo'\], which --algos"),
        # a repeated flag adds to the first, which argparse's default would silently drop
        (["--steps", "100", "--override", "ppo:n_steps=64", "--override", "ars_es:n_delta=2"], r"\['ppo'\], which"),
        (["--steps", "100", "--threshold", "CartPol-v1=4", "--threshold", "CartPole-v1=4"], r"\['CartPol-v1'\], which"),
        (["--steps", "100", "--override", "ars_es:n_timesteps=100"], r"n_timesteps with --steps"),
        (["--steps", "100", "--algos", "ars_es", "ppo_typo"], r"--algos \['ppo_typo'\]: unknown"),
        # checked before the runs, not when their turn comes
        (["--steps", "100", "--envs", "CartPole-v1", "Pendulum-v9"], r"--envs Pendulum-v9: Environment version"),
        (["--steps", "100", "--override", "ars_es:n_deltaa=4"], r"ars_es:n_deltaa: n_deltaa is not a hyperparameter"),
        (["--steps", "100", "--threshold", "CartPole-v1=abc"], r"use ENV_ID=VALUE with a number"),
        (["--seconds", "nan"], r"--seconds nan: it must be positive"),
        (["--steps", "100", "--override", "ars_es:n_delta=[1,"], r"'\[1,' is not a value \(ParserError"),
        (
            ["--steps", "100", "--override", "ars_es:policy_kwargs=dict(a=[8]"],
            r"is not a value \(SyntaxError: '\(' was",
        ),
        (
            ["--steps", "100", "--continue-from", "r/logs/ars_es/Pendulum-v1_1_seed0/last_model.zip"],
            r"was trained on Pendulum-v1, not on --envs \['CartPole-v1'\]",
        ),
        (
            ["--steps", "100", "--seeds", "1", "--continue-from", "r/logs/ars_es/CartPole-v1_1_seed0/last_model.zip"],
            r"was trained with seed 0, not --seeds 1: a continued run goes on with its own seed",
        ),
    ],
)
def test_compare_refuses_what_it_would_ignore(extra: list[str], message: str, tmp_path: Any) -> None:
    base = ["--algos", "ars_es", "--envs", "CartPole-v1", "--eval-freq", "0", "--out", str(tmp_path)]
    with pytest.raises(SystemExit, match=message):
        load_script("compare").main(base + extra)
    assert not (tmp_path / "logs").exists()  # refused before any run


def test_compare_keep_going_reports_the_failed_runs_and_fails(tmp_path: Any) -> None:
    # a run that fails at its start (n_delta=0 is refused by ARS) is recorded, the others run, the exit says so
    args = ["--algos", "cmaes", "ars_es", "--envs", "CartPole-v1", "--steps", "100", "--eval-freq", "0"]
    with pytest.raises(SystemExit, match=r"1 run\(s\) failed \(--keep-going\): \[2/2\] ars_es CartPole-v1 seed 0"):
        load_script("compare").main([*args, "--override", "ars_es:n_delta=0", "--keep-going", "--out", str(tmp_path)])
    report = (tmp_path / "results.md").read_text()
    assert "| cmaes (CMAES) | 1 (0) |" in report
    assert "**Failed** (no result, `--keep-going`): `logs/ars_es/CartPole-v1_1_seed0`, see its `error.txt`" in report


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--envs", "CartPole-v1", "Pendulm-v1"], r"No entry for \['Pendulm-v1'\]"),
        (["--envs", "CartPole-v1", "--max-steps", "0"], r"--max-steps 0: it must be positive"),
        (["--envs", "CartPole-v1", "--threshold", "Pendulm-v1=-100"], r"--threshold for \['Pendulm-v1'\]"),
        (
            ["--envs", "CartPole-v1", "--threshold", "Pendulm-v1=-1", "--threshold", "CartPole-v1=4"],
            r"\['Pendulm-v1'\]",
        ),
        (["--envs", "CartPole-v1", "--seeds", "0", "0"], r"--seeds repeats \[0\]"),
        (["--envs", "CartPole-v1", "--algos", "ars_ess"], r"--algos \['ars_ess'\]: not sb3-es algorithms"),
    ],
)
def test_verify_configs_refuses_what_it_would_ignore(extra: list[str], message: str, tmp_path: Any) -> None:
    with pytest.raises(SystemExit, match=message):
        load_script("verify_configs").main(["--table-only", "--out", str(tmp_path), *extra])


@pytest.mark.parametrize("flag", ["--steps", "--episodes", "--fps", "--every"])
def test_render_refuses_counts_below_one(flag: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        load_script("render").main(["model.zip", flag, "0"])
    assert f"{flag} 0: it must be at least 1" in capsys.readouterr().err
