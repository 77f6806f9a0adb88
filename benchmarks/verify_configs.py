"""
Verify the packaged hyperparameters (``sb3_es/hyperparams/<algo>.yml``): train each selected (algorithm, env) entry
with ``benchmarks/compare.py`` over seeds, to the entry's own ``n_timesteps`` (or a stated cap) or until an
evaluation reaches the env's threshold, and write one table row per entry (docs/benchmarks.md, "Verified configs").

Examples::

    # every entry for the cheap classic-control envs, 2 seeds, at most 300 s of training per run
    PYTHONPATH=. python benchmarks/verify_configs.py --envs CartPole-v1 Pendulum-v1 --seeds 0 1 --max-seconds 300 \\
        --out results/verify

    # only the table, from the runs already in the output folder
    PYTHONPATH=. python benchmarks/verify_configs.py --envs CartPole-v1 Pendulum-v1 --out results/verify --table-only

Thresholds: ``--threshold ENV=X`` if given, else :data:`THRESHOLDS` (stated here where Gymnasium has none),
else the env's ``spec.reward_threshold``. Evaluations: every :func:`eval_freq_for` env steps, or ``--eval-freq N``
(stated in the YAML comment's command when it differs). Each run's outputs are compare.py's, under
``<out>/<algo>/<env>/`` (``results.md``, ``logs/<algo>/<env>_1_seed<s>/summary.json`` and ``evaluations.npz``, or
``error.txt`` for a seed that failed), and its output is also appended to ``<out>/<algo>/<env>/compare.log``. A
failed compare.py run or seed is named in the table, and the script then exits with status 1.
"""

from __future__ import annotations

import argparse
import codecs
import json
import os
import shlex
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import shimmy
import yaml
from common import PAPER_THRESHOLDS, parse_thresholds, positive_problems, selection_problems, step_count

import sb3_es
from sb3_es.zoo import default_conf_file, sb3_es_algos

#: Thresholds (mean deterministic return) where Gymnasium's ``spec.reward_threshold`` is missing or is not used.
THRESHOLDS = {
    "Pendulum-v1": -200.0,  # no spec threshold; rl-zoo's Pendulum results are about -150 to -200
    "CartPole-v1": 475.0,
    "Acrobot-v1": -100.0,
    "MountainCar-v0": -110.0,
    "MountainCarContinuous-v0": 90.0,
    "LunarLander-v3": 200.0,
    "LunarLanderContinuous-v3": 200.0,
    "BipedalWalker-v3": 300.0,
    **PAPER_THRESHOLDS,  # the MuJoCo tasks: the ARS paper's levels, below Gymnasium's where it has one
}

#: Env steps between evaluations, by env (default :data:`DEFAULT_EVAL_FREQ`).
EVAL_FREQ = {"CartPole-v1": 5_000, "LunarLander-v3": 50_000, "LunarLanderContinuous-v3": 50_000}
# 1,000-step episodes, millions of steps
EVAL_FREQ.update(dict.fromkeys([*PAPER_THRESHOLDS, "dm_control/cheetah-run-v0"], 100_000))
DEFAULT_EVAL_FREQ = 20_000
#: Evaluation episodes per evaluation unless --eval-episodes says otherwise.
DEFAULT_EVAL_EPISODES = 10


def eval_freq_for(env_id: str) -> int:
    """:return: The env steps between evaluations of an env's runs unless ``--eval-freq`` is given."""
    return EVAL_FREQ.get(env_id, DEFAULT_EVAL_FREQ)


gym.register_envs(shimmy)  # the dm_control/ ids, for their spec thresholds


def threshold_for(env_id: str, given: dict[str, float]) -> float | None:
    """
    :param env_id: Env id.
    :param given: Thresholds from the command line.
    :return: The return threshold for ``env_id`` (None if there is none).
    """
    if env_id in given:
        return given[env_id]
    if env_id in THRESHOLDS:
        return THRESHOLDS[env_id]
    return gym.spec(env_id).reward_threshold


