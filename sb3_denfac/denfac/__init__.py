"""DENFAC (paper section 3, Algorithm 1) for Stable-Baselines3."""

from sb3_denfac.denfac.buffers import DENFACDictReplayBuffer, DENFACReplayBuffer, DENFACReplayBufferSamples
from sb3_denfac.denfac.denfac import DENFAC
from sb3_denfac.denfac.her import DENFACHerReplayBuffer
from sb3_denfac.denfac.policies import DENFACActor, DENFACCritic, DENFACPolicy, MlpPolicy, MultiInputPolicy

__all__ = [
    "DENFAC",
    "DENFACActor",
    "DENFACCritic",
    "DENFACDictReplayBuffer",
    "DENFACHerReplayBuffer",
    "DENFACPolicy",
    "DENFACReplayBuffer",
    "DENFACReplayBufferSamples",
    "MlpPolicy",
    "MultiInputPolicy",
]
