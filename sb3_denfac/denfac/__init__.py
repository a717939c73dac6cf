"""DENFAC (paper section 3, Algorithm 1) for Stable-Baselines3."""

from sb3_denfac.denfac.buffers import DENFACReplayBuffer, DENFACReplayBufferSamples
from sb3_denfac.denfac.denfac import DENFAC
from sb3_denfac.denfac.policies import DENFACActor, DENFACCritic, DENFACPolicy, MlpPolicy

__all__ = [
    "DENFAC",
    "DENFACActor",
    "DENFACCritic",
    "DENFACPolicy",
    "DENFACReplayBuffer",
    "DENFACReplayBufferSamples",
    "MlpPolicy",
]