def entries(algos: list[str], envs: list[str]) -> list[tuple[str, str, dict[str, Any]]]:
    """
    The packaged entries for the selected algorithms and envs (``default`` entries are not verified).

    :param algos: sb3-es algorithm keys.
    :param envs: Env ids.
    :return: ``(algo, env_id, entry)`` in the order of ``envs`` then ``algos``.
    """
    found = []
    for env_id in envs:
        for algo in algos:
            data = yaml.safe_load(default_conf_file(algo).read_text())
            if env_id in data:
                found.append((algo, env_id, data[env_id]))
    return found


def slug(env_id: str) -> str:
    """:return: ``env_id`` as a folder name."""
    return env_id.replace("/", "-")


def entry_folder(args: argparse.Namespace, algo: str, env_id: str) -> Path:
    """:return: The compare.py output folder of one entry: ``<out>/<algo>/<env>[-<tag>]``."""
    return Path(args.out) / algo / (slug(env_id) + (f"-{args.tag}" if args.tag else ""))


def run_entry(algo: str, env_id: str, entry: dict[str, Any], args: argparse.Namespace, threshold: float | None) -> int:
    """
    Run compare.py for one entry (skipping seeds already done), its output shown and appended to the entry's
    ``compare.log``.

    :return: compare.py's exit status.
    """
    steps = int(float(entry["n_timesteps"]))
    if args.max_steps is not None:
        steps = min(steps, args.max_steps)
    command = [
        sys.executable,
        str(Path(__file__).with_name("compare.py")),
        "--algos",
        algo,
        "--envs",
        env_id,
        "--seeds",
        *map(str, args.seeds),
        "--steps",
        str(steps),
        "--eval-freq",
        str(eval_freq_for(env_id) if args.eval_freq is None else args.eval_freq),
        "--eval-episodes",
        str(args.eval_episodes),
        "--eval-envs",
        str(args.eval_envs),
        "--out",
        str(entry_folder(args, algo, env_id)),
        "--skip-existing",
        "--keep-going",
    ]
    if args.max_seconds is not None:
        command += ["--seconds", str(args.max_seconds)]
    if threshold is not None:
        command += ["--threshold", f"{env_id}={threshold:g}", "--stop-at-threshold"]
    print("$ " + shlex.join(command), flush=True)
    # compare.py reads the packaged YAML of the sb3_es it imports: make it this one (the script's folder, not the
    # working directory, is first on a script's sys.path)
    root = str(Path(sb3_es.__file__).resolve().parents[1])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
    env["PYTHONUNBUFFERED"] = "1"  # its output as it comes, through the pipe
    return run_logged(command, env, compare_log(args, algo, env_id))


def compare_log(args: argparse.Namespace, algo: str, env_id: str) -> Path:
    """:return: The file the entry's compare.py output is appended to."""
    return entry_folder(args, algo, env_id) / "compare.log"


def run_logged(command: list[str], env: dict[str, str], log: Path) -> int:
    """
    Run a command, its output (stdout and stderr) printed as it comes and appended to ``log``.

    :param command: The command.
    :param env: Its environment.
    :param log: The file to append its output to (after a ``$ command`` line).
    :return: Its exit status.
    """
    log.parent.mkdir(parents=True, exist_ok=True)
    decoder = codecs.getincrementaldecoder("utf-8")(errors="replace")
    with log.open("ab") as file:
        file.write(f"$ {shlex.join(command)}\n".encode())
        with subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT) as proc:
            assert proc.stdout is not None
            while chunk := os.read(proc.stdout.fileno(), 1 << 16):
                file.write(chunk)
                file.flush()
                sys.stdout.write(decoder.decode(chunk))
                sys.stdout.flush()
    return proc.returncode


