"""
Optuna samplers for the sb3-es algorithms, with the signature of rl-zoo's (``rl_zoo3.hyperparams_opt``).

``python -m sb3_es.zoo train --algo <key> --env <env> -optimize`` runs rl-zoo's search with them: each trial
trains a model with the sampled values on top of the hyperparameter file's entry, rl-zoo's
``TrialEvalCallback`` evaluates it ``--n-evaluations`` times and reports every evaluation to Optuna, and the
pruner (``--pruner median`` by default) stops unpromising trials at an evaluation.

A sampler returns the keyword arguments of the algorithm; the values it draws are stored in the Optuna study
under the names given to ``trial.suggest_*``. A converter turns those stored values back into keyword
arguments (rl-zoo uses it to train with a finished trial's values, ``--trial-id``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import optuna
from rl_zoo3.hyperparams_opt import convert_ars_params, sample_ars_params

#: ``(trial, n_actions, n_envs, additional_args) -> algorithm keyword arguments``, as rl-zoo's samplers: the Optuna
#: trial, the action dimension (0 for ``Discrete`` actions), the number of env slots and rl-zoo's extra arguments.
#: Only the REINFORCE sampler reads more than the trial (``n_actions``).
Sampler = Callable[[optuna.Trial, int, int, dict], dict[str, Any]]


def suggest_population_size_pow(trial: optuna.Trial) -> dict[str, int]:
    """
    :param trial: The Optuna trial.
    :return: ``population_size_pow``, 3 to 7: a population of 8 to 128, a power of 2, so that it is even (mirrored
        or symmetric sampling) and divides the usual ``n_envs``; :func:`convert_population_params` turns it into
        ``population_size``.
    """
    return {"population_size_pow": trial.suggest_int("population_size_pow", 3, 7)}


def convert_population_params(sampled: dict[str, Any]) -> dict[str, Any]:
    """
    Keyword arguments from the values stored for an OpenES or CMA-ES trial (``population_size_pow`` is a power of 2).

    :param sampled: The trial's values.
    :return: Keyword arguments for the algorithm.
    """
    params = dict(sampled)
    if "population_size_pow" in params:
        params["population_size"] = 2 ** params.pop("population_size_pow")
    return params


#: The floors of OpenES's decays, as a fraction of the sampled starting values.
OPENES_LIMIT_FRACTION = 0.1


def convert_openes_params(sampled: dict[str, Any]) -> dict[str, Any]:
    """
    Keyword arguments from the values stored for an OpenES trial: those of :func:`convert_population_params`, and
    ``sigma_limit`` and ``learning_rate_limit`` a tenth of the sampled ``sigma`` and ``learning_rate``, so that an
    entry's ``sigma_decay`` or ``learning_rate_decay`` applies whatever value is sampled (OpenES refuses a decay
    that starts at or below its floor).

    :param sampled: The trial's values.
    :return: Keyword arguments for :class:`~sb3_es.OpenES`.
    """
    params = convert_population_params(sampled)
    for name in ("sigma", "learning_rate"):
        if name in params:
            params[f"{name}_limit"] = OPENES_LIMIT_FRACTION * params[name]
    return params


def sample_openes_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """
    :data:`Sampler` of OpenES: noise ``sigma``, optimizer ``learning_rate`` and ``population_size`` (see
    :func:`suggest_population_size_pow`); the decays' floors follow them (:func:`convert_openes_params`).

    :return: Keyword arguments for :class:`~sb3_es.OpenES`.
    """
    return convert_openes_params(
        {
            "sigma": trial.suggest_float("sigma", 0.005, 0.5, log=True),
            "learning_rate": trial.suggest_float("learning_rate", 1e-3, 0.1, log=True),
            **suggest_population_size_pow(trial),
        }
    )


def sample_cmaes_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """
    :data:`Sampler` of CMA-ES: initial step size ``sigma`` and ``population_size``.

    :return: Keyword arguments for :class:`~sb3_es.CMAES`.
    """
    return convert_population_params(
        {
            "sigma": trial.suggest_float("sigma", 0.01, 1.0, log=True),
            **suggest_population_size_pow(trial),
        }
    )


def sample_pgpe_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """
    :data:`Sampler` of PGPE with ClipUp: initial standard deviation ``stdev_init``, ClipUp's ``max_speed`` (the
    center learning rate is half of it) and ``population_size``.

    :return: Keyword arguments for :class:`~sb3_es.PGPE`.
    """
    return convert_population_params(
        {
            "stdev_init": trial.suggest_float("stdev_init", 0.01, 0.5, log=True),
            "max_speed": trial.suggest_float("max_speed", 0.01, 0.5, log=True),
            **suggest_population_size_pow(trial),
        }
    )


def convert_simple_es_params(sampled: dict[str, Any]) -> dict[str, Any]:
    """
    Keyword arguments from the values stored for a SimpleES trial (``n_elite`` as a fraction of the population).

    :param sampled: The trial's values.
    :return: Keyword arguments for :class:`~sb3_es.SimpleES`.
    """
    params = convert_population_params(sampled)
    if "elite_fraction" in params:
        params["n_elite"] = max(1, int(params.pop("elite_fraction") * params["population_size"]))
    return params


def sample_simple_es_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """
    :data:`Sampler` of SimpleES: ``sigma``, ``population_size`` and ``n_elite`` as a fraction of it (1 child at
    least: WinnerES).

    :return: Keyword arguments for :class:`~sb3_es.SimpleES`.
    """
    return convert_simple_es_params(
        {
            "sigma": trial.suggest_float("sigma", 0.01, 1.0, log=True),
            **suggest_population_size_pow(trial),
            "elite_fraction": trial.suggest_float("elite_fraction", 0.0, 0.5),
        }
    )


def convert_reinforce_params(sampled: dict[str, Any]) -> dict[str, Any]:
    """
    Keyword arguments from the values stored for a REINFORCE trial (``n_bins`` goes into ``policy_kwargs``).

    :param sampled: The trial's values.
    :return: Keyword arguments for :class:`~sb3_es.REINFORCE`.
    """
    params = dict(sampled)
    if "n_bins" in params:
        params["policy_kwargs"] = dict(n_bins=params.pop("n_bins"))
    return params


def sample_reinforce_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """
    :data:`Sampler` of REINFORCE: Adam ``learning_rate`` and, for ``Box`` actions (``n_actions > 0``), the number
    of levels per dimension ``n_bins`` (set as ``policy_kwargs=dict(n_bins=...)``, which replaces the file's
    ``policy_kwargs``, as rl-zoo's samplers replace ``net_arch``).

    :return: Keyword arguments for :class:`~sb3_es.REINFORCE`.
    """
    sampled: dict[str, Any] = {"learning_rate": trial.suggest_float("learning_rate", 1e-4, 3e-2, log=True)}
    if n_actions > 0:
        sampled["n_bins"] = trial.suggest_categorical("n_bins", [3, 5, 7, 9, 11])
    return convert_reinforce_params(sampled)


#: Samplers by rl-zoo key (ARS: rl-zoo's own ARS sampler, whose hyperparameters sb3-es's ARS shares).
SAMPLERS: dict[str, Sampler] = {
    "ars_es": sample_ars_params,
    "openes": sample_openes_params,
    "cmaes": sample_cmaes_params,
    "pgpe": sample_pgpe_params,
    "simple_es": sample_simple_es_params,
    "reinforce": sample_reinforce_params,
}

#: Converters by rl-zoo key, from a trial's stored values to keyword arguments.
CONVERTERS: dict[str, Callable[[dict[str, Any]], dict[str, Any]]] = {
    "ars_es": convert_ars_params,
    "openes": convert_openes_params,
    "cmaes": convert_population_params,
    "pgpe": convert_population_params,
    "simple_es": convert_simple_es_params,
    "reinforce": convert_reinforce_params,
}
