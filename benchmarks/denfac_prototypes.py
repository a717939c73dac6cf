"""Prototypes of the paper's future work (issue #12), as DENFAC subclasses with a plain-autograd ``_update``.

NOT library code: the lead ports what works into the library's updater interface. Every option defaults to "off",
in which case :class:`PlainDENFAC` computes DENFAC's own update (Algorithm 1 with the constructor's knobs) in plain
autograd; only weighting "none"/"retrace" and mini-batches (``batch_size`` int) are supported here.

Per end-of-episode update, with D the buffer (N transitions), for k = 1..K:

    y_i   = r_i + gamma (1 - done_i) Qtarget(s'_i, clip(pi_{k-1}(s'_i)))      frozen for the iteration
    critic: ``critic_steps`` Adam steps on  sum_{i in B} w_i c_i (Q(s_i, a_i) - y_i)^2 / |B|
    actor : ``actor_steps``  Adam steps on  -sum_{i in B'} v_i Q(s_i, pi(s_i)) / |B'|  (+ proximal term)

Options (constructor keywords on top of DENFAC's):

- ``prox_coef`` = lambda > 0 (slower policy change, proximal): pi_old = the actor at the start of the update (the
  end-of-episode update, i.e. before fitted iteration 1). The actor minimises
      L(theta) = - mean_B Q(s, pi(s)) / S + lambda mean_B ||pi(s) - pi_old(s)||^2,
  S = mean_B |Q(s, pi(s))| (detached, as TD3+BC) so lambda is free of the reward scale; the Q part keeps the inverting
  gradients when ``inverting_gradients`` (dQ/da inverted, then divided by S). ``prox_norm="grad"`` uses instead
  S = mean_B ||dQ/da(s, pi(s))||_2 (after inversion), so the Q term has unit action-gradient per sample and the
  per-update equilibrium action change is about 1/(2 lambda) in the scaled [-1, 1] space, whatever the reward scale.
- ``trust_region`` = eps > 0 (step-size control across fitted iterations): after the actor steps of each fitted
  iteration, m = sqrt(mean_D ||pi(s) - pi_old(s)||^2 / action_dim) (RMS change of the action per dimension, over the
  whole buffer, in the scaled [-1, 1] space). If m > eps the actor parameters are pulled back on the segment
  theta <- theta_old + beta (theta - theta_old), beta halved from 1 until m <= eps (at most 8 halvings, then
  theta_old). pi_old is the actor at the start of the update, so the bound is per update (episode).
- ``clipped_double_q``: a second critic Q2 (own init and Adam), both fitted to
  y = r + gamma (1-done) min(Q1, Q2)(s', pi(s')); the actor ascends Q1 (TD3's clipped double-Q without target nets).
- ``target_norm`` (Pop-Art, van Hasselt et al. 2016): the critic's net f outputs normalised values, Q = sigma_y f + mu_y.
  At each fitted iteration mu_y, sigma_y = mean, std of the new targets over D; the last linear layer is rescaled
  (W <- W sigma_old / sigma_new, b <- (sigma_old b + mu_old - mu_new) / sigma_new) so Q is unchanged, then f is fitted
  to (y - mu_y) / sigma_y. The actor ascends Q (gradient scaled by sigma_y, which Adam ignores).
- :class:`PrioritisedDENFAC` (``critic_per``, ``actor_per``, ``per_alpha``, ``per_beta``, ``per_eps``): at every fitted
  iteration the TD errors of the whole buffer delta_i = y_i - Q(s_i, a_i) are recomputed exactly (DENFAC recomputes
  all targets anyway, so priorities are never stale), p_i = (|delta_i| + per_eps)^alpha, P(i) = p_i / sum_j p_j;
  minibatches are drawn from P with replacement and weighted by w_i = (N P(i))^-beta / max_j (N P(j))^-beta.
  ``critic_per`` applies it to the critic's mini-batches (w in the loss), ``actor_per`` to the actor's (v = w in the
  objective; the priorities are the critic's TD errors at the start of the iteration).
- ``retention="td"`` (:class:`PrioritisedDENFAC`): once D is full, a new transition overwrites the stored transition
  of lowest |delta| (of the last update) instead of the oldest; new transitions get priority +inf until an update
  has measured them; the most recent episode is always kept.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch as th
from torch.nn.utils import clip_grad_norm_

from sb3_denfac import DENFAC
from sb3_denfac.common.exploration import behaviour_log_prob
from sb3_denfac.common.inverting_gradients import invert_gradients
from sb3_denfac.common.truncated_normal import truncated_importance_weights
from sb3_denfac.denfac.buffers import DENFACReplayBuffer


class PlainDENFAC(DENFAC):
    def __init__(
        self,
        *args: Any,
        prox_coef: float = 0.0,
        prox_norm: str = "q",
        trust_region: float = 0.0,
        clipped_double_q: bool = False,
        target_norm: bool = False,
        **kwargs: Any,
    ):
        self.prox_coef = prox_coef
        self.prox_norm = prox_norm
        self.trust_region = trust_region
        self.clipped_double_q = clipped_double_q
        self.target_norm = target_norm
        super().__init__(*args, update_path="plain", **kwargs)

    def _setup_model(self) -> None:
        super()._setup_model()
        self.critic2 = None
        if self.clipped_double_q:
            self.critic2 = copy.deepcopy(self.critic)
            for m in self.critic2.modules():
                if hasattr(m, "reset_parameters") and m is not self.critic2:
                    m.reset_parameters()
            self.critic2.optimizer = th.optim.Adam(
                self.critic2.parameters(),
                lr=self.critic.optimizer.param_groups[0]["lr"],
                betas=self.adam_betas,
                eps=self.adam_eps,
            )
        self.pop_mu, self.pop_sigma = 0.0, 1.0

    # ---- helpers ----
    def _q(self, critic, obs, act):
        out = critic(obs, act)
        return self.pop_sigma * out + self.pop_mu if self.target_norm else out

    def _last_linear(self, critic):
        return [m for m in critic.modules() if isinstance(m, th.nn.Linear)][-1]

    def _popart_rescale(self, mu_new: float, sigma_new: float) -> None:
        for critic in [self.critic] + ([self.critic2] if self.critic2 is not None else []):
            lin = self._last_linear(critic)
            with th.no_grad():
                lin.weight.mul_(self.pop_sigma / sigma_new)
                lin.bias.mul_(self.pop_sigma).add_(self.pop_mu - mu_new).div_(sigma_new)
        self.pop_mu, self.pop_sigma = mu_new, sigma_new

    def _sample(self, n: int, size: int, probs: np.ndarray | None):
        if probs is None:
            if self.batch_size is None or self.batch_size >= n:
                return None, None
            return th.from_numpy(np.random.randint(0, n, size=size)), None
        idx = np.random.choice(n, size=size, p=probs)
        w = (n * probs[idx]) ** (-self.per_beta)
        w = w / ((n * probs.min()) ** (-self.per_beta))  # max_j w_j is at the least likely transition
        return th.from_numpy(idx), th.as_tensor(w, dtype=th.float32).unsqueeze(1)

    def _reset_bn_statistics(self, net) -> None:
        """With ``bn_momentum=None`` the running statistics are those of this fit only (the library's updaters do the
        same in ``Updater.fresh_bn_statistics``)."""
        if self.policy.bn_momentum is None:
            for layer in net.modules():
                if isinstance(layer, th.nn.modules.batchnorm._BatchNorm):
                    layer.reset_running_stats()

    def _fit_critic_plain(self, critic, obs, actions, y, c, probs):
        opt = critic.optimizer
        critic.set_training_mode(True)
        n = obs.shape[0]
        loss = th.zeros(())
        for _ in range(self.critic_steps):
            idx, w = self._sample(n, self.batch_size or n, probs)
            o, a, q, cc = (obs, actions, y, c) if idx is None else (obs[idx], actions[idx], y[idx], c[idx])
            pred = critic(o, a)
            target = (q - self.pop_mu) / self.pop_sigma if self.target_norm else q
            err = cc * (pred - target).pow(2)
            if w is not None:
                err = err * w
            loss = err.mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            if self.max_grad_norm is not None:
                clip_grad_norm_(critic.parameters(), self.max_grad_norm)
            opt.step()
        critic.set_training_mode(False)
        return loss.detach()

    def _fit_actor_plain(self, obs, probs, actor_old):
        actor, critic, opt = self.actor, self.critic, self.actor.optimizer
        actor.set_training_mode(True)
        critic.set_training_mode(False)
        critic.requires_grad_(False)
        n = obs.shape[0]
        for _ in range(self.actor_steps):
            idx, w = self._sample(n, self.batch_size or n, probs)
            o = obs if idx is None else obs[idx]
            opt.zero_grad(set_to_none=True)
            pi = actor(o)
            q = self._q(critic, o, pi)
            weights = w if w is not None else th.ones_like(q)
            (dq,) = th.autograd.grad((weights * q).mean(), pi)
            if self.inverting_gradients:
                dq = invert_gradients(dq, pi.detach(), th.full_like(pi, -1.0), th.full_like(pi, 1.0))
            if self.prox_coef > 0:
                if self.prox_norm == "grad":  # per-sample action-gradient norm: equilibrium step ~ 1/(2 lambda)
                    scale = (dq.norm(dim=1).mean() * dq.shape[0]).clamp(min=1e-12)
                else:
                    scale = q.detach().abs().mean().clamp(min=1e-6)
                with th.no_grad():
                    pi_old = actor_old(o)
                loss = -(pi * dq.detach()).sum() / scale + self.prox_coef * (pi - pi_old).pow(2).sum(1).mean()
            else:
                loss = -(pi * dq.detach()).sum()
            loss.backward()
            if self.max_grad_norm is not None:
                clip_grad_norm_(actor.parameters(), self.max_grad_norm)
            opt.step()
        critic.requires_grad_(True)
        actor.set_training_mode(False)

    def _trust_region_project(self, obs, actor_old) -> float:
        actor = self.actor
        params_old = [p.detach().clone() for p in actor_old.parameters()]
        params_new = [p.detach().clone() for p in actor.parameters()]
        with th.no_grad():
            ref = actor_old(obs)
            beta = 1.0
            for _ in range(9):
                for p, po, pn in zip(actor.parameters(), params_old, params_new, strict=True):
                    p.copy_(po + beta * (pn - po))
                m = float(((actor(obs) - ref).pow(2).mean()).sqrt())
                if m <= self.trust_region:
                    return beta
                beta *= 0.5
            for p, po in zip(actor.parameters(), params_old, strict=True):
                p.copy_(po)
        return 0.0

    def _update(self) -> None:
        data = self.replay_buffer.all_samples(env=self._vec_normalize_env)
        obs, actions, next_obs, rewards = data.observations, data.actions, data.next_observations, data.rewards
        terminal = data.dones if self.bootstrap_on_timeout else th.clamp(data.dones + data.timeouts, max=1.0)
        low, high = th.full_like(actions, -1.0), th.full_like(actions, 1.0)
        self.policy.set_training_mode(False)
        actor_old = copy.deepcopy(self.actor)
        actor_old.set_training_mode(False)
        betas = []
        td = None
        for _ in range(self.n_fitted_iterations):
            with th.no_grad():
                na = self.actor(next_obs).clamp(-1.0, 1.0)
                qn = self._q(self.critic, next_obs, na)
                if self.critic2 is not None:
                    qn = th.min(qn, self._q(self.critic2, next_obs, na))
                y = rewards + self.gamma * (1.0 - terminal) * qn
                if self.weighting == "none":
                    c = th.ones_like(rewards)
                else:
                    lpb = behaviour_log_prob(actions, data.behaviour_means, self.sigma)
                    lpt = self._target_log_prob(actions, self.actor(obs), low, high)
                    c = truncated_importance_weights(lpt, lpb).unsqueeze(1)
                if self.target_norm:
                    self._popart_rescale(float(y.mean()), max(float(y.std()), 1e-3))
                td = (y - self._q(self.critic, obs, actions)).squeeze(1)
            probs_c, probs_a = self._priorities(td)
            if self.reset_critic:
                self.policy.reset_critic()
            self._reset_bn_statistics(self.critic)
            self._fit_critic_plain(self.critic, obs, actions, y, c, probs_c)
            if self.critic2 is not None:
                self._fit_critic_plain(self.critic2, obs, actions, y, c, probs_c)
            if self.reset_actor:
                self.policy.reset_actor()
            self._reset_bn_statistics(self.actor)
            if self.actor_steps > 0:
                self._fit_actor_plain(obs, probs_a, actor_old)
            if self.trust_region > 0:
                betas.append(self._trust_region_project(obs, actor_old))
        self._after_update(td)
        self._n_updates += 1
        self._last_update_stats = dict(weights=c, q_targets=y, tr_beta=betas)

    def _after_update(self, td) -> None:
        pass

    def _priorities(self, td):  # type: ignore[override]
        return None, None


class TDRetentionBuffer(DENFACReplayBuffer):
    """FIFO until full; then a new transition overwrites the lowest-priority one outside the protected recent set."""

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.priority = np.full(self.buffer_size, np.inf)
        self.protect = 0  # number of most recent writes that may not be evicted (one episode)
        self.recent: list[int] = []

    def add(self, obs, next_obs, action, reward, done, infos, behaviour_means=None):  # type: ignore[override]
        if self.full:
            pr = self.priority.copy()
            pr[self.recent] = np.inf
            self.pos = int(np.argmin(pr))
        slot = self.pos
        super().add(obs, next_obs, action, reward, done, infos, behaviour_means)
        self.priority[slot] = np.inf
        self.recent.append(slot)
        if len(self.recent) > max(self.protect, 1):
            self.recent.pop(0)


class PrioritisedDENFAC(PlainDENFAC):
    def __init__(
        self,
        *args: Any,
        critic_per: bool = True,
        actor_per: bool = False,
        per_alpha: float = 0.6,
        per_beta: float = 0.4,
        per_eps: float = 1e-3,
        retention: str = "fifo",
        **kwargs: Any,
    ):
        self.critic_per, self.actor_per = critic_per, actor_per
        self.per_alpha, self.per_beta, self.per_eps = per_alpha, per_beta, per_eps
        self.retention = retention
        if retention == "td":
            kwargs["replay_buffer_class"] = TDRetentionBuffer
        super().__init__(*args, **kwargs)
        if retention == "td":
            spec = getattr(self.env.get_attr("spec")[0], "max_episode_steps", None)
            self.replay_buffer.protect = int(spec or 1000)

    def _priorities(self, td):  # type: ignore[override]
        p = (td.abs().numpy().astype(np.float64) + self.per_eps) ** self.per_alpha
        probs = p / p.sum()
        return (probs if self.critic_per else None), (probs if self.actor_per else None)

    def _after_update(self, td) -> None:
        if self.retention == "td" and td is not None:
            n = td.shape[0]
            self.replay_buffer.priority[:n] = td.abs().numpy()
