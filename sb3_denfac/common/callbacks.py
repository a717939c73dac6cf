"""Callbacks for measuring data-efficiency the way the paper does (best registered performance per episode), and the
progress bar of ``learn(progress_bar=True)``."""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, ConvertCallback
from stable_baselines3.common.callbacks import ProgressBarCallback as SB3ProgressBarCallback
from stable_baselines3.common.type_aliases import MaybeCallback
from tqdm import TqdmExperimentalWarning

from sb3_denfac.common.performance import best_so_far


class EpisodePerformanceCallback(BaseCallback):
    """
    Record every finished training episode and optionally stop training after ``max_episodes`` episodes.

    The paper (Section 4, Figure 3) measures data-efficiency as the *best registered performance* since the start of
    learning, plotted against the number of episodes. The paper's environments put their per-episode measure in the
    last step's ``info["paper_performance"]`` (Acrobot: steps to reach the goal, lower is better; CartPole and
    Half-Cheetah: episode return). For each finished episode this callback stores one record::

        {"episode", "performance", "best_so_far", "return", "length", "timesteps", "wall_time"}

    ``return``/``length`` come from the ``Monitor`` wrapper's ``info["episode"]`` when present (unnormalised, even under
    ``VecNormalize``), else from the rewards seen by the callback. ``timesteps`` is the model's step counter at the end
    of the episode and ``wall_time`` the seconds since the first ``learn()`` started. With several envs, episodes are
    numbered in the order they finish. It also logs ``rollout/paper_performance`` and ``rollout/best_paper_performance``.

    :param max_episodes: stop training once this many episodes have finished (``None``: never stop).
        Note that an off-policy algorithm stopped this way does not run the update that would follow the last episode.
    :param performance_key: info key holding the per-episode measure.
    :param lower_is_better: whether a lower measure is better (Acrobot), for the running best.
    :param fallback_to_return: if the info has no ``performance_key``, use the episode return instead of NaN
        (lets the callback run on any Gymnasium env).
    :param best_model_path: if given, ``model.save(best_model_path)`` at the end of every episode whose performance is
        a new best: the policy that played it (the authors' "best of stored policies"; for CMA-ES, the candidate that was
        evaluated). With several envs, the policy at the end of the episode.
    :param verbose: verbosity level: 0 silent, 1 prints one line per episode.
    """

    def __init__(
        self,
        max_episodes: int | None = None,
        performance_key: str = "paper_performance",
        lower_is_better: bool = False,
        fallback_to_return: bool = True,
        best_model_path: str | None = None,
        verbose: int = 0,
    ):
        super().__init__(verbose=verbose)
        if max_episodes is not None and max_episodes < 1:
            raise ValueError(f"max_episodes must be None or >= 1, got {max_episodes}")
        self.max_episodes = max_episodes
        self.performance_key = performance_key
        self.lower_is_better = lower_is_better
        self.fallback_to_return = fallback_to_return
        self.best_model_path = best_model_path
        self.records: list[dict[str, Any]] = []
        self._start_time = 0.0
        self._returns = np.zeros(0)
        self._lengths = np.zeros(0, dtype=np.int64)

    @property
    def best_so_far(self) -> float:
        """Best performance registered so far (NaN before the first episode)."""
        return self.records[-1]["best_so_far"] if self.records else float("nan")

    @property
    def n_episodes(self) -> int:
        return len(self.records)

    def performances(self) -> np.ndarray:
        """Per-episode measures, in episode order."""
        return np.array([r["performance"] for r in self.records], dtype=np.float64)

    def _on_training_start(self) -> None:
        if not self.records:  # keep the clock and the episode count across successive learn() calls
            self._start_time = time.perf_counter()
        n_envs = self.training_env.num_envs
        self._returns = np.zeros(n_envs)
        self._lengths = np.zeros(n_envs, dtype=np.int64)

    def _on_step(self) -> bool:
        for key in ("dones", "infos"):
            if key not in self.locals:
                raise RuntimeError(f"`{key}` is not defined in the locals passed to callback.on_step() by {type(self.model)}")
        dones = np.asarray(self.locals["dones"]).reshape(-1)
        infos = self.locals["infos"]
        rewards = self.locals.get("rewards")
        if rewards is not None:
            self._returns += np.asarray(rewards, dtype=np.float64).reshape(-1)
        self._lengths += 1
        for env_idx in np.flatnonzero(dones):
            self._record_episode(infos[env_idx], int(env_idx))
        return self.max_episodes is None or len(self.records) < self.max_episodes

    def _record_episode(self, info: dict[str, Any], env_idx: int) -> None:
        monitor = info.get("episode")
        ep_return = float(monitor["r"]) if monitor is not None else float(self._returns[env_idx])
        ep_length = int(monitor["l"]) if monitor is not None else int(self._lengths[env_idx])
        self._returns[env_idx] = 0.0
        self._lengths[env_idx] = 0
        if self.performance_key in info:
            performance = float(info[self.performance_key])
        else:
            performance = ep_return if self.fallback_to_return else float("nan")
        previous = self.best_so_far
        best = float(best_so_far([previous, performance], self.lower_is_better)[-1])
        record = {
            "episode": len(self.records) + 1,
            "performance": performance,
            "best_so_far": best,
            "return": ep_return,
            "length": ep_length,
            "timesteps": int(self.num_timesteps),
            "wall_time": time.perf_counter() - self._start_time,
        }
        self.records.append(record)
        if self.best_model_path is not None and not np.isnan(performance) and (np.isnan(previous) or best != previous):
            self._save_acting_policy()
        self.logger.record("rollout/paper_performance", performance)
        self.logger.record("rollout/best_paper_performance", best)
        if self.verbose >= 1:
            print(
                f"episode {record['episode']}: performance={performance:.4g} best={best:.4g} "
                f"return={ep_return:.4g} length={ep_length} timesteps={record['timesteps']}"
            )

    def _save_acting_policy(self) -> None:
        candidate = getattr(self.model, "_candidate_policy", None)  # CMA-ES plays candidates, not model.policy
        if candidate is None:
            self.model.save(self.best_model_path)
            return
        incumbent = {key: value.clone() for key, value in self.model.policy.state_dict().items()}
        self.model.policy.load_state_dict(candidate.state_dict())
        try:
            self.model.save(self.best_model_path)
        finally:
            self.model.policy.load_state_dict(incumbent)


