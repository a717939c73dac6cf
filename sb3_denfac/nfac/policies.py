"""NFAC policy: deterministic actor mu(s) and state-value critic V(s), both batch-normalised MLPs ("NFAC+")."""

from sb3_denfac.common.actor_value_policy import DeterministicActorValuePolicy


class NFACPolicy(DeterministicActorValuePolicy):
    """NFAC's actor mu(s) and critic V(s); see :class:`~sb3_denfac.common.actor_value_policy.DeterministicActorValuePolicy`.

    A class of its own so that a CACLA model file is not mistaken for an NFAC one.
    """


MlpPolicy = NFACPolicy

__all__ = ["MlpPolicy", "NFACPolicy"]
