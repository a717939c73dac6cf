from sb3_denfac.nfac.nfac import NFAC
from sb3_denfac.nfac.policies import MlpPolicy, NFACPolicy

__all__ = ["NFAC", "MlpPolicy", "NFACPolicy"]
