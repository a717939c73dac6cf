"""Hindsight experience replay (Andrychowicz et al. 2017) for DENFAC's fitted iterations.

SB3's ``HerReplayBuffer`` relabels goals when it samples a mini-batch: a fraction ``her_ratio = n / (n + 1)``
(``n = n_sampled_goal``) of the batch are stored transitions whose desired goal g is replaced by a goal g' achieved
later in the same episode ("future"; or "final", "episode"), with the reward recomputed by the env,
r' = ``env.compute_reward(achieved_goal(s'), g')``. DENFAC does not sample D: each fitted iteration computes the
targets of eq. (4) on the whole buffer (or on mini-batches drawn from it), so :class:`DENFACHerReplayBuffer` relabels
when D is read (:meth:`~DENFACHerReplayBuffer.all_samples`, once per update): every stored transition, plus
``n_sampled_goal`` relabelled copies of each transition of a finished episode, with goals drawn anew at every update.
A mini-batch drawn uniformly from that set has SB3's ``her_ratio`` of relabelled transitions.

Eq. (4) on a relabelled transition is the target of the goal-conditioned problem: q = r' + gamma (1 - d)
Q_{k-1}((s', g'), pi_{k-1}(s', g')), with the critic and the actor taking the goal in the observation, as in HER's
DDPG. Its importance weight is not defined: c = min(1, pi_{k-1}(a | s, g') / pi_b(a | s, g')) needs the behaviour
policy's density under the new goal g', and D holds only the mean mu_b(s, g) the actor had for the goal it pursued.
So HER needs ``weighting="none"`` (c = 1, DENFAC's default; HER's DDPG has no weights either), and DENFAC refuses it
with the paper's ``"retrace"`` weights (``presets.PAPER``), naming this reason.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.vec_env import VecNormalize
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer

from sb3_denfac.denfac.buffers import (
    BehaviourMeansBuffer,
    DENFACDictReplayBuffer,
    DENFACReplayBuffer,
    DENFACReplayBufferSamples,
)


def replay_buffer_class_for(model: Any, given: type[ReplayBuffer] | None) -> type[ReplayBuffer]:
    """D's class for a DENFAC ``model``: its buffer for the observations (Dict ones: :class:`DENFACDictReplayBuffer`),
    SB3's ``HerReplayBuffer`` taken as :class:`DENFACHerReplayBuffer` (the same arguments: ``n_sampled_goal``,
    ``goal_selection_strategy``, ...), or a subclass of one of them; HER is refused with importance weights."""
    if given is None:
        return DENFACDictReplayBuffer if isinstance(model.observation_space, spaces.Dict) else DENFACReplayBuffer
    if given is HerReplayBuffer:
        given = DENFACHerReplayBuffer
    if not issubclass(given, BehaviourMeansBuffer):
        raise ValueError(
            "replay_buffer_class must be SB3's HerReplayBuffer or subclass DENFACReplayBuffer, DENFACDictReplayBuffer or "
            f"DENFACHerReplayBuffer (they keep each transition's behaviour mean), got {given}"
        )
    if issubclass(given, HerReplayBuffer):
        check_her(type(model).__name__, model.weighting)
    return given


def check_her(algorithm: str, weighting: str) -> None:
    """Refuse hindsight goals with importance weights, naming the reason (module docstring)."""
    if weighting != "none":
        raise ValueError(
            f"{algorithm} with HerReplayBuffer needs weighting='none', got weighting={weighting!r}: the importance weight "
            "of a relabelled transition, min(1, pi(a | s, g') / pi_b(a | s, g')), needs the behaviour policy's density "
            "under the new goal g', and the buffer holds only its mean for the goal the episode pursued (presets.PAPER "
            "sets 'retrace': pass weighting='none' with it)"
        )


class DENFACHerReplayBuffer(BehaviourMeansBuffer, HerReplayBuffer):
    """SB3's ``HerReplayBuffer`` (its arguments: ``n_sampled_goal``, ``goal_selection_strategy``, ``copy_info_dict``)
    with each transition's behaviour mean, read whole with relabelled copies (module docstring)."""

    def all_samples(self, env: VecNormalize | None = None) -> DENFACReplayBufferSamples:
        """Every stored transition, then ``n_sampled_goal`` relabelled copies of each one of a finished episode."""
        batch, envs = self._indices()
        real = self._gather(batch, envs, env)
        finished = self.ep_length[batch, envs] > 0  # the episode's end is known: "future" goals can be drawn
        batch, envs = np.repeat(batch[finished], self.n_sampled_goal), np.repeat(envs[finished], self.n_sampled_goal)
        if len(batch) == 0:
            return real
        relabelled = self._get_virtual_samples(batch, envs, env)  # SB3's: new goals, rewards from env.compute_reward
        virtual = DENFACReplayBufferSamples(
            relabelled.observations,
            relabelled.actions,
            relabelled.next_observations,
            relabelled.dones,
            relabelled.rewards,
            self._tensor(self.behaviour_means[batch, envs]),
            self._tensor(self.timeouts[batch, envs].reshape(-1, 1)),
        )
        return DENFACReplayBufferSamples(*(_concatenate(a, b) for a, b in zip(real, virtual, strict=True)))


def _concatenate(a: Any, b: Any) -> Any:
    if isinstance(a, dict):
        return {key: th.cat([a[key], b[key]]) for key in a}
    return th.cat([a, b])
