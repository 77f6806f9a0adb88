from sb3_es.simple_es.policies import LinearPolicy, MlpPolicy
from sb3_es.simple_es.simple_es import SimpleES

__all__ = ["LinearPolicy", "MlpPolicy", "SimpleES"]
