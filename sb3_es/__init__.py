"""sb3-es: evolution strategies and derivative-free policy search for Stable-Baselines3."""

import os

from sb3_es.ars import ARS
from sb3_es.cmaes import CMAES
from sb3_es.common.policies import FlatPolicy, LinearPolicy, MlpPolicy
from sb3_es.openes import OpenES
from sb3_es.reinforce import REINFORCE

with open(os.path.join(os.path.dirname(__file__), "version.txt")) as file_handler:
    __version__ = file_handler.read().strip()

__all__ = ["ARS", "CMAES", "FlatPolicy", "LinearPolicy", "MlpPolicy", "OpenES", "REINFORCE", "__version__"]
