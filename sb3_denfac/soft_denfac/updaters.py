"""SoftDENFAC's updaters: DENFAC's two implementations of Algorithm 1's update with SAC's actor step.

The critic's steps are DENFAC's (autograd, or the fast updater's flat ones); the actor and its temperature are fitted on
the policy's modules by autograd in both (:class:`SoftActorFit`), and the targets' next actions are sampled from the
actor (:meth:`SoftActorFit.sample_actor`).
"""

from __future__ import annotations

import torch as th
from torch import nn
from torch.nn.utils import clip_grad_norm_

from sb3_denfac.denfac.buffers import n_rows, take
from sb3_denfac.denfac.fast import FastUpdater
from sb3_denfac.denfac.options import anchor_scale
from sb3_denfac.denfac.update_paths import UpdaterClasses
from sb3_denfac.denfac.updaters import AutogradUpdater, FitSettings, Updater, frozen_copy


class SoftActorFit(Updater):
    """SAC's actor step in the fitted iterations (mixed in before an :class:`~sb3_denfac.denfac.updaters.Updater`)."""

    def __init__(self, policy: nn.Module, settings: FitSettings, *args, **kwargs):
        super().__init__(policy, settings, *args, **kwargs)  # type: ignore[call-arg]
        self.ent_coef_loss = th.zeros(())  # the last temperature loss (SAC's eq. 18)
        # the anchor's pi_old, the actor at the start of the update (the autograd updater has made it already)
        self.old_actor: nn.Module | None = getattr(self, "old_actor", None)
        if settings.actor_proximal > 0 and self.old_actor is None:
            self.old_actor = frozen_copy(policy.actor)

    @th.no_grad()
    def sample_actor(self, obs: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """a ~ pi(.|s) and log pi(a|s), shapes (N, A) and (N, 1), in eval mode."""
        actor = self.policy.actor
        actor.set_training_mode(False)
        actions, log_prob = actor.action_log_prob(obs)
        return actions, log_prob.unsqueeze(1)

    def fit_actor(self, obs: th.Tensor, batches: th.Tensor | None = None) -> th.Tensor:
        """G Adam steps of the actor on SAC's objective (Haarnoja et al. 2018, eq. 7), 1/B sum alpha log pi(a|s) -
        min_j Q_j(s, a) with a ~ pi(.|s) reparameterised (the critics in eval mode), each followed by one step of the
        tuned alpha (eq. 18, :meth:`~sb3_denfac.soft_denfac.policies.SoftDENFACPolicy.temperature_step`); no inverting
        gradients (tanh bounds the actions). With ``actor_proximal`` = lambda > 0 the proximal actor's anchor
        (:mod:`~sb3_denfac.denfac.options`) on the deterministic action: the objective divided by S = 1/B sum ||dQ/da_i||
        (detached) plus lambda 1/B sum ||tanh(m(s_i)) - tanh(m_old(s_i))||^2, m_old the actor's mean at the start of
        the update. Step i reads the rows ``batches[i]`` (None: one uniform mini-batch per step, or the full batch);
        returns the last objective, the negated loss (of SAC's objective, without the anchor)."""
        policy, settings = self.policy, self.settings
        actor, critic = policy.actor, policy.critic
        objective = th.zeros(())
        if settings.actor_steps == 0:
            return objective
        with th.enable_grad():
            actor.set_training_mode(True)
            critic.set_training_mode(False)
            critic.requires_grad_(False)
            for step in range(settings.actor_steps):
                idx = batches[step] if batches is not None else self.batch_indices(n_rows(obs))
                o = take(obs, idx)
                ent_coef = policy.entropy_coefficient()  # alpha before this step's temperature update, as SB3's SAC
                mean, log_std, _ = actor.get_action_dist_params(o)
                actions, log_prob = actor.action_dist.log_prob_from_params(mean, log_std)
                log_prob = log_prob.unsqueeze(1)
                q = critic.target_q(o, actions, "min")
                loss = (ent_coef * log_prob - q).mean()
                actor.optimizer.zero_grad(set_to_none=True)
                if self.old_actor is None:
                    loss.backward()
                else:
                    (grad,) = th.autograd.grad(q.sum(), actions, retain_graph=True)  # dQ/da_i per sample
                    scale = anchor_scale(grad)
                    with th.no_grad():
                        old_mean = self.old_actor(o)  # tanh(m_old(s)), the deterministic action
                    anchor = (th.tanh(mean) - old_mean).pow(2).sum(1).mean()
                    (loss / scale + settings.actor_proximal * anchor).backward()
                if settings.max_grad_norm is not None:
                    clip_grad_norm_(actor.parameters(), settings.max_grad_norm)
                actor.optimizer.step()
                self.ent_coef_loss = policy.temperature_step(log_prob)
                objective = -loss.detach()
            critic.requires_grad_(True)
            actor.set_training_mode(False)
        # SB3's distribution caches the last step's tensors, and with them its graph: dropped, so that the policy keeps
        # no graph between updates and can be copied (DENFAC's ``async_update`` fits a copy)
        actor.action_dist.distribution = actor.action_dist.gaussian_actions = None
        return objective


class SoftAutogradUpdater(SoftActorFit, AutogradUpdater):
    """DENFAC's autograd updater with SAC's actor step."""


class SoftFastUpdater(SoftActorFit, FastUpdater):
    """DENFAC's fast updater for the critic (the critic module's parameters are views of its flat ones, so the actor's
    autograd steps ascend the critic as fitted so far), SAC's actor step on autograd."""

    flat_actor = False


#: SoftDENFAC's updaters (its ``updater_classes``).
SOFT_UPDATERS = UpdaterClasses(plain=SoftAutogradUpdater, fast=SoftFastUpdater)
