"""
rl-baselines3-zoo with the sb3-es algorithms: ``python -m sb3_es.zoo COMMAND [rl-zoo arguments]``.

* :mod:`sb3_es.zoo.registry`: the rl-zoo keys of the sb3-es algorithms (``ars_es``, ``openes``, ``cmaes``,
  ``pgpe``, ``simple_es``, ``reinforce``), their packaged hyperparameter files and :func:`register`, which adds
  them to rl-zoo's ``ALGOS`` and hyperparameter samplers;
* :mod:`sb3_es.zoo.hyperparams_opt`: the Optuna samplers (``-optimize``);
* :mod:`sb3_es.zoo.commands`: the command line, every rl-zoo script (``train``, ``enjoy``, ``record_video``,
  ``record_training``, ``push_to_hub``, ``load_from_hub``, ``plot_train``, ``all_plots``, ``plot_from_file``).
"""

from sb3_es.zoo.commands import SCRIPTS, main, prepare_args, run
from sb3_es.zoo.registry import (
    ALGOS,
    HYPERPARAMS_DIR,
    RENAMED,
    UsageError,
    check_algo,
    config_entry,
    default_conf_file,
    is_sb3_es_algo,
    register,
    register_envs,
    sb3_es_algos,
)

__all__ = [
    "ALGOS",
    "HYPERPARAMS_DIR",
    "RENAMED",
    "SCRIPTS",
    "UsageError",
    "check_algo",
    "config_entry",
    "default_conf_file",
    "is_sb3_es_algo",
    "main",
    "prepare_args",
    "register",
    "register_envs",
    "run",
    "sb3_es_algos",
]
