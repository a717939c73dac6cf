"""SoftDENFAC: DENFAC's Algorithm 1 with SB3 SAC's stochastic actor and soft targets in its fitted iterations."""

from sb3_denfac.soft_denfac.policies import MlpPolicy, MultiInputPolicy, SoftDENFACActor, SoftDENFACPolicy
from sb3_denfac.soft_denfac.soft_denfac import SoftDENFAC

__all__ = ["MlpPolicy", "MultiInputPolicy", "SoftDENFAC", "SoftDENFACActor", "SoftDENFACPolicy"]
