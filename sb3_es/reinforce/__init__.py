from sb3_es.reinforce.policies import DiscretizedPolicy, MlpPolicy, MultiInputPolicy
from sb3_es.reinforce.reinforce import REINFORCE

__all__ = ["REINFORCE", "DiscretizedPolicy", "MlpPolicy", "MultiInputPolicy"]
