from sb3_es.pgpe.pgpe import PGPE
from sb3_es.pgpe.policies import LinearPolicy, MlpPolicy

__all__ = ["PGPE", "LinearPolicy", "MlpPolicy"]
