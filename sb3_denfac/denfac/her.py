"""Hindsight experience replay (Andrychowicz et al. 2017) for DENFAC's fitted iterations.

SB3's ``HerReplayBuffer`` relabels goals when it samples a mini-batch: a fraction ``her_ratio = n / (n + 1)``
(``n = n_sampled_goal``) of the batch are stored transitions whose desired goal g is replaced by a goal g' achieved
later in the same episode ("future"; or "final", "episode"), with the reward recomputed by the env,
r' = ``env.compute_reward(achieved_goal(s'), g')``. DENFAC does not sample D: each fitted iteration computes the
targets of eq. (4) on the whole buffer (or on mini-batches drawn from it), so :class:`DENFACHerReplayBuffer` relabels
when D is read (:meth:`~DENFACHerReplayBuffer.all_samples`, once per update): every stored transition, plus
``n_sampled_goal`` relabelled copies of each transition of a finished episode. A mini-batch drawn uniformly from that
set has SB3's ``her_ratio`` of relabelled transitions.

**Fresh goals at every fitted iteration.** The set :meth:`~DENFACHerReplayBuffer.all_samples` returns is a
:class:`HerSamples`: its ``redraw_goals()`` draws new goals g' (and rewards r') for the relabelled copies, keeping their
states, actions and behaviour means, and the stored transitions as they are. DENFAC's fit calls it before every fitted
iteration but the first (``DENFAC._fit``), so that an update of K_e iterations sees K_e goal sets, not one: with one
set per update, every iteration of an update regressed on the same few goals per transition, where SB3's buffer gives
each mini-batch goals of its own. Data without ``redraw_goals`` (every other buffer) is read as it is: the fit's
arithmetic without HER is unchanged. The draws read a copy of what they need, taken when D is read (the achieved goals,
the episodes' bounds, the infos), so the asynchronous update's learner thread can draw while the env steps write D;
the rewards come from the first env's ``compute_reward``, called directly for a ``DummyVecEnv`` (GoalEnv's
``compute_reward`` is a function of its arguments). Subprocess envs are only reached through their pipes: there the
learner thread of ``async_update`` keeps the update's first goal set (a draw from the model's thread asks the env, as
SB3 does). "final" goals are the same at every draw: no redraw.

Eq. (4) on a relabelled transition is the target of the goal-conditioned problem: q = r' + gamma (1 - d)
Q_{k-1}((s', g'), pi_{k-1}(s', g')), with the critic and the actor taking the goal in the observation, as in HER's
DDPG. A fresh draw changes which goals g' eq. (4) is computed for, not what it means: each iteration's targets are
eq. (4) on that iteration's transitions (Q_{k-1} of the same goal g' at s and s'). Its importance weight is not
defined: c = min(1, pi_{k-1}(a | s, g') / pi_b(a | s, g')) needs the behaviour policy's density under the new goal g',
and D holds only the mean mu_b(s, g) the actor had for the goal it pursued. So HER needs ``weighting="none"`` (c = 1,
DENFAC's default; HER's DDPG has no weights either), and DENFAC refuses it with the paper's ``"retrace"`` weights
(``presets.PAPER``), naming this reason.
"""

from __future__ import annotations

import copy
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnvWrapper, VecNormalize
from stable_baselines3.her.goal_selection_strategy import GoalSelectionStrategy
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer

