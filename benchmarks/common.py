"""
What the benchmark scripts share: the description of the machine and software a figure was measured on (SB3's
``get_system_info()`` plus what it lacks: the CPU model, the core count, sb3-es and optional packages), and the
plain ``env.step`` loop, the machine's ceiling that throughputs are compared with.

The scripts import it as ``from common import ...`` (Python puts a script's own folder on ``sys.path``).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import multiprocessing as mp
import os
import platform
import subprocess
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import gymnasium as gym
import yaml
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.utils import get_system_info

import sb3_es
from sb3_es.strategies.base import parse_number

#: Reward thresholds of the ARS paper (Mania et al. 2018, Table 1: the levels its MuJoCo tasks are counted as
#: solved at), used for the ``-v5`` tasks, and the seed document's levels for dm_control walker-walk (a linear policy
#: near 500, an MLP with layer normalization near 700; the stricter one here).
PAPER_THRESHOLDS = {
    "Swimmer-v5": 325.0,
    "Hopper-v5": 3120.0,
    "HalfCheetah-v5": 3430.0,
    "Walker2d-v5": 4390.0,
    "Ant-v5": 3580.0,
    "Humanoid-v5": 6000.0,
    "dm_control/walker-walk-v0": 500.0,
}

#: The entries of SB3's ``get_system_info()`` that :func:`versions` reports, in this order.
SB3_VERSIONS = ("Python", "Stable-Baselines3", "PyTorch", "Numpy", "Gymnasium")


def algorithm_classes(base: type) -> dict[str, Any]:
    """
    sb3-es's algorithm classes by name, for a script's ``--algo``.

    :param base: Only the subclasses of this class (``BaseAlgorithm``: all).
    :return: ``{"ARS": ARS, ...}``.
    """
    return {
        name: cls
        for name, cls in vars(sb3_es).items()
        if name in sb3_es.__all__ and isinstance(cls, type) and issubclass(cls, base)
    }


def read_value(text: str) -> Any:
    """
    Read a command-line value as YAML (numbers, booleans, lists, ``lin_0.01``, ``"dict(...)"``), and numbers in
    exponent form such as ``5e7`` or ``1e-3`` as floats (YAML 1.1 reads them as strings, which rl-zoo then rejects).

    :param text: The value as typed.
    :return: The value.
    :raises ValueError: Saying why, in one line, when ``text`` is not YAML.
    """
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise ValueError(f"{type(e).__name__}: {str(e).splitlines()[0]}") from e
    if isinstance(value, str):
        with contextlib.suppress(ValueError):
            return float(value)
    return value


def step_count(text: str) -> int:
    """
    An ``argparse`` type for env-step counts: ``2000000``, ``2_000_000`` or ``2e6`` (the range is the script's to
    check, with the flag's own message).

    :param text: The value as typed.
    :return: The count.
    """
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a step count; give one such as 2000000 or 2e6") from None
    if not value.is_integer():
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of steps; give one such as 2000000 or 2e6")
    return int(value)


def parse_thresholds(items: list[str]) -> dict[str, float]:
    """
    Parse ``ENV=VALUE`` items.

    :param items: Items from the command line.
    :return: Threshold per env id.
    """
    thresholds = {}
    for item in items:
        env_id, sep, value = item.rpartition("=")
        number = parse_number(value) if sep else None
        if number is None or not math.isfinite(number):  # NaN or inf: never reached, or always
            raise SystemExit(f"--threshold {item!r}: use ENV_ID=VALUE with a number, e.g. Pendulum-v1=-200")
        thresholds[env_id] = number
    return thresholds


def positive_problems(flags: dict[str, float | None]) -> list[str]:
    """
    :param flags: Value of each flag (``None``: not given).
    :return: ``FLAG VALUE: it must be positive`` for each value given that is not above 0 (NaN included).
    """
    return [
        f"{flag} {value:g}: it must be positive" for flag, value in flags.items() if value is not None and not value > 0
    ]


def env_id_problems(flag: str, env_ids: list[str]) -> list[str]:
    """
    :param flag: The flag that gave the env ids, for the messages.
    :param env_ids: Env ids.
    :return: ``FLAG ID: Gymnasium's reason`` for each id that is not registered (checked before any run).
    """
    problems = []
    for env_id in env_ids:
        try:
            gym.spec(env_id)
        except gym.error.Error as e:
            problems.append(f"{flag} {env_id}: {str(e).rstrip('.')}")
    return problems


def selection_problems(seeds: list[int], envs: list[str], thresholds: dict[str, float]) -> list[str]:
    """
    :param seeds: ``--seeds``.
    :param envs: ``--envs``.
    :param thresholds: ``--threshold`` values per env id.
    :return: What a script would otherwise silently get wrong: repeated seeds or envs (one run folder each),
        thresholds for envs it does not run.
    """
    problems = []
    repeated = sorted({seed for seed in seeds if seeds.count(seed) > 1})
    if repeated:
        problems.append(f"--seeds repeats {repeated}: each seed is one run (and one run folder)")
    repeated_envs = sorted({env for env in envs if envs.count(env) > 1})
    if repeated_envs:
        problems.append(f"--envs repeats {repeated_envs}: give each once (a seed is one run on each)")
    stray = sorted(set(thresholds) - set(envs))
    if stray:
        problems.append(f"--threshold for {stray}, which --envs {envs} does not run")
    return problems


def cpu_model() -> str:
    """:return: The CPU's model name (from ``/proc/cpuinfo`` on Linux), else what ``platform`` knows."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine() or "unknown CPU"


def hardware() -> str:
    """:return: One line: CPU model, logical CPUs, operating system."""
    return f"{cpu_model()}, {os.cpu_count()} logical CPUs, {platform.system()} {platform.release()}"


def source_commit() -> str | None:
    """
    :return: The git commit of the imported ``sb3_es`` source (short hash, ``+changes`` if ``sb3_es/`` has
        uncommitted changes), or None outside a git checkout.
    """
    root = Path(sb3_es.__file__).resolve().parents[1]

    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, check=True).stdout

    try:
        head, changes = git("rev-parse", "--short", "HEAD").strip(), git("status", "--porcelain", "sb3_es").strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("+changes" if changes else "")


