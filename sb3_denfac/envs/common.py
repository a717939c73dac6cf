"""Shared pieces of the paper's environments: episode bookkeeping and the composite "paper env".

Reference: M. Zimmer, Y. Boniface, A. Dutech, "Off-Policy Neural Fitted Actor-Critic" (DENFAC), section 4
(Experimental Setup).
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

PAPER_PERFORMANCE_KEY = "paper_performance"
DEFAULT_EPISODE_LENGTH = 500


class EpisodeRewardWrapper(gym.Wrapper):
    """Base class of the paper's reward wrappers: counts steps and ends episodes after ``max_episode_steps``.

    The step counter lives in the wrapper itself so that the time-limit step is known *inside* the wrapper (the
    paper's Acrobot reward depends on it), whatever ``TimeLimit`` is or is not applied outside. A truncation coming
    from an inner env (e.g. an inner ``TimeLimit``) is also treated as the last step.

    Subclasses implement :meth:`_reward` and :meth:`_performance`. The last step's ``info`` (terminated or
    truncated) carries ``info["paper_performance"]``.

    :param env: The environment to wrap.
    :param max_episode_steps: Episode length (``None``: rely on the inner env's truncation only).
    """

    def __init__(self, env: gym.Env, max_episode_steps: int | None = 500) -> None:
        super().__init__(env)
        if max_episode_steps is not None and max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be >= 1 or None, got {max_episode_steps}")
        self.max_episode_steps = max_episode_steps
        self.elapsed_steps = 0
        self.episode_return = 0.0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        self.elapsed_steps = 0
        self.episode_return = 0.0
        obs, info = self.env.reset(seed=seed, options=options)
        self._on_reset(obs, info)
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, base_reward, base_terminated, base_truncated, info = self.env.step(action)
        self.elapsed_steps += 1
        time_limit = self.max_episode_steps is not None and self.elapsed_steps >= self.max_episode_steps
        last_by_time = time_limit or bool(base_truncated)
        reward, terminated = self._reward(action, info, bool(base_terminated), last_by_time)
        truncated = last_by_time and not terminated
        self.episode_return += reward
        if terminated or truncated:
            info[PAPER_PERFORMANCE_KEY] = self._performance(terminated)
        return obs, reward, terminated, truncated, info

    def _on_reset(self, obs: Any, info: dict[str, Any]) -> None:
        """Hook called after every reset."""

    def _reward(self, action: Any, info: dict[str, Any], base_terminated: bool, last_by_time: bool) -> tuple[float, bool]:
        """Return ``(reward, terminated)`` for the step just taken (``self.elapsed_steps`` is 1-based)."""
        raise NotImplementedError

    def _performance(self, terminated: bool) -> float:
        """Per-episode performance measure of the paper (default: the episode return)."""
        return float(self.episode_return)


class PaperEnv(gym.Env):
    """A plain ``gymnasium.Env`` holding ``reward_wrapper(base_env)``.

    The registered ids use subclasses of this class rather than the wrapper chain itself so that ``env.unwrapped``
    includes the paper's reward (gymnasium's checker and SB3 see one raw environment). The inner chain is available as
    ``self.env`` and the dynamics env as ``self.base_env``.

    Episode length: the reward wrapper counts steps itself (the last step's reward and ``paper_performance`` depend on
    it). It is ``episode_length`` if given, else the ``TimeLimit`` that ``gym.make`` puts around the env
    (``gym.make(id, max_episode_steps=N)``, registered: 500; :class:`EpisodeLengthFromTimeLimit` passes it in), else
    500. An ``episode_length`` longer than that ``TimeLimit`` is refused (its last step would never come).

    :param env: The wrapped environment (a reward wrapper around a base env).
    :param episode_length_given: whether the user chose the episode length (else a ``TimeLimit`` may set it).
    """

    def __init__(self, env: gym.Env, episode_length_given: bool = True) -> None:
        self.env = env
        self.episode_length_given = episode_length_given
        self.observation_space = env.observation_space
        self.action_space = env.action_space
        self.render_mode = env.render_mode
        self.metadata = env.unwrapped.metadata

    @property
    def base_env(self) -> gym.Env:
        """The innermost (dynamics) environment."""
        return self.env.unwrapped

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        return self.env.reset(seed=seed, options=options)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        return self.env.step(action)

    def render(self) -> Any:
        return self.env.render()

    @property
    def episode_length(self) -> int | None:
        return self.env.max_episode_steps  # type: ignore[attr-defined]

    def set_time_limit(self, max_episode_steps: int) -> None:
        """Take the length of an outer ``TimeLimit`` as the episode length, unless ``episode_length`` was given (then it
        must not be longer)."""
        if not self.episode_length_given:
            self.env.max_episode_steps = max_episode_steps  # type: ignore[attr-defined]
        elif self.episode_length is not None and self.episode_length > max_episode_steps:
            raise ValueError(
                f"episode_length={self.episode_length} is longer than the TimeLimit around the env "
                f"(max_episode_steps={max_episode_steps}): its last step, which carries the paper's last-step reward and "
                "paper_performance, would never come. Pass only max_episode_steps, or equal values"
            )

    def close(self) -> None:
        self.env.close()


def as_action_vector(action: Any, action_space: gym.spaces.Box) -> np.ndarray:
    """Flatten an action to a float64 vector clipped to the Box bounds."""
    return np.clip(np.asarray(action, dtype=np.float64).reshape(action_space.shape), action_space.low, action_space.high)


class EpisodeLengthFromTimeLimit(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Pass-through wrapper that ``gym.make`` adds outside the ``TimeLimit`` of the paper's ids (their registered
    ``additional_wrappers``): it gives the :class:`PaperEnv` inside the ``TimeLimit``'s length, so
    ``gym.make(id, max_episode_steps=N)`` alone gives N-step episodes with the paper's last-step reward."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        limits, node = [], env
        while isinstance(node, gym.Wrapper):
            if isinstance(node, gym.wrappers.TimeLimit):
                limits.append(node._max_episode_steps)
            node = node.env
        if limits and isinstance(node, PaperEnv):
            node.set_time_limit(min(limits))