from sb3_denfac.denfac.buffers import (
    BehaviourMeansBuffer,
    DENFACDictReplayBuffer,
    DENFACReplayBuffer,
    DENFACReplayBufferSamples,
    stack_rows,
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


def is_goal_task(model: Any) -> bool:
    """Whether ``model`` learns a goal-conditioned task with hindsight goals: a Dict observation space holding
    ``achieved_goal`` and ``desired_goal`` (gymnasium-robotics' GoalEnv, panda-gym) and SB3's ``HerReplayBuffer`` or
    a subclass as D's class."""
    space, buffer = model.observation_space, model.replay_buffer_class
    has_goals = isinstance(space, spaces.Dict) and {"achieved_goal", "desired_goal"} <= set(space.spaces)
    return has_goals and isinstance(buffer, type) and issubclass(buffer, HerReplayBuffer)


def take_goal_settings(model: Any, arguments: dict[str, Any], store: Callable[[Any, dict[str, Any]], Any]) -> list[str]:
    """On a goal task with HER (:func:`is_goal_task`), the values of ``presets.GOALS`` for the settings the
    constructor was not given (``model._given_arguments``; nor those its class pins), stored with ``store`` (the
    constructor's settings check, on ``arguments`` with them) and ``gamma`` on the model; returns their names. Other
    tasks: nothing. Why each value: the preset's comment."""
    from sb3_denfac.denfac.presets import GOALS

    given = getattr(model, "_given_arguments", None)
    if given is None or not is_goal_task(model):
        return []
    pinned = getattr(type(model), "PINNED", {})
    taken = {key: value for key, value in GOALS.items() if key not in given and key not in pinned and key in arguments}
    taken.pop("replay_buffer_class", None)
    if taken:
        store(model, {**arguments, **taken})
        model.gamma = taken.get("gamma", model.gamma)
    return sorted(taken)


def check_her(algorithm: str, weighting: str) -> None:
    """Refuse hindsight goals with importance weights, naming the reason (module docstring)."""
    if weighting != "none":
        raise ValueError(
            f"{algorithm} with HerReplayBuffer needs weighting='none', got weighting={weighting!r}: the importance weight "
            "of a relabelled transition, min(1, pi(a | s, g') / pi_b(a | s, g')), needs the behaviour policy's density "
            "under the new goal g', and the buffer holds only its mean for the goal the episode pursued (presets.PAPER "
            "sets 'retrace': pass weighting='none' with it)"
        )


class _OtherThread(Exception):
    """A draw of goals that would reach subprocess envs from another thread than the one that read D."""


class HerSamples(DENFACReplayBufferSamples):
    """D's content with relabelled copies (:class:`DENFACReplayBufferSamples`: the stored transitions, then the
    copies), whose copies' goals can be drawn anew: ``redraw_goals()`` returns the observations, next observations and
    rewards of the whole set with new goals for the copies (the other fields hold for every draw); None where a draw
    would repeat the last one (module docstring)."""

    redraw_goals: Callable[[], tuple[Any, Any, th.Tensor]] | None = None


class DENFACHerReplayBuffer(BehaviourMeansBuffer, HerReplayBuffer):
    """SB3's ``HerReplayBuffer`` (its arguments: ``n_sampled_goal``, ``goal_selection_strategy``, ``copy_info_dict``)
    with each transition's behaviour mean, read whole with relabelled copies whose goals each fitted iteration draws
    anew (module docstring)."""

    def all_samples(self, env: VecNormalize | None = None) -> DENFACReplayBufferSamples:
        """Every stored transition, then ``n_sampled_goal`` relabelled copies of each one of a finished episode (a
        :class:`HerSamples`, whose ``redraw_goals`` gives the copies new goals)."""
        batch, envs = self._indices()
        real = self._gather(batch, envs, env)
        finished = self.ep_length[batch, envs] > 0  # the episode's end is known: "future" goals can be drawn
        batch, envs = np.repeat(batch[finished], self.n_sampled_goal), np.repeat(envs[finished], self.n_sampled_goal)
        if len(batch) == 0:
            return real
        relabel = self._relabelling(batch, envs, env)
        obs, next_obs, rewards = relabel()
        virtual = DENFACReplayBufferSamples(
            obs,
            self._tensor(self.actions[batch, envs]),
            next_obs,
            self._tensor((self.dones[batch, envs] * (1 - self.timeouts[batch, envs])).reshape(-1, 1)),
            rewards,
            self._tensor(self.behaviour_means[batch, envs]),
            self._tensor(self.timeouts[batch, envs].reshape(-1, 1)),
        )
        samples = HerSamples(*(stack_rows(a, b) for a, b in zip(real, virtual, strict=True)))
        if self.goal_selection_strategy != GoalSelectionStrategy.FINAL:

            def redraw_goals() -> tuple[Any, Any, th.Tensor]:
                try:
                    obs, next_obs, rewards = relabel()
                except _OtherThread:  # subprocess envs, from the learner thread: the update's first goal set
                    return samples.observations, samples.next_observations, samples.rewards
                return (
                    stack_rows(real.observations, obs),
                    stack_rows(real.next_observations, next_obs),
                    th.cat([real.rewards, rewards]),
                )

            samples.redraw_goals = redraw_goals
        return samples

    def _relabelling(
        self, batch: np.ndarray, envs: np.ndarray, env: VecNormalize | None
    ) -> Callable[[], tuple[Any, Any, th.Tensor]]:
        """A draw of new goals for the transitions (``batch``, ``envs``), as SB3's ``_get_virtual_samples`` (goals by
        ``goal_selection_strategy``, rewards from the env's ``compute_reward``), on a copy of what it reads: each call
        returns the observations and next observations with the new goals, and the rewards, as tensors."""
        obs = {key: value[batch, envs] for key, value in self.observations.items()}  # copies (fancy indexing)
        next_obs = {key: value[batch, envs] for key, value in self.next_observations.items()}
        ep_start, ep_length = self.ep_start[batch, envs], self.ep_length[batch, envs]
        current = (batch - ep_start) % self.buffer_size
        achieved = self.next_observations["achieved_goal"][: self.size()].copy()  # an episode's rows never wrap past it
        infos = list(self.infos[batch, envs]) if self.copy_info_dict else None
        compute_reward = self._reward_function()

        def draw() -> tuple[Any, Any, th.Tensor]:
            if self.goal_selection_strategy == GoalSelectionStrategy.FINAL:
                in_episode = ep_length - 1
            elif self.goal_selection_strategy == GoalSelectionStrategy.FUTURE:
                in_episode = np.random.randint(current, ep_length)  # inclusive of the transition itself, as SB3
            else:
                in_episode = np.random.randint(0, ep_length)
            goals = achieved[(in_episode + ep_start) % self.buffer_size, envs]
            o, o2 = {**obs, "desired_goal": goals}, {**next_obs, "desired_goal": goals}
            info = copy.deepcopy(infos) if infos is not None else [{} for _ in batch]
            rewards = np.asarray(compute_reward(o2["achieved_goal"], goals, info), dtype=np.float32).reshape(-1, 1)
            o, o2 = self._normalize_obs(o, env), self._normalize_obs(o2, env)  # type: ignore[attr-defined]
            rewards = self._normalize_reward(rewards, env)  # type: ignore[attr-defined]
            tensors = ({key: self._tensor(value) for key, value in x.items()} for x in (o, o2))
            return next(tensors), next(tensors), self._tensor(rewards)

        return draw

    def _reward_function(self) -> Callable[[Any, Any, Any], np.ndarray]:
        """The first env's ``compute_reward``: called directly in a ``DummyVecEnv`` (any thread), else through
        ``env_method`` in this thread, and in another (the asynchronous update's learner) it raises
        :class:`_OtherThread` (module docstring)."""
        assert self.env is not None, "HER needs the VecEnv to compute the rewards of relabelled transitions"
        venv = self.env
        while isinstance(venv, VecEnvWrapper):
            venv = venv.venv
        if isinstance(venv, DummyVecEnv):
            return venv.envs[0].get_wrapper_attr("compute_reward")
        owner, vec_env = threading.get_ident(), self.env

        def through_the_pipe(achieved: Any, desired: Any, infos: Any) -> np.ndarray:
            if threading.get_ident() != owner:
                raise _OtherThread
            return vec_env.env_method("compute_reward", achieved, desired, infos, indices=[0])[0]

        return through_the_pipe
