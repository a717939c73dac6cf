from sb3_denfac.cmaes.cmaes import CMAES
from sb3_denfac.cmaes.policies import CMAESPolicy, MlpPolicy

__all__ = ["CMAES", "CMAESPolicy", "MlpPolicy"]
