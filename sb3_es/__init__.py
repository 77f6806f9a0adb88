"""sb3-es: evolution strategies and derivative-free policy search for Stable-Baselines3."""

import os

from sb3_es.ars import ARS
from sb3_es.cmaes import CMAES
from sb3_es.common.policies import FlatPolicy, LinearPolicy, MlpPolicy
from sb3_es.openes import OpenES
from sb3_es.pgpe import PGPE
from sb3_es.reinforce import REINFORCE
from sb3_es.simple_es import SimpleES

with open(os.path.join(os.path.dirname(__file__), "version.txt")) as file_handler:
    __version__ = file_handler.read().strip()

__all__ = [
    "ARS",
    "CMAES",
    "FlatPolicy",
    "LinearPolicy",
    "MlpPolicy",
    "OpenES",
    "PGPE",
    "REINFORCE",
    "SimpleES",
    "__version__",
]
