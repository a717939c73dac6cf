"""One meaning of the learning rates, and one place for the optimizers, in the algorithms with an actor and a critic.

- ``learning_rate`` (a float or a schedule of the remaining progress, as in SB3) is the rate of every network that has
  no rate of its own.
- ``actor_learning_rate`` and ``critic_learning_rate`` (a float, a schedule or None) are the paper's alpha_a and alpha_c
  (section 4): each overrides ``learning_rate`` for its network.
- The optimizers are ``policy.actor.optimizer`` and ``policy.critic.optimizer``, as in SB3's TD3 and SAC.

:class:`ActorCriticRatesMixin` turns the three arguments into ``actor_lr_schedule`` and ``critic_lr_schedule`` and applies
them to the two optimizers (SB3's ``_update_learning_rate`` applies the single ``lr_schedule`` to a list of optimizers).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

from stable_baselines3.common.type_aliases import Schedule
from stable_baselines3.common.utils import FloatSchedule, update_learning_rate

NETWORKS = ("actor", "critic")


@runtime_checkable
class RatesHost(Protocol):
    """What :class:`ActorCriticRatesMixin` needs from the algorithm it is mixed into."""

    learning_rate: float | Schedule
    actor_learning_rate: float | Schedule | None
    critic_learning_rate: float | Schedule | None
    policy: Any  # with ``actor.optimizer`` and ``critic.optimizer``
    logger: Any
    _current_progress_remaining: float


class ActorCriticRatesMixin:
    """``actor_lr_schedule`` / ``critic_lr_schedule`` from ``learning_rate`` and the per-network rates (module doc).

    The host sets ``learning_rate``, ``actor_learning_rate`` and ``critic_learning_rate``, calls
    :meth:`_setup_actor_critic_schedules` once the policy exists and :meth:`_update_learning_rates` before each update.
    """

    learning_rate: float | Schedule
    actor_learning_rate: float | Schedule | None
    critic_learning_rate: float | Schedule | None
    actor_lr_schedule: Schedule
    critic_lr_schedule: Schedule
    policy: Any
    logger: Any
    _current_progress_remaining: float

    def _setup_actor_critic_schedules(self) -> None:
        """Build the two schedules and give each optimizer its initial rate (the rate at progress remaining 1)."""
        for net in NETWORKS:
            own = getattr(self, f"{net}_learning_rate", None)
            setattr(self, f"{net}_lr_schedule", FloatSchedule(self.learning_rate if own is None else own))
        self._apply_learning_rates(1.0)

    def _apply_learning_rates(self, progress_remaining: float) -> dict[str, float]:
        rates = {}
        for net in NETWORKS:
            rates[net] = getattr(self, f"{net}_lr_schedule")(progress_remaining)
            update_learning_rate(getattr(self.policy, net).optimizer, rates[net])
        return rates

    def _update_learning_rates(self) -> None:
        """Apply alpha_a and alpha_c at the current progress and log them (``train/actor_learning_rate``...)."""
        for net, rate in self._apply_learning_rates(self._current_progress_remaining).items():
            self.logger.record(f"train/{net}_learning_rate", rate)
