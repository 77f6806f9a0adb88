"""Evaluation layer: who runs the candidates of a population (a local VecEnv, or Ray actors)."""

from sb3_es.evaluation.base import ObsStats, PopulationEvaluator, PopulationResult, StepHook
from sb3_es.evaluation.ray import RayEvaluator
from sb3_es.evaluation.shaping import RewardShaping
from sb3_es.evaluation.vec_env import VecEnvEvaluator

__all__ = [
    "ObsStats",
    "PopulationEvaluator",
    "PopulationResult",
    "RayEvaluator",
    "RewardShaping",
    "StepHook",
    "VecEnvEvaluator",
]
