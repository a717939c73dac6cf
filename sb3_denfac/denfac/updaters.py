"""The updater interface behind DENFAC's end-of-episode update, and its autograd implementation.

``DENFAC._update`` is Algorithm 1 written once; everything it does to the networks goes through an :class:`Updater`:

- ``actor(s)`` and ``critic(s, a)``: pi_{k-1} and Q_{k-1} in eval mode (running statistics), for the targets q_k and
  the importance weights c of eq. (4);
- ``reset_critic()`` and ``reset_actor()``: a random re-initialisation, with a fresh Adam state;
- ``fit_critic(s, a, q, c)``: ``critic_steps`` Adam steps on 1/N sum c_t (Q(s_t, a_t) - q_t)^2 (eq. 4);
- ``fit_actor(s)``: G Adam steps ascending 1/N sum Q(s_t, pi(s_t)) (eq. 5), with inverting gradients if asked;
- ``finish()``: once at the end, whatever the implementation keeps outside the modules is written back.

Two implementations compute the same update up to float rounding (tested): :class:`AutogradUpdater` (autograd on the
policy's modules and ``torch.optim.Adam``; the reference) and :class:`~sb3_denfac.denfac.fast.FastUpdater`
(hand-written steps on flat parameters).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import torch as th
from torch import nn
from torch.nn.utils import clip_grad_norm_

from sb3_denfac.common.inverting_gradients import inverting_gradient_actor_backward


@dataclass(frozen=True)
class FitSettings:
    """How the critic and the actor are fitted in every fitted iteration."""

    critic_steps: int  # Adam steps of the critic per fitted iteration
    actor_steps: int  # G, Adam steps of the actor per fitted iteration
    max_grad_norm: float | None  # clip each network's global gradient norm (None: no clipping)
    inverting_gradients: bool  # bound the unbounded actor with inverting gradients
    batch_size: int | None  # None: the whole buffer at every step; else one uniform mini-batch per step
    fresh_bn_statistics: bool  # reset the running statistics at the start of every fit (``bn_momentum=None``)


class Updater(ABC):
    """What Algorithm 1 does to the networks of a :class:`~sb3_denfac.denfac.policies.DENFACPolicy` (module docstring).

    Made anew for every update; the policy's modules and optimizers hold the whole state between updates.
    """

    def __init__(self, policy: nn.Module, settings: FitSettings):
        self.policy = policy
        self.settings = settings

    def batch_indices(self, n: int) -> th.Tensor | None:
        """Indices of one uniformly drawn mini-batch out of ``n`` samples, or None for the full batch."""
        size = self.settings.batch_size
        if size is None or size >= n:
            return None
        return th.randperm(n, device=self.policy.device)[:size]

    def sample_count(self, n: int) -> int:
        """Samples per step out of ``n``: the whole buffer, or the mini-batch that :meth:`batch_indices` draws."""
        size = self.settings.batch_size
        return n if size is None or size >= n else size

    def reset_critic(self) -> None:
        self.policy.reset_critic()

    def reset_actor(self) -> None:
        self.policy.reset_actor()

    def fresh_bn_statistics(self, net: nn.Module) -> bool:
        """With ``bn_momentum=None`` the running statistics are the cumulative average of this fit's steps: reset them."""
        if not self.settings.fresh_bn_statistics:
            return False
        for layer in net.modules():
            if isinstance(layer, nn.modules.batchnorm._BatchNorm):
                layer.reset_running_stats()
        return True

    @abstractmethod
    def actor(self, obs: th.Tensor) -> th.Tensor:
        """pi(s) in eval mode, shape (N, action_dim)."""

    @abstractmethod
    def critic(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """Q(s, a) in eval mode, shape (N, 1)."""

    @abstractmethod
    def fit_critic(self, obs: th.Tensor, actions: th.Tensor, q_targets: th.Tensor, weights: th.Tensor) -> th.Tensor:
        """``critic_steps`` Adam steps on 1/N sum c (Q(s, a) - q)^2; returns the last step's loss."""

    @abstractmethod
    def fit_actor(self, obs: th.Tensor) -> th.Tensor:
        """G Adam steps ascending 1/N sum Q(s, pi(s)) with the critic in eval mode; returns the last objective."""

    def finish(self) -> None:  # noqa: B027 (optional hook: the autograd updater keeps nothing outside the modules)
        """Called once after the K fitted iterations."""


class AutogradUpdater(Updater):
    """Autograd on the policy's modules, ``clip_grad_norm_`` and the modules' own ``torch.optim`` optimizers.

    Works with any policy (features extractors, optimizer classes); the reference the fast updater is tested and
    benchmarked against.
    """

    def actor(self, obs: th.Tensor) -> th.Tensor:
        self.policy.actor.set_training_mode(False)
        return self.policy.actor(obs)

    def critic(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
        self.policy.critic.set_training_mode(False)
        return self.policy.critic(obs, actions)

    def fit_critic(self, obs: th.Tensor, actions: th.Tensor, q_targets: th.Tensor, weights: th.Tensor) -> th.Tensor:
        critic, settings = self.policy.critic, self.settings
        self.fresh_bn_statistics(critic)
        critic.set_training_mode(True)
        loss = th.zeros(())
        for _ in range(settings.critic_steps):
            idx = self.batch_indices(obs.shape[0])
            o, a, q, c = (
                (obs, actions, q_targets, weights) if idx is None else (obs[idx], actions[idx], q_targets[idx], weights[idx])
            )
            loss = (c * (critic(o, a) - q).pow(2)).mean()
            critic.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if settings.max_grad_norm is not None:
                clip_grad_norm_(critic.parameters(), settings.max_grad_norm)
            critic.optimizer.step()
        critic.set_training_mode(False)
        return loss.detach()

    def fit_actor(self, obs: th.Tensor) -> th.Tensor:
        actor, critic, settings = self.policy.actor, self.policy.critic, self.settings
        objective = th.zeros(())
        if settings.actor_steps == 0:
            return objective
        self.fresh_bn_statistics(actor)
        actor.set_training_mode(True)
        critic.set_training_mode(False)  # ascend the fitted Q without touching its running statistics
        critic.requires_grad_(False)
        low, high = th.full((1,), -1.0, device=obs.device), th.full((1,), 1.0, device=obs.device)
        for _ in range(settings.actor_steps):
            idx = self.batch_indices(obs.shape[0])
            o = obs if idx is None else obs[idx]
            actor.optimizer.zero_grad(set_to_none=True)
            pi = actor(o)
            q = critic(o, pi)
            if settings.inverting_gradients:
                objective = inverting_gradient_actor_backward(q, pi, low, high)
            else:
                (-q.mean()).backward()
                objective = q.detach().mean()
            if settings.max_grad_norm is not None:
                clip_grad_norm_(actor.parameters(), settings.max_grad_norm)
            actor.optimizer.step()
        critic.requires_grad_(True)
        actor.set_training_mode(False)
        return objective.detach()
