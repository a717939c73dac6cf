"""The episodic base of DENFAC and SoftDENFAC: an SB3 off-policy algorithm whose update runs after each finished episode.

SB3's off-policy algorithms train every ``train_freq`` steps or episodes. In episodes they refuse a VecEnv of several
envs ("You must use only one env when doing episodic training."), and they wait for the episode's end, which never
comes on an env without a time limit. Algorithm 1 updates after every episode, whichever env finishes when.
:class:`EpisodicOffPolicyAlgorithm` owns that collection, in one ``collect_rollouts``:

- **Episode ends.** Each env's steps since its last update are counted. A rollout ends at the first step at which an
  env's episode ends, and ``train`` takes the lengths of the episodes finished then (:meth:`_finished_episodes`:
  several when several envs finish at the same step). With one env this is SB3's episodic rollout, and ``train``'s
  ``gradient_steps`` (SB3's ``gradient_steps=-1``: the steps collected) is the episode's length. Episodes that end
  before ``learning_starts`` trigger no update, as in SB3.
- **The budget.** ``learn(total_timesteps)`` stops at ``total_timesteps``, also inside episodes: the unfinished
  episodes count as finished (their last transition bootstraps: it is not terminal) and get their update. The next
  ``learn(reset_num_timesteps=False)`` continues them and counts their steps from 0 (SB3 resets the envs only with
  ``reset_num_timesteps=True`` or after ``load``).
- **Exploration.** The subclass's :meth:`_explore` gives each step's actions and the behaviour means mu_b(s) that D
  stores with the transition (the uniform warm-up before ``learning_starts``, as SB3's, stores NaN means:
  :func:`~sb3_denfac.common.exploration.warm_up_actions`).
- **The asynchronous update** (``async_update=True``). On a robot or a slow simulator the update at an episode's end
  stalls the control loop. Then :meth:`_run_updates` snapshots D (``all_samples``, a copy) and the policy
  (``copy.deepcopy``: networks, optimizers, running statistics) and hands them to one learner thread
  (:class:`~sb3_denfac.common.learner.BackgroundLearner`), which runs the update (with several envs, one per episode
  finished, back to back) on the copies. Meanwhile the env steps with the last published policy, ``model.policy``,
  which no thread writes. The first env step after the update ends publishes it: the copy becomes ``model.policy``,
  and the update is recorded (logging keys, ``last_update``), in the calling thread.

  The update also publishes its progress: after each fitted iteration the learner offers a copy of the policy as
  fitted so far (:meth:`_offer_snapshot`, which the subclass's fit calls), and the next env step plays the newest one
  (it becomes ``model.policy``; nothing is recorded until the update ends). Without these snapshots an update that
  outlasts an episode left that whole episode to the policy from before the update (the newest data then came from
  the policy before last, while the update fitted the actor a step further): on Reacher-v5 the critic never saw the
  actions the actor moved to before it moved further, and the actor ran off to the action bounds
  (research/several_envs/README.md, "The asynchronous update's lag on Reacher").

  With several envs the episodes that end at the same step get their updates back to back, in one job. When the next
  episode ends while a job runs, the job ends at its next fitted iteration (:meth:`_job_goes_on`, which the subclass
  asks between iterations of a job's later updates; the first update of a job always runs whole, so with one env
  nothing is cut): the updates left are dropped. Without that bound the episodes played while 4 back-to-back updates
  ran came from the first of them, and the next job fitted the actor 4 updates further on a critic that had seen none
  of its actions: on Reacher-v5 with 4 envs the actor ran off to the action bounds. With the bound it held 2 of 3
  seeds there, and Pendulum-v1 kept its episodes to the level (research/several_envs/README.md); ``learn`` still warns
  beyond :data:`ASYNC_ENVS_MEASURED` envs. On a fast env, where the updates outlast the episodes, most updates past a
  job's first are dropped: the asynchronous update is for envs whose steps, not the updates, take the time.

  What changes against the update in place: the first steps of an episode are played by the previous policy and by
  the running update's snapshots; an episode's end waits for the update still running, if any (at most one is in
  flight; the next update starts from the finished one, never from a snapshot); with several envs, updates may be
  dropped (above); the learner's random draws interleave with the env's, so runs are not reproducible from the seed.
  ``learn`` returns after the last update is published. On an exception (``KeyboardInterrupt`` included) it waits for
  the running update, publishes it, and ends the thread before the exception propagates. ``save`` during ``learn``
  writes the last published policy (possibly a snapshot inside an update).

- **Policy checkpoints** (``checkpoint_episodes`` n >= 1; :mod:`~sb3_denfac.common.checkpoints`). After each env
  step, before the policy may change, :meth:`_assess_episodes` hands the rewards (the env's own, before ``VecNormalize``)
  and the policy's version (``_policy_version``, which counts its changes) to the running
  :class:`~sb3_denfac.common.checkpoints.Assessment`, and copies the actor it keeps into the policy. While an
  assessment runs, the rollout does not end at an episode's end: the updates of the episodes that end wait for it.

``learn`` runs with ``torch_threads`` torch threads (:mod:`~sb3_denfac.common.threads`). A subclass provides
:meth:`_explore`, :meth:`_fit_all`, :meth:`_record` and :meth:`_create_aliases`, calls :meth:`_run_updates` from its
``train`` with what :meth:`_finished_episodes` hands it, :meth:`_offer_snapshot` between its fitted iterations and
:meth:`_job_goes_on` inside a job's later updates, and uses a replay buffer with the :class:`EpisodicBuffer` methods.
"""

