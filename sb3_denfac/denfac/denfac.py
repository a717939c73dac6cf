"""DENFAC: Data Efficient Neural Fitted Actor Critic (paper section 3, Algorithm 1) as an SB3 off-policy algorithm."""

from __future__ import annotations

import time
from typing import Any, ClassVar

import numpy as np
import torch as th
from gymnasium import spaces
from sb3_contrib.common.torch_layers import BatchRenorm
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, Schedule

from sb3_denfac.common.callbacks import ProgressBarMixin
from sb3_denfac.common.checks import InputChecksMixin
from sb3_denfac.common.compat import denfac_attributes_of_old_files, record_policy_defaults, upgrade_denfac
from sb3_denfac.common.device import warn_about_device
from sb3_denfac.common.episodic import EpisodicOffPolicyAlgorithm
from sb3_denfac.common.exploration import behaviour_log_prob, truncated_gaussian_actions
from sb3_denfac.common.learning_rates import ActorCriticRatesMixin
from sb3_denfac.common.truncated_normal import clamp_mean
from sb3_denfac.denfac.buffers import BehaviourMeansBuffer, DENFACReplayBufferSamples, check_holds_one_episode, n_rows, take
from sb3_denfac.denfac.her import replay_buffer_class_for, take_goal_settings
from sb3_denfac.denfac.options import (
    FittedIterations,
    bootstrap_range,
    clip_bootstrap,
    fitted_iterations,
    importance_weights,
    target_actions,
)
from sb3_denfac.denfac.policies import DEFAULT_NET_ARCH, DENFACPolicy, MlpPolicy, MultiInputPolicy
from sb3_denfac.denfac.settings import check_checkpoint_episodes, store_settings, warn_ignored_settings
from sb3_denfac.denfac.update_paths import DENFAC_UPDATERS, UpdaterClasses, check_update_path, make_updater
from sb3_denfac.denfac.updaters import FitResult, FitSettings, Updater, UpdateStats


