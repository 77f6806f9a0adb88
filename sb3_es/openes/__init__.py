from sb3_es.openes.openes import OpenES
from sb3_es.openes.policies import LinearPolicy, MlpPolicy

__all__ = ["LinearPolicy", "MlpPolicy", "OpenES"]
