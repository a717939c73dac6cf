"""NFAC policy: deterministic actor mu(s) and state-value critic V(s), both batch-normalised MLPs ("NFAC+")."""

from sb3_denfac.common.on_policy import DeterministicActorValuePolicy

NFACPolicy = DeterministicActorValuePolicy
MlpPolicy = DeterministicActorValuePolicy

__all__ = ["MlpPolicy", "NFACPolicy"]