def versions(*packages: str) -> str:
    """
    :param packages: Distribution names of optional packages to report too (e.g. ``"sb3-contrib"``, ``"ray"``).
    :return: One line: the versions of Python, sb3-es, SB3, PyTorch, NumPy, Gymnasium and ``packages``.
    """
    info = get_system_info(print_info=False)[0]
    items = [f"{key} {info[key]}" for key in SB3_VERSIONS[:1]] + [f"sb3-es {sb3_es.__version__}"]
    items += [f"{key} {info[key]}" for key in SB3_VERSIONS[1:]]
    for package in packages:
        try:
            items.append(f"{package} {metadata.version(package)}")
        except metadata.PackageNotFoundError:
            items.append(f"{package} not installed")
    return ", ".join(items)


def system_info() -> dict[str, str]:
    """:return: SB3's ``get_system_info()`` with the CPU model, the logical CPUs and the sb3-es version added."""
    info = dict(get_system_info(print_info=False)[0])
    info.update({"CPU": cpu_model(), "Logical CPUs": str(os.cpu_count()), "sb3-es": sb3_es.__version__})
    return info


# ---------------------------------------------------------------------------------------------- plain loop
@dataclass
class PlainLoop:
    """
    What the plain step loop measured, over all its processes.

    :param rate: Env steps per second, the sum of the processes' rates.
    :param steps: Env steps taken in the timed window, all processes.
    :param episodes: Episodes ended in the timed window, all processes.
    :param seconds: The longest process's timed window.
    """

    rate: float
    steps: int
    episodes: int
    seconds: float


def _plain_worker(env_id: str, seconds: float, warmup: float, seed: int, barrier: Any, queue: Any) -> None:
    env = gym.make(env_id)
    env.reset(seed=seed)
    env.action_space.seed(seed)

    def loop(duration: float) -> tuple[int, int, float]:
        steps = episodes = 0
        start = time.perf_counter()
        end = start + duration
        while time.perf_counter() < end:
            for _ in range(100):
                _, _, terminated, truncated, _ = env.step(env.action_space.sample())
                steps += 1
                if terminated or truncated:
                    episodes += 1
                    env.reset()
        return steps, episodes, time.perf_counter() - start

    loop(warmup)
    barrier.wait()
    queue.put(loop(seconds))
    env.close()


def measure_plain(env_id: str, n_procs: int, seconds: float, warmup: float = 1.0) -> PlainLoop:
    """
    The machine's ceiling: ``n_procs`` fresh processes step ``gym.make(env_id)`` with random actions (resetting at
    the end of each episode), warm up for ``warmup`` seconds, wait for each other, then count for ``seconds``.

    :param env_id: Gymnasium env id.
    :param n_procs: Processes stepping in parallel.
    :param seconds: Timed window.
    :param warmup: Untimed seconds before the window.
    :return: The measurement.
    """
    ctx: Any = mp.get_context("forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn")
    barrier, queue = ctx.Barrier(n_procs), ctx.Queue()
    procs = [
        ctx.Process(target=_plain_worker, args=(env_id, seconds, warmup, i, barrier, queue)) for i in range(n_procs)
    ]
    for proc in procs:
        proc.start()
    outs = [queue.get() for _ in procs]
    for proc in procs:
        proc.join()
    return PlainLoop(
        rate=sum(steps / elapsed for steps, _, elapsed in outs),
        steps=sum(out[0] for out in outs),
        episodes=sum(out[1] for out in outs),
        seconds=max(out[2] for out in outs),
    )


def load_model(parser: argparse.ArgumentParser, algo_class: type[BaseAlgorithm], path: str | Path) -> BaseAlgorithm:
    """
    A script's saved model, or the parser's error naming what is wrong (no such file, another algorithm's model).

    :param parser: The script's parser.
    :param algo_class: The algorithm that saved it.
    :param path: The model's ``.zip`` file (the suffix may be left out, as ``load()`` allows).
    :return: The model, on the CPU.
    """
    try:
        return algo_class.load(path, device="cpu")
    except FileNotFoundError:  # SB3 tries the path, then with .zip added
        parser.error(f"{path}: no such model; give a saved model's .zip file.")
    except (ValueError, KeyError, TypeError) as e:
        parser.error(
            f"{path}: {algo_class.__name__} cannot load it ({type(e).__name__}: {e}); give the algorithm that saved it."
        )