class DENFAC(InputChecksMixin, ProgressBarMixin, ActorCriticRatesMixin, EpisodicOffPolicyAlgorithm):
    """Data Efficient Neural Fitted Actor Critic (DENFAC).

    Zimmer, Boniface & Dutech, "Off-Policy Neural Fitted Actor-Critic", section 3, eqs. (4)-(5) and Algorithm 1;
    hyper-parameters from section 4 and Figure 5. At the end of every episode, K fitted iterations over the whole FIFO
    replay buffer D: targets q_t of eq. (4) from (Q_{k-1}, pi_{k-1}) with truncated importance weights c_t, a weighted
    regression of the critic on them, then G steps of the actor ascending eq. (5) (:meth:`_update`).

    ``DENFAC("MlpPolicy", env)`` is the library default (mini-batch Adam on a kept actor and critic, the proximal actor,
    two critics whose mean makes the targets, with TD3's target policy smoothing, 64-64 networks); ``DENFAC("MlpPolicy",
    env, **presets.PAPER)`` is Algorithm 1 as written (:mod:`~sb3_denfac.denfac.presets`). Why the default differs from
    the paper, and the implementation's choices (time limits, loss scale, batch norm, warm-up): docs/denfac.md.

    :param policy: the policy model ("MlpPolicy"; "MultiInputPolicy" for Dict observations, SB3's CombinedExtractor; or a
        :class:`DENFACPolicy` subclass)
    :param env: the environment, or a VecEnv of several: an update after each env's finished episode
        (:mod:`~sb3_denfac.common.episodic`)
    :param learning_rate: the rate (float or schedule) of each network whose own rate below is None
        (:mod:`~sb3_denfac.common.learning_rates`; paper, Figure 5: alpha_a = alpha_c = 0.1)
    :param actor_learning_rate: alpha_a, the actor's Adam step size (float or schedule); None means ``learning_rate``
    :param critic_learning_rate: alpha_c, the critic's Adam step size (float or schedule); None means ``learning_rate``
    :param buffer_size: D, size of the FIFO replay buffer (paper: 3000-6000)
    :param learning_starts: steps before the first update (uniform actions meanwhile; paper: 0)
    :param batch_size: an int = one uniform mini-batch of that size (drawn with replacement) per critic/actor step; None = full
        batch (paper)
    :param gamma: discount factor gamma (on a goal env with HER, not given: ``presets.GOALS``' 0.95; below)
    :param n_fitted_iterations: K, fitted iterations per update (paper: 10); with ``update_to_data_ratio``, the cap on K_e, or
        its range ``(K_min, K_max)`` (K_max None: no cap; None alone: ``(1, None)``)
    :param critic_steps: Adam steps of the critic per fitted iteration (authors: 10)
    :param actor_steps: G, Adam steps of the actor per fitted iteration (paper: 25)
    :param reset_critic: re-initialise the critic (and its Adam state) at every fitted iteration (paper: Acrobot yes)
    :param reset_actor: re-initialise the actor (and its Adam state) at every fitted iteration (Algorithm 1: yes)
    :param inverting_gradients: bound the unbounded actor with inverting gradients (Hausknecht & Stone 2016)
    :param weighting: "retrace" (c = min(1, pi_{k-1}(a|s)/pi_b(a|s))), "retrace_next_state_quirk" (the authors' code evaluates
        pi_{k-1} at s' instead of s) or "none" (c = 1)
    :param sigma: std of the truncated Gaussian exploration in the scaled action space (paper: 0.05)
    :param max_grad_norm: clip each network's global gradient L2 norm (authors: 10); None disables clipping
    :param bootstrap_on_timeout: bootstrap on time-limit truncations (True) or treat them as terminal (paper-era code)
    :param update_path: the :class:`~sb3_denfac.denfac.updaters.Updater` of Algorithm 1: "fast"
        (:class:`~sb3_denfac.denfac.fast.FastUpdater`: hand-written steps on flat parameters; vector observations or a Dict of
        1-D Boxes, the default MLP networks and Adam), "plain" (:class:`~sb3_denfac.denfac.updaters.AutogradUpdater`, any
        policy) or "auto" (default: "fast" where it applies). Both compute the same update up to float rounding (cost:
        ``benchmarks/results/update_cost/``). Models saved with the removed "compiled" path load with "fast". Prioritised
        sampling is autograd only: "auto" then picks "plain" and "fast" refuses it
    :param prioritized: mini-batches of D drawn by TD error (paper: future work; Schaul et al.; :mod:`~.options`): "none"
        (uniform, default), "critic" (the critic's; the actor's stay uniform) or "both"; or a dict ``on`` (one of those),
        ``alpha`` in p_i = (abs(delta_i) + eps)^alpha (0.6), ``beta`` in w_i = (N P(i))^-beta / max_j (N P(j))^-beta (0.4),
        ``eps`` (1e-3); needs an int ``batch_size``
    :param actor_proximal: lambda of the proximal actor (:mod:`~.options`): normalised eq. (5) plus lambda mean ||pi(s) -
        pi_old(s)||^2, pi_old = the actor before the update (default 1.0; paper: 0.0, eq. (5) as written)
    :param update_to_data_ratio: rho, the compute dial (:mod:`~.options`): the update after an episode of n steps runs K_e =
        min(K, ceil(rho n / critic_steps)) fitted iterations, about rho critic steps per env step, or within the range
        ``n_fitted_iterations=(K_min, K_max)``; None (default, the paper): K at every update, whatever the episode's length
    :param target_policy_noise: std of the Gaussian noise added to pi_{k-1}(s') in the targets of eq. (4) (TD3's target policy
        smoothing, in the scaled action space; default 0.2, TD3's; paper: 0, the deterministic next action)
    :param target_noise_clip: the noise of ``target_policy_noise`` is clipped to +-this (TD3: 0.5)
    :param critic_target: how the Q networks of ``n_critics`` > 1 make the bootstrap value of eq. (4): "mean" (default, their
        average) or "min" (clipped double Q, 0.4's default)
    :param bootstrap_bounds: clip eq. (4)'s bootstrap value to the range of discounted returns the rewards in D allow
        (:mod:`~.options`; default False, paper: no bound)
    :param frozen_targets: True (default, Algorithm 1): eq. (4)'s targets come from Q_{k-1}, computed once per fitted iteration
        and held for its ``critic_steps``; False: CrossQ's bootstrapping without a target network (Bhatt et al. 2024): every
        critic step computes Q(s, a) and Q(s', a') in one train-mode forward pass of the critic it fits (its batch statistics
        over both), the bootstrap value detached; a' is pi_{k-1}(s') as above, fixed over the iteration (the actor only moves
        after the critic's steps). Meant with ``policy_kwargs=dict(batch_renorm=True)`` (:class:`~.policies.DENFACCritic`); the
        autograd updater only
    :param reset_every: re-initialise the actor and the critic, with fresh Adam states, at the first update at or past every
        ``reset_every`` env steps, keeping D (periodic resets against the loss of plasticity at high update-to-data ratios:
        SR-SAC, D'Oro et al. 2023; BRO, Nauman et al. 2024); None (default): never
    :param checkpoint_episodes: n of TD7's policy checkpoints (:mod:`~sb3_denfac.common.checkpoints`): the actor best
        over up to n whole training episodes plays ``predict(deterministic=True)``. 0 (default, Algorithm 1): the
        current actor. Not with ``async_update``
    :param async_update: run each end-of-episode update on a learner thread, beside the next episode's env steps, which the
        last published policy plays (:mod:`~sb3_denfac.common.episodic`: what changes; default False: the update runs between
        episodes, reproducible from the seed)
    :param replay_buffer_class: D's class: None (:class:`~.buffers.DENFACReplayBuffer`, or
        :class:`~.buffers.DENFACDictReplayBuffer` for Dict observations), SB3's ``HerReplayBuffer`` (hindsight goals:
        :mod:`~.her`, with ``weighting="none"``) or a subclass of one of them. With HER on a goal env (a Dict observation with
        ``achieved_goal`` and ``desired_goal``), the settings not given take ``presets.GOALS``' values (gamma 0.95, the compute
        dial, no proximal anchor: why, in :mod:`~.presets`); the model's ``goal_settings_taken`` names them
    :param replay_buffer_kwargs: keyword arguments of the replay buffer
    :param stats_window_size: episodes averaged in the rollout logs
    :param tensorboard_log: TensorBoard log directory (None: no logging)
    :param policy_kwargs: ``net_arch`` (default ``dict(pi=[64, 64], qf=[64, 64])``; paper ``dict(pi=[20], qf=[50, 7])``),
        ``batch_norm`` (default False; paper True), ``init`` ("default": PyTorch's; "paper": N(0, 0.01^2)), ``n_critics``
        (default 2, whose mean or minimum makes the targets: ``critic_target``; paper 1), ``bn_momentum``, ``activation_fn``:
        :class:`DENFACPolicy`, whose defaults apply to the keys left out (and are saved with the model)
    :param verbose: verbosity level
    :param seed: random seed
    :param device: torch device
    :param torch_threads: torch threads inside ``learn()`` (default 1: tiny networks; None: leave torch's setting alone); the
        caller's setting is restored when ``learn()`` returns (:mod:`~sb3_denfac.common.threads`)
    :param _init_setup_model: whether to build the networks at construction
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"MlpPolicy": MlpPolicy, "MultiInputPolicy": MultiInputPolicy}
    #: the two implementations of the update that ``update_path`` picks from (:mod:`~.update_paths`); a subclass that
    #: fits its networks otherwise names its own (:class:`~sb3_denfac.soft_denfac.SoftDENFAC`)
    updater_classes: ClassVar[UpdaterClasses] = DENFAC_UPDATERS
    policy: DENFACPolicy
    replay_buffer: BehaviourMeansBuffer  # type: ignore[assignment]
    #: periodic resets made so far (``reset_every``)
    _resets_done: int = 0
    #: the last update's statistics (:class:`UpdateStats`), None before the first
    last_update: UpdateStats | None = None
    #: the last updates' statistics: the 2 n_envs last, at least all those since the previous env step (several envs'
    #: episodes that end together, and with ``async_update`` the update published with them)
    last_updates: list[UpdateStats] = []  # noqa: RUF012  (replaced, never mutated in place, by _record)

    def __init__(
        self,
        policy: str | type[DENFACPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 1e-3,
        actor_learning_rate: float | Schedule | None = None,
        critic_learning_rate: float | Schedule | None = None,
        buffer_size: int = 100_000,
        learning_starts: int = 0,
        batch_size: int | None = 256,
        gamma: float = 0.99,
        n_fitted_iterations: FittedIterations = 10,
        critic_steps: int = 50,
        actor_steps: int = 25,
        reset_critic: bool = False,
        reset_actor: bool = False,
        inverting_gradients: bool = True,
        weighting: str = "none",
        sigma: float = 0.1,
        max_grad_norm: float | None = 10.0,
        bootstrap_on_timeout: bool = True,
        update_path: str = "auto",
        prioritized: str | dict[str, Any] = "none",
        actor_proximal: float = 1.0,
        update_to_data_ratio: float | None = None,
        target_policy_noise: float = 0.2,
        target_noise_clip: float = 0.5,
        critic_target: str = "mean",
        bootstrap_bounds: bool = False,
        async_update: bool = False,
        frozen_targets: bool = True,
        reset_every: int | None = None,
        checkpoint_episodes: int = 0,
        replay_buffer_class: type[ReplayBuffer] | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        torch_threads: int | None = 1,
        _init_setup_model: bool = True,
    ):
        arguments = dict(locals())
        learning_rate = store_settings(self, arguments)  # every setting checked and stored, one place (settings.py)
        if not _init_setup_model:  # SB3's load: the attributes a file saved are written over these next
            denfac_attributes_of_old_files(self)
        super().__init__(
            policy,
            env,
            learning_rate,
            buffer_size,
            learning_starts,
            batch_size,  # type: ignore[arg-type]
            tau=1.0,  # no target networks in DENFAC
            gamma=gamma,
            train_freq=(1, "episode"),
            gradient_steps=-1,  # SB3 then passes train() the steps collected; one Algorithm 1 update per episode
            replay_buffer_class=replay_buffer_class,
            replay_buffer_kwargs=replay_buffer_kwargs,
            policy_kwargs=dict(policy_kwargs or {}),  # copied: the caller's dict is not modified
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=device,
            seed=seed,
            sde_support=False,
            support_multi_env=True,  # checked below with a clear message
        )
        check_holds_one_episode(self.env, self.buffer_size)
        record_policy_defaults(self.policy_kwargs, self.policy_class, DEFAULT_NET_ARCH)  # saved: the file says its networks
        if _init_setup_model:  # a goal env with HER: presets.GOALS for the settings not given (her.py)
            self.goal_settings_taken = take_goal_settings(self, arguments, store_settings)
            warn_ignored_settings(self)
            self._setup_model()
            warn_about_device(type(self).__name__, device, self.device, self.policy)

    def _setup_model(self) -> None:
        upgrade_denfac(self)  # a model loaded from a file of an earlier version: that version's settings
        self.replay_buffer_class = replay_buffer_class_for(self, self.replay_buffer_class)
        check_checkpoint_episodes(self.checkpoint_episodes, self.async_update)  # load may change either
        self.policy_kwargs.update(self._policy_settings())
        super()._setup_model()
        self._create_aliases()
        self._setup_actor_critic_schedules()
        check_update_path(self.update_path, FitSettings.of(self))  # "fast" with an option it does not implement

    def _policy_settings(self) -> dict[str, Any]:
        """The algorithm's settings its policy is built with (on top of ``policy_kwargs``): the exploration's sigma, and
        whether it keeps a checkpoint actor (``checkpoint_episodes``)."""
        return dict(sigma=self.sigma, checkpoints=self.checkpoint_episodes > 0)

    def _create_aliases(self) -> None:
        self.actor = self.policy.actor
        self.critic = self.policy.critic

    # ----- execution -----------------------------------------------------------------------------------------------
    def _explore(self, observation: Any) -> tuple[np.ndarray, np.ndarray]:
        """a ~ N(mu(s), sigma^2) truncated to [-1, 1] (paper, section 4); D stores mu_b(s) clamped to
        [-1 - 3 sigma, 1 + 3 sigma], as the authors' code."""
        assert isinstance(self.action_space, spaces.Box)
        actions, means = truncated_gaussian_actions(self.policy, self.action_space, observation, self.sigma)
        return actions, clamp_mean(means, -1.0, 1.0, self.sigma)

    # ----- Algorithm 1 ---------------------------------------------------------------------------------------------
    def train(self, gradient_steps: int, batch_size: int | None = None) -> None:
        """The updates of Algorithm 1 over the whole replay buffer due now: one per finished episode
        (:mod:`~sb3_denfac.common.episodic`; with one env ``gradient_steps`` is its length, SB3's
        ``gradient_steps=-1``), each with K_e fitted iterations from its length and ``update_to_data_ratio``."""
        lengths = self._finished_episodes(gradient_steps)
        if not lengths:
            return  # several envs: no episode ended at this step
        self._update_learning_rates()  # alpha_a and alpha_c at the current progress (ActorCriticRatesMixin)
        uses_batch_norm = any(isinstance(m, (th.nn.modules.batchnorm._BatchNorm, BatchRenorm)) for m in self.policy.modules())
        if uses_batch_norm and self.replay_buffer.size() < 2:
            return  # batch statistics of a single transition are undefined (a first episode of one step): wait
        k = self.n_fitted_iterations, self.critic_steps, self.update_to_data_ratio
        iterations = [fitted_iterations(*k, n) for n in lengths]
        self._run_updates(iterations, self._reset_due())  # here or on the learner thread (common/episodic.py)

    def _reset_due(self) -> bool:
        """Whether this update starts from re-initialised networks (``reset_every``): the first at or past each multiple
        of ``reset_every`` env steps; counts it."""
        if self.reset_every is None or self.num_timesteps < (self._resets_done + 1) * self.reset_every:
            return False
        self._resets_done = self.num_timesteps // self.reset_every
        return True

    def make_updater(self, policy: DENFACPolicy | None = None) -> Updater:
        """The next update's updater of ``policy`` (default: the model's): one of :attr:`updater_classes`, as
        ``update_path`` picks (:mod:`~.update_paths`)."""
        policy = self.policy if policy is None else policy
        return make_updater(policy, FitSettings.of(self), self.update_path, self.updater_classes).updater

    def _update(self, n_iterations: int | None = None) -> None:
        """One end-of-episode update now (in this thread, outside an asynchronous ``learn()``): Algorithm 1 with
        ``n_iterations`` (default K) fitted iterations over D."""
        if n_iterations is None:
            if not isinstance(self.n_fitted_iterations, int):
                raise ValueError("n_fitted_iterations is a range for update_to_data_ratio: pass _update the iterations")
            n_iterations = self.n_fitted_iterations
        self._run_updates([n_iterations], False)

    def _fit_all(self, policy: DENFACPolicy, data: DENFACReplayBufferSamples, iterations: list[int], reset: bool) -> list:
        """The updates of ``policy`` on D's content ``data``, back to back, ``iterations[i]`` fitted iterations each: a
        new updater for each, made after the previous one finished; with ``reset`` (``reset_every``), ``policy``'s actor
        and critic re-initialised first. An asynchronous job's updates past the first end at the fitted iteration after
        which the next episode has ended (``_job_goes_on``; the updates left are dropped)."""
        if reset:
            policy.reset_actor()
            policy.reset_critic()
        fits = [self._fit(self.make_updater(policy), data, iterations[0])]
        for n in iterations[1:]:
            if not self._job_goes_on():
                break
            fits.append(self._fit(self.make_updater(policy), data, n, may_end_early=True))
        return fits

    def _fit(
        self, updater: Updater, data: DENFACReplayBufferSamples, n_iterations: int, may_end_early: bool = False
    ) -> FitResult:
        """One end-of-episode update: Algorithm 1 with ``n_iterations`` fitted iterations over D (``data``, the
        buffer's content), on the networks of ``updater``. Reads nothing else of the model but its settings, so that it
        can run on copies in the learner thread (``async_update``); ``may_end_early``: a job's later update, which ends
        after the fitted iteration at which the next episode has ended (``_job_goes_on``)."""
        start = time.perf_counter()
        obs, actions, next_obs, rewards = data.observations, data.actions, data.next_observations, data.rewards
        terminal = data.dones if self.bootstrap_on_timeout else th.clamp(data.dones + data.timeouts, max=1.0)
        log_prob_b = behaviour_log_prob(actions, data.behaviour_means, self.sigma)  # type: ignore[arg-type]
        bounds = bootstrap_range(rewards, self.gamma) if self.bootstrap_bounds else None
        critic_loss = actor_objective = th.zeros(())
        redraw_goals = getattr(data, "redraw_goals", None)  # HER: new goals for the relabelled copies (her.py)
        for k in range(n_iterations):
            if redraw_goals is not None and k > 0:  # each fitted iteration its own goals; the rest of D as it is
                obs, next_obs, rewards = redraw_goals()
            # With mini-batches, the iteration's batches are drawn first: q_k and c are then needed on their rows only
            # (the same values as over all of D). ``rows`` None: the whole buffer.
            sample = updater.iteration_sample(n_rows(rewards))
            rows = None if sample is None else sample.critic_rows
            o, a, o2, r, done, lp_b = (take(x, rows) for x in (obs, actions, next_obs, rewards, terminal, log_prob_b))
            # Targets q_k and weights c from (Q_{k-1}, pi_{k-1}), before any reset (eval mode: running statistics).
            # With frozen_targets=False the joint critic steps make their own targets: q_k is then computed only where
            # it is read, the iteration that may be the update's last (logging, last_update) and prioritised sampling.
            with th.no_grad():
                discounts = self.gamma * (1.0 - done)
                # a' of eq. (4) (one draw per iteration, read by q_k and, with frozen_targets=False, by every joint
                # critic step, CrossQ's) and what the bootstrap value subtracts at it (SoftDENFAC: alpha log pi)
                next_actions, penalty = self._next_actions(updater, o2)
                if self.frozen_targets or may_end_early or k == n_iterations - 1 or self.prioritized != "none":
                    next_q, clipped = clip_bootstrap(updater.critic(o2, next_actions), bounds)
                    if penalty is not None:
                        next_q = next_q - penalty
                    q_targets = r + discounts * next_q
                    updater.set_priorities(o, a, q_targets)  # delta = q_k - Q_{k-1}(s, a) (``prioritized``)
                weights = importance_weights(self.weighting, updater.actor, o, o2, a, lp_b, self.sigma)
            if self.reset_critic:
                updater.reset_critic()
            batches = None if sample is None else sample.critic_batches
            if self.frozen_targets:
                critic_loss = updater.fit_critic(o, a, q_targets, weights, batches)
            else:  # CrossQ: each step bootstraps from the critic it fits, at the iteration's next actions
                critic_loss = updater.fit_critic_joint(o, a, o2, next_actions, r, discounts, weights, batches, bounds, penalty)
            if self.reset_actor:
                updater.reset_actor()
            if sample is None or sample.actor_rows is None:
                actor_objective = updater.fit_actor(obs)
            else:
                actor_objective = updater.fit_actor(take(obs, sample.actor_rows), sample.actor_batches)
            self._offer_snapshot(updater.policy, updater.finish)  # async_update: the update so far plays next
            if may_end_early and not self._job_goes_on():  # a job's later update, cut by the next episodes' end
                n_iterations = k + 1
                break
        updater.finish()
        seconds = time.perf_counter() - start
        n = n_rows(rewards)
        return FitResult(updater, n_iterations, seconds, q_targets, weights, rows, critic_loss, actor_objective, clipped, n)

    def _record(self, fits: list[FitResult]) -> None:
        """Count the updates ``fits`` (run back to back), keep their statistics (:attr:`last_update`,
        :attr:`last_updates`) and log them; in the model's thread."""
        kept = max(2 * self.n_envs, len(fits))  # all of these (held by an assessment: several with one env)
        for fit in fits:
            self._n_updates += 1
            stats = UpdateStats(self._n_updates, fit.fitted_iterations, fit.seconds, fit.q_targets, fit.weights, fit.rows)
            self.last_update = stats
            self.last_updates = [*self.last_updates, stats][-kept:]
            self._record_update(fit.updater, fit.critic_loss, fit.actor_objective, fit.clipped, fit.n_transitions)

    def _record_update(
        self, updater: Updater, critic_loss: th.Tensor, actor_objective: th.Tensor, clipped: th.Tensor, n: int
    ) -> None:
        """The update's logging keys (docs/conventions.md; :mod:`~sb3_denfac.common.logging_keys`)."""
        stats = self.last_update
        assert stats is not None
        weights = stats.weights
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/critic_loss", float(critic_loss))
        self.logger.record("train/actor_loss", -float(actor_objective))
        self.logger.record("train/q_target_mean", stats.q_targets.mean().item())
        self.logger.record("train/bootstrap_clip_fraction", clipped.item())
        self.logger.record("train/n_transitions", n)  # |D|
        self.logger.record("train/update_time", stats.seconds)
        self.logger.record("train/importance_weight_mean", weights.mean().item())
        self.logger.record("train/importance_weight_min", weights.min().item())
        self.logger.record("train/fitted_iterations", stats.fitted_iterations)

    def _next_actions(self, updater: Updater, next_obs: th.Tensor) -> tuple[th.Tensor, th.Tensor | None]:
        """The next actions a' of eq. (4)'s targets (:func:`~.options.target_actions`: pi_{k-1}(s') with TD3's target
        policy smoothing), and what the bootstrap value subtracts at them: nothing here (SoftDENFAC: alpha log pi(a'|s'))."""
        return target_actions(updater.actor(next_obs), self.target_policy_noise, self.target_noise_clip), None

    # ----- SB3 plumbing --------------------------------------------------------------------------------------------
    def _excluded_save_params(self) -> list[str]:
        # gradient_steps: always -1 (_setup_model); a saved -1 would make sb3-denfac <= 0.4.0 update once per step
        return [*super()._excluded_save_params(), "actor", "critic", "last_update", "last_updates", "gradient_steps"]

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        return ["policy", "actor.optimizer", "critic.optimizer"], []
