"""DDPG as compared against in the paper: batch norm, truncated-Gaussian exploration, optional inverting gradients."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import torch as th
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, Schedule
from stable_baselines3.common.utils import polyak_update
from stable_baselines3.ddpg import DDPG as SB3DDPG
from torch.nn import functional as F

from sb3_denfac.common.budget import StopAtTotalTimestepsMixin
from sb3_denfac.common.callbacks import ProgressBarMixin
from sb3_denfac.common.checks import InputChecksMixin, check_gamma, check_learning_rate, check_number, check_sigma
from sb3_denfac.common.device import warn_about_device
from sb3_denfac.common.exploration import TruncatedGaussianExplorationMixin
from sb3_denfac.common.inverting_gradients import inverting_gradient_actor_backward
from sb3_denfac.common.learning_rates import ActorCriticRatesMixin
from sb3_denfac.common.networks import set_bn_training_mode
from sb3_denfac.common.threads import TorchThreadsMixin, check_torch_threads
from sb3_denfac.ddpg.policies import DDPGPolicy, MlpPolicy


class DDPG(
    InputChecksMixin,
    TorchThreadsMixin,
    ProgressBarMixin,
    StopAtTotalTimestepsMixin,
    ActorCriticRatesMixin,
    TruncatedGaussianExplorationMixin,
    SB3DDPG,
):
    """Deep Deterministic Policy Gradient (Lillicrap et al. 2016) in the configuration the DENFAC paper compares with.

    Paper: "Data-efficient Neural Fitted Actor-Critic" (Zimmer, Boniface, Dutech), sections 2 and 4, Figure 5: DDPG with
    batch normalization in actor and critic, leaky-ReLU networks (critic 50-7), N(0, 0.01^2) initial weights, the
    truncated Gaussian exploration N(mu(s), sigma^2) on [-1, 1] with sigma = 0.05 used by every algorithm of the paper,
    a tuned number of "additional updates" (``gradient_steps`` per environment step) and, "when it was better", the
    inverting-gradient strategy of Hausknecht & Stone (2016) with an unbounded (linear) actor instead of a tanh.

    With ``inverting_gradients=True`` the actor update back-propagates dQ/da scaled by the distance to the bound it
    pushes toward (sign reversed beyond it, :mod:`sb3_denfac.common.inverting_gradients`), which pulls out-of-bound
    outputs back; targets and executed actions use the actor output clamped to [-1, 1].

    Input checks (:class:`~sb3_denfac.common.checks.InputChecksMixin`): NaN/inf observations, rewards or actions raise
    a ValueError, ``load`` refuses corrupted zips and zips saved by another algorithm, and an action space that is not
    a Box with finite bounds raises an :class:`~sb3_denfac.common.checks.UnsupportedSpaceError` (a ValueError that is
    also SB3's AssertionError).

    Differences from SB3's DDPG: networks and exploration above; separate actor and critic learning rates (alpha_a,
    alpha_c); with ``batch_norm=False``, ``init="default"``, ``activation_fn=nn.ReLU``, a tanh actor and ``sigma=None`` it
    performs SB3's DDPG updates exactly (tested). As in SB3/TD3, batch-norm running statistics are copied to the target
    networks after every update. Unlike SB3's TD3/DDPG, the actor loss evaluates the critic with its batch-norm running
    statistics (eval mode): in training mode, BN on the critic's action input removes the batch-mean part of dQ/da, so
    the actor could not shift all its actions together (observed: it does not learn a constant best action).

    :param policy: policy class or "MlpPolicy" (:class:`sb3_denfac.ddpg.policies.DDPGPolicy`; policy_kwargs:
        ``net_arch=dict(pi=[...], qf=[50, 7])``, ``batch_norm``, ``init``, ``activation_fn``, ``tanh_output``)
    :param env: environment (Box action space) or its registered id
    :param learning_rate: the rate (float or schedule of the remaining progress) of each network whose own rate below
        is None (:mod:`~sb3_denfac.common.learning_rates`)
    :param actor_learning_rate: alpha_a, the actor's Adam step size (float or schedule); None means ``learning_rate``
    :param critic_learning_rate: alpha_c, the critic's Adam step size (float or schedule); None means ``learning_rate``
    :param buffer_size: replay buffer size (FIFO)
    :param learning_starts: environment steps with uniform random actions before learning starts (the paper has none)
    :param batch_size: minibatch size (paper: 64); must be >= 2 with batch norm
    :param tau: soft target update coefficient (paper: 0.001 Acrobot / Half-Cheetah, 0.1 Cartpole)
    :param gamma: discount factor
    :param train_freq: update every ``train_freq`` steps, or ``(n, "episode")``
    :param gradient_steps: gradient steps per rollout, the paper's "additional updates" (Figure 5: 8); -1 = as many as
        environment steps collected
    :param sigma: std of the truncated Gaussian exploration in the scaled [-1, 1] action space (paper: 0.05);
        None switches it off and uses SB3's ``action_noise`` (additive, clipped) instead
    :param inverting_gradients: use inverting gradients for the actor update; requires the unbounded actor
        (``tanh_output=False``, set automatically)
    :param action_noise: SB3 action noise; only allowed with ``sigma=None``
    :param replay_buffer_class: replay buffer class (default SB3's ReplayBuffer)
    :param replay_buffer_kwargs: its keyword arguments
    :param optimize_memory_usage: memory-efficient replay buffer variant
    :param n_steps: n-step returns (SB3's NStepReplayBuffer)
    :param tensorboard_log: TensorBoard log directory (the ``train/`` keys of :mod:`sb3_denfac.common.logging_keys`;
        with inverting gradients train/actor_loss is -mean Q, the inverted gradient having no scalar loss)
    :param policy_kwargs: keyword arguments of the policy
    :param verbose: verbosity level
    :param seed: random seed
    :param device: torch device
    :param torch_threads: torch threads inside ``learn()`` (default 1; None: leave torch's setting alone), restored
        after it (:mod:`~sb3_denfac.common.threads`)
    :param _init_setup_model: build the networks at construction
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"MlpPolicy": MlpPolicy}  # type: ignore[assignment]
    policy: DDPGPolicy

    def __init__(
        self,
        policy: str | type[DDPGPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 1e-3,
        actor_learning_rate: float | Schedule | None = None,
        critic_learning_rate: float | Schedule | None = None,
        buffer_size: int = 1_000_000,
        learning_starts: int = 100,
        batch_size: int = 64,
        tau: float = 0.005,
        gamma: float = 0.99,
        train_freq: int | tuple[int, str] = 1,
        gradient_steps: int = 1,
        sigma: float | None = 0.05,
        inverting_gradients: bool = False,
        action_noise: ActionNoise | None = None,
        replay_buffer_class: type[ReplayBuffer] | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        optimize_memory_usage: bool = False,
        n_steps: int = 1,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        torch_threads: int | None = 1,
        _init_setup_model: bool = True,
    ):
        super().__init__(
            policy=policy,
            env=env,
            learning_rate=learning_rate,
            buffer_size=buffer_size,
            learning_starts=learning_starts,
            batch_size=batch_size,
            tau=tau,
            gamma=gamma,
            train_freq=train_freq,
            gradient_steps=gradient_steps,
            action_noise=action_noise,
            replay_buffer_class=replay_buffer_class,
            replay_buffer_kwargs=replay_buffer_kwargs,
            optimize_memory_usage=optimize_memory_usage,
            n_steps=n_steps,
            tensorboard_log=tensorboard_log,
            policy_kwargs=dict(policy_kwargs or {}),  # copied: we add tanh_output below
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=False,
        )
        self.sigma = check_sigma(sigma, none_ok=True)
        self.torch_threads = check_torch_threads(torch_threads)
        self.learning_rate = check_learning_rate("learning_rate", learning_rate)
        self.actor_learning_rate = check_learning_rate("actor_learning_rate", actor_learning_rate)
        self.critic_learning_rate = check_learning_rate("critic_learning_rate", critic_learning_rate)
        self.inverting_gradients = bool(inverting_gradients)
        if self.sigma is not None and action_noise is not None:
            raise ValueError("action_noise is only used with sigma=None (sigma > 0 selects truncated Gaussian exploration)")
        check_number("tau", tau, minimum=0, exclusive_minimum=True, maximum=1)
        check_gamma(gamma)
        batch_norm = self.policy_kwargs.get("batch_norm", True)
        check_number("batch_size", batch_size, minimum=2 if batch_norm else 1, integer=True, note=" (batch norm needs 2)")
        if gradient_steps != -1:  # 0: collect without training, as SB3's DDPG/TD3
            check_number("gradient_steps", gradient_steps, minimum=0, integer=True, note=" (or -1: one per env step)")
        if issubclass(self.policy_class, DDPGPolicy):
            tanh_output = self.policy_kwargs.setdefault("tanh_output", not self.inverting_gradients)
            if self.inverting_gradients and tanh_output:
                raise ValueError("inverting_gradients=True needs an unbounded actor: do not set tanh_output=True")
        elif self.inverting_gradients:
            raise ValueError("inverting_gradients=True needs a DDPGPolicy (unbounded actor)")
        if _init_setup_model:
            self._setup_model()
            warn_about_device(type(self).__name__, device, self.device, self.policy)

    def _setup_model(self) -> None:
        super()._setup_model()
        self._setup_actor_critic_schedules()

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rates()
        low = th.tensor(-1.0, device=self.device)
        high = th.tensor(1.0, device=self.device)

        actor_losses, critic_losses, q_targets, out_of_bounds = [], [], [], []
        for _ in range(gradient_steps):
            self._n_updates += 1
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma

            with th.no_grad():
                # Executed actions are clamped, so the target uses the clamped target-actor output.
                next_actions = self.actor_target(replay_data.next_observations).clamp(-1.0, 1.0)
                next_q = th.cat(self.critic_target(replay_data.next_observations, next_actions), dim=1)
                next_q, _ = th.min(next_q, dim=1, keepdim=True)
                target_q = replay_data.rewards + (1 - replay_data.dones) * discounts * next_q
                q_targets.append(target_q.mean().item())

            current_q = self.critic(replay_data.observations, replay_data.actions)
            critic_loss = sum(F.mse_loss(q, target_q) for q in current_q)
            assert isinstance(critic_loss, th.Tensor)
            critic_losses.append(critic_loss.item())
            self.critic.optimizer.zero_grad()
            critic_loss.backward()
            self.critic.optimizer.step()

            # Actor: ascend Q(s, mu(s)); the critic's gradients are zeroed before its next step. The critic's batch
            # norm uses its running statistics here: with batch statistics, BN on the action input would cancel the
            # batch-mean component of dQ/da (the actor's bias would get no gradient) and policy actions would leak
            # into the running statistics.
            actions_pi = self.actor(replay_data.observations)
            set_bn_training_mode(self.critic, False)
            q_pi = self.critic.q1_forward(replay_data.observations, actions_pi)
            set_bn_training_mode(self.critic, True)
            self.actor.optimizer.zero_grad()
            if self.inverting_gradients:
                actor_loss = -inverting_gradient_actor_backward(q_pi, actions_pi, low, high)
            else:
                actor_loss = -q_pi.mean()
                actor_loss.backward()
            self.actor.optimizer.step()
            actor_losses.append(actor_loss.item())
            out_of_bounds.append((actions_pi.detach().abs() > 1.0).float().mean().item())

            polyak_update(self.critic.parameters(), self.critic_target.parameters(), self.tau)
            polyak_update(self.actor.parameters(), self.actor_target.parameters(), self.tau)
            # Batch-norm running statistics are buffers, not parameters: the target gets a hard copy (tau = 1), as in
            # SB3's TD3 and SAC; averaging running means and variances would not make sense
            # (https://github.com/DLR-RM/stable-baselines3/issues/996).
            polyak_update(self.critic_batch_norm_stats, self.critic_batch_norm_stats_target, 1.0)
            polyak_update(self.actor_batch_norm_stats, self.actor_batch_norm_stats_target, 1.0)

        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        if critic_losses:
            self.logger.record("train/critic_loss", float(np.mean(critic_losses)))
            self.logger.record("train/actor_loss", float(np.mean(actor_losses)))
            self.logger.record("train/q_target_mean", float(np.mean(q_targets)))
            self.logger.record("train/actor_out_of_bounds", float(np.mean(out_of_bounds)))
