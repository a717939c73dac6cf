"""Replay buffers of DENFAC: SB3's FIFO buffers that also store the behaviour mean mu_b(s) of each transition.

Algorithm 1 weights every sample by c = min(1, pi_{k-1}(a|s) / pi_b(a|s)), where pi_b is the truncated Gaussian that
played ``a``. The behaviour density is fully described by its mean mu_b(s) (sigma and the bounds are fixed), so the
buffer keeps mu_b(s) next to ``a``, in the same [-1, 1] scaled action space, as the authors' ``pure_a``.

:class:`BehaviourMeansBuffer` adds that to any SB3 buffer: :class:`DENFACReplayBuffer` (SB3's ``ReplayBuffer``, vector
observations), :class:`DENFACDictReplayBuffer` (``DictReplayBuffer``, Dict observations, ``MultiInputPolicy``) and
:class:`~sb3_denfac.denfac.her.DENFACHerReplayBuffer` (``HerReplayBuffer``). Each gives Algorithm 1 its whole content
with :meth:`BehaviourMeansBuffer.all_samples`; :func:`take` and :func:`n_rows` read rows of its observations, tensors or
dicts of tensors alike.

Only the importance weights (``weighting="retrace"`` or ``"retrace_next_state_quirk"``) read the behaviour means. So the
buffers take SB3's ``add``/``extend`` without them (demonstrations, logged data) wherever no importance weight needs
them, as with DENFAC's default ``weighting="none"``. Such rows hold the mean :data:`UNKNOWN_BEHAVIOUR` (+inf), apart
from the NaN of uniform warm-up rows (whose density is known); where the weights need the means, ``add`` without them
is refused, and so is an update that would read such rows (a buffer filled without them, then loaded), naming the
setting.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch as th
from stable_baselines3.common.buffers import DictReplayBuffer, ReplayBuffer
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


def take(x: th.Tensor | dict[str, th.Tensor], rows: th.Tensor | None) -> Any:
    """Rows ``rows`` of a tensor or of each tensor of a dict (Dict observations); all of it for ``rows`` None."""
    if rows is None:
        return x
    return {key: value[rows] for key, value in x.items()} if isinstance(x, dict) else x[rows]


def stack_rows(x: th.Tensor | dict[str, th.Tensor], y: th.Tensor | dict[str, th.Tensor]) -> Any:
    """The rows of ``x`` then those of ``y`` (tensors, or dicts of tensors with the same keys)."""
    if isinstance(x, dict):
        return {key: th.cat([value, y[key]]) for key, value in x.items()}  # type: ignore[index]
    return th.cat([x, y])  # type: ignore[list-item]


def n_rows(x: th.Tensor | dict[str, th.Tensor]) -> int:
    """The number of rows of a tensor or of a dict of tensors."""
    return int(next(iter(x.values())).shape[0]) if isinstance(x, dict) else int(x.shape[0])


class DENFACReplayBufferSamples(NamedTuple):
    #: a tensor, or a dict of tensors for Dict observations
    observations: Any
    actions: th.Tensor
    next_observations: Any
    #: 1 on true terminal states only (time-limit truncations removed, as SB3's ``ReplayBufferSamples``)
    dones: th.Tensor
    rewards: th.Tensor
    #: behaviour means mu_b(s) (scaled action space, clamped to [-1 - 3 sigma, 1 + 3 sigma])
    behaviour_means: th.Tensor
    #: 1 where the episode was cut by a time limit (``TimeLimit.truncated``)
    timeouts: th.Tensor


#: The behaviour mean of a row added without one (SB3's ``add``/``extend``): unknown, unlike the NaN of a uniform
#: warm-up action, whose density is known (module docstring).
UNKNOWN_BEHAVIOUR = np.inf


class BehaviourMeansBuffer:
    """Mixed in before an SB3 buffer: the FIFO replay buffer D of Algorithm 1 with an extra ``behaviour_means`` array.

    ``add`` takes the behaviour means either as the keyword ``behaviour_means`` or, when called through SB3's
    ``_store_transition`` (which does not know about them), from :meth:`stage_behaviour_means` called just before.
    Without either, the row's mean is :data:`UNKNOWN_BEHAVIOUR`, unless :attr:`behaviour_means_needed_by` says that
    the algorithm's importance weights need it. Time-limit truncations are always recorded (``timeouts``); whether they
    bootstrap is decided by the algorithm.
    """

    #: the setting whose importance weights read the behaviour means (e.g. ``"weighting='retrace'"``), None where none
    #: does; the algorithm says which with every transition it stores (:meth:`stage_behaviour_means`)
    behaviour_means_needed_by: str | None = None

    behaviour_means: np.ndarray
    buffer_size: int
    n_envs: int
    action_dim: int
    pos: int
    timeouts: np.ndarray

    def __init__(self, *args: Any, optimize_memory_usage: bool = False, **kwargs: Any):
        if optimize_memory_usage:
            raise ValueError(f"{type(self).__name__} does not support optimize_memory_usage=True")
        super().__init__(*args, **kwargs)  # type: ignore[call-arg]
        self.behaviour_means = np.zeros((self.buffer_size, self.n_envs, self.action_dim), dtype=np.float32)
        self._staged_behaviour_means: np.ndarray | None = None

    def __getstate__(self) -> dict[str, Any]:
        """Pickled (``save_replay_buffer``) without :attr:`behaviour_means_needed_by`: the model that loads it says."""
        state = dict(super().__getstate__())  # type: ignore[misc]
        state.pop("behaviour_means_needed_by", None)
        return state

    def stage_behaviour_means(self, behaviour_means: np.ndarray, weighting: str | None = None) -> None:
        """Remember mu_b(s) for the next call to :meth:`add` (shape (n_envs, action_dim)); ``weighting``, the
        algorithm's importance weights, says whether they need the means (:attr:`behaviour_means_needed_by`)."""
        self._staged_behaviour_means = np.asarray(behaviour_means, dtype=np.float32)
        if weighting is not None:
            self.behaviour_means_needed_by = None if weighting == "none" else f"weighting={weighting!r}"

    def add(
        self,
        obs: Any,
        next_obs: Any,
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
            if self.behaviour_means_needed_by is not None:
                raise ValueError(
                    f"{type(self).__name__}.add needs the behaviour means mu_b(s) with {self.behaviour_means_needed_by}: "
                    "its importance weights divide by the density of the policy that played each action. Pass "
                    "behaviour_means=... (NaN rows: uniformly drawn actions), or use weighting='none'"
                )
            behaviour_means = np.full((self.n_envs, self.action_dim), UNKNOWN_BEHAVIOUR, dtype=np.float32)
        self.behaviour_means[self.pos] = np.asarray(behaviour_means, dtype=np.float32).reshape((self.n_envs, self.action_dim))
        super().add(obs, next_obs, action, reward, done, infos)  # type: ignore[misc]

    def _get_samples(self, batch_inds: np.ndarray, env: VecNormalize | None = None) -> DENFACReplayBufferSamples:  # type: ignore[override]
        env_indices = np.random.randint(0, high=self.n_envs, size=(len(batch_inds),))
        return self._gather(batch_inds, env_indices, env)

    def _gather(self, batch_inds: np.ndarray, env_indices: np.ndarray, env: VecNormalize | None) -> DENFACReplayBufferSamples:
        """Transitions (``batch_inds``, ``env_indices``) as :class:`DENFACReplayBufferSamples`."""
        timeouts = self.timeouts[batch_inds, env_indices]
        means = self.behaviour_means[batch_inds, env_indices, :]
        self._check_means_known(means)
        data = (
            self.actions[batch_inds, env_indices, :],  # type: ignore[attr-defined]
            (self.dones[batch_inds, env_indices] * (1 - timeouts)).reshape(-1, 1),  # type: ignore[attr-defined]
            self._normalize_reward(self.rewards[batch_inds, env_indices].reshape(-1, 1), env),  # type: ignore[attr-defined]
            means,
            timeouts.reshape(-1, 1),
        )
        actions, dones, rewards, means, timeouts_ = (self._tensor(x) for x in data)
        obs, next_obs = (
            self._observations(which, batch_inds, env_indices, env) for which in ("observations", "next_observations")
        )
        return DENFACReplayBufferSamples(obs, actions, next_obs, dones, rewards, means, timeouts_)

    def _check_means_known(self, means: np.ndarray) -> None:
        """Refuse rows added without behaviour means where the importance weights need them: they would otherwise
        be weighted as if played by some policy they were not."""
        if self.behaviour_means_needed_by is None:
            return
        unknown = int(np.isinf(means).any(axis=-1).sum())
        if unknown:
            raise ValueError(
                f"{unknown} transitions of the replay buffer were added without behaviour means (add or extend without "
                f"behaviour_means=), and {self.behaviour_means_needed_by} needs them: its importance weights divide by "
                "the density of the policy that played each action. Add them with behaviour_means=..., or use "
                "weighting='none'"
            )

    def _observations(self, which: str, batch_inds: np.ndarray, env_indices: np.ndarray, env: VecNormalize | None) -> Any:
        stored = getattr(self, which)
        if isinstance(stored, dict):
            normalised = self._normalize_obs({key: obs[batch_inds, env_indices] for key, obs in stored.items()}, env)  # type: ignore[attr-defined]
            return {key: self._tensor(value) for key, value in normalised.items()}
        return self._tensor(self._normalize_obs(stored[batch_inds, env_indices, :], env))  # type: ignore[attr-defined]

    def _tensor(self, x: np.ndarray) -> th.Tensor:
        return self.to_torch(np.asarray(x, dtype=np.float32))  # type: ignore[attr-defined]

    def _indices(self) -> tuple[np.ndarray, np.ndarray]:
        """(step, env) indices of every stored transition, in the order :meth:`all_samples` returns them."""
        size = self.size()  # type: ignore[attr-defined]
        return np.repeat(np.arange(size), self.n_envs), np.tile(np.arange(self.n_envs), size)

    def all_samples(self, env: VecNormalize | None = None) -> DENFACReplayBufferSamples:
        """The whole buffer content (every stored transition of every env), for Algorithm 1's full-batch update."""
        return self._gather(*self._indices(), env)


class DENFACReplayBuffer(BehaviourMeansBuffer, ReplayBuffer):
    """D with vector observations: SB3's ``ReplayBuffer`` and each transition's behaviour mean."""


class DENFACDictReplayBuffer(BehaviourMeansBuffer, DictReplayBuffer):
    """D with Dict observations (``MultiInputPolicy``): SB3's ``DictReplayBuffer`` and each transition's behaviour mean."""
