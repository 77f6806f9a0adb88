"""
The sb3-es algorithms in rl-baselines3-zoo: their rl-zoo keys, hyperparameter files and Optuna samplers.

rl-zoo's route for outside algorithms is its ``rl_zoo3.ALGOS`` dict (one dict, shared by every rl-zoo script)
and a hyperparameter file passed with ``--conf-file``; hyperparameter search looks samplers up in
``rl_zoo3.hyperparams_opt.HYPERPARAMS_SAMPLER``. :func:`register` adds the sb3-es entries to those dicts and
changes nothing else in rl-zoo.

**Adding an algorithm**: add ``"<key>": <Class>`` to :data:`ALGOS`, a sampler to
:data:`sb3_es.zoo.hyperparams_opt.SAMPLERS` (and, if it samples derived values, a converter to ``CONVERTERS``),
and a file ``sb3_es/hyperparams/<key>.yml`` with a ``default`` entry. ``tests/test_zoo.py`` checks all three for
every key.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

try:
    import rl_zoo3
    import rl_zoo3.hyperparams_opt
except ImportError as e:  # pragma: no cover - exercised only without the extra
    raise ImportError(
        "sb3_es.zoo needs rl-baselines3-zoo, the [zoo] extra: in the sb3-es checkout, pip install -c constraints.txt "
        "-e '.[zoo]' (docs/guide/install.md)."
    ) from e
import yaml
from stable_baselines3.common.base_class import BaseAlgorithm

from sb3_es import ARS, CMAES, PGPE, REINFORCE, OpenES, SimpleES
from sb3_es.zoo.hyperparams_opt import CONVERTERS, SAMPLERS

#: The sb3-es algorithms by rl-zoo key (``--algo``). The key also names the log folder (``logs/<key>/``) and the
#: Hugging Face repository (``<key>-<env>``). ``ars`` stays sb3-contrib's ARS: sb3-es's is ``ars_es``.
ALGOS: dict[str, type[BaseAlgorithm]] = {
    "ars_es": ARS,
    "openes": OpenES,
    "cmaes": CMAES,
    "pgpe": PGPE,
    "simple_es": SimpleES,
    "reinforce": REINFORCE,
}

#: Keys that meant an sb3-es algorithm in earlier versions of ``sb3_es.zoo`` and mean another one in rl-zoo.
RENAMED: dict[str, str] = {"ars": "ars_es"}

#: Folder of the packaged hyperparameter files, ``<key>.yml``.
HYPERPARAMS_DIR = Path(__file__).resolve().parent.parent / "hyperparams"


class UsageError(ValueError):
    """A command line that cannot mean what its author wants (the message says what to run instead)."""


def sb3_es_algos() -> dict[str, type[BaseAlgorithm]]:
    """
    The sb3-es algorithms by rl-zoo key.

    :return: A new dict ``key -> class``.
    """
    return dict(ALGOS)


def is_sb3_es_algo(algo: str) -> bool:
    """
    Whether an rl-zoo key names an sb3-es algorithm.

    :param algo: rl-zoo key.
    :return: True for the keys of :data:`ALGOS`.
    """
    return algo in ALGOS


def zoo_meaning(algo: str) -> str | None:
    """
    :param algo: rl-zoo key.
    :return: What rl-zoo runs under it, e.g. ``"sb3-contrib's ARS"``, or ``None`` if rl-zoo has no such key.
    """
    theirs = rl_zoo3.ALGOS.get(algo)
    return f"{theirs.__module__.split('.')[0].replace('_', '-')}'s {theirs.__name__}" if theirs else None


def check_algo(algo: str) -> None:
    """
    Refuse a key that sb3-es used for one of its algorithms before and that means another library's in rl-zoo.

    :param algo: rl-zoo key given by the user.
    """
    if algo not in RENAMED:
        return
    new = RENAMED[algo]
    meaning = zoo_meaning(algo) or "not an sb3-es key"
    raise UsageError(
        f"--algo {algo} is {meaning} in rl-zoo; sb3-es's {ALGOS[new].__name__} is --algo {new} (runs in logs/{new}/). "
        f"Runs that sb3-es saved under logs/{algo}/ before the rename work with --algo {new} once moved to "
        f"logs/{new}/. For {meaning}, use rl-zoo's own commands (python -m rl_zoo3.train --algo {algo} ...)."
    )


def default_conf_file(algo: str) -> Path:
    """
    The packaged hyperparameter file of an sb3-es algorithm, ``sb3_es/hyperparams/<algo>.yml``.

    :param algo: rl-zoo key of an sb3-es algorithm.
    :return: The file's path.
    """
    path = HYPERPARAMS_DIR / f"{algo}.yml"
    if not path.is_file():
        raise FileNotFoundError(
            f"No hyperparameter file {path} for {algo!r} (the sb3-es package is incomplete); pass --conf-file PATH."
        )
    return path


def config_entry(conf_file: str | Path, env_id: str) -> tuple[str | None, dict[str, Any]]:
    """
    The entry that rl-zoo will use from a YAML hyperparameter file: the env's own, or ``default``.

    :param conf_file: A ``.yml`` file in rl-zoo's format.
    :param env_id: The env id.
    :return: The entry's key (``env_id``, ``"default"`` or ``None`` when there is neither) and its values.
    """
    data = yaml.safe_load(Path(conf_file).read_text()) or {}
    for key in (env_id, "default"):
        if key in data:
            return key, dict(data[key])
    return None, {}


def register_envs() -> None:
    """Register shimmy's ``dm_control/...`` environments with gymnasium, when shimmy is installed."""
    import gymnasium as gym

    with warnings.catch_warnings():
        # dm_control imports glfw, which warns about a missing X11 DISPLAY on headless machines
        warnings.simplefilter("ignore")
        try:
            import shimmy
        except ImportError:
            return
    gym.register_envs(shimmy)


def register() -> dict[str, type[BaseAlgorithm]]:
    """
    Add the sb3-es algorithms to ``rl_zoo3.ALGOS`` and their samplers to rl-zoo's ``HYPERPARAMS_SAMPLER`` and
    ``HYPERPARAMS_CONVERTER``; register the ``dm_control`` environments. Idempotent; rl-zoo's own keys are kept.

    :return: The algorithms registered.
    """
    clashes = {key for key, cls in ALGOS.items() if rl_zoo3.ALGOS.get(key, cls) is not cls}
    if clashes:
        raise RuntimeError(f"rl-zoo already has algorithms named {sorted(clashes)}; sb3-es cannot register them.")
    register_envs()
    rl_zoo3.ALGOS.update(ALGOS)
    rl_zoo3.hyperparams_opt.HYPERPARAMS_SAMPLER.update(SAMPLERS)
    rl_zoo3.hyperparams_opt.HYPERPARAMS_CONVERTER.update(CONVERTERS)
    return sb3_es_algos()
