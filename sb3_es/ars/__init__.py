from sb3_es.ars.ars import ARS
from sb3_es.ars.policies import LinearPolicy, MlpPolicy

__all__ = ["ARS", "LinearPolicy", "MlpPolicy"]