def seed_results(folder: Path, threshold: float | None, seeds: list[int]) -> list[dict[str, Any]]:
    """
    :param folder: compare.py output folder of one entry.
    :param threshold: Return threshold.
    :param seeds: The seeds to report (others in the folder are left out).
    :return: Per seed, by seed number, its ``status``: ``"done"`` with steps, wall-clock, final and best return and
        where the threshold was first reached; ``"failed"`` with the ``error`` file compare.py's ``--keep-going``
        wrote; or ``"not run"``.
    """
    results: list[dict[str, Any]] = []
    for seed in sorted(seeds):  # by number: the folder names put seed 10 before seed 2
        runs = sorted(folder.glob(f"logs/*/*_seed{seed}"))
        summary_path = next((run / "summary.json" for run in runs if (run / "summary.json").is_file()), None)
        if summary_path is None:  # a seed's error.txt counts only without a result (a later run may have one)
            error = next((run / "error.txt" for run in runs if (run / "error.txt").is_file()), None)
            results.append(
                {"seed": seed, "status": "not run"}
                if error is None
                else {"seed": seed, "status": "failed", "error": error}
            )
            continue
        summary = json.loads(summary_path.read_text())
        evaluations = np.load(summary_path.parent / "evaluations.npz")
        means = [float(np.mean(r)) for r in evaluations["results"]]
        hit = next((i for i, m in enumerate(means) if threshold is not None and m >= threshold), None)
        results.append(
            {
                "status": "done",
                "seed": summary["seed"],
                "steps": summary["env_steps"],
                "seconds": summary["train_seconds"],
                "first": means[0],
                "final": means[-1],
                "best": max(means),
                "hit_steps": None if hit is None else int(evaluations["timesteps"][hit]),
                "hit_seconds": None if hit is None else summary["eval_train_seconds"][hit],
                "budget_steps": summary["budget_steps"],
                "budget_seconds": summary["budget_seconds"],
                "command": summary["command"],
                "date": summary["date"],
                "commit": summary.get("commit"),
                "eval_freq": summary["eval_freq"],
                "eval_episodes": summary["eval_episodes"],
                "eval_envs": summary["eval_envs"],
                "hardware": summary["hardware"],
            }
        )
    return results


