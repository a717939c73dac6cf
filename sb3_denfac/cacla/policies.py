"""CACLA policy: deterministic actor mu(s) and state-value critic V(s) ("CACLA+" with batch norm)."""

from sb3_denfac.common.actor_value_policy import DeterministicActorValuePolicy


class CACLAPolicy(DeterministicActorValuePolicy):
    """CACLA's actor mu(s) and critic V(s); see :class:`~sb3_denfac.common.actor_value_policy.DeterministicActorValuePolicy`.

    A class of its own so that an NFAC model file is not mistaken for a CACLA one.
    """


MlpPolicy = CACLAPolicy

__all__ = ["CACLAPolicy", "MlpPolicy"]
