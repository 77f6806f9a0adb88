"""
Compare algorithms on environments over seeds with equal budgets, in rl-zoo's log layout: one TensorBoard root,
rl-zoo run folders with ``evaluations.npz`` (so that rl-zoo's ``all_plots`` and ``plot_from_file`` read them), and
what rl-zoo lacks: the return against training wall-clock and a race table (steps taken, time to a threshold).

Examples::

    # ES methods against PPO and SAC on Pendulum-v1, 3 seeds, 200k env steps each
    python benchmarks/compare.py --algos ars_es openes cmaes reinforce ppo sac --envs Pendulum-v1 \\
        --seeds 0 1 2 --steps 200000 --eval-freq 10000 --out results/pendulum

    # equal wall-clock budgets (training time, evaluations excluded) instead of env steps
    python benchmarks/compare.py --algos ars_es ppo --envs Swimmer-v5 --seconds 600 --out results/swimmer

    # redraw the wall-clock plot and the table from the runs already in an output folder
    python benchmarks/compare.py --out results/pendulum --report-only

    # learning curves against env steps, the results table, rliable's IQM with bootstrap intervals
    python -m sb3_es.zoo all_plots -a ars_es ppo -e Pendulum-v1 -f results/pendulum/logs -o results/pendulum/all_plots
    python -m sb3_es.zoo plot_from_file -i results/pendulum/all_plots.pkl --rliable --iqm

Runs are sequential, one process, with a progress line. Algorithm keys are rl-zoo's (``ppo``, ``sac``, ``ars`` for
sb3-contrib's ARS, ...) and sb3-es's (``ars_es``, ``openes``, ``cmaes``, ``pgpe``, ``simple_es``, ``reinforce``).
Hyperparameters: the packaged ``sb3_es/hyperparams/<algo>.yml`` for the sb3-es algorithms, rl-zoo3's own
``hyperparams/<algo>.yml`` for the others. When rl-zoo3 has no entry for an env id but has one for an older version
(``Hopper-v4`` for ``Hopper-v5``) that entry is used, otherwise rl-zoo3's ``default``; for Dict observations
(dm_control) a ``FlattenObservation`` wrapper is added. The rl-zoo3 entries used are written to ``configs/``; the
values a run used, ``--override`` applied, are in its ``summary.json`` and rl-zoo's ``<env>/config.yml``. Models,
envs and ``VecNormalize`` come from rl-zoo3's ``ExperimentManager``.

Every ``--eval-freq`` env steps, and at the start and the end of training, SB3's ``EvalCallback`` evaluates the
current policy (deterministic, ``--eval-episodes`` episodes on a separate env), writes ``eval/mean_reward`` to
TensorBoard and appends to the run's ``evaluations.npz``; the training wall-clock of each evaluation (evaluation
time excluded) goes to ``summary.json``. Two evaluations at least per run, so that ``all_plots`` keeps a run that
stopped early (it drops single-evaluation runs). A budget in steps is passed to ``learn()``, which ends within
one generation (an sb3-es algorithm) or one rollout (PPO) past it; the steps taken are reported. A wall-clock
budget stops training through a callback. With ``--stop-at-threshold --confirm-episodes 100`` an evaluation that
reaches the threshold is confirmed on 100 more episodes (evaluation time), training stops only if they reach it
too, and the race counts the confirmed time (the confirmed model: ``confirmed_model.zip`` in the run folder). A run
that ends without a confirmed threshold has its final model confirmed too, whatever its last evaluation gave.
Each evaluation also saves the model as ``last_model.zip``; ``--continue-from <run>/last_model.zip --out <other>``
trains it on (one algorithm, env and seed; its step count goes on, the new run's wall-clock starts at 0).

Output folder layout::

    logs/<algo>/<env>_1_seed<s>/          rl-zoo run folder: model, <env>/config.yml, monitor files,
                                          evaluations.npz, best_model.zip, last_model.zip, summary.json
                                          (wall-clock, steps taken, confirmations), confirmed_model.zip
    tb/<env>/<RUN>_<n>/                   TensorBoard runs side by side (tensorboard --logdir <out>/tb)
    configs/<algo>-<env>.yml              rl-zoo3's entries used for its algorithms, before --override
    plots/<env>-wallclock.png             mean return against training wall-clock, band over seeds
    results.md                            race table: steps taken, time, final return, time to threshold
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import re
import shlex
import shutil
import sys
import tempfile
import time
import traceback
import warnings
from collections import defaultdict
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
import yaml
from common import (
    env_id_problems,
    hardware,
    parse_thresholds,
    read_value,
    selection_problems,
    source_commit,
    step_count,
    versions,
)
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.utils import set_random_seed
from stable_baselines3.common.vec_env import VecEnv

try:
    import rl_zoo3
    from rl_zoo3.exp_manager import ExperimentManager
    from rl_zoo3.utils import get_wrapper_class

    from sb3_es.zoo import RENAMED, UsageError, check_algo, default_conf_file, register, sb3_es_algos
    from sb3_es.zoo.commands import ZOO_KEYS, constructor_names
    from sb3_es.zoo.registry import zoo_meaning
except ImportError as e:  # pragma: no cover
    raise SystemExit(f"benchmarks/compare.py needs rl_zoo3: pip install 'sb3-es[zoo]' ({e})") from e

DEFAULT_ALGOS = ("ars_es", "openes", "cmaes", "reinforce", "ppo", "sac")


class TrainingWrapperManager(ExperimentManager):
    """
    rl-zoo's ``ExperimentManager`` whose training envs, and not its evaluation env, get one more wrapper.

    rl-zoo's ``env_wrapper`` wraps both; a wrapper that changes the task itself for the search (where episodes
    start, say) must stay out of the evaluations. It is applied first, inside the entry's ``env_wrapper``.
    """

    #: The training-only wrapper (``None``: none).
    train_wrapper: Any = None

    def create_envs(self, n_envs: int, eval_env: bool = False, no_log: bool = False) -> VecEnv:
        if eval_env or self.train_wrapper is None:
            return super().create_envs(n_envs, eval_env=eval_env, no_log=no_log)
        entry_wrapper, train_wrapper = self.env_wrapper, self.train_wrapper
        if entry_wrapper is not None:
            self.env_wrapper = lambda env: entry_wrapper(train_wrapper(env))
        else:
            self.env_wrapper = train_wrapper
        try:
            return super().create_envs(n_envs, eval_env=eval_env, no_log=no_log)
        finally:
            self.env_wrapper = entry_wrapper


def parse_train_wrapper(value: str | None) -> Any:
    """
    Read ``--train-wrapper``: a wrapper in rl-zoo's ``env_wrapper`` form, as YAML (``module.Class`` or
    ``{module.Class: {key: value}}``).

    :param value: The option's value (``None``: no wrapper).
    :return: The callable that wraps an env, or ``None``.
    """
    if value is None:
        return None
    try:
        return get_wrapper_class({"env_wrapper": yaml.safe_load(value)})
    except (ImportError, AttributeError, AssertionError, yaml.YAMLError) as e:
        raise SystemExit(
            f"--train-wrapper {value!r}: {e}; give an importable wrapper class as module.Class or "
            "'{module.Class: {key: value}}' (run from a folder where the module can be imported, e.g. PYTHONPATH=.)"
        ) from e


def env_slug(env_id: str) -> str:
    """
    File-name form of an env id (``dm_control/walker-walk-v0`` -> ``dm_control-walker-walk-v0``), as rl-zoo.

    :param env_id: Gymnasium env id.
    :return: The slug.
    """
    return env_id.replace("/", "-")


# ---------------------------------------------------------------------------------------------- configs
def resolve_zoo_entry(algo: str, env_id: str) -> tuple[dict[str, Any], str]:
    """
    rl-zoo3's own hyperparameters for ``algo`` on ``env_id``, with fallbacks for newer env versions.

    :param algo: rl-zoo algorithm name (``ppo``, ``sac``, ...).
    :param env_id: Gymnasium env id.
    :return: The entry and a note saying where it comes from.
    """
    path = Path(rl_zoo3.__file__).parent / "hyperparams" / f"{algo}.yml"
    data = yaml.safe_load(path.read_text())
    source = f"rl_zoo3 {rl_zoo3.__version__} hyperparams/{algo}.yml"
    if env_id in data:
        entry, note = dict(data[env_id]), f"{source}, entry {env_id}"
    else:
        match = re.fullmatch(r"(.+)-v(\d+)", env_id)
        older = []
        if match:
            for key in data:
                other = re.fullmatch(re.escape(match.group(1)) + r"-v(\d+)", str(key))
                if other and int(other.group(1)) < int(match.group(2)):
                    older.append((int(other.group(1)), key))
        if older:
            key = max(older)[1]
            entry, note = dict(data[key]), f"{source}, entry {key} (no {env_id} entry; same task, older version)"
        elif "default" in data:
            entry, note = dict(data["default"]), f"{source}, entry default (no {env_id} entry)"
        else:
            raise ValueError(f"{path} has no entry for {env_id} and no default entry.")
    env = gym.make(env_id)
    try:
        dict_obs = isinstance(env.observation_space, gym.spaces.Dict)
    finally:
        env.close()
    if dict_obs and entry.get("policy") == "MlpPolicy" and "env_wrapper" not in entry:
        entry["env_wrapper"] = "gymnasium.wrappers.FlattenObservation"
        note += "; env_wrapper FlattenObservation added (Dict observations)"
    return entry, note


def config_for(algo: str, env_id: str, out: Path) -> tuple[Path, str]:
    """
    The hyperparameter file for one (algorithm, env): ours, or a derived copy of rl-zoo3's entry.

    :param algo: Algorithm name.
    :param env_id: Env id.
    :param out: Output folder (derived files go to ``out/configs``).
    :return: Path of a YAML file with an entry for ``env_id`` and a note on its source.
    """
    if algo in sb3_es_algos():
        path = default_conf_file(algo)
        data = yaml.safe_load(path.read_text())
        key = env_id if env_id in data else "default"
        return path, f"sb3-es sb3_es/{path.parent.name}/{path.name}, entry {key}"
    entry, note = resolve_zoo_entry(algo, env_id)
    path = out / "configs" / f"{algo}-{env_slug(env_id)}.yml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"# {note}\n" + yaml.safe_dump({env_id: entry}, sort_keys=True))
    return path, note


# ---------------------------------------------------------------------------------------------- progress
class Progress:
    """
    One progress line per run: ``\\r``-updated on a terminal, a new line every 30 s otherwise.

    :param label: Run label, e.g. ``[2/6] PPO Pendulum-v1 seed 0``.
    :param total_steps: Step budget (or None).
    :param total_seconds: Wall-clock budget (or None).
    """

    def __init__(self, label: str, total_steps: int | None, total_seconds: float | None) -> None:
        self.label = label
        self.total_steps = total_steps
        self.total_seconds = total_seconds
        self.tty = sys.stdout.isatty()
        self.period = 1.0 if self.tty else 30.0
        self._last = -math.inf

    def update(self, steps: int, train_s: float, last_return: float | None, force: bool = False) -> None:
        """
        Print the line if enough time has passed.

        :param steps: Env steps so far.
        :param train_s: Training wall-clock seconds so far.
        :param last_return: Last evaluation's mean return.
        :param force: Print now.
        """
        now = time.perf_counter()
        if not force and now - self._last < self.period:
            return
        self._last = now
        parts = [f"{steps:,}" + (f"/{self.total_steps:,} steps" if self.total_steps else " steps")]
        fractions = []
        if self.total_steps:
            fractions.append(steps / self.total_steps)
        if self.total_seconds:
            fractions.append(train_s / self.total_seconds)
        if fractions:
            parts.append(f"{100 * min(1.0, max(fractions)):3.0f}%")
        parts.append(f"{train_s:,.0f}s" + (f"/{self.total_seconds:,.0f}s" if self.total_seconds else ""))
        if last_return is not None:
            parts.append(f"eval {last_return:,.1f}")
        line = f"{self.label}: " + " | ".join(parts)
        if self.tty:
            print("\r" + line.ljust(110), end="", flush=True)
        else:
            print(line, flush=True)

    def note(self, text: str) -> None:
        """
        Print a line of its own (a confirmation's result), after the progress line.

        :param text: The line, printed after the run's label.
        """
        print(("\n" if self.tty else "") + f"{self.label}: {text}", flush=True)
        self._last = -math.inf  # the progress line follows at once

    def close(self) -> None:
        """End the line on a terminal."""
        if self.tty:
            print(flush=True)


# ---------------------------------------------------------------------------------------------- recording
class RecordingEvalCallback(EvalCallback):
    """
    SB3's ``EvalCallback`` on a grid of env steps: at the start, at every multiple of ``eval_freq`` env steps
    below the step budget, and at the end of training (so every run has two evaluations at least). Runs with the
    same budget and ``eval_freq`` thus have the same number of evaluations whatever their generation (rollout)
    size, ``n_envs`` or overshoot, as rl-zoo's ``plot_from_file --iqm`` needs (it stacks the evaluations of every
    algorithm). It records the training wall-clock time of each evaluation (evaluations excluded), stops training
    at a wall-clock budget or a return threshold, and drives the progress line. The evaluations go to
    ``<log_path>/evaluations.npz``, as with rl-zoo's ``--eval-freq``.

    :param eval_env: Evaluation env.
    :param eval_freq: Env steps between evaluations; 0 for start and end only.
    :param n_eval_episodes: Episodes per evaluation.
    :param log_path: The rl-zoo run folder (``evaluations.npz`` and ``best_model.zip`` go there).
    :param budget_seconds: Stop training after this much training wall-clock (None: no limit).
    :param progress: Progress line.
    :param stop_at: Stop training once an evaluation's mean return reaches this value (None: never).
    :param budget_steps: The env-step budget given to ``learn()``: no grid evaluation at or past it (the one at
        the end of training takes its place, after the last generation's update).
    :param confirm_episodes: With ``stop_at``: an evaluation reaching it is confirmed on this many more episodes
        (evaluation time, excluded from training time), and training stops only if their mean reaches it too;
        the confirmed model is saved as ``confirmed_model.zip`` (0: the evaluation alone decides). A run that ends
        without reaching it has its final model confirmed as well.
    :param vecnormalize_path: Where rl-zoo keeps the run's ``VecNormalize`` statistics (``<run>/<env>/
        vecnormalize.pkl``, read by ``--continue-from``); None: not saved.

    After every evaluation the model is saved as ``last_model.zip`` in ``log_path`` (strategy state included, in
    evaluation time), with the training env's ``VecNormalize`` statistics if it has any: the checkpoint that
    ``--continue-from`` trains on from, also when the run was stopped before its end.
    """

    def __init__(
        self,
        eval_env: VecEnv,
        eval_freq: int,
        n_eval_episodes: int,
        log_path: str,
        budget_seconds: float | None,
        progress: Progress,
        stop_at: float | None = None,
        budget_steps: int | None = None,
        confirm_episodes: int = 0,
        vecnormalize_path: str | None = None,
    ) -> None:
        super().__init__(
            eval_env,
            n_eval_episodes=n_eval_episodes,
            eval_freq=1,  # SB3's schedule (every eval_freq calls) is replaced by the env-step grid, see _on_step
            log_path=log_path,
            best_model_save_path=log_path,
            deterministic=True,
            verbose=0,
        )
        self.grid = max(int(eval_freq), 0)
        self.budget_steps = budget_steps
        self.budget_seconds = budget_seconds
        self.stop_at = stop_at
        self.confirm_episodes = max(int(confirm_episodes), 0)
        self.vecnormalize_path = vecnormalize_path
        #: Confirmations: ``env_steps``, ``wall_s`` (training wall-clock), ``mean_return``, ``std_return``.
        self.confirmations: list[dict[str, float]] = []
        self._checked = 0  # evaluations checked against stop_at
        self.reached = False  # whether one reached it (confirmed, with confirm_episodes)
        self.progress = progress
        self.next_eval = self.grid
        #: Training wall-clock (s) and total wall-clock (s) of each evaluation, in the order of evaluations.npz.
        self.train_s: list[float] = []
        self.total_s: list[float] = []
        self.eval_seconds = 0.0
        self._start = 0.0

    def train_seconds(self) -> float:
        """
        Wall-clock seconds since training started, evaluations excluded.

        :return: Seconds.
        """
        return time.perf_counter() - self._start - self.eval_seconds

    def _grid_point_due(self) -> bool:
        """:return: Whether ``num_timesteps`` reached the next grid point, which lies below the step budget."""
        if self.grid <= 0 or self.num_timesteps < self.next_eval:
            return False
        due = self.budget_steps is None or self.next_eval < self.budget_steps
        self.next_eval = (self.num_timesteps // self.grid + 1) * self.grid
        return due

    def _evaluate(self) -> bool:
        start = time.perf_counter()
        continue_training = super()._on_step()  # eval_freq=1: evaluates now
        self.model.save(Path(self.best_model_save_path or ".") / "last_model")
        normalize = self.model.get_vec_normalize_env()
        if normalize is not None and self.vecnormalize_path is not None:
            Path(self.vecnormalize_path).parent.mkdir(parents=True, exist_ok=True)
            normalize.save(self.vecnormalize_path)
        self.eval_seconds += time.perf_counter() - start
        self.train_s.append(round(self.train_seconds(), 3))
        self.total_s.append(round(time.perf_counter() - self._start, 3))
        self.progress.update(self.num_timesteps, self.train_seconds(), self.last_mean_reward, force=True)
        return continue_training

    def _on_training_start(self) -> None:
        super()._on_training_start()
        self._start = time.perf_counter()
        self.next_eval = (self.num_timesteps // self.grid + 1) * self.grid if self.grid > 0 else 0
        self._evaluate()

    def _confirm(self, final: bool = False) -> bool:
        """
        Evaluate the deterministic policy on ``confirm_episodes`` more episodes, as evaluation time.

        :param final: Whether training has ended (the message then does not say that it goes on).
        :return: Whether their mean reaches ``stop_at``.
        """
        assert self.stop_at is not None
        start = time.perf_counter()
        returns, _ = evaluate_policy(
            self.model, self.eval_env, self.confirm_episodes, deterministic=True, return_episode_rewards=True
        )
        mean = float(np.mean(returns))
        held = mean >= self.stop_at
        if held:
            self.model.save(Path(self.best_model_save_path or ".") / "confirmed_model")
        self.eval_seconds += time.perf_counter() - start
        confirmation = {
            "env_steps": self.evaluations_timesteps[-1],
            "wall_s": round(self.train_seconds(), 3),
            "mean_return": mean,
            "std_return": float(np.std(returns)),
        }
        self.confirmations.append(confirmation)
        verdict = "confirmed" if held else "not confirmed" if final else "not confirmed, training goes on"
        self.progress.note(
            f"{self.confirm_episodes} confirmation episodes at {confirmation['env_steps']:,} steps: "
            f"{mean:,.1f} +- {confirmation['std_return']:,.1f} ({verdict}; threshold {self.stop_at:g})"
        )
        return held

    def _check_threshold(self) -> bool:
        """:return: Whether a new evaluation reached ``stop_at`` (and, with ``confirm_episodes``, was confirmed)."""
        if self.stop_at is None or len(self.train_s) <= self._checked:
            return False
        self._checked = len(self.train_s)
        self.reached = self.last_mean_reward >= self.stop_at and (not self.confirm_episodes or self._confirm())
        return self.reached

    def _on_step(self) -> bool:
        continue_training = self._evaluate() if self._grid_point_due() else True
        train_s = self.train_seconds()
        self.progress.update(self.num_timesteps, train_s, self.last_mean_reward if self.train_s else None)
        if self._check_threshold():  # checked first: an evaluation at the end of the time budget counts too
            return False
        if self.budget_seconds is not None and train_s >= self.budget_seconds:
            return False
        return continue_training

    def _on_training_end(self) -> None:
        if not self.evaluations_timesteps or self.evaluations_timesteps[-1] != self.num_timesteps:
            self._evaluate()
        confirmed_here = bool(self.confirmations) and self.confirmations[-1]["env_steps"] == self.num_timesteps
        if self.reached or confirmed_here:  # stopped at the threshold, or this very model failed its confirmation
            pass
        elif self.confirm_episodes and self.stop_at is not None:
            # The final model is confirmed whatever its evaluation gave: a policy whose episodes vary much can hold
            # the threshold over many episodes while its evaluation, on few, fell short.
            self.reached = self._confirm(final=True)
        else:
            self._check_threshold()  # the final evaluation is checked too, as the grid ones are
        self.progress.update(self.num_timesteps, self.train_seconds(), self.last_mean_reward, force=True)
        super()._on_training_end()


# ---------------------------------------------------------------------------------------------- one run
def run_folder(out: Path, algo: str, env_id: str, seed: int) -> Path:
    """
    The rl-zoo run folder of one (algorithm, env, seed): ``<out>/logs/<algo>/<env>_1_seed<seed>``.

    :param out: Output folder.
    :param algo: Algorithm key.
    :param env_id: Env id.
    :param seed: Seed.
    :return: The folder (rl-zoo's ``ExperimentManager`` names it from ``uuid_str="_seed<seed>"``).
    """
    return out / "logs" / algo / f"{env_slug(env_id)}_1_seed{seed}"


class RunRefused(ValueError):
    """A run's input that it cannot use (a ``--continue-from`` model it cannot load): said without a traceback."""


def run_one(
    algo: str,
    env_id: str,
    seed: int,
    out: Path,
    steps: int | None,
    seconds: float | None,
    eval_freq: int,
    eval_episodes: int,
    label: str,
    verbose: int = 0,
    overrides: dict[str, Any] | None = None,
    command: str = "",
    stop_at: float | None = None,
    confirm_episodes: int = 0,
    eval_envs: int = 1,
    continue_from: Path | None = None,
    train_wrapper: str | None = None,
) -> dict[str, Any]:
    """
    Train one (algorithm, env, seed) run through rl-zoo's ExperimentManager and record its evaluations.

    :param algo: Algorithm key (of ``rl_zoo3.ALGOS`` after :func:`sb3_es.zoo.register`).
    :param env_id: Env id.
    :param seed: Seed.
    :param out: Output folder.
    :param steps: Env-step budget (None: the config's ``n_timesteps``, used with ``seconds``).
    :param seconds: Training wall-clock budget in seconds (None: no limit).
    :param eval_freq: Env steps between evaluations (0: start and end only).
    :param eval_episodes: Episodes per evaluation.
    :param label: Progress label.
    :param verbose: Verbosity of the model (0: progress line only).
    :param overrides: Hyperparameters replacing the config's (as rl-zoo's ``-params``).
    :param command: Command line of the comparison, for the record.
    :param stop_at: Stop training once an evaluation reaches this mean return (None: run the whole budget).
    :param confirm_episodes: With ``stop_at``: episodes of the confirmation that must reach it too (0: none).
    :param eval_envs: Envs the evaluation episodes run on, side by side (one process, batched policy calls).
    :param continue_from: A saved model (e.g. a run's ``last_model.zip``) to train on from, loaded by rl-zoo's
        ``--trained-agent`` with the overrides applied: its step count goes on, so evaluations keep the grid and the
        budget in steps counts from there; the wall-clock columns count this run only.
    :param train_wrapper: A wrapper for the training envs only, in rl-zoo's ``env_wrapper`` form as YAML (see
        :class:`TrainingWrapperManager`); the evaluations run on the env without it.
    :return: The run summary (also written to the run folder's ``summary.json``).
    """
    started = time.strftime("%Y-%m-%d %H:%M %Z")
    config, note = config_for(algo, env_id, out)
    folder = run_folder(out, algo, env_id, seed)
    if continue_from is not None:
        continue_from = continue_from.resolve()
        if not continue_from.is_file() or continue_from.suffix != ".zip":
            raise RunRefused(f"--continue-from {continue_from}: no such model; give a saved model's .zip file.")
        if continue_from.is_relative_to(folder.resolve()):
            raise RunRefused(
                f"--continue-from {continue_from} lies in the run folder {folder}, which the new run replaces: "
                "give another --out, or copy the model elsewhere first."
            )
    replaced, replaced_tb = None, None
    if folder.exists():  # a new run of the same (algorithm, env, seed) replaces the old one once it is set up
        with contextlib.suppress(OSError, ValueError, AttributeError):  # its TensorBoard run goes too
            replaced_tb = json.loads((folder / "summary.json").read_text()).get("tensorboard_dir")
        replaced = Path(tempfile.mkdtemp(prefix=".replaced_", dir=out)) / folder.name
        folder.rename(replaced)
    try:
        args = argparse.Namespace(
            algo=algo, env=env_id, seed=seed, n_timesteps=steps or -1, conf_file=str(config), env_kwargs=None
        )
        set_random_seed(seed)
        manager = TrainingWrapperManager(
            args,
            algo,
            env_id,
            str(out / "logs"),
            tensorboard_log=str(out / "tb"),
            n_timesteps=steps or 0,
            eval_freq=-1,
            seed=seed,
            verbose=verbose,
            config=str(config),
            hyperparams=dict(overrides) if overrides else None,
            uuid_str=f"_seed{seed}",
            trained_agent=str(continue_from or ""),
        )
        assert Path(manager.save_path) == folder, (manager.save_path, folder)
        manager.train_wrapper = parse_train_wrapper(train_wrapper)
        if overrides:
            note += f"; overridden: {', '.join(f'{k}={v}' for k, v in overrides.items())}"
        if train_wrapper is not None:
            note += f"; training envs only: {train_wrapper}"
        setup_log = io.StringIO()
        try:
            with contextlib.redirect_stdout(setup_log if verbose == 0 else sys.stdout):
                result = manager.setup_experiment()
        except (TypeError, ValueError, KeyError) as e:
            if continue_from is None:
                raise
            # e.g. a PPO run given an ARS model: the policy's constructor refuses PPO's arguments
            raise RunRefused(
                f"--continue-from {continue_from}: {algo} cannot load it ({type(e).__name__}: {e}); give a model saved "
                f"by {algo}."
            ) from e
        assert result is not None
        (folder / "setup.txt").write_text(setup_log.getvalue())
    except BaseException:
        if replaced is not None:  # the old run is put back: nothing is lost to a run that could not start
            shutil.rmtree(folder, ignore_errors=True)
            replaced.rename(folder)
        raise
    finally:
        if replaced is not None:
            shutil.rmtree(replaced.parent)
    if replaced_tb and Path(replaced_tb).resolve().is_relative_to((out / "tb").resolve()):
        shutil.rmtree(replaced_tb, ignore_errors=True)
    model, hyperparams = result
    total = manager.n_timesteps
    offset = model.num_timesteps  # 0 for a new model; a continued one goes on from its saved count
    progress = Progress(label, offset + total if steps else None, seconds)
    n_envs = model.get_env().num_envs  # type: ignore[union-attr]
    recorder = RecordingEvalCallback(
        manager.create_envs(eval_envs, eval_env=True),
        eval_freq=eval_freq,
        n_eval_episodes=eval_episodes,
        log_path=str(folder),
        budget_seconds=seconds,
        progress=progress,
        stop_at=stop_at,
        budget_steps=offset + total,
        confirm_episodes=confirm_episodes,
        vecnormalize_path=str(Path(manager.params_path) / "vecnormalize.pkl"),
    )
    start = time.perf_counter()
    try:
        model.learn(total, callback=[*manager.callbacks, recorder], reset_num_timesteps=continue_from is None)
    except KeyboardInterrupt:
        kept = [name for name in ("evaluations.npz", "last_model.zip") if (folder / name).is_file()]
        print(
            f"\n{label}: interrupted at {model.num_timesteps:,} env steps; the run has no summary.json, so reports "
            f"leave it out. Kept in {folder}: {', '.join(kept) or 'nothing (no evaluation yet)'}"
            + (f"; train on with --continue-from {folder / 'last_model.zip'} --out ANOTHER_FOLDER." if kept else "."),
            file=sys.stderr,
        )
        raise
    finally:
        progress.close()
    total_s = time.perf_counter() - start
    with contextlib.redirect_stdout(io.StringIO()):
        manager.save_trained_model(model)
    tb_dir = model.logger.get_dir()
    model.get_env().close()  # type: ignore[union-attr]
    recorder.eval_env.close()
    returns = [float(np.mean(r)) for r in recorder.evaluations_results]
    summary = {
        "algo": algo,
        "algorithm": type(model).__name__,
        "env": env_id,
        "seed": seed,
        "env_steps": int(model.num_timesteps),
        "train_seconds": round(recorder.train_seconds(), 2),
        "total_seconds": round(total_s, 2),
        "final_return": returns[-1],
        "best_return": max(returns),
        "eval_timesteps": [int(x) for x in recorder.evaluations_timesteps],
        "eval_train_seconds": recorder.train_s,
        "eval_total_seconds": recorder.total_s,
        "n_envs": n_envs,
        "torch_threads": torch.get_num_threads(),
        "budget_steps": steps,
        "budget_seconds": seconds,
        "eval_freq": eval_freq,
        "eval_episodes": eval_episodes,
        "eval_envs": eval_envs,
        "continued_from": {"model": str(continue_from), "env_steps": offset} if continue_from is not None else None,
        "train_wrapper": train_wrapper,
        "stop_at": stop_at,
        "confirm_episodes": recorder.confirm_episodes if stop_at is not None else 0,
        "confirmations": recorder.confirmations,
        "hyperparams_source": note,
        "config": str(config),
        "hyperparams": {k: str(v) for k, v in hyperparams.items()},
        "tensorboard_dir": tb_dir,
        "model": str(folder / f"{manager.env_name}.zip"),
        "command": command,
        "started": started,
        "date": time.strftime("%Y-%m-%d %H:%M %Z"),  # the end of the run
        "hardware": hardware(),
        "commit": source_commit(),
    }
    (folder / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


# ---------------------------------------------------------------------------------------------- report
def load_runs(out: Path) -> list[dict[str, Any]]:
    """
    Every finished run in an output folder: its ``summary.json`` with the evaluations of its ``evaluations.npz``.

    :param out: Output folder.
    :return: Run summaries, each with ``rows`` (``env_steps``, ``wall_s``, ``mean_return`` per evaluation).
    """
    runs = []
    for summary_path in sorted((out / "logs").glob("*/*_seed*/summary.json")):
        summary = json.loads(summary_path.read_text())
        evaluations = np.load(summary_path.parent / "evaluations.npz")
        summary["rows"] = [
            {"env_steps": float(steps), "wall_s": float(wall), "mean_return": float(np.mean(results))}
            for steps, wall, results in zip(
                evaluations["timesteps"], summary["eval_train_seconds"], evaluations["results"]
            )
        ]
        runs.append(summary)
    return runs


def aggregate(curves: list[tuple[np.ndarray, np.ndarray]], n_points: int = 200) -> tuple[np.ndarray, ...]:
    """
    Mean, min, max and std over seeds of curves sampled at different x, on a common grid.

    Each curve is interpolated linearly inside its own x range only; a grid point uses the seeds
    whose range covers it (``count`` says how many).

    :param curves: ``(x, y)`` per seed, x increasing.
    :param n_points: Grid size.
    :return: ``grid, mean, low, high, std, count``.
    """
    x_max = max(float(x[-1]) for x, _ in curves)
    grid = np.linspace(0.0, x_max, n_points)
    values = np.full((len(curves), n_points), np.nan)
    for i, (x, y) in enumerate(curves):
        inside = (grid >= x[0]) & (grid <= x[-1])
        values[i, inside] = np.interp(grid[inside], x, y)
    count = np.sum(~np.isnan(values), axis=0)
    with warnings.catch_warnings():  # all-NaN columns (no seed covers the point) give NaN, as intended
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(values, axis=0)
        low, high = np.nanmin(values, axis=0), np.nanmax(values, axis=0)
        std = np.nanstd(values, axis=0)
    return grid, mean, low, high, std, count


def plot_env(env_id: str, runs: list[dict[str, Any]], path: Path, band: str, threshold: float | None = None) -> None:
    """
    One PNG: mean return against training wall-clock where every seed has data, band over seeds, each seed as a thin
    line over its whole run, and the threshold (rl-zoo's ``all_plots`` draws env steps).

    :param env_id: Env id (title).
    :param runs: The env's runs.
    :param path: PNG path.
    :param band: ``"minmax"`` or ``"std"``.
    :param threshold: Return threshold, drawn dashed (None: none).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    by_algo: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for run in runs:
        by_algo[run["algo"]].append(run)
    for color_index, (name, algo_runs) in enumerate(sorted(by_algo.items())):
        color = f"C{color_index}"
        curves = [
            (np.array([r["wall_s"] for r in run["rows"]]), np.array([r["mean_return"] for r in run["rows"]]))
            for run in algo_runs
            if run["rows"]
        ]
        if not curves:
            continue
        for x, y in curves:  # each seed over its whole run, thin: a seed that stops early still shows
            ax.plot(x, y, color=color, alpha=0.35, linewidth=0.8)
        grid, mean, low, high, std, count = aggregate(curves)
        shown = count == len(curves)  # where every seed has data: no jumps where one seed ends early
        seeds = f"{len(curves)} seed" + ("s" if len(curves) > 1 else "")
        ax.plot(grid[shown], mean[shown], color=color, label=f"{name} ({seeds})")
        if len(curves) > 1:
            lo, hi = (low, high) if band == "minmax" else (mean - std, mean + std)
            ax.fill_between(grid[shown], lo[shown], hi[shown], color=color, alpha=0.2, linewidth=0)
    if threshold is not None:
        ax.axhline(threshold, color="grey", linestyle="--", linewidth=0.8)
    band_text = "min-max over seeds" if band == "minmax" else "mean ± std over seeds"
    ax.set_xlabel("training wall-clock (s), evaluations excluded")
    ax.set_ylabel("mean evaluation return")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    ax.set_title(f"{env_id}: mean over seeds, band {band_text}", fontsize="medium")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _mean_std(values: list[float]) -> str:
    if len(values) == 1:
        return f"{values[0]:.1f}"
    return f"{np.mean(values):.1f} ± {np.std(values):.1f}"


def time_to_threshold(runs: list[dict[str, Any]], threshold: float) -> str:
    """
    The race measure: median over seeds of the training wall-clock at the first evaluation reaching ``threshold``,
    a seed that never reaches it counting as its whole training time (its budget), with the per-seed times. A run
    made with ``--confirm-episodes`` counts its first confirmation reaching ``threshold`` instead.

    :param runs: The runs of one algorithm on one env.
    :param threshold: Return threshold.
    :return: Table cell, seeds in order, e.g. ``1,959 s median (1,959 / >2,700 / 1,028 s; 2/3 seeds)``.
    """
    per_seed = []  # (seconds, censored) in seed order; censored: never reached, the seconds are its budget
    # A run confirmed against another threshold (its stop_at) counts its evaluations: its confirmations say nothing
    # about this one.
    other = [run for run in runs if run.get("confirm_episodes") and run.get("stop_at", threshold) != threshold]
    other_ids = {id(run) for run in other}
    confirmed = sorted({int(run.get("confirm_episodes") or 0) for run in runs if id(run) not in other_ids})
    for run in sorted(runs, key=lambda r: r["seed"]):
        use_confirmations = run.get("confirm_episodes") and id(run) not in other_ids
        rows = run["confirmations"] if use_confirmations else run["rows"]
        hit = next((r for r in rows if r["mean_return"] >= threshold), None)
        if hit is None:
            # its wall-clock budget, also when it stopped earlier at its step budget (it never reached the threshold)
            per_seed.append((max(float(run["train_seconds"]), float(run.get("budget_seconds") or 0.0)), True))
        else:
            per_seed.append((float(hit["wall_s"]), False))
    cells = " / ".join(f"{'>' if censored else ''}{seconds:,.0f}" for seconds, censored in per_seed)
    reached = sum(not censored for _, censored in per_seed)
    order = sorted(per_seed)
    middle = order[(len(order) - 1) // 2 : len(order) // 2 + 1]  # one entry (odd count) or two (even)
    prefix = ">" if any(censored for _, censored in middle) else ""  # a budget in the median: a lower bound
    median = float(np.mean([seconds for seconds, _ in middle]))
    note = f"; confirmed on {' or '.join(map(str, confirmed))} episodes" if confirmed not in ([0], []) else ""
    for run in other:
        note += f"; s{run['seed']} confirmed at {run['stop_at']:g}, so its evaluations count"
    return f"{prefix}{median:,.0f} s median ({cells} s; {reached}/{len(runs)} seeds{note})"


def write_report(out: Path, runs: list[dict[str, Any]], thresholds: dict[str, float], band: str, command: str) -> Path:
    """
    The wall-clock plots (one PNG per env) and ``results.md``, the race table; the env-steps curves and rliable's
    intervals come from rl-zoo's ``all_plots`` and ``plot_from_file`` (their commands are in the report).

    :param out: Output folder.
    :param runs: Runs from :func:`load_runs`.
    :param thresholds: Return thresholds per env id, for the time-to-threshold column.
    :param band: ``"minmax"`` or ``"std"``.
    :param command: Command line, for the record.
    :return: Path of ``results.md``.
    """
    ends = [r.get("date") or "?" for r in runs]
    starts = [r.get("started") or r.get("date") or "?" for r in runs]  # summaries before "started": the end
    lines = [
        "# Benchmark results",
        "",
        *[f"- Training command: `{c}`" for c in sorted({r.get("command") or "?" for r in runs})],
        f"- Report command: `{command}`",
        *[f"- Hardware: {h}" for h in sorted({r.get("hardware") or hardware() for r in runs})],
        f"- Versions: {versions('rl_zoo3')}",
        f"- Runs: first started {min(starts)}, last ended {max(ends)}",
        "- Returns: mean over the evaluation episodes of the deterministic policy; across seeds, mean ± std.",
        "  *final*: last evaluation; *env steps*: taken (a run ends within one generation or rollout past its",
        "  budget); wall-clock excludes evaluations.",
        *[
            f"- **Failed** (no result, `--keep-going`): `{error.parent.relative_to(out)}`, see its `error.txt`"
            for error in sorted((out / "logs").glob("*/*_seed*/error.txt"))
            if not (error.parent / "summary.json").is_file()
        ],
        "",
    ]
    by_env: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for run in runs:
        by_env[run["env"]].append(run)
    for env_id, env_runs in sorted(by_env.items()):
        png = out / "plots" / f"{env_slug(env_id)}-wallclock.png"
        threshold = thresholds.get(env_id)
        plot_env(env_id, env_runs, png, band, threshold)
        header = "| algorithm | seeds | env steps | train wall-clock (s) | final return |"
        rule = "|---|---|---|---|---|"
        if threshold is not None:
            header += f" time to return ≥ {threshold:g} (a seed that misses: its budget) |"
            rule += "---|"
        budgets = sorted(
            {
                (r["budget_steps"] or 0, r["budget_seconds"] or 0, r["eval_freq"], r["eval_episodes"])
                + (r.get("torch_threads", "?"),)
                for r in env_runs
            }
        )
        lines += [f"## {env_id}", ""]
        for b_steps, b_seconds, freq, episodes, threads in budgets:
            budget = " and ".join(
                x for x in (f"{b_steps:,} env steps" if b_steps else "", f"{b_seconds:g} s" if b_seconds else "") if x
            )
            every = f"every {freq:,} env steps" if freq else "at the start and the end"
            lines.append(f"Budget: {budget}; evaluation {every}, {episodes} episodes; torch threads: {threads}.")
        for run in sorted(env_runs, key=lambda r: (r["algo"], r["seed"])):
            if run.get("continued_from"):
                lines.append(
                    f"{run['algo']} seed {run['seed']} continued `{run['continued_from']['model']}` from "
                    f"{run['continued_from']['env_steps']:,} env steps: its env steps count from the first run's "
                    "start, its wall-clock from this run's."
                )
        lines += ["", header, rule]
        by_algo: dict[str, list[dict[str, Any]]] = defaultdict(list)
        for run in env_runs:
            by_algo[run["algo"]].append(run)
        for name, algo_runs in sorted(by_algo.items()):
            seeds = ", ".join(str(r["seed"]) for r in sorted(algo_runs, key=lambda r: r["seed"]))
            row = (
                f"| {name} ({algo_runs[0]['algorithm']}) | {len(algo_runs)} ({seeds}) "
                f"| {np.mean([r['env_steps'] for r in algo_runs]):,.0f} "
                f"| {np.mean([r['train_seconds'] for r in algo_runs]):,.1f} "
                f"| {_mean_std([r['final_return'] for r in algo_runs])} |"
            )
            if threshold is not None:
                row += f" {time_to_threshold(algo_runs, threshold)} |"
            lines.append(row)
        sources = sorted({f"{r['algo']}: {r['hyperparams_source']}" for r in env_runs})
        pickle = out / f"all_plots-{env_slug(env_id)}"
        # rl-zoo's --iqm stacks the evaluations of every algorithm: it needs as many per run everywhere
        n_evals = sorted({len(r["eval_timesteps"]) for r in env_runs})
        iqm = "--iqm " if len(n_evals) == 1 else ""
        lines += [
            "",
            "Hyperparameters: " + "; ".join(sources) + ".",
            "",
            f"![{env_id}](plots/{png.name})",
            "",
            "Curves against env steps, rl-zoo's table and rliable's intervals (aggregate scores; with --iqm, the",
            "IQM per evaluation):",
            "",
            f"    python -m sb3_es.zoo all_plots -a {' '.join(sorted(by_algo))} -e {env_id} -f {out / 'logs'} "
            f"--no-million -o {pickle}",
            f"    python -m sb3_es.zoo plot_from_file -i {pickle}.pkl --rliable {iqm}--no-million",
            "",
        ]
        if not iqm:
            lines += [
                f"(No --iqm: the runs have {' or '.join(map(str, n_evals))} evaluations, a wall-clock budget or",
                "--stop-at-threshold having ended some early; rl-zoo's IQM curve needs the same number in every run.)",
                "",
            ]
    path = out / "results.md"
    path.write_text("\n".join(lines))
    return path


# ---------------------------------------------------------------------------------------------- main
def parse_overrides(items: list[str]) -> dict[str, dict[str, Any]]:
    """
    Parse ``ALGO:KEY=VALUE`` items (values read as YAML: numbers, booleans, ``lin_0.01``, ``"dict(...)"``).

    :param items: Items from the command line.
    :return: Overrides per algorithm.
    """
    overrides: dict[str, dict[str, Any]] = defaultdict(dict)
    for item in items:
        target, sep, value = item.partition("=")
        algo, colon, key = target.partition(":")
        if not sep or not colon or not algo or not key:
            raise SystemExit(f"--override {item!r}: use ALGO:KEY=VALUE, e.g. ppo:n_steps=256")
        try:
            overrides[algo][key] = read_value(value)
            if isinstance(overrides[algo][key], str) and "(" in value:
                compile(overrides[algo][key], "--override", "eval")  # rl-zoo evaluates it: "dict(...)"
        except (ValueError, SyntaxError) as e:  # read_value's one-line reason, or the expression's
            reason = f"SyntaxError: {str(e).splitlines()[0]}" if isinstance(e, SyntaxError) else str(e)
            raise SystemExit(
                f"--override {item!r}: {value!r} is not a value ({reason}); "
                "write numbers, true/false, [lists] or a Python expression such as dict(net_arch=[64, 64])"
            ) from e
    return dict(overrides)


def check_run_arguments(args: argparse.Namespace, thresholds: dict[str, float], overrides: dict[str, Any]) -> None:
    """
    Refuse, with a message naming the flag, what a run would otherwise ignore or misread.

    :param args: The parsed arguments (not ``--report-only``).
    :param thresholds: Parsed ``--threshold`` values.
    :param overrides: Parsed ``--override`` values.
    """
    problems = []
    for flag, value, low in (
        ("--steps", args.steps, 1),
        ("--seconds", args.seconds, 1e-9),
        ("--eval-freq", args.eval_freq, 0),
        ("--eval-episodes", args.eval_episodes, 1),
        ("--eval-envs", args.eval_envs, 1),
        ("--confirm-episodes", args.confirm_episodes, 0),
    ):
        if value is not None and not value >= low:  # NaN too
            problems.append(f"{flag} {value}: it must be {'positive' if low > 0 else '0 or more'}")
    problems += selection_problems(args.seeds, args.envs, thresholds)
    repeated_algos = sorted({algo for algo in args.algos if args.algos.count(algo) > 1})
    if repeated_algos:
        problems.append(f"--algos repeats {repeated_algos}: give each once (a seed is one run of each)")
    unknown_algos = sorted(set(overrides) - set(args.algos))
    if unknown_algos:
        problems.append(f"--override for {unknown_algos}, which --algos {args.algos} does not run")
    if args.steps is not None and any("n_timesteps" in values for values in overrides.values()):
        problems.append("--override ...:n_timesteps with --steps: --steps sets every run's budget; give one of them")
    missing = [algo for algo in args.algos if algo not in rl_zoo3.ALGOS]
    if missing:
        problems.append(f"--algos {missing}: unknown or unavailable (known: {sorted(rl_zoo3.ALGOS)})")
    problems += env_id_problems("--envs", args.envs)  # before any run, not when its turn comes after hours of others
    for algo, values in overrides.items():
        if algo not in rl_zoo3.ALGOS:
            continue
        # rl-zoo passes every other key to the constructor, whose TypeError would end the batch at that run
        params = constructor_names(rl_zoo3.ALGOS[algo])
        zoo_keys = [*ZOO_KEYS, *(() if algo in sb3_es_algos() else ("noise_type", "noise_std"))]
        unknown = sorted(set(values) - params - set(zoo_keys))
        if unknown:
            problems.append(
                f"--override {algo}:{unknown[0]}: {', '.join(unknown)} is not a hyperparameter of "
                f"{rl_zoo3.ALGOS[algo].__name__} (its: {', '.join(sorted(params))}; rl-zoo's: {', '.join(zoo_keys)})"
            )
    if args.continue_from is not None:
        # A run folder of this script, <algo>/<env>_1_seed<s>, names the env the model was trained on.
        trained = re.fullmatch(r"(.+)_\d+_seed(\d+)", args.continue_from.parent.name)
        if trained and trained.group(1) not in [env_slug(env_id) for env_id in args.envs]:
            problems.append(
                f"--continue-from {args.continue_from} was trained on {trained.group(1)}, not on --envs {args.envs}"
            )
        if trained and len(args.seeds) == 1 and int(trained.group(2)) != args.seeds[0]:
            problems.append(
                f"--continue-from {args.continue_from} was trained with seed {trained.group(2)}, not --seeds "
                f"{' '.join(map(str, args.seeds))}: a continued run goes on with its own seed ('--seeds "
                f"{trained.group(2)}'), or would be reported as another seed"
            )
    if problems:
        raise SystemExit("compare.py: " + "; ".join(problems) + ".")


def main(argv: list[str] | None = None) -> Path:
    """
    Run the comparison and write the report.

    :param argv: Arguments (defaults to ``sys.argv[1:]``).
    :return: Path of ``results.md``.
    """
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algos", nargs="+", default=list(DEFAULT_ALGOS), help="rl-zoo algorithm names")
    parser.add_argument("--envs", nargs="+", default=["Pendulum-v1"], help="gymnasium env ids")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--steps", type=step_count, default=None, help="env-step budget per run")
    parser.add_argument("--seconds", type=float, default=None, help="training wall-clock budget per run")
    parser.add_argument(
        "--eval-freq",
        type=step_count,
        default=10_000,
        help="env steps between evaluations (0: at the start and the end only)",
    )
    parser.add_argument("--eval-episodes", type=int, default=5)
    parser.add_argument("--out", default="results/compare", help="output folder")
    parser.add_argument("--band", choices=["minmax", "std"], default="minmax", help="band over seeds in the plots")
    parser.add_argument(
        "--threshold",
        nargs="+",
        action="extend",
        default=[],
        help="ENV_ID=RETURN for the time-to-threshold column (repeatable)",
    )
    parser.add_argument(
        "--stop-at-threshold", action="store_true", help="end a run once an evaluation reaches its --threshold"
    )
    parser.add_argument(
        "--eval-envs",
        type=int,
        default=1,
        help="envs the evaluation episodes run on side by side (faster evaluations of long episodes, e.g. 10)",
    )
    parser.add_argument(
        "--confirm-episodes",
        type=int,
        default=0,
        help="with --stop-at-threshold: stop only when this many more episodes confirm the threshold (e.g. 100)",
    )
    parser.add_argument(
        "--continue-from",
        type=Path,
        default=None,
        help="a saved model (e.g. a run's last_model.zip) to train on from; one algorithm, env and seed only",
    )
    parser.add_argument(
        "--train-wrapper",
        default=None,
        help="a wrapper for the training envs only, not the evaluations, as rl-zoo's env_wrapper in YAML: "
        "module.Class or '{module.Class: {key: value}}'",
    )
    parser.add_argument("--skip-existing", action="store_true", help="skip runs that already have a summary.json")
    parser.add_argument("--keep-going", action="store_true", help="record a failed run and go on with the others")
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="only redraw plots and table, from every run in --out (--algos, --envs, --seeds and budgets unused)",
    )
    parser.add_argument(
        "--num-threads",
        type=int,
        default=1,
        help="torch threads (default 1: small networks on a CPU train faster single-threaded; -1: torch's default)",
    )
    parser.add_argument("--verbose", type=int, default=0, help="model verbosity (0: progress line only)")
    parser.add_argument(
        "--override",
        nargs="+",
        action="extend",
        default=[],
        help="ALGO:KEY=VALUE hyperparameter overrides, e.g. ppo:n_steps=256 (repeatable)",
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    thresholds = parse_thresholds(args.threshold)
    overrides = parse_overrides(args.override)
    given = argv if argv is not None else sys.argv[1:]
    command = "python benchmarks/compare.py " + " ".join(shlex.quote(a) for a in given)
    register()
    for algo in args.algos:
        # A key sb3-es used before (RENAMED) that is rl-zoo's own is taken as rl-zoo's, with a note; the zoo commands
        # refuse it (check_algo), and so does a comparison when rl-zoo has no such key.
        theirs = zoo_meaning(algo) if algo in RENAMED else None
        if theirs is None:
            try:
                check_algo(algo)
            except UsageError as e:
                raise SystemExit(str(e)) from e
        else:
            print(
                f"--algos {algo} is {theirs} (rl-zoo's key, with rl-zoo's hyperparameters); "
                f"sb3-es's is {RENAMED[algo]}."
            )
    if not args.report_only:
        if args.steps is None and args.seconds is None:
            raise SystemExit("Give a budget: --steps N (env steps), --seconds S (training wall-clock), or both.")
        if args.confirm_episodes and not args.stop_at_threshold:
            raise SystemExit("--confirm-episodes confirms --stop-at-threshold's threshold: add it, with --threshold.")
        if args.stop_at_threshold and not thresholds:
            raise SystemExit("--stop-at-threshold stops at a --threshold ENV_ID=RETURN: give one.")
        check_run_arguments(args, thresholds, overrides)
        if args.num_threads > 0:
            torch.set_num_threads(args.num_threads)
        plan = [(e, a, s) for e in args.envs for a in args.algos for s in args.seeds]
        if args.continue_from is not None and len(plan) != 1:
            raise SystemExit(
                f"--continue-from trains one model on: give one algorithm, env and seed (the plan has {len(plan)})."
            )
        start = time.perf_counter()
        failures: list[str] = []
        for i, (env_id, algo, seed) in enumerate(plan, 1):
            run_dir = run_folder(out, algo, env_id, seed)
            label = f"[{i}/{len(plan)}] {algo} {env_id} seed {seed}"
            if args.skip_existing and (run_dir / "summary.json").is_file():
                print(f"{label}: done already, skipped")
                continue
            try:
                summary = run_one(
                    algo,
                    env_id,
                    seed,
                    out,
                    args.steps,
                    args.seconds,
                    args.eval_freq,
                    args.eval_episodes,
                    label,
                    verbose=args.verbose,
                    overrides=overrides.get(algo),
                    command=command,
                    stop_at=thresholds.get(env_id) if args.stop_at_threshold else None,
                    confirm_episodes=args.confirm_episodes,
                    eval_envs=args.eval_envs,
                    continue_from=args.continue_from,
                    train_wrapper=args.train_wrapper,
                )
            except Exception as e:
                if not args.keep_going:
                    if isinstance(e, RunRefused):
                        raise SystemExit(f"compare.py: {e}") from e
                    raise
                failures.append(label)
                run_dir.mkdir(parents=True, exist_ok=True)
                (run_dir / "error.txt").write_text(traceback.format_exc())
                print(f"{label}: FAILED, see {run_dir / 'error.txt'}")
                continue
            confirmed = "".join(
                f", {args.confirm_episodes} episodes at {c['env_steps']:,} steps: {c['mean_return']:.1f}"
                for c in summary["confirmations"]
            )
            print(
                f"{label}: {summary['env_steps']:,} steps in {summary['train_seconds']:,.0f} s, "
                f"final {summary['final_return']:.1f}, best {summary['best_return']:.1f}{confirmed}"
            )
        print(f"{len(plan)} runs in {time.perf_counter() - start:,.0f} s")
        if failures:
            print(f"{len(failures)} failed: {failures}")
    runs = load_runs(out)
    if not runs:
        raise SystemExit(f"No finished runs under {out / 'logs'}.")
    report = write_report(out, runs, thresholds, args.band, command)
    print(f"Report: {report}\nPlots: {out / 'plots'}\nTensorBoard: tensorboard --logdir {out / 'tb'}")
    if not args.report_only and failures:
        raise SystemExit(f"compare.py: {len(failures)} run(s) failed (--keep-going): {', '.join(failures)}.")
    return report


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        sys.exit(130)  # what was kept is said above; no traceback for a Ctrl-C
