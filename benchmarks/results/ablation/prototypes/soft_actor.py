"""Prototype, not in the library (ablation README, section 23): SAC's actor inside DENFAC's episode-end fitted
iterations.

Sections 12-22 changed the deterministic actor's step or its noise one ingredient at a time. Here the whole actor is
SAC's (Haarnoja et al. 2018, "Soft Actor-Critic Algorithms and Applications", eqs. 7, 11 and 18), and everything else is
the 0.5 default's: K = 10 fitted iterations at every episode end, each with its targets frozen for 50 critic steps and
followed by 25 actor steps, mini-batches of 256 from D, two 64-64 Q networks whose mean makes the targets, leaky ReLU,
Adam at 1e-3, gradient norms clipped at 10.

- The actor: a 64-64 leaky-ReLU trunk with two linear heads, the mean m(s) and log std l(s) (clamped to [-20, 2], as
  SB3's SAC), and a = tanh(m(s) + exp(l(s)) eps), eps ~ N(0, I) (tanh bounds the action: no inverting gradients).
  Its deterministic action (``predict(deterministic=True)``, the evaluations) is tanh(m(s)).
- The episodes are played with a sampled a (no truncated Gaussian of sigma; ``learning_starts`` as the default's, 0).
- Each actor step minimises 1/B sum alpha log pi(a_i|s_i) - Q(s_i, a_i) with a_i reparameterised (eq. 7 of SAC;
  Q = Q_1, the critic DENFAC's actor ascends, or ``SA_Q=min`` / ``mean`` of the two), with no proximal term and no
  normalisation of the gradient; then one Adam step of log alpha on -log alpha (log pi + target entropy) (eq. 18;
  target entropy -dim(A), ``SA_ENTROPY=k`` for -k dim(A); alpha starts at 1, SB3's ``ent_coef="auto"``).
- The targets of eq. (4) are soft, q = r + gamma (1 - d) (Qbar(s', a') - alpha log pi(a'|s')), a' ~ pi(.|s') drawn
  anew at every fitted iteration (in place of TD3's smoothing noise), with Qbar the two critics' mean (the default's
  ``critic_target``); with ``bootstrap_bounds`` (``abl:default05+bounds``) Qbar is clipped to the bounds of
  ``sb3_denfac.denfac.options`` before the entropy term.

The critic's steps are the library's (the autograd updater: the fast one keeps the critic outside the modules until
the update ends). Runs ``benchmarks.run`` in this process with the patch (use ``--workers 0 --checkpoint-every 0``: the
actor is not DENFAC's and alpha is not in the checkpoints); ``soft_actor/`` holds its runs and, per run, alpha and the
policy's entropy after every tenth update (``soft_actor/alpha/<env>_<seed>.jsonl``).

Usage: ``python soft_actor.py --algos abl:default05 --envs cartpole --seeds 0 1 2 --workers 0 --checkpoint-every 0
--results benchmarks/results/ablation/prototypes/soft_actor``
"""

import dataclasses
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch as th
from stable_baselines3.common.noise import ActionNoise
from torch import nn
from torch.nn.utils import clip_grad_norm_

from benchmarks import run
from sb3_denfac.denfac.denfac import DENFAC
from sb3_denfac.denfac.options import bootstrap_range
from sb3_denfac.denfac.policies import combine_critics
from sb3_denfac.denfac.updaters import FitSettings, make_updater

ACTOR_Q = os.environ.get("SA_Q", "q1")  # what the actor ascends: "q1" (DENFAC's), "min" (SAC's) or "mean"
ENTROPY_SCALE = float(os.environ.get("SA_ENTROPY", "1"))  # target entropy -SA_ENTROPY x dim(A) (SAC: 1)
STATS = Path(os.environ.get("SA_STATS", "benchmarks/results/ablation/prototypes/soft_actor/alpha"))
LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0

_setup_model = DENFAC._setup_model
_sample_action = DENFAC._sample_action