class UpdateStatsCallback(BaseCallback):
    """Hands every end-of-episode update's statistics of DENFAC or SoftDENFAC (``model.last_updates``, each an
    :class:`~sb3_denfac.denfac.updaters.UpdateStats`: K_e, wall time, the last fitted iteration's targets and weights) to
    ``on_update``, once per update, also when several envs' episodes end together: read when the next rollout starts
    (the update runs between two rollouts) and when training ends (the last update)."""

    def __init__(self, on_update: Callable[[Any], None], verbose: int = 0):
        super().__init__(verbose)
        self.on_update = on_update
        self._seen = 0

    def _read(self) -> None:
        for stats in getattr(self.model, "last_updates", []):  # several when several envs' episodes end together
            if stats.n_updates > self._seen:
                self._seen = stats.n_updates
                self.on_update(stats)

    def _on_training_start(self) -> None:
        self._seen = self.model._n_updates  # a learn() that continues an earlier one

    def _on_rollout_start(self) -> None:
        self._read()

    def _on_step(self) -> bool:
        return True

    def _on_training_end(self) -> None:
        self._read()


class ProgressBarCallback(SB3ProgressBarCallback):
    """SB3's progress bar (tqdm.rich) without tqdm's "rich is experimental" ``TqdmExperimentalWarning``.

    :param max_episodes: count finished episodes up to this number instead of steps, for a run budgeted in episodes
        (e.g. with ``StopTrainingOnMaxEpisodes``): the bar then reaches 100% even when episodes end early.
    """

    def __init__(self, max_episodes: int | None = None) -> None:
        super().__init__()
        if max_episodes is not None and max_episodes < 1:
            raise ValueError(f"max_episodes must be None or >= 1, got {max_episodes}")
        self.max_episodes = max_episodes

    def _on_training_start(self) -> None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", TqdmExperimentalWarning)
            if self.max_episodes is None:
                super()._on_training_start()
            else:
                from tqdm.rich import tqdm

                self.pbar = tqdm(total=self.max_episodes, unit="episode")

    def _on_step(self) -> bool:
        if self.max_episodes is None:
            return super()._on_step()
        self.pbar.update(int(np.sum(self.locals["dones"])))
        return True


@runtime_checkable
class ProgressBarHost(Protocol):
    """What :class:`ProgressBarMixin` needs from the algorithm it is mixed into: SB3's ``_init_callback``."""

    def _init_callback(self, callback: MaybeCallback, progress_bar: bool = False) -> BaseCallback: ...


class ProgressBarMixin:
    """``learn(progress_bar=True)`` shows :class:`ProgressBarCallback` instead of SB3's (same bar, no warning)."""

    def _init_callback(self, callback: MaybeCallback, progress_bar: bool = False) -> BaseCallback:
        if progress_bar:
            callbacks = callback if isinstance(callback, list) else [] if callback is None else [callback]
            callbacks = [c if isinstance(c, BaseCallback) else ConvertCallback(c) for c in callbacks]
            callback = CallbackList([*callbacks, ProgressBarCallback()])
        return super()._init_callback(callback, progress_bar=False)  # type: ignore[misc]
