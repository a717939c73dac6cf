"""Neural Fitted Actor-Critic (NFAC), the on-policy batch baseline of the paper (section 2, [33]); "NFAC+" with batch norm."""

from __future__ import annotations

import time
from typing import Any, ClassVar, TypeVar

import torch as th
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from torch.nn import functional as F

from sb3_denfac.common.budget import budget_reached
from sb3_denfac.common.checks import check_positive
from sb3_denfac.common.device import warn_about_device
from sb3_denfac.common.on_policy import (
    DeterministicOnPolicyAlgorithm,
    Transitions,
    td_targets,
)
from sb3_denfac.nfac.policies import MlpPolicy, NFACPolicy

SelfNFAC = TypeVar("SelfNFAC", bound="NFAC")


class NFAC(DeterministicOnPolicyAlgorithm):
    """Neural Fitted Actor-Critic (Zimmer et al. 2016, ref. [33] of the paper; the authors' ``OfflineCaclaAg``).

    On-policy and offline: the data D is the last ``n_episodes`` episode(s) only ("the data is forgotten after each end
    of episode because the actor features on-policy update", section 2). At the end of each rollout:

    - critic, ``n_fitted_iterations`` (K) fitted rounds: y = r + gamma V(s') (y = r on true terminals), computed before
      the optional re-initialisation of V (``reset_critic``), then ``critic_steps`` full-batch Adam steps (rate alpha_c)
      on mean (V(s) - y)^2;
    - actor, CACLA-style: delta = r + gamma V(s') - V(s); the regression target of mu(s) is the executed action a where
      delta > 0, the behaviour mean mu_b(s) elsewhere if ``update_delta_neg`` (else those samples are dropped);
      ``actor_steps`` full-batch Adam steps (rate alpha_a) on mean ||mu(s) - target||^2.

    Exploration is the paper's truncated Gaussian N(mu(s), sigma^2) on the [-1, 1]-scaled action space. Episodes that
    end on a time limit are bootstrapped from V of their last observation; only true terminations give y = r.

    Batch norm ("NFAC+", policy_kwargs ``batch_norm=True``, the default) uses the same rule as CACLA+: every gradient
    step normalises with the running statistics (BN in eval mode), which are refreshed at the start of each update by a
    gradient-free train-mode forward of the states of D (momentum ``bn_momentum``; a new or re-initialised network,
    e.g. after ``reset_critic``, takes the statistics of D as they are). The function that is fitted is then exactly
    the one that computes the targets, the TD errors and the actions. (Train-mode BN on the batch of one short episode,
    and on the positive-delta subset for the actor, learns a function of batch-normalised inputs whose scale does not
    carry over to eval mode.)

    :param policy: policy class or "MlpPolicy" (:class:`~sb3_denfac.nfac.policies.NFACPolicy`).
    :param env: environment or its registered id, one or several: a rollout ends when ``n_episodes`` episodes have
        ended in all, and the episodes still running in the other environments enter the update as they are (their
        last transition bootstraps) and go on in the next rollout.
    :param learning_rate: the rate (float or schedule) of each network whose own rate below is None.
    :param actor_learning_rate: alpha_a, the actor's Adam step size (float or schedule); None means ``learning_rate``.
    :param critic_learning_rate: alpha_c, the critic's Adam step size (float or schedule); None means ``learning_rate``.
    :param n_episodes: episodes finished per update, over all environments (authors: 1).
    :param n_fitted_iterations: K, fitted rounds of the critic per update (authors' ``number_fitted_iteration``).
    :param critic_steps: full-batch Adam steps per fitted round (authors' ``stoch_iter``).
    :param actor_steps: full-batch Adam steps of the actor per update (authors' ``stoch_iter``).
    :param reset_critic: re-initialise V (and its Adam state) before each fitted round (authors' ``vnn_from_scratch``).
    :param update_delta_neg: where delta <= 0, regress mu(s) toward mu_b(s) instead of ignoring the sample.
    :param update_critic_first: fit the critic before the actor update (else the actor uses the previous critic).
    :param gamma: discount factor.
    :param sigma: exploration standard deviation in the scaled action space (paper: 0.05).
    :param max_grad_norm: global gradient-norm clip of every step (authors: 10); None disables it.
    :param stats_window_size: episodes averaged in the rollout/ logs.
    :param tensorboard_log: TensorBoard log directory (None: no logging).
    :param policy_kwargs: extra arguments of the policy (net_arch, batch_norm, bn_momentum, init, optimizer_kwargs...).
    :param verbose: 0 silent, 1 info, 2 debug.
    :param seed: random seed.
    :param device: torch device.
    :param torch_threads: torch threads inside ``learn()`` (default 1; None: leave torch's setting alone), restored
        after it (:mod:`~sb3_denfac.common.threads`).
    :param _init_setup_model: build the networks at construction.
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"MlpPolicy": MlpPolicy}
    policy: NFACPolicy

    def __init__(
        self,
        policy: str | type[NFACPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 1e-3,
        actor_learning_rate: float | Schedule | None = None,
        critic_learning_rate: float | Schedule | None = None,
        n_episodes: int = 1,
        n_fitted_iterations: int = 10,
        critic_steps: int = 10,
        actor_steps: int = 25,
        reset_critic: bool = False,
        update_delta_neg: bool = False,
        update_critic_first: bool = True,
        gamma: float = 0.99,
        sigma: float = 0.05,
        max_grad_norm: float | None = 10.0,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        torch_threads: int | None = 1,
        _init_setup_model: bool = True,
    ):
        for name, value in (
            ("n_episodes", n_episodes),
            ("n_fitted_iterations", n_fitted_iterations),
            ("critic_steps", critic_steps),
            ("actor_steps", actor_steps),
        ):
            check_positive(name, value, integer=True)
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            actor_learning_rate=actor_learning_rate,
            critic_learning_rate=critic_learning_rate,
            n_steps=1,  # unused: rollouts end with episodes
            gamma=gamma,
            sigma=sigma,
            max_grad_norm=max_grad_norm,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            policy_kwargs=policy_kwargs,
            verbose=verbose,
            seed=seed,
            device=device,
            torch_threads=torch_threads,
            _init_setup_model=False,
        )
        self.n_episodes = n_episodes
        self.n_fitted_iterations = n_fitted_iterations
        self.critic_steps = critic_steps
        self.actor_steps = actor_steps
        self.reset_critic = reset_critic
        self.update_delta_neg = update_delta_neg
        self.update_critic_first = update_critic_first
        if _init_setup_model:
            self._setup_model()
            warn_about_device(type(self).__name__, device, self.device, self.policy)

    def _rollout_done(self, n_steps: int, n_episodes: int, n_rollout_steps: int) -> bool:
        return n_episodes >= self.n_episodes or budget_reached(self)  # an unfinished episode is used as it is

    @th.no_grad()
    def _td_targets(self, data: Transitions) -> th.Tensor:
        next_values = self.policy.predict_values(data.next_observations).flatten()
        return td_targets(data.rewards, next_values, data.terminals, self.gamma)

    def fit_critic(self, data: Transitions) -> float:
        """K fitted rounds of V on y = r + gamma V_{k-1}(s'); returns the last loss."""
        loss = th.zeros(())
        for _ in range(self.n_fitted_iterations):
            targets = self._td_targets(data)  # computed before the optional reset, as the authors
            if self.reset_critic:
                self.policy.reset_critic()  # new weights, BN statistics and Adam state; same learning rate
                self.policy.refresh_bn_statistics(data.observations, exact_when_fresh=True, critic_only=True)
            for _ in range(self.critic_steps):
                loss = F.mse_loss(self.policy.predict_values(data.observations).flatten(), targets)
                self._gradient_step(loss, self.policy.critic.optimizer)
        return loss.item()

    def actor_targets(self, data: Transitions) -> tuple[th.Tensor, th.Tensor, float]:
        """CACLA selection: target a where delta = r + gamma V(s') - V(s) > 0, mu_b(s) elsewhere if ``update_delta_neg``.

        :return: (mask of the samples used, their regression targets, fraction of positive TD errors).
        """
        with th.no_grad():
            delta = self._td_targets(data) - self.policy.predict_values(data.observations).flatten()
        positive = delta > 0
        if self.update_delta_neg:
            mask = th.ones_like(positive)
            targets = th.where(positive.unsqueeze(-1), data.actions, data.behaviour_means)
        else:
            mask, targets = positive, data.actions[positive]
        return mask, targets, positive.float().mean().item()

    def update_actor(self, data: Transitions) -> tuple[float, float]:
        """``actor_steps`` full-batch Adam steps of mu(s) toward the CACLA targets; returns (loss, positive fraction)."""
        mask, targets, positive_fraction = self.actor_targets(data)
        loss = float("nan")
        if len(targets) > 0:
            observations = data.observations[mask]
            for _ in range(self.actor_steps):
                actor_loss = F.mse_loss(self.policy.actor_mean(observations), targets)
                self._gradient_step(actor_loss, self.policy.actor.optimizer)
            loss = actor_loss.item()
        return loss, positive_fraction

    def train(self) -> None:
        """One NFAC update on the collected episode(s)."""
        start = time.perf_counter()
        self._update_learning_rates()
        data = self.rollout_buffer.get(self.device)
        self.policy.set_training_mode(False)  # gradient steps with BN in eval mode, see the class docstring
        self.policy.refresh_bn_statistics(data.observations, exact_when_fresh=True)
        if self.update_critic_first:
            critic_loss = self.fit_critic(data)
            actor_loss, positive_fraction = self.update_actor(data)
        else:
            actor_loss, positive_fraction = self.update_actor(data)
            critic_loss = self.fit_critic(data)
        self._n_updates += 1
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/critic_loss", critic_loss)
        if actor_loss == actor_loss:  # not NaN: the actor was updated
            self.logger.record("train/actor_loss", actor_loss)
        self.logger.record("train/positive_td_fraction", positive_fraction)
        self.logger.record("train/n_transitions", len(data.rewards))
        self.logger.record("train/update_time", time.perf_counter() - start)

    def learn(
        self: SelfNFAC,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 4,
        tb_log_name: str = "NFAC",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfNFAC:
        """Train for ``total_timesteps`` steps; ``log_interval`` counts updates. An episode still running at
        ``total_timesteps`` ends the rollout there: the update uses it as it is (its last transition bootstraps), and the
        next ``learn(reset_num_timesteps=False)`` continues it."""
        return super().learn(
            total_timesteps=total_timesteps,
            callback=callback,
            log_interval=log_interval,
            tb_log_name=tb_log_name,
            reset_num_timesteps=reset_num_timesteps,
            progress_bar=progress_bar,
        )
