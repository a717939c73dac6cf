"""``learn(total_timesteps)`` stops at ``total_timesteps``, also inside an episode.

The package's episodic algorithms (DENFAC and NFAC update at episode ends, CMA-ES scores candidates on whole episodes)
would otherwise wait for the end of the episode, which never comes on an env without a time limit. Here, as with SB3's
step-based algorithms, collection stops once ``num_timesteps`` reaches the budget:

- off-policy algorithms that train every n episodes (:class:`StopAtTotalTimestepsMixin`: DENFAC, and DDPG with
  ``train_freq=(n, "episode")``) end the rollout there and run their update on the buffer as it is; the unfinished
  episode's transitions are in it, its last one bootstraps (not terminal);
- NFAC updates on the partial episode the same way (:func:`budget_reached` in its rollout test);
- CMA-ES keeps the unfinished candidate evaluation and resumes it with the next ``learn(reset_num_timesteps=False)``.

The next ``learn(reset_num_timesteps=False)`` continues the same episode (SB3 only resets the env when
``reset_num_timesteps=True`` or after ``load``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.type_aliases import RolloutReturn, TrainFrequencyUnit


def stored_dones(args: tuple[Any, ...], kwargs: dict[str, Any]) -> np.ndarray:
    """The ``dones`` of SB3's ``_store_transition(replay_buffer, buffer_action, new_obs, reward, dones, infos)``, from
    the arguments after ``buffer_action``."""
    return np.asarray(args[2] if len(args) > 2 else kwargs["dones"], dtype=bool)


def budget_reached(model: Any) -> bool:
    """True once ``model.num_timesteps`` has reached the ``total_timesteps`` of the running ``learn`` call."""
    return model.num_timesteps >= model._total_timesteps


class _BudgetReached(Exception):
    """Raised after storing the transition that reached the budget, to leave SB3's collection loop."""


class StopAtTotalTimestepsMixin:
    """For an SB3 ``OffPolicyAlgorithm`` (put it before that base): with ``train_freq`` in episodes, the rollout also
    ends when ``total_timesteps`` is reached inside an episode, and the update then runs as at an episode end.

    SB3's loop waits for the episode's end; this mixin leaves it right after the transition that reaches the budget is
    stored (so ``_last_obs`` and the replay buffer are up to date), with ``continue_training=True``.
    """

    _rollout_counts: list[int] | None = None  # [steps, episodes] of the rollout being collected (episode unit only)

    def collect_rollouts(self, env: Any, callback: Any, train_freq: Any, *args: Any, **kwargs: Any) -> RolloutReturn:
        self._rollout_counts = [0, 0] if train_freq.unit == TrainFrequencyUnit.EPISODE else None
        try:
            return super().collect_rollouts(env, callback, train_freq, *args, **kwargs)  # type: ignore[misc]
        except _BudgetReached:
            callback.on_rollout_end()
            steps, episodes = self._rollout_counts  # type: ignore[misc]
            return RolloutReturn(steps * env.num_envs, episodes, continue_training=True)
        finally:
            self._rollout_counts = None

    def _store_transition(self, replay_buffer: Any, buffer_action: np.ndarray, *args: Any, **kwargs: Any) -> None:
        super()._store_transition(replay_buffer, buffer_action, *args, **kwargs)  # type: ignore[misc]
        dones = stored_dones(args, kwargs)
        if self._rollout_counts is None:
            return
        self._rollout_counts[0] += 1
        self._rollout_counts[1] += int(np.sum(dones))
        if not np.any(dones) and budget_reached(self):
            self._update_current_progress_remaining(self.num_timesteps, self._total_timesteps)  # type: ignore[attr-defined]
            raise _BudgetReached

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_rollout_counts"]  # type: ignore[misc]