def done(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """:return: The seed results that have figures (status ``"done"``, :func:`seed_results`)."""
    return [r for r in results if r["status"] == "done"]


#: The settings of a run that its figures depend on: seeds run with different ones are reported apart.
RUN_SETTINGS = ("budget_steps", "budget_seconds", "eval_freq", "eval_episodes", "eval_envs")


def settings_groups(results: list[dict[str, Any]]) -> list[list[dict[str, Any]]]:
    """
    :param results: Seed results (:func:`seed_results`).
    :return: The results grouped by their :data:`RUN_SETTINGS` (e.g. a seed run again with another budget), in order.
    """
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for r in results:
        groups.setdefault(tuple(r[key] for key in RUN_SETTINGS), []).append(r)
    return list(groups.values())


def budget_text(r: dict[str, Any]) -> str:
    """:return: A run's budget, e.g. ``2,000,000 steps or 150 s``."""
    budget = f"{r['budget_steps']:,} steps"
    return budget + (f" or {r['budget_seconds']:g} s" if r["budget_seconds"] else "")


def outcome_text(r: dict[str, Any]) -> str:
    """:return: One seed's cell of the table's outcome column (:func:`seed_results`)."""
    if r["status"] == "failed":
        return f"s{r['seed']}: failed, see {r['error']}"
    if r["status"] == "not run":
        return f"s{r['seed']}: not run"
    if r["hit_steps"] is not None:
        return f"s{r['seed']}: {r['hit_steps']:,}"
    return f"s{r['seed']}: {r['final']:.1f} / {r['best']:.1f} ({r['steps']:,} steps)"


def table(
    rows: list[tuple[str, str, float | None, list[dict[str, Any]]]], failures: dict[tuple[str, str], str] | None = None
) -> str:
    """
    :param rows: ``(algo, env_id, threshold, seed results)`` per entry.
    :param failures: What to say of the entries whose compare.py run failed, by ``(algo, env_id)``.
    :return: The markdown table, one row per entry; a seed that failed or was not run counts as not reaching the
        threshold.
    """
    lines = [
        "| algorithm | env | threshold | seeds | budget | start return | steps to threshold, or final / best return "
        "(steps taken) | train wall-clock (s) | reached |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for algo, env_id, threshold, results in rows:
        shown = "none" if threshold is None else f"{threshold:g}"
        failure = (failures or {}).get((algo, env_id))
        if all(r["status"] == "not run" for r in results):
            lines.append(f"| {algo} | {env_id} | {shown} | | | | {failure or 'not run'} | | |")
            continue
        groups = settings_groups(done(results))
        budget = (
            budget_text(groups[0][0])
            if len(groups) == 1
            else "; ".join(f"{budget_text(g[0])} ({', '.join('s' + str(r['seed']) for r in g)})" for g in groups)
        )
        outcome = "; ".join([*map(outcome_text, results), *([failure] if failure else [])])
        seconds = ", ".join(
            "-"
            if r["status"] != "done"
            else f"{r['hit_seconds'] if r['hit_seconds'] is not None else r['seconds']:,.0f}"
            for r in results
        )
        reached = sum(r["status"] == "done" and r["hit_steps"] is not None for r in results)
        seeds = ", ".join(str(r["seed"]) for r in results)
        start = ", ".join(f"{r['first']:.1f}" if r["status"] == "done" else "-" for r in results)
        lines.append(
            f"| {algo} | {env_id} | {shown} | {seeds} | {budget} | {start} | {outcome} | {seconds} "
            f"| {reached}/{len(results)} |"
        )
    return "\n".join(lines)


def comment(algo: str, env_id: str, threshold: float | None, results: list[dict[str, Any]], n_timesteps: int) -> str:
    """
    The YAML comment lines that state an entry's measured result and the command that reproduces it: one statement
    and command per group of seeds run with the same settings (:func:`settings_groups`), then a line naming the seeds
    that failed or were not run.

    :param results: The entry's seed results (:func:`seed_results`).
    :param n_timesteps: The entry's ``n_timesteps``.
    :return: ``# ``-prefixed lines.
    """
    lines = [group_comment(algo, env_id, threshold, group, n_timesteps) for group in settings_groups(done(results))]
    others = [f"seed {r['seed']} {r['status']}" for r in results if r["status"] != "done"]
    if others:
        lines.append(f"# Not counted above: {', '.join(others)}.")
    return "\n".join(lines)


def group_comment(
    algo: str, env_id: str, threshold: float | None, results: list[dict[str, Any]], n_timesteps: int
) -> str:
    """:func:`comment` for seeds run with the same settings."""
    first = results[0]
    commits = sorted({r["commit"] or "commit not recorded" for r in results})
    budget = f"at most {first['budget_steps']:,} steps"
    if first["budget_seconds"]:
        budget += f" or {first['budget_seconds']:g} s of training"
    outcomes = []
    for r in results:
        if r["hit_steps"] is not None:
            outcomes.append(
                f"seed {r['seed']} reached {threshold:g} at {r['hit_steps']:,} steps ({r['hit_seconds']:.0f} s)"
            )
        else:
            outcomes.append(
                f"seed {r['seed']} went from {r['first']:.1f} to best {r['best']:.1f}, final {r['final']:.1f} "
                f"({r['steps']:,} steps, {r['seconds']:.0f} s)"
            )
    reached = (
        ""
        if threshold is None
        else f"; {threshold:g} reached by {sum(r['hit_steps'] is not None for r in results)} of {len(results)}"
    )
    command = f"python benchmarks/verify_configs.py --algos {algo} --envs {env_id} --seeds " + " ".join(
        str(r["seed"]) for r in results
    )
    if first["budget_seconds"]:
        command += f" --max-seconds {first['budget_seconds']:g}"
    if first["budget_steps"] < n_timesteps:
        command += f" --max-steps {first['budget_steps']}"
    if first["eval_freq"] != eval_freq_for(env_id):
        command += f" --eval-freq {first['eval_freq']}"
    if first["eval_episodes"] != DEFAULT_EVAL_EPISODES:
        command += f" --eval-episodes {first['eval_episodes']}"
    if first["eval_envs"] != 1:
        command += f" --eval-envs {first['eval_envs']}"
    text = (
        f"Measured {first['date'][:10]} ({', '.join(commits)}; {budget}; {first['eval_episodes']} evaluation "
        f"episodes every {first['eval_freq']:,} steps): {'; '.join(outcomes)}{reached}."
    )
    lines = ["# " + line for line in textwrap.wrap(text, 118)]
    return "\n".join([*lines, "# Command:", f"#   {command}"])


def main(argv: list[str] | None = None) -> str:
    """
    Run the selected entries and print the table; exit with status 1 after it if a compare.py run or a seed failed.

    :param argv: Arguments (defaults to ``sys.argv[1:]``).
    :return: The table.
    """
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algos", nargs="+", default=sorted(sb3_es_algos()), help="sb3-es algorithm keys")
    parser.add_argument("--envs", nargs="+", required=True, help="env ids (entries of the packaged YAML files)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    parser.add_argument("--max-steps", type=step_count, default=None, help="cap on the entry's n_timesteps")
    parser.add_argument("--max-seconds", type=float, default=None, help="training wall-clock cap per run")
    parser.add_argument("--eval-episodes", type=int, default=DEFAULT_EVAL_EPISODES)
    parser.add_argument("--eval-envs", type=int, default=1, help="envs the evaluation episodes run on side by side")
    parser.add_argument(
        "--eval-freq", type=step_count, default=None, help="env steps between evaluations (default: chosen per env)"
    )
    parser.add_argument(
        "--threshold", nargs="+", action="extend", default=[], help="ENV_ID=RETURN, replacing the defaults (repeatable)"
    )
    parser.add_argument("--out", default="results/verify", help="output folder (one compare.py folder per entry)")
    parser.add_argument("--tag", default="", help="suffix of the entries' output folders (a re-run after a fix)")
    parser.add_argument("--table-only", action="store_true", help="only print the table from existing runs")
    parser.add_argument(
        "--comments", action="store_true", help="with --table-only: also print each entry's YAML comment lines"
    )
    args = parser.parse_args(argv)
    given = parse_thresholds(args.threshold)
    problems = positive_problems(
        {"--max-steps": args.max_steps, "--max-seconds": args.max_seconds, "--eval-freq": args.eval_freq}
    )
    unknown_algos = sorted(set(args.algos) - set(sb3_es_algos()))
    if unknown_algos:
        problems.append(f"--algos {unknown_algos}: not sb3-es algorithms (known: {sorted(sb3_es_algos())})")
    problems += selection_problems(args.seeds, args.envs, given)
    if problems:
        raise SystemExit("verify_configs.py: " + "; ".join(problems) + ".")
    selected = entries(args.algos, args.envs)
    without = [env_id for env_id in args.envs if env_id not in {env for _, env, _ in selected}]
    if without:
        raise SystemExit(f"No entry for {without} in the packaged files of {args.algos}: check the env ids.")
    rows, comments = [], []
    failures: dict[tuple[str, str], str] = {}  # the compare.py runs that failed
    for algo, env_id, entry in selected:
        threshold = threshold_for(env_id, given)
        if not args.table_only:
            status = run_entry(algo, env_id, entry, args, threshold)
            if status != 0:
                log = compare_log(args, algo, env_id)
                failures[(algo, env_id)] = f"compare.py failed (exit status {status}), see {log}"
        results = seed_results(entry_folder(args, algo, env_id), threshold, args.seeds)
        rows.append((algo, env_id, threshold, results))
        if args.comments and done(results):
            comments.append(
                f"{algo} {env_id}:\n" + comment(algo, env_id, threshold, results, int(float(entry["n_timesteps"])))
            )
    text = "\n\n".join([table(rows, failures), *comments])
    print(text)
    failed = [f"{algo} {env_id}: {message}" for (algo, env_id), message in failures.items()]
    failed += [
        f"{a} {e} seed {r['seed']} failed, see {r['error']}"
        for a, e, _, rs in rows
        for r in rs
        if r["status"] == "failed"
    ]
    if failed:
        raise SystemExit("verify_configs.py: " + "; ".join(failed) + ".")
    return text


if __name__ == "__main__":
    main()
