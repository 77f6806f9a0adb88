"""Evaluation layer: who runs the candidates of a population (a local VecEnv, worker processes, or Ray actors).

Below the SB3 glue: it imports only :mod:`sb3_es.strategies` (noise tables), never :mod:`sb3_es.common` or an
algorithm. ``RayEvaluator`` is imported on first access, so that ``import sb3_es`` does not import Ray.
"""

from typing import TYPE_CHECKING, Any

from sb3_es.evaluation.base import Generation, ObsStats, PopulationEvaluator, PopulationResult, StepHook
from sb3_es.evaluation.network import NetworkSpec
from sb3_es.evaluation.processes import ProcessEvaluator
from sb3_es.evaluation.shaping import RewardShaping
from sb3_es.evaluation.vec_env import VecEnvEvaluator

if TYPE_CHECKING:
    from sb3_es.evaluation.ray import RayEvaluator

__all__ = [
    "Generation",
    "NetworkSpec",
    "ObsStats",
    "PopulationEvaluator",
    "PopulationResult",
    "ProcessEvaluator",
    "RayEvaluator",
    "RewardShaping",
    "StepHook",
    "VecEnvEvaluator",
]


def __getattr__(name: str) -> Any:
    if name == "RayEvaluator":
        from sb3_es.evaluation.ray import RayEvaluator

        return RayEvaluator
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
