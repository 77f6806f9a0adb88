"""Strategy layer: ask/tell search distributions over flat parameter vectors (no environment)."""

from sb3_es.strategies.ars import ARSStrategy
from sb3_es.strategies.base import Strategy, check_fitness
from sb3_es.strategies.cmaes import CMAESStrategy
from sb3_es.strategies.openes import OpenESStrategy

__all__ = ["ARSStrategy", "CMAESStrategy", "OpenESStrategy", "Strategy", "check_fitness"]
