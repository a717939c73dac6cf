from sb3_denfac.ddpg.ddpg import DDPG
from sb3_denfac.ddpg.policies import DDPGPolicy, MlpPolicy

__all__ = ["DDPG", "DDPGPolicy", "MlpPolicy"]
