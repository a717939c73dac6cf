"""Replay buffer of DENFAC: SB3's FIFO ``ReplayBuffer`` that also stores the behaviour mean mu_b(s) of each transition.

Algorithm 1 weights every sample by c = min(1, pi_{k-1}(a|s) / pi_b(a|s)), where pi_b is the truncated Gaussian that
played ``a``. The behaviour density is fully described by its mean mu_b(s) (sigma and the bounds are fixed), so the
buffer keeps mu_b(s) next to ``a``, in the same [-1, 1] scaled action space, as the authors' ``pure_a``.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.vec_env import VecEnv, VecNormalize


def check_holds_one_episode(env: VecEnv | None, buffer_size: int) -> None:
    """A buffer shorter than one episode would never hold a whole episode (of each env): refuse it when the length is
    known."""
    if env is None:
        return
    try:
        spec = env.get_attr("spec")[0]
    except (AttributeError, IndexError):
        spec = None
    max_steps = getattr(spec, "max_episode_steps", None)
    per_env = buffer_size // env.num_envs  # SB3's buffers keep buffer_size // n_envs steps of each env
    if max_steps is not None and per_env < max_steps:
        of_each = f" // n_envs={env.num_envs}" if env.num_envs > 1 else ""
        raise ValueError(
            f"buffer_size (D={buffer_size}){of_each} is smaller than the environment's episode length "
            f"(spec.max_episode_steps={max_steps}): the FIFO buffer must hold at least one whole episode of each env"
        )


class DENFACReplayBufferSamples(NamedTuple):
    observations: th.Tensor
    actions: th.Tensor
    next_observations: th.Tensor
    #: 1 on true terminal states only (time-limit truncations removed, as SB3's ``ReplayBufferSamples``)
    dones: th.Tensor
    rewards: th.Tensor
    #: behaviour means mu_b(s) (scaled action space, clamped to [-1 - 3 sigma, 1 + 3 sigma])
    behaviour_means: th.Tensor
    #: 1 where the episode was cut by a time limit (``TimeLimit.truncated``)
    timeouts: th.Tensor


class DENFACReplayBuffer(ReplayBuffer):
    """FIFO replay buffer D of Algorithm 1 with an extra ``behaviour_means`` array.

    ``add`` takes the behaviour means either as the keyword ``behaviour_means`` or, when called through SB3's
    ``_store_transition`` (which does not know about them), from :meth:`stage_behaviour_means` called just before.
    Time-limit truncations are always recorded (``timeouts``); whether they bootstrap is decided by the algorithm.
    """

    behaviour_means: np.ndarray

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        device: th.device | str = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = False,
        handle_timeout_termination: bool = True,
    ):
        if optimize_memory_usage:
            raise ValueError("DENFACReplayBuffer does not support optimize_memory_usage=True")
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device=device,
            n_envs=n_envs,
            optimize_memory_usage=False,
            handle_timeout_termination=handle_timeout_termination,
        )
        self.behaviour_means = np.zeros((self.buffer_size, self.n_envs, self.action_dim), dtype=np.float32)
        self._staged_behaviour_means: np.ndarray | None = None

    def stage_behaviour_means(self, behaviour_means: np.ndarray) -> None:
        """Remember mu_b(s) for the next call to :meth:`add` (shape (n_envs, action_dim))."""
        self._staged_behaviour_means = np.asarray(behaviour_means, dtype=np.float32)

    def add(
        self,
        obs: np.ndarray,
        next_obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
        behaviour_means: np.ndarray | None = None,
    ) -> None:
        if behaviour_means is None:
            behaviour_means = self._staged_behaviour_means
            self._staged_behaviour_means = None
        if behaviour_means is None:
            raise ValueError(
                "DENFACReplayBuffer.add needs the behaviour means mu_b(s): pass behaviour_means=... "
                "or call stage_behaviour_means() before add()"
            )
        self.behaviour_means[self.pos] = np.asarray(behaviour_means, dtype=np.float32).reshape((self.n_envs, self.action_dim))
        super().add(obs, next_obs, action, reward, done, infos)

    def _get_samples(self, batch_inds: np.ndarray, env: VecNormalize | None = None) -> DENFACReplayBufferSamples:  # type: ignore[override]
        env_indices = np.random.randint(0, high=self.n_envs, size=(len(batch_inds),))
        return self._gather(batch_inds, env_indices, env)

    def _gather(self, batch_inds: np.ndarray, env_indices: np.ndarray, env: VecNormalize | None) -> DENFACReplayBufferSamples:
        timeouts = self.timeouts[batch_inds, env_indices]
        data = (
            self._normalize_obs(self.observations[batch_inds, env_indices, :], env),
            self.actions[batch_inds, env_indices, :],
            self._normalize_obs(self.next_observations[batch_inds, env_indices, :], env),
            (self.dones[batch_inds, env_indices] * (1 - timeouts)).reshape(-1, 1),
            self._normalize_reward(self.rewards[batch_inds, env_indices].reshape(-1, 1), env),
            self.behaviour_means[batch_inds, env_indices, :],
            timeouts.reshape(-1, 1),
        )
        return DENFACReplayBufferSamples(*tuple(self.to_torch(np.asarray(x, dtype=np.float32)) for x in data))

    def all_samples(self, env: VecNormalize | None = None) -> DENFACReplayBufferSamples:
        """The whole buffer content (every stored transition of every env), for Algorithm 1's full-batch update."""
        size = self.size()
        batch_inds = np.repeat(np.arange(size), self.n_envs)
        env_indices = np.tile(np.arange(self.n_envs), size)
        return self._gather(batch_inds, env_indices, env)