class SoftActor(nn.Module):
    """SAC's squashed Gaussian pi(a|s) on DENFAC's 64-64 leaky-ReLU networks (module docstring)."""

    def __init__(self, obs_dim: int, action_dim: int, hidden: list[int], activation: type[nn.Module]):
        super().__init__()
        layers, width = [], obs_dim
        for size in hidden:
            layers += [nn.Linear(width, size), activation()]
            width = size
        self.trunk = nn.Sequential(*layers)
        self.mean = nn.Linear(width, action_dim)
        self.log_std = nn.Linear(width, action_dim)
        self.optimizer: th.optim.Optimizer | None = None

    def forward(self, obs: th.Tensor) -> th.Tensor:
        """The deterministic action tanh(m(s)), in [-1, 1]."""
        return th.tanh(self.mean(self.trunk(obs.float().flatten(1))))

    def sample(self, obs: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """a = tanh(m + std eps) (reparameterised) and log pi(a|s), shape (N, A) and (N, 1)."""
        h = self.trunk(obs.float().flatten(1))
        mean, log_std = self.mean(h), self.log_std(h).clamp(LOG_STD_MIN, LOG_STD_MAX)
        u = mean + log_std.exp() * th.randn_like(mean)
        action = th.tanh(u)
        normal = -0.5 * ((u - mean) / log_std.exp()).pow(2) - log_std - 0.5 * math.log(2 * math.pi)
        log_prob = (normal - th.log(1.0 - action.pow(2) + 1e-6)).sum(1, keepdim=True)  # SB3's squash correction
        return action, log_prob

    def set_training_mode(self, mode: bool) -> None:
        self.train(mode)

    def _predict(self, obs: th.Tensor, deterministic: bool = False) -> th.Tensor:
        return self(obs) if deterministic else self.sample(obs)[0]


def setup_model(self) -> None:
    _setup_model(self)
    policy = self.policy
    hidden = policy.actor_kwargs["net_arch"]
    actor = SoftActor(
        int(np.prod(self.observation_space.shape)), int(np.prod(self.action_space.shape)), hidden, policy.activation_fn
    ).to(self.device)
    actor.optimizer = th.optim.Adam(
        actor.parameters(), lr=policy.actor.optimizer.param_groups[0]["lr"], betas=self.adam_betas, eps=self.adam_eps
    )
    policy.actor = actor
    self._create_aliases()
    self.log_alpha = th.zeros(1, device=self.device, requires_grad=True)
    self.alpha_optimizer = th.optim.Adam([self.log_alpha], lr=actor.optimizer.param_groups[0]["lr"])
    self.target_entropy = -ENTROPY_SCALE * float(np.prod(self.action_space.shape))


def sample_action(self, learning_starts: int, action_noise: ActionNoise | None = None, n_envs: int = 1):
    if self.num_timesteps < learning_starts:  # the library's uniform warm-up (NaN behaviour means)
        return _sample_action(self, learning_starts, action_noise, n_envs)
    self.policy.set_training_mode(False)
    obs, _ = self.policy.obs_to_tensor(self._last_obs)
    with th.no_grad():
        action, _ = self.actor.sample(obs)
        self._last_behaviour_mean = self.actor(obs).cpu().numpy().astype(np.float32)
    buffer_action = action.cpu().numpy().astype(np.float32)
    return self.policy.unscale_action(buffer_action), buffer_action


def actor_value(critic: nn.Module, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
    return critic(obs, actions) if ACTOR_Q == "q1" else combine_critics(critic.all_q(obs, actions), ACTOR_Q)


def fit_soft_actor(self, obs: th.Tensor, batches: th.Tensor | None) -> tuple[float, float]:
    """25 steps of SAC's actor and temperature on the rows ``obs`` (``batches[i]``: step i's; None: all rows)."""
    actor, critic = self.actor, self.critic
    critic.set_training_mode(False)
    critic.requires_grad_(False)
    actor.set_training_mode(True)
    objective = entropy = 0.0
    for step in range(self.actor_steps):
        o = obs if batches is None else obs[batches[step]]
        alpha = self.log_alpha.exp().detach()
        action, log_prob = actor.sample(o)
        q = actor_value(critic, o, action)
        loss = (alpha * log_prob - q).mean()
        actor.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if self.max_grad_norm is not None:
            clip_grad_norm_(actor.parameters(), self.max_grad_norm)
        actor.optimizer.step()
        alpha_loss = -(self.log_alpha * (log_prob.detach() + self.target_entropy)).mean()
        self.alpha_optimizer.zero_grad(set_to_none=True)
        alpha_loss.backward()
        self.alpha_optimizer.step()
        objective, entropy = float(q.detach().mean()), float(-log_prob.detach().mean())
    critic.requires_grad_(True)
    actor.set_training_mode(False)
    return objective, entropy


def update(self, n_iterations: int | None = None) -> None:
    """The default's ``DENFAC._update`` with SAC's actor and soft targets (module docstring)."""
    start = time.perf_counter()
    n_iterations = self.n_fitted_iterations if n_iterations is None else n_iterations
    data = self.replay_buffer.all_samples(env=self._vec_normalize_env)
    obs, actions, next_obs, rewards = data.observations, data.actions, data.next_observations, data.rewards
    terminal = data.dones if self.bootstrap_on_timeout else th.clamp(data.dones + data.timeouts, max=1.0)
    settings = dataclasses.replace(FitSettings.of(self), actor_proximal=0.0)
    updater = make_updater(self.policy, settings, "plain").updater
    bounds = bootstrap_range(rewards, self.gamma) if self.bootstrap_bounds else None
    critic_loss, objective, entropy = th.zeros(()), 0.0, 0.0
    for _ in range(n_iterations):
        sample = updater.iteration_sample(obs.shape[0])
        rows = None if sample is None else sample.critic_rows
        o, a, o2, r, done = ((x if rows is None else x[rows]) for x in (obs, actions, next_obs, rewards, terminal))
        with th.no_grad():
            self.actor.set_training_mode(False)
            next_actions, next_log_prob = self.actor.sample(o2)
            next_q = updater.critic(o2, next_actions)
            if bounds is not None:  # ``bootstrap_bounds``: Qbar clipped to what D's rewards allow (options.py)
                next_q = next_q.clamp(*bounds)
            next_q = next_q - self.log_alpha.exp() * next_log_prob
            q_targets = r + self.gamma * (1.0 - done) * next_q
        weights = th.ones_like(q_targets)
        critic_loss = updater.fit_critic(o, a, q_targets, weights, None if sample is None else sample.critic_batches)
        if sample is None or sample.actor_rows is None:
            objective, entropy = fit_soft_actor(self, obs, None)
        else:
            objective, entropy = fit_soft_actor(self, obs[sample.actor_rows], sample.actor_batches)
    self._n_updates += 1
    self._last_update_stats = dict(weights=weights, q_targets=q_targets, rows=rows)
    self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
    self.logger.record("train/critic_loss", float(critic_loss))
    self.logger.record("train/actor_loss", -objective)
    self.logger.record("train/ent_coef", float(self.log_alpha.exp()))
    self.logger.record("train/entropy", entropy)
    self.logger.record("train/q_target_mean", q_targets.mean().item())
    self.logger.record("train/n_transitions", obs.shape[0])
    self.logger.record("train/update_time", time.perf_counter() - start)
    self.logger.record("train/fitted_iterations", n_iterations)
    if self._n_updates % 10 == 0:
        STATS.mkdir(parents=True, exist_ok=True)
        env_id = self.env.envs[0].spec.id if hasattr(self.env, "envs") else "env"
        name = f"{env_id.split('/')[-1]}_{self.seed}.jsonl"
        with open(STATS / name, "a") as f:
            f.write(
                json.dumps(
                    dict(
                        update=self._n_updates,
                        alpha=float(self.log_alpha.exp()),
                        entropy=entropy,
                        q_target_mean=q_targets.mean().item(),
                        objective=objective,
                    )
                )
                + "\n"
            )


if __name__ == "__main__":
    DENFAC._setup_model = setup_model
    DENFAC._sample_action = sample_action
    DENFAC._update = update
    sys.exit(run.main(sys.argv[1:]))
