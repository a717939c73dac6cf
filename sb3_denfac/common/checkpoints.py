"""Policy checkpoints: which actor ``predict(deterministic=True)`` plays (``checkpoint_episodes`` n >= 1).

TD7's (Fujimoto et al. 2023, "For SALE", section 5). In DENFAC the actor changes only at episode ends, so an episode is a
rollout of one actor, and its return (the exploring actions included) an assessment of it. The training episodes that
one actor played whole (no warm-up action, no update or ``set_parameters`` inside; an episode cut by the budget goes on
in the next ``learn``) assess it, up to n of them; while its assessment runs, the updates of the episodes that end wait
(with n = 1 nothing waits). It ends at its n-th episode, or earlier at an episode whose return falls below the best
assessment so far; its value is the minimum of its episodes' returns. An actor whose value is at least the best so far
is copied into the policy (``policy.checkpoint_actor``), which plays ``predict(deterministic=True)`` from then on;
exploration and the updates keep the current actor. One assessment per actor: with several envs, the first of its whole
episodes to end starts it.

:class:`Assessment` keeps the books; the episodic base
(:class:`~sb3_denfac.common.episodic.EpisodicOffPolicyAlgorithm`) feeds it each env step's rewards with the policy's
version (a counter of its changes) and copies the actor it returns. The copy is a module of the policy, saved with its
value (``policy.checkpoint_return``); the assessment running is not saved. The asynchronous update changes the actor
inside every episode, so the two are refused together.
"""

from __future__ import annotations

import numpy as np

#: an env's episode not yet begun, and one that no single actor played whole (the versions are >= 0)
_NEW, _SPOILED = -2, -1


class Assessment:
    """The running assessment of the current actor over the episodes it plays whole (module docstring), for n =
    ``episodes``."""

    def __init__(self, episodes: int) -> None:
        self.episodes = episodes
        #: per env, the return of its running episode, and the policy version at its first step (None: no episode yet)
        self._returns: np.ndarray | None = None
        self._versions: np.ndarray | None = None
        #: the policy version of the actor assessed last, and the returns of its whole episodes (None: it ended)
        self._version = -1
        self._assessed: list[float] | None = None

    def new_episodes(self) -> None:
        """The envs were reset: their running episodes are dropped (an assessment running goes on with the next)."""
        self._returns = self._versions = None

    def step(self, rewards: np.ndarray, dones: np.ndarray, warm_up: bool, version: int, best: float | None) -> float | None:
        """After an env step played by policy ``version`` (``warm_up``: uniform actions, not the actor's): add
        ``rewards`` to each env's episode return; the episodes that end (``dones``) and that ``version`` played whole
        assess it. Returns the value of the actor to keep now (its assessment is at least ``best``), else None."""
        n_envs = len(dones)
        if self._versions is None or self._returns is None or len(self._versions) != n_envs:
            self._returns, self._versions = np.zeros(n_envs), np.full(n_envs, _NEW)
        versions, returns = self._versions, self._returns
        versions[versions == _NEW] = version
        if warm_up:
            versions[:] = _SPOILED
        returns += rewards
        whole = [float(returns[i]) for i in np.flatnonzero(dones) if versions[i] == version]
        versions[dones] = _NEW
        returns[dones] = 0.0
        for episode_return in whole:
            value = self._take(episode_return, version, best)
            if value is not None:  # the assessment ends with it: the later episodes are not read
                return value
        return None

    def _take(self, episode_return: float, version: int, best: float | None) -> float | None:
        """A whole episode of actor ``version``: its assessment ends at its n-th episode, with the minimum of their
        returns to keep if at least ``best``, or earlier at an episode below ``best``. Once it ended, the actor's
        episodes are not read (so at most one value per actor)."""
        if self._version != version:
            self._version, self._assessed = version, []
        if self._assessed is None:
            return None
        self._assessed.append(episode_return)
        if best is not None and episode_return < best:
            self._assessed = None
        elif len(self._assessed) == self.episodes:
            value, self._assessed = min(self._assessed), None
            return value
        return None

    def going_on(self, version: int) -> bool:
        """Whether actor ``version``'s assessment has begun and not ended (the updates of episodes that end wait)."""
        return self._version == version and bool(self._assessed)
