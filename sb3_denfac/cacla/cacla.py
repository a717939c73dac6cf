"""Continuous Actor Critic Learning Automaton (CACLA), the online baseline of the paper (section 2, [30]); "CACLA+" with
batch norm."""

from __future__ import annotations

import time
from collections import deque
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from torch.nn import functional as F

from sb3_denfac.cacla.policies import CACLAPolicy, MlpPolicy
from sb3_denfac.common.checks import check_number, check_positive
from sb3_denfac.common.device import warn_about_device
from sb3_denfac.common.on_policy import (
    DeterministicOnPolicyAlgorithm,
    Transitions,
    td_targets,
)

SelfCACLA = TypeVar("SelfCACLA", bound="CACLA")


class CACLA(DeterministicOnPolicyAlgorithm):
    """Continuous Actor Critic Learning Automaton (van Hasselt & Wiering 2007, ref. [30] of the paper; the authors'
    ``BaseCaclaAg``).

    Online and on-policy: after every environment step, with y = r + gamma V(s') (y = r on true terminals) and
    V_old(s) the value before the update,

    - critic: one Adam step (rate alpha_c) on (V(s) - y)^2;
    - actor: if delta = y - V_old(s) > 0, one Adam step (rate alpha_a) on ||mu(s) - a||^2, a the executed action.

    With several environments, each step updates on the batch of their transitions. Exploration is the paper's truncated
    Gaussian N(mu(s), sigma^2) on the [-1, 1]-scaled action space.

    Batch norm ("CACLA+", policy_kwargs ``batch_norm=True``, the default) with single-transition updates uses this rule:
    the gradient steps normalise with the running statistics (BN in eval mode), so a batch of one is well defined and the
    function being trained is exactly the one that acts and is evaluated; the running statistics are refreshed before
    every update by a gradient-free, train-mode forward of actor and critic on the states of the last ``bn_window`` steps
    (PyTorch momentum ``bn_momentum``). The affine BN parameters are learned by the gradient steps as usual.
    ``batch_norm=False`` in policy_kwargs gives plain CACLA.

    :param policy: policy class or "MlpPolicy" (:class:`~sb3_denfac.cacla.policies.CACLAPolicy`).
    :param env: environment or its registered id (one or several environments).
    :param learning_rate: the rate (float or schedule) of each network whose own rate below is None.
    :param actor_learning_rate: alpha_a, the actor's Adam step size (float or schedule); None means ``learning_rate``.
    :param critic_learning_rate: alpha_c, the critic's Adam step size (float or schedule); None means ``learning_rate``.
    :param n_steps: steps per environment per rollout: the logging period (learning is per step).
    :param gamma: discount factor.
    :param sigma: exploration standard deviation in the scaled action space (paper: 0.05).
    :param bn_window: number of recent steps whose states refresh the batch-norm running statistics (>= 2).
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
    policy: CACLAPolicy
    _learns_online: ClassVar[bool] = True

    def __init__(
        self,
        policy: str | type[CACLAPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 1e-3,
        actor_learning_rate: float | Schedule | None = None,
        critic_learning_rate: float | Schedule | None = None,
        n_steps: int = 100,
        gamma: float = 0.99,
        sigma: float = 0.05,
        bn_window: int = 32,
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
        check_positive("n_steps", n_steps, integer=True)
        check_number("bn_window", bn_window, minimum=2, integer=True, note=" (batch statistics of one sample are undefined)")
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            actor_learning_rate=actor_learning_rate,
            critic_learning_rate=critic_learning_rate,
            n_steps=n_steps,
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
        self.bn_window = bn_window
        if _init_setup_model:
            self._setup_model()
            warn_about_device(type(self).__name__, device, self.device, self.policy)

    def _setup_model(self) -> None:
        super()._setup_model()
        # States of the last bn_window steps (numpy, saved with the model so that a resumed run continues exactly)
        self._bn_states: deque[np.ndarray] = deque(getattr(self, "_bn_states", ()), maxlen=self.bn_window)
        self._batch_norm = any(isinstance(m, th.nn.modules.batchnorm._BatchNorm) for m in self.policy.modules())
        self._reset_step_stats()

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_step_stats"]

    def _reset_step_stats(self) -> None:
        self._step_stats: dict[str, list[float]] = {"critic_loss": [], "actor_loss": [], "positive": [], "time": []}

    def _rollout_done(self, n_steps: int, n_episodes: int, n_rollout_steps: int) -> bool:
        return n_steps >= n_rollout_steps

    def refresh_bn_statistics(self) -> None:
        """Move the running statistics of every BN layer toward those of the states of the last ``bn_window`` steps."""
        states = th.as_tensor(np.concatenate(self._bn_states), device=self.device)
        self.policy.refresh_bn_statistics(states)

    def _on_step_transition(self, transitions: Transitions) -> None:
        """One CACLA update on the transition(s) of the last step (BN in eval mode, see the class docstring)."""
        start = time.perf_counter()
        self.policy.set_training_mode(False)
        if self._batch_norm:
            self._bn_states.append(transitions.observations.cpu().numpy())
            self.refresh_bn_statistics()
        with th.no_grad():
            next_values = self.policy.predict_values(transitions.next_observations).flatten()
            targets = td_targets(transitions.rewards, next_values, transitions.terminals, self.gamma)
        values = self.policy.predict_values(transitions.observations).flatten()
        positive = (targets - values.detach()) > 0  # delta computed with V_old, before the critic step
        critic_loss = F.mse_loss(values, targets)
        self._gradient_step(critic_loss, self.policy.critic.optimizer)
        self._step_stats["critic_loss"].append(critic_loss.item())
        self._step_stats["positive"].append(positive.float().mean().item())
        if positive.any():
            means = self.policy.actor_mean(transitions.observations[positive])
            actor_loss = F.mse_loss(means, transitions.actions[positive])
            self._gradient_step(actor_loss, self.policy.actor.optimizer)
            self._step_stats["actor_loss"].append(actor_loss.item())
        self._step_stats["time"].append(time.perf_counter() - start)

    def train(self) -> None:
        """Learning happens online during the rollout; log its statistics and apply the learning-rate schedules."""
        stats = self._step_stats
        self._n_updates += len(stats["time"])
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        if stats["critic_loss"]:
            self.logger.record("train/critic_loss", float(np.mean(stats["critic_loss"])))
            self.logger.record("train/positive_td_fraction", float(np.mean(stats["positive"])))
            self.logger.record("train/update_time", float(np.sum(stats["time"])))
        if stats["actor_loss"]:
            self.logger.record("train/actor_loss", float(np.mean(stats["actor_loss"])))
        self._reset_step_stats()
        self._update_learning_rates()

    def learn(
        self: SelfCACLA,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,  # rollouts of n_steps (its logging period), as SB3's on-policy algorithms
        tb_log_name: str = "CACLA",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfCACLA:
        """Train for at least ``total_timesteps`` steps (whole rollouts of ``n_steps``); ``log_interval`` counts rollouts."""
        return super().learn(
            total_timesteps=total_timesteps,
            callback=callback,
            log_interval=log_interval,
            tb_log_name=tb_log_name,
            reset_num_timesteps=reset_num_timesteps,
            progress_bar=progress_bar,
        )