from __future__ import annotations

import copy
import warnings
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.base_class import SelfBaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.type_aliases import MaybeCallback, RolloutReturn, TrainFreq
from stable_baselines3.common.vec_env import VecEnv

from sb3_denfac.common.checkpoints import Assessment
from sb3_denfac.common.exploration import warm_up_actions
from sb3_denfac.common.learner import BackgroundLearner
from sb3_denfac.common.threads import DEFAULT_TORCH_THREADS, torch_threads

#: the most envs with which the asynchronous update held the return in every seed where it was measured (Reacher-v5,
#: 2 envs; with 4 one seed of 3 ran off to the action bounds: :meth:`EpisodicOffPolicyAlgorithm.learn` warns beyond)
ASYNC_ENVS_MEASURED = 2


class EpisodicBuffer(Protocol):
    """What the episodic base needs of its replay buffer D (DENFAC's buffers: :mod:`sb3_denfac.denfac.buffers`)."""

    def stage_behaviour_means(self, behaviour_means: np.ndarray, weighting: str | None = None) -> None:
        """mu_b(s) of the transition that SB3's ``_store_transition`` adds next (``weighting``: which importance
        weights read them)."""

    def all_samples(self, env: Any = None) -> Any:
        """D's whole content, a copy (the update's data)."""


