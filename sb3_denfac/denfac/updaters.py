"""The updater interface behind DENFAC's end-of-episode update, and its autograd implementation.

``DENFAC._fit`` is Algorithm 1 written once; everything it does to the networks goes through an :class:`Updater`:

- ``actor(s)`` and ``critic(s, a)``: pi_{k-1} and Q_{k-1} in eval mode (running statistics), for the targets q_k and
  the importance weights c of eq. (4); with ``n_critics`` > 1 Q_{k-1} is the minimum over the critics (clipped double
  Q, :class:`~sb3_denfac.denfac.policies.DENFACCritic`) or their mean (``critic_target``);
- ``set_priorities(s, a, q)``: with ``prioritized`` on, the TD errors q_k - Q_{k-1}(s, a) of the buffer, before any
  reset, set the sampling priorities of the iteration's mini-batches (:mod:`~sb3_denfac.denfac.options`);
- ``reset_critic()`` and ``reset_actor()``: a random re-initialisation, with a fresh Adam state;
- ``iteration_sample(n)``: with mini-batches, the iteration's critic and actor mini-batches, drawn first, so that the
  targets are computed on the rows they read only (None: full batch, or prioritised sampling);
- ``fit_critic(s, a, q, c, batches)``: ``critic_steps`` Adam steps on 1/N sum c_t (Q(s_t, a_t) - q_t)^2 (eq. 4), for
  each Q network, on the same mini-batches (``batches``, or drawn by the updater);
- ``fit_critic_joint(s, a, s', a', r, g, c, batches, bounds, p)``: with ``frozen_targets=False``, the same steps, each
  bootstrapping from the critic it fits: q = r + g clip(Q(s', a')) from one train-mode forward pass of (s, a) and
  (s', a') together, detached (CrossQ); the autograd updater only;
- ``fit_actor(s, batches)``: G Adam steps ascending 1/N sum Q_1(s_t, pi(s_t)) (eq. 5), with inverting gradients if asked
  (with ``actor_proximal`` > 0: the proximal loss towards the actor at the start of the update, :mod:`~.options`);
  :class:`~sb3_denfac.soft_denfac.SoftDENFAC`'s updaters fit SAC's actor and temperature instead;
- ``finish()``: at the end, whatever the implementation keeps outside the modules is written back (idempotent: the
  asynchronous update also calls it before each snapshot between fitted iterations, and its arithmetic goes on
  unchanged).

Two implementations compute the same update up to float rounding (tested): :class:`AutogradUpdater` (autograd on the
policy's modules and ``torch.optim.Adam``; the reference) and :class:`~sb3_denfac.denfac.fast.FastUpdater`
(hand-written steps on flat parameters). Of the options of :mod:`~sb3_denfac.denfac.options`, both implement the
proximal actor and several critics (``n_critics``); prioritised sampling exists in the autograd updater only.
:func:`~sb3_denfac.denfac.update_paths.make_updater` is the one place that picks between them (DENFAC's
``update_path``).
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import torch as th
from torch import nn
from torch.nn.utils import clip_grad_norm_

from sb3_denfac.common.inverting_gradients import inverting_gradient_actor_backward
from sb3_denfac.denfac.buffers import n_rows, stack_rows, take
from sb3_denfac.denfac.options import PrioritisedSampler, clip_bootstrap, proximal_actor_backward


@dataclass(frozen=True)
class FitSettings:
    """How the critic and the actor are fitted in every fitted iteration: the algorithm's settings, read by
    :meth:`of` (no defaults of its own: DENFAC's signature is their one home)."""

    critic_steps: int  # Adam steps of the critic per fitted iteration
    actor_steps: int  # G, Adam steps of the actor per fitted iteration
    max_grad_norm: float | None  # clip each network's global gradient norm (None: no clipping)
    inverting_gradients: bool  # bound the unbounded actor with inverting gradients
    batch_size: int | None  # None: the whole buffer at every step; else one uniform mini-batch per step
    fresh_bn_statistics: bool  # reset the running statistics at the start of every fit (``bn_momentum=None``)
    prioritized: str  # "none" (uniform), "critic" or "both": mini-batches drawn by TD error (options.py)
    priority_alpha: float  # p_i = (|delta_i| + eps)^alpha
    priority_beta: float  # w_i = (N P(i))^-beta / max_j (N P(j))^-beta
    priority_eps: float
    actor_proximal: float  # lambda of the proximal actor loss (0: plain ascent of eq. 5)
    critic_target: str  # how several Q networks make the bootstrap value: "min" or "mean" (combine_critics)
    frozen_targets: bool  # False: every critic step bootstraps from the critic it fits (fit_critic_joint)

    @staticmethod
    def of(model: Any) -> FitSettings:
        """The settings of a :class:`~sb3_denfac.denfac.denfac.DENFAC` (its constructor arguments)."""
        return FitSettings(
            critic_steps=model.critic_steps,
            actor_steps=model.actor_steps,
            max_grad_norm=model.max_grad_norm,
            inverting_gradients=model.inverting_gradients,
            batch_size=model.batch_size,
            fresh_bn_statistics=model.policy.bn_momentum is None,
            prioritized=model.prioritized,
            priority_alpha=model.priority_alpha,
            priority_beta=model.priority_beta,
            priority_eps=model.priority_eps,
            actor_proximal=model.actor_proximal,
            critic_target=model.critic_target,
            frozen_targets=model.frozen_targets,
        )


@dataclass(frozen=True)
class UpdateStats:
    """What the last end-of-episode update did (``DENFAC.last_update``; None before the first): its number, K_e, its
    wall time, and the last fitted iteration's targets q_k and weights c of eq. (4) on the rows of D they were computed
    for (``rows`` None: all of D, in D's order)."""

    n_updates: int
    fitted_iterations: int
    seconds: float
    q_targets: th.Tensor
    weights: th.Tensor
    rows: th.Tensor | None


class FitResult(NamedTuple):
    """One update's outcome, as ``DENFAC._fit`` returns it, for ``DENFAC._record`` (the logging keys, :class:`UpdateStats`)."""

    updater: Updater
    fitted_iterations: int
    seconds: float
    q_targets: th.Tensor
    weights: th.Tensor
    rows: th.Tensor | None
    critic_loss: th.Tensor
    actor_objective: th.Tensor
    clipped: th.Tensor
    n_transitions: int


class IterationSample(NamedTuple):
    """What one fitted iteration reads of D: the rows of its critic steps and of its actor steps (transition indices,
    in draw order), and each step's mini-batch as indices into those rows, shape (steps, batch_size)."""

    critic_rows: th.Tensor
    critic_batches: th.Tensor
    actor_rows: th.Tensor | None  # None: no actor step
    actor_batches: th.Tensor | None


class Updater(ABC):
    """What Algorithm 1 does to the networks of a :class:`~sb3_denfac.denfac.policies.DENFACPolicy` (module docstring).

    Made anew for every update; the policy's modules and optimizers hold the whole state between updates.
    """

    def __init__(self, policy: nn.Module, settings: FitSettings):
        self.policy = policy
        self.settings = settings

    def batch_indices(self, n: int) -> th.Tensor | None:
        """Indices of one uniformly drawn mini-batch out of ``n`` samples (with replacement, as SB3's replay buffers
        sample), or None for the full batch."""
        size = self.settings.batch_size
        if size is None or size >= n:
            return None
        return th.randint(n, (size,), device=self.policy.device)

    def iteration_sample(self, n: int) -> IterationSample | None:
        """The mini-batches of one fitted iteration over a buffer of ``n`` transitions, drawn uniformly with replacement
        (as SB3's replay buffers sample) before its targets, so that q_k and c are computed on the rows they read only;
        None: every step reads the whole buffer (full batch) or draws its own mini-batch (prioritised sampling, whose
        priorities need the TD errors of the whole buffer)."""
        settings = self.settings
        if settings.prioritized != "none" or settings.batch_size is None or settings.batch_size >= n:
            return None
        device, size = self.policy.device, settings.batch_size

        def draw(steps: int) -> tuple[th.Tensor, th.Tensor]:
            # the rows in draw order (a row drawn twice is read twice); step i reads rows[i * size:(i + 1) * size]
            rows = th.randint(n, (steps * size,), device=device)
            return rows, th.arange(steps * size, device=device).view(steps, size)

        critic_rows, critic_batches = draw(settings.critic_steps)
        actor_rows, actor_batches = draw(settings.actor_steps) if settings.actor_steps > 0 else (None, None)
        return IterationSample(critic_rows, critic_batches, actor_rows, actor_batches)

    def sample_count(self, n: int) -> int:
        """Samples per step out of ``n``: the whole buffer, or the mini-batch that :meth:`batch_indices` draws."""
        size = self.settings.batch_size
        return n if size is None or size >= n else size

    def set_priorities(self, obs: th.Tensor, actions: th.Tensor, q_targets: th.Tensor) -> None:  # noqa: B027
        """The TD errors q - Q_{k-1}(s, a) of this fitted iteration set its sampling priorities (``prioritized``);
        called before any reset. Uniform sampling (the default) needs nothing."""

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
        """Q(s, a) in eval mode, shape (N, 1): the Q networks combined by ``critic_target`` (the paper's one network)."""

    @abstractmethod
    def fit_critic(
        self, obs: th.Tensor, actions: th.Tensor, q_targets: th.Tensor, weights: th.Tensor, batches: th.Tensor | None = None
    ) -> th.Tensor:
        """``critic_steps`` Adam steps on 1/N sum c (Q(s, a) - q)^2, step i on the rows ``batches[i]`` (None: the full
        batch, or mini-batches it draws itself); returns the last step's loss."""

    def fit_critic_joint(
        self,
        obs: th.Tensor,
        actions: th.Tensor,
        next_obs: th.Tensor,
        next_actions: th.Tensor,
        rewards: th.Tensor,
        discounts: th.Tensor,
        weights: th.Tensor,
        batches: th.Tensor | None,
        bounds: tuple[float, float] | None,
        next_penalty: th.Tensor | None = None,
    ) -> th.Tensor:
        """``critic_steps`` Adam steps on 1/N sum c (Q(s, a) - q)^2 with q = r + g (clip(Q(s', a')) - p) recomputed at
        every step by the critic being fitted (``frozen_targets=False``), ``discounts`` g = gamma (1 - d), p the
        ``next_penalty`` at a' (SoftDENFAC's alpha log pi(a'|s'); None: 0); returns the last step's loss."""
        raise NotImplementedError(f"{type(self).__name__} does not implement frozen_targets=False")

    @abstractmethod
    def fit_actor(self, obs: th.Tensor, batches: th.Tensor | None = None) -> th.Tensor:
        """G Adam steps ascending 1/N sum Q(s, pi(s)) with the critic in eval mode, step i on the rows ``batches[i]``
        (as :meth:`fit_critic`); returns the last objective."""

    def finish(self) -> None:  # noqa: B027 (optional hook: the autograd updater keeps nothing outside the modules)
        """Called after the K fitted iterations, and before each snapshot of the asynchronous update (idempotent)."""


def frozen_copy(actor: nn.Module) -> nn.Module:
    """A copy of ``actor`` as it is now, frozen in eval mode (its running statistics) and without an optimiser: the
    proximal actor's pi_old (:mod:`~.options`)."""
    old = copy.deepcopy(actor)
    old.optimizer = None
    old.set_training_mode(False)
    old.requires_grad_(False)
    return old


class AutogradUpdater(Updater):
    """Autograd on the policy's modules, ``clip_grad_norm_`` and the modules' own ``torch.optim`` optimizers.

    Works with any policy (features extractors, optimizer classes); the reference the fast updater is tested and
    benchmarked against. Implements the options of :mod:`~sb3_denfac.denfac.options`: prioritised mini-batches
    (``prioritized``, after :meth:`set_priorities`) and the proximal actor (``actor_proximal``, towards a frozen copy
    of the actor made here, i.e. at the start of the update).
    """

    def __init__(self, policy: nn.Module, settings: FitSettings):
        super().__init__(policy, settings)
        self.sampler: PrioritisedSampler | None = None
        # gradient-norm groups of the critic: Q_1 with any features extractor, then each twin Q network
        twins = [list(q_net.parameters()) for q_net in policy.critic.q_networks[1:]]
        twin_ids = {id(p) for group in twins for p in group}
        self.clip_groups = [[p for p in policy.critic.parameters() if id(p) not in twin_ids], *twins]
        # pi_old: the actor at the start of the update
        self.old_actor = frozen_copy(policy.actor) if settings.actor_proximal > 0 else None

    def actor(self, obs: th.Tensor) -> th.Tensor:
        self.policy.actor.set_training_mode(False)
        return self.policy.actor(obs)

    def critic(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
        self.policy.critic.set_training_mode(False)
        return self.policy.critic.target_q(obs, actions, self.settings.critic_target)

    def set_priorities(self, obs: th.Tensor, actions: th.Tensor, q_targets: th.Tensor) -> None:
        settings = self.settings
        if settings.prioritized == "none":
            return
        assert settings.batch_size is not None  # checked by DENFAC: prioritised sampling draws mini-batches
        with th.no_grad():
            self.policy.critic.set_training_mode(False)
            td_errors = q_targets - self.policy.critic(obs, actions)  # delta of Q_1, the critic the actor ascends
        self.sampler = PrioritisedSampler(
            td_errors, settings.priority_alpha, settings.priority_beta, settings.priority_eps, settings.batch_size
        )

    def draw(self, n: int, prioritised: bool) -> tuple[th.Tensor | None, th.Tensor | None]:
        """One step's mini-batch indices (None: full batch) and weights w (None: uniform sampling)."""
        if prioritised and self.sampler is not None:
            return self.sampler.batch()
        return self.batch_indices(n), None

    def fit_critic(
        self, obs: th.Tensor, actions: th.Tensor, q_targets: th.Tensor, weights: th.Tensor, batches: th.Tensor | None = None
    ) -> th.Tensor:
        settings = self.settings

        def losses(step: int) -> list[th.Tensor]:
            idx, w = (batches[step], None) if batches is not None else self.draw(n_rows(obs), settings.prioritized != "none")
            o, a, q, c = (
                (obs, actions, q_targets, weights)
                if idx is None
                else (take(obs, idx), actions[idx], q_targets[idx], weights[idx])
            )
            errors = [c * (q_value - q).pow(2) for q_value in self.policy.critic.all_q(o, a)]  # each Q network, same rows
            return [(e if w is None else w * e).mean() for e in errors]

        return self._critic_steps(losses)

    def fit_critic_joint(
        self,
        obs: th.Tensor,
        actions: th.Tensor,
        next_obs: th.Tensor,
        next_actions: th.Tensor,
        rewards: th.Tensor,
        discounts: th.Tensor,
        weights: th.Tensor,
        batches: th.Tensor | None,
        bounds: tuple[float, float] | None,
        next_penalty: th.Tensor | None = None,
    ) -> th.Tensor:
        critic = self.policy.critic

        def losses(step: int) -> list[th.Tensor]:
            idx = batches[step] if batches is not None else self.batch_indices(n_rows(obs))
            o, a, o2, a2 = take(obs, idx), take(actions, idx), take(next_obs, idx), take(next_actions, idx)
            r, g, c = take(rewards, idx), take(discounts, idx), take(weights, idx)
            n = n_rows(o)
            # one forward pass of (s, a) and (s', a') together: the batch statistics of both (CrossQ)
            values = critic.all_q(stack_rows(o, o2), th.cat([a, a2]))
            with th.no_grad():
                next_q, _ = clip_bootstrap(critic.combine([v[n:] for v in values], self.settings.critic_target), bounds)
                if next_penalty is not None:
                    next_q = next_q - take(next_penalty, idx)
                q = r + g * next_q
            return [(c * (v[:n] - q).pow(2)).mean() for v in values]

        return self._critic_steps(losses)

    def _critic_steps(self, step_losses: Callable[[int], list[th.Tensor]]) -> th.Tensor:
        """``critic_steps`` Adam steps of the critic in training mode, step i on the sum of ``step_losses(i)`` (one
        loss per Q network), each Q network's gradient clipped to its own norm as if it were alone; returns the last
        step's loss of Q_1."""
        critic, settings = self.policy.critic, self.settings
        self.fresh_bn_statistics(critic)
        critic.set_training_mode(True)
        loss = th.zeros(())
        for step in range(settings.critic_steps):
            critic.optimizer.zero_grad(set_to_none=True)
            losses = step_losses(step)
            sum(losses).backward()
            if settings.max_grad_norm is not None:
                for group in self.clip_groups:
                    clip_grad_norm_(group, settings.max_grad_norm)
            critic.optimizer.step()
            loss = losses[0]
        critic.set_training_mode(False)
        return loss.detach()

    def fit_actor(self, obs: th.Tensor, batches: th.Tensor | None = None) -> th.Tensor:
        actor, critic, settings = self.policy.actor, self.policy.critic, self.settings
        objective = th.zeros(())
        if settings.actor_steps == 0:
            return objective
        self.fresh_bn_statistics(actor)
        actor.set_training_mode(True)
        critic.set_training_mode(False)  # ascend the fitted Q without touching its running statistics
        critic.requires_grad_(False)
        low, high = th.full((1,), -1.0, device=self.policy.device), th.full((1,), 1.0, device=self.policy.device)
        for step in range(settings.actor_steps):
            idx, w = (batches[step], None) if batches is not None else self.draw(n_rows(obs), settings.prioritized == "both")
            o = take(obs, idx)
            actor.optimizer.zero_grad(set_to_none=True)
            pi = actor(o)
            q = critic(o, pi) if w is None else w * critic(o, pi)
            if self.old_actor is not None:
                with th.no_grad():
                    old_pi = self.old_actor(o)
                objective = proximal_actor_backward(q, pi, old_pi, settings.actor_proximal, settings.inverting_gradients)
            elif settings.inverting_gradients:
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
