"""CACLA policy: deterministic actor mu(s) and state-value critic V(s) ("CACLA+" with batch norm), shared with NFAC."""

from sb3_denfac.common.on_policy import DeterministicActorValuePolicy

CACLAPolicy = DeterministicActorValuePolicy
MlpPolicy = DeterministicActorValuePolicy

__all__ = ["CACLAPolicy", "MlpPolicy"]
