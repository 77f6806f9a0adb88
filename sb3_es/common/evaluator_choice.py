"""Which evaluator runs a model's candidates: the algorithms' ``evaluator=`` argument, checked and resolved."""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

from stable_baselines3.common.vec_env import SubprocVecEnv, VecEnv

from sb3_es.common.env_recipe import env_recipe
from sb3_es.evaluation import PopulationEvaluator, VecEnvEvaluator
from sb3_es.evaluation.processes import ProcessEvaluator

if TYPE_CHECKING:
    from sb3_es.evaluation.ray import RayEvaluator

#: The evaluators chosen by name; "processes" and "ray" build their workers' envs from the model's env id, or
#: from the Gymnasium specs of its VecEnv's envs (:func:`~sb3_es.common.env_recipe.env_recipe`).
EVALUATOR_NAMES = ("local", "processes", "ray")


def check_evaluator_name(evaluator: str | PopulationEvaluator) -> None:
    """
    Raise a clear error for an evaluator that is neither a known name nor an instance (what ``load()`` can check
    before it has an env).

    :param evaluator: The algorithm's ``evaluator`` argument.
    """
    if not isinstance(evaluator, PopulationEvaluator) and evaluator not in EVALUATOR_NAMES:
        raise ValueError(f"evaluator={evaluator!r}: use 'local', 'processes', 'ray' or a PopulationEvaluator instance.")


def check_evaluator(evaluator: str | PopulationEvaluator, env_id: str | None, env: VecEnv | None = None) -> None:
    """
    Raise a clear error for an evaluator the model cannot use.

    :param evaluator: The algorithm's ``evaluator`` argument.
    :param env_id: The env id the model was given, or ``None`` if it was given an env object.
    :param env: The model's VecEnv, whose envs the workers rebuild when there is no env id.
    """
    if isinstance(evaluator, PopulationEvaluator):
        return
    check_evaluator_name(evaluator)
    if evaluator != "local" and env_id is None and env is not None:  # (no env: the constructors refuse it)
        env_recipe(env, evaluator)  # raises if the workers cannot rebuild the envs


def _host(name: str) -> type[ProcessEvaluator] | type[RayEvaluator]:
    if name == "ray":
        from sb3_es.evaluation.ray import RayEvaluator  # Ray is optional: imported only when asked for

        return RayEvaluator
    return ProcessEvaluator


def resolve_evaluator(
    evaluator: str | PopulationEvaluator,
    env_id: str | None,
    env: VecEnv | None,
    current: PopulationEvaluator | None,
) -> PopulationEvaluator:
    """
    :param evaluator: The algorithm's ``evaluator`` argument.
    :param env_id: The env id the model was created with (not saved: ``None`` after ``load()``).
    :param env: The model's VecEnv.
    :param current: The evaluator built for the model last time, reused if it still fits.
    :return: The evaluator to run the next generations.
    """
    if isinstance(evaluator, PopulationEvaluator):
        return evaluator
    if evaluator in ("processes", "ray"):
        host = _host(evaluator)
        if isinstance(current, host):
            return current
        if env_id is not None:
            return host(env_id)
        if env is not None:
            factory, env_args = env_recipe(env, evaluator)
            return host(factory, **env_args)
        raise ValueError(
            f"evaluator={evaluator!r} needs an env to rebuild in its workers, and this model has none (the env id "
            "it was created with is not saved): pass env= to load() (a Gymnasium env or a VecEnv, e.g. "
            "make_vec_env('Pendulum-v1')) or call model.set_env(...) before learn()."
        )
    check_evaluator(evaluator, env_id, env)  # a name other than "local" (a typo given to load()) is refused
    if env is None:
        raise ValueError("This model has no environment: pass env= to load() or call set_env() before learn().")
    if isinstance(current, VecEnvEvaluator) and current.env is env:
        return current
    warn_if_subproc(env)
    return VecEnvEvaluator(env)


def warn_if_subproc(env: VecEnv) -> None:
    """
    Tell a ``SubprocVecEnv`` user (warning) that worker processes running whole episodes are faster.

    :param env: The model's VecEnv (possibly wrapped, e.g. in ``VecNormalize``).
    """
    if isinstance(env.unwrapped, SubprocVecEnv):
        warnings.warn(
            "The env is a SubprocVecEnv: it sends every vec step over a pipe to its processes, which costs more than "
            "a step of most envs (on BipedalWalker-v3 it ran at about 30% of a plain 2-process step loop). For all "
            "cores, let worker processes run whole episodes: give the env id with evaluator='processes' (one "
            "worker per CPU), or evaluator=ProcessEvaluator(env_id_or_factory, num_workers=N) from "
            "sb3_es.evaluation.processes. See the guide's 'All cores of one machine' page.",
            UserWarning,
            stacklevel=3,
        )