class EpisodicOffPolicyAlgorithm(OffPolicyAlgorithm):
    """An SB3 ``OffPolicyAlgorithm`` with one update after each finished episode of each env (module docstring).

    Build it with ``train_freq=(1, "episode")``, ``gradient_steps=-1`` and ``support_multi_env=True``.
    """

    #: run each end-of-episode update on a learner thread (module docstring); the subclass's constructor sets it
    async_update: bool = False
    #: torch intra-op threads inside ``learn()`` (None: torch's setting); the class default serves files saved without
    torch_threads: int | None = DEFAULT_TORCH_THREADS
    #: the importance weights that read D's behaviour means (e.g. ``"retrace"``); ``"none"``: none does
    weighting: str = "none"
    replay_buffer: Any  # an EpisodicBuffer

    #: the env steps at which the running ``learn`` call stops
    _budget: int = 0
    #: per env, the steps since its last update (None before the first rollout of a ``learn`` that reset the envs)
    _episode_steps: np.ndarray | None = None
    #: the lengths of the episodes finished and not yet handed to ``train`` (None: no rollout collected them)
    _finished: list[int] | None = None
    #: the learner thread, inside an asynchronous ``learn``
    _learner: BackgroundLearner | None = None

    #: n of the policy checkpoints (module docstring): the most episodes that assess an actor; 0: none
    checkpoint_episodes: int = 0
    #: counts the changes of ``self.policy``'s networks (an update in place, a published update or snapshot,
    #: ``set_parameters``); an episode whose version is still the current one at its end was played by one actor
    _policy_version: int = 0
    #: the running assessment of the policy checkpoints (None: none yet, or ``checkpoint_episodes`` is 0)
    _assessment: Assessment | None = None

    # ----- what the subclass provides ------------------------------------------------------------------------------
    def _explore(self, observation: Any) -> tuple[np.ndarray, np.ndarray]:
        """The actions to play at ``observation`` (one row per env, in the scaled [-1, 1] space) and the behaviour
        means mu_b(s) that D stores with them."""
        raise NotImplementedError

    def _fit_all(self, policy: Any, data: Any, *plan: Any) -> Any:
        """The updates of ``policy`` on D's content ``data`` that ``plan`` (the arguments of :meth:`_run_updates`)
        describes, returning what :meth:`_record` takes. Reads nothing of the model but its settings: it may run on
        copies in the learner thread."""
        raise NotImplementedError

    def _record(self, fits: Any) -> None:
        """Count and log the updates :meth:`_fit_all` returned, in the model's thread."""
        raise NotImplementedError

    def _create_aliases(self) -> None:
        """Point the model's network attributes (``actor``, ``critic``) at ``self.policy``'s, after it changed."""
        raise NotImplementedError

    # ----- collection ----------------------------------------------------------------------------------------------
    def learn(
        self: SelfBaseAlgorithm,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 4,  # episodes, as SB3's off-policy algorithms (TD3, SAC): the zoo's default output
        tb_log_name: str | None = None,  # None: the algorithm's name (DENFAC, SoftDENFAC)
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfBaseAlgorithm:
        assert isinstance(self, EpisodicOffPolicyAlgorithm)
        # SB3's _setup_learn: total_timesteps counts on from num_timesteps unless reset_num_timesteps
        self._budget = total_timesteps if reset_num_timesteps else self.num_timesteps + total_timesteps
        if reset_num_timesteps or self._last_obs is None:  # SB3 resets the envs: new episodes
            # the updates an assessment held (checkpoint_episodes > 1) and a stopping callback left stay due
            self._episode_steps, self._finished = None, self._finished or None
            if self._assessment is not None:  # an assessment running goes on with the new episodes
                self._assessment.new_episodes()
        tb_log_name = type(self).__name__ if tb_log_name is None else tb_log_name
        arguments = (total_timesteps, callback, log_interval, tb_log_name, reset_num_timesteps, progress_bar)
        with torch_threads(self.torch_threads):
            if not self.async_update:
                return super().learn(*arguments)  # type: ignore[return-value]
            self._warn_async_with_several_envs()
            self._learner = BackgroundLearner()
            try:
                return super().learn(*arguments)  # type: ignore[return-value]
            finally:  # also on an exception (KeyboardInterrupt too): the running update is kept, no thread is left
                try:
                    self._publish(wait=True)
                finally:
                    self._learner.close()
                    self._learner = None

    def _warn_async_with_several_envs(self) -> None:
        """Warn, once per model, that the asynchronous update with more than 2 envs lost a seed where it was measured."""
        if self.n_envs <= ASYNC_ENVS_MEASURED or getattr(self, "_warned_async_envs", False):
            return
        self._warned_async_envs = True
        warnings.warn(
            f"async_update=True with {self.n_envs} envs: the episodes that end together get their updates in one job, "
            "which the next episodes play while it runs; on Reacher-v5 with 4 envs the actor still ran off to the "
            "action bounds in 1 of 3 seeds (-108 against -4 to -23 with the update in place), with up to "
            f"{ASYNC_ENVS_MEASURED} envs it held (research/several_envs/README.md). Compare with async_update=False, "
            "or use fewer envs",
            UserWarning,
            stacklevel=3,
        )

    def collect_rollouts(
        self,
        env: VecEnv,
        callback: BaseCallback,
        train_freq: TrainFreq,
        replay_buffer: Any,
        action_noise: ActionNoise | None = None,
        learning_starts: int = 0,
        log_interval: int | None = None,
    ) -> RolloutReturn:
        """SB3's collection loop, ended by an episode's end or the budget (module docstring). ``train_freq`` is always
        one episode, of each env; ``action_noise`` is not used: :meth:`_explore` explores."""
        self.policy.set_training_mode(False)
        if self._episode_steps is None or len(self._episode_steps) != env.num_envs:
            self._episode_steps = np.zeros(env.num_envs, dtype=np.int64)
        if self._finished is None:
            self._finished = []
        assert isinstance(self.action_space, spaces.Box)
        num_collected_steps, num_collected_episodes = 0, 0
        callback.on_rollout_start()
        while True:
            warm_up = self.num_timesteps < learning_starts
            if warm_up:
                buffer_actions, behaviour_means = warm_up_actions(self.policy, self.action_space, env.num_envs)
            else:
                buffer_actions, behaviour_means = self._explore(self._last_obs)
            actions = self.policy.unscale_action(buffer_actions)
            new_obs, rewards, dones, infos = env.step(actions)
            self.num_timesteps += env.num_envs
            num_collected_steps += 1
            callback.update_locals(locals())
            if not callback.on_step():  # as SB3: the step's transition is not stored
                self._assess_episodes(rewards, dones, warm_up)  # the episodes that end here start anew
                return RolloutReturn(num_collected_steps * env.num_envs, num_collected_episodes, continue_training=False)
            self._update_info_buffer(infos, dones)
            replay_buffer.stage_behaviour_means(behaviour_means, self.weighting)
            self._store_transition(replay_buffer, buffer_actions, new_obs, rewards, dones, infos)
            self._update_current_progress_remaining(self.num_timesteps, self._budget)
            self._on_step()
            budget_reached = self._budget_reached()
            assessing = self._assess_episodes(rewards, dones, warm_up)  # by the actor that played them
            self._publish(wait=False)  # an asynchronous update that has ended: the policy of the next step
            self._count_episode_steps(np.ones_like(dones) if budget_reached else dones)
            for done in dones:
                if done:
                    num_collected_episodes += 1
                    self._episode_num += 1
                    if log_interval is not None and self._episode_num % log_interval == 0:
                        self.dump_logs()
            if budget_reached or (np.any(dones) and not assessing):
                break
        callback.on_rollout_end()
        return RolloutReturn(num_collected_steps * env.num_envs, num_collected_episodes, continue_training=True)

    def _count_episode_steps(self, ended: np.ndarray) -> None:
        """One more step of every env's episode; the episodes ``ended`` (a done, or the budget) are finished, and due
        for an update once past ``learning_starts``."""
        assert self._episode_steps is not None and self._finished is not None
        self._episode_steps += 1
        if self.num_timesteps > self.learning_starts:
            self._finished.extend(int(n) for n in self._episode_steps[ended])
        self._episode_steps[ended] = 0

    def _budget_reached(self) -> bool:
        return self.num_timesteps >= self._budget

    def _finished_episodes(self, gradient_steps: int) -> list[int]:
        """The lengths of the episodes to update on now, one update each (often none with several envs). Outside a
        rollout (``train`` called directly) one episode of ``gradient_steps``."""
        if self._finished is None:
            return [gradient_steps]
        finished, self._finished = self._finished, []
        return finished

    # ----- policy checkpoints (module docstring) --------------------------------------------------------------------
    def _assess_episodes(self, rewards: np.ndarray, dones: np.ndarray, warm_up: bool) -> bool:
        """After an env step, before the policy may change: the episodes that end now (``dones``) assess the actor that
        played them whole (:class:`~sb3_denfac.common.checkpoints.Assessment`, with the env's own ``rewards``, before
        ``VecNormalize``), which the policy keeps if it is the best so far. Returns whether the actor's assessment goes
        on (the updates of the episodes that end wait for it)."""
        if self.checkpoint_episodes == 0:
            return False
        if self._assessment is None or self._assessment.episodes != self.checkpoint_episodes:
            self._assessment = Assessment(self.checkpoint_episodes)
        vec_normalize = self._vec_normalize_env
        if vec_normalize is not None:
            rewards = vec_normalize.get_original_reward()
        keep = self._assessment.step(rewards, dones, warm_up, self._policy_version, self.checkpoint_return)
        if keep is not None:
            self.policy.save_checkpoint(keep)
        if dones.any() and self.checkpoint_return is not None:  # a value is kept only at an episode's end
            self.logger.record("train/best_return", self.checkpoint_return)  # common/logging_keys.py
        return self._assessment.going_on(self._policy_version)

    @property
    def checkpoint_return(self) -> float | None:
        """The value of the kept actor (``checkpoint_episodes``): the best assessment so far; None before the first."""
        value = getattr(self.policy, "checkpoint_return", None)
        return None if value is None or not th.isfinite(value) else float(value)

    def set_parameters(self, *args: Any, **kwargs: Any) -> None:
        """SB3's; the networks loaded are another actor: the running episodes no longer assess one."""
        super().set_parameters(*args, **kwargs)
        self._policy_version += 1

    # ----- the update: in place, or on the learner thread ----------------------------------------------------------
    def _run_updates(self, *plan: Any) -> None:
        """The updates that ``plan`` describes (:meth:`_fit_all`'s arguments after the policy and the data): here, or
        inside an asynchronous ``learn`` on the learner thread (module docstring)."""
        if self._learner is None:
            self._record(self._fit_all(self.policy, self.replay_buffer.all_samples(env=self._vec_normalize_env), *plan))
            self._policy_version += 1
            return
        if self._learner.busy:  # the update still running: its updates not started are dropped (module docstring)
            self._learner.request_end()
        self._publish(wait=True)  # at most one in flight
        policy = copy.deepcopy(self.policy)
        data = self.replay_buffer.all_samples(env=self._vec_normalize_env)
        self._learner.submit(self._fit_in_background, policy, data, plan)
        if self._budget_reached():  # the last update of this learn(): published before learn() returns
            self._publish(wait=True)

    def _fit_in_background(self, policy: Any, data: Any, plan: tuple[Any, ...]) -> tuple[Any, Any]:
        return policy, self._fit_all(policy, data, *plan)

    def _offer_snapshot(self, policy: Any, flush: Callable[[], None] | None = None) -> None:
        """Between two fitted iterations of :meth:`_fit_all` on ``policy``: inside an asynchronous ``learn``, on the
        learner thread, a copy of ``policy`` as fitted so far (``flush`` first: what the fit keeps outside the modules
        written back into them) is handed to the env steps, which play it from the next one (module docstring).
        Anywhere else (the update in place) nothing: the update's arithmetic is the same either way."""
        learner = self._learner
        if learner is None or not learner.inside_job():
            return
        if flush is not None:
            flush()
        learner.offer(copy.deepcopy(policy))

    def _job_goes_on(self) -> bool:
        """Inside a job's updates past its first, after each fitted iteration: False inside an asynchronous ``learn``
        once the next episode has ended (the job ends there: module docstring); True anywhere else."""
        learner = self._learner
        return learner is None or not learner.inside_job() or not learner.end_requested()

    def _publish(self, wait: bool) -> None:
        """Make the learner's finished update (``wait``: or the running one, once it ends) the model's policy, and
        record it; else the newest snapshot the running update offered becomes the model's policy (not recorded);
        nothing if there is neither."""
        learner = self._learner
        if learner is None:
            return
        if learner.ready() or (wait and learner.busy):
            policy, fits = learner.result()
            self.policy = policy
            self._create_aliases()
            self._record(fits)
            self._policy_version += 1
            return
        snapshot = learner.take_offer()
        if snapshot is not None:
            snapshot.set_training_mode(False)
            self.policy = snapshot
            self._create_aliases()
            self._policy_version += 1

    def _excluded_save_params(self) -> list[str]:
        running = ["_budget", "_episode_steps", "_finished", "_learner", "_warned_async_envs", "_policy_version"]
        return [*super()._excluded_save_params(), *running, "_assessment"]
