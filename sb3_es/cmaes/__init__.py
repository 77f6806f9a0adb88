from sb3_es.cmaes.cmaes import CMAES
from sb3_es.cmaes.policies import LinearPolicy, MlpPolicy

__all__ = ["CMAES", "LinearPolicy", "MlpPolicy"]
