"""Strategy layer: ask/tell search distributions over flat parameter vectors (no environment)."""

from sb3_es.strategies.ars import ARSStrategy
from sb3_es.strategies.base import Strategy, check_fitness
from sb3_es.strategies.cmaes import CMAESStrategy
from sb3_es.strategies.openes import OpenESStrategy
from sb3_es.strategies.optimizers import ClipUp, GradientStrategy
from sb3_es.strategies.pgpe import PGPEStrategy
from sb3_es.strategies.simple_es import SimpleESStrategy

__all__ = [
    "ARSStrategy",
    "CMAESStrategy",
    "ClipUp",
    "GradientStrategy",
    "OpenESStrategy",
    "PGPEStrategy",
    "SimpleESStrategy",
    "Strategy",
    "check_fitness",
]
