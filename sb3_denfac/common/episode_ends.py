"""An update after every finished episode, with one env or several (``n_envs > 1``).

SB3's off-policy algorithms train every ``train_freq`` steps or episodes; in episodes they refuse a VecEnv of several
envs (``"You must use only one env when doing episodic training."``), because their rollout would end after n
episodes of all the envs together. An algorithm that updates after each finished episode (DENFAC) wants each env's
episode end to trigger the update it would trigger with one env, whichever env finishes when.

:class:`EpisodeEndsMixin` does that:

- one env: SB3's episodic rollout, unchanged; ``train(gradient_steps)`` gets the episode's length (SB3's
  ``gradient_steps=-1``), and :meth:`~EpisodeEndsMixin._finished_episodes` returns ``[gradient_steps]``;
- several envs: the rollout is one VecEnv step (SB3's ``train_freq=(1, "step")``, which SB3 allows), the mixin counts
  each env's steps since its last update, and :meth:`~EpisodeEndsMixin._finished_episodes` returns the lengths of the
  episodes that ended since the last call (none at most steps; several when several envs finish at the same step).

Episodes that end before ``learning_starts`` trigger no update, as with one env. When ``learn(total_timesteps)`` stops
inside episodes, their steps so far count as finished episodes (as :mod:`~sb3_denfac.common.budget` does with one env),
and the next ``learn(reset_num_timesteps=False)`` counts the same episodes on from 0.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.type_aliases import RolloutReturn, TrainFreq, TrainFrequencyUnit

from sb3_denfac.common.budget import budget_reached, stored_dones


class EpisodeEndsMixin:
    """For an SB3 ``OffPolicyAlgorithm`` with ``train_freq=(1, "episode")`` and ``gradient_steps=-1`` (put it before
    that base and before :class:`~sb3_denfac.common.budget.StopAtTotalTimestepsMixin`): see the module docstring."""

    #: per env, the steps since its last update (None: one env, SB3's episodic rollout counts them)
    _episode_steps: np.ndarray | None = None
    #: the lengths of the episodes finished and not yet handed to ``train``
    _finished: list[int] | None = None

    def _setup_learn(
        self, total_timesteps: int, callback: Any = None, reset_num_timesteps: bool = True, *args: Any, **kwargs: Any
    ) -> Any:
        if reset_num_timesteps or getattr(self, "_last_obs", None) is None:  # SB3 resets the envs: new episodes
            self._episode_steps, self._finished = None, None
        return super()._setup_learn(total_timesteps, callback, reset_num_timesteps, *args, **kwargs)  # type: ignore[misc]

    def collect_rollouts(self, env: Any, callback: Any, train_freq: TrainFreq, *args: Any, **kwargs: Any) -> RolloutReturn:
        if env.num_envs > 1 and train_freq.unit == TrainFrequencyUnit.EPISODE:
            if train_freq.frequency != 1:
                raise ValueError(f"train_freq={train_freq} with several envs: only an update per episode is supported")
            if self._episode_steps is None or len(self._episode_steps) != env.num_envs:
                self._episode_steps, self._finished = np.zeros(env.num_envs, dtype=np.int64), []
            train_freq = TrainFreq(1, TrainFrequencyUnit.STEP)  # one VecEnv step; train() then takes what finished
        return super().collect_rollouts(env, callback, train_freq, *args, **kwargs)  # type: ignore[misc]

    def _store_transition(self, replay_buffer: Any, buffer_action: np.ndarray, *args: Any, **kwargs: Any) -> None:
        super()._store_transition(replay_buffer, buffer_action, *args, **kwargs)  # type: ignore[misc]
        if self._episode_steps is None or self._finished is None:
            return
        dones = stored_dones(args, kwargs)
        self._episode_steps += 1
        ended = np.ones_like(dones) if budget_reached(self) else dones
        if self.num_timesteps > self.learning_starts:  # type: ignore[attr-defined]
            self._finished.extend(int(n) for n in self._episode_steps[ended])
        self._episode_steps[ended] = 0

    def _finished_episodes(self, gradient_steps: int) -> list[int]:
        """The lengths of the episodes to update on now, one update each: with one env the rollout's (SB3's
        ``gradient_steps``), with several the episodes finished since the last call (often none)."""
        if self._finished is None:
            return [gradient_steps]
        finished, self._finished = self._finished, []
        return finished

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_episode_steps", "_finished"]  # type: ignore[misc]
