"""Prototype, not in the library (ablation README, section 21): a state-dependent exploration sigma(s) fitted on the
critic, as SAC fits its policy's std, around DENFAC's unchanged deterministic mean.

Sections 12-13 found the balance tasks' fall-back in the exploring episodes (the deterministic policies are level with
SAC's), and that changing what the *mean* ascends (Q at noisy actions) fixes them and costs locomotion. Here the mean
mu(s) is fitted exactly as in the default (eq. 5 with the proximal term); only the noise it is played with changes.
A separate network l(s) (64-64, ReLU, last layer zero: sigma = SIGMA0 everywhere at the start) gives, per action
dimension,

    log sigma(s) = log S_MIN + (log S_MAX - log S_MIN) sigmoid(l(s))        (S_MIN 0.01, S_MAX 1; l = 0: 0.1)

and after every end-of-episode update (the default's, unchanged) it takes CS_STEPS Adam steps (lr 1e-3) on
mini-batches of 256 states of D, SAC's reparameterised objective with the critic Q_1 frozen and mu(s) detached:

    L = - 1/B sum Q_1(s, clip(mu(s) + sigma(s) eps, -1, 1)) / S  -  alpha 1/B sum_s sum_d log sigma_d(s),
    S = std over the batch of Q_1(s, mu(s)) (detached: the objective is scale-free),

and alpha (a Lagrange multiplier, as SAC's ``ent_coef="auto"``) keeps the average log sigma over D at log SIGMA0:
log alpha descends (mean_s sum_d log sigma_d(s) - d log SIGMA0). For a critic locally quadratic in a,
E Q(s, mu + sigma eps) = Q(s, mu) + sigma^2 tr(H) / 2, so the optimum is sigma_d(s)^2 ~ alpha S / (-H_dd): less noise
where the value is sharply peaked in the action (a balance), more where it is flat, with the default's 0.1 on average.
The episodes are played with the truncated Gaussian N(mu(s), sigma(s)^2) on [-1, 1]; the targets' smoothing noise and
everything else are the default's. Only ``weighting="none"`` (the default): D's behaviour means are stored as usual,
the importance weights would need sigma_b(s) too.

Runs ``benchmarks.run`` in this process with the patch (use ``--workers 0 --checkpoint-every 0``: sigma's network is not
in the checkpoints); ``critic_sigma/`` holds its runs and, per run, sigma's statistics every 10 episodes
(``critic_sigma/sigma/<env>_<seed>.jsonl``).

Usage: ``python critic_sigma.py --algos abl:default05 --envs cartpole --seeds 0 1 2 --workers 0 --checkpoint-every 0
--results benchmarks/results/ablation/prototypes/critic_sigma``
"""

import json
import math
import os
import sys
from pathlib import Path

import numpy as np
import torch as th
from scipy import special
from torch import nn

from benchmarks import run
from sb3_denfac.common.exploration import TruncatedGaussianExplorationMixin
from sb3_denfac.denfac.denfac import DENFAC

SIGMA0 = float(os.environ.get("CS_SIGMA0", "0.1"))
S_MIN, S_MAX = 0.01, 1.0
STEPS = int(os.environ.get("CS_STEPS", "100"))
BATCH = 256
STATS = Path(os.environ.get("CS_STATS", "benchmarks/results/ablation/prototypes/critic_sigma/sigma"))

_train = DENFAC.train
_sample_action = TruncatedGaussianExplorationMixin._sample_action


class SigmaNet(nn.Module):
    def __init__(self, obs_dim: int, action_dim: int):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(obs_dim, 64), nn.ReLU(), nn.Linear(64, 64), nn.ReLU(), nn.Linear(64, action_dim))
        nn.init.zeros_(self.net[-1].weight)
        offset = math.log(SIGMA0 / S_MIN) / math.log(S_MAX / S_MIN)  # sigmoid(b) = offset: sigma = SIGMA0 at l = 0
        nn.init.constant_(self.net[-1].bias, math.log(offset / (1 - offset)))

    def forward(self, obs: th.Tensor) -> th.Tensor:
        """log sigma(s), shape (N, action_dim)."""
        return math.log(S_MIN) + math.log(S_MAX / S_MIN) * th.sigmoid(self.net(obs))


def _state(model: DENFAC) -> dict:
    state = getattr(model, "_critic_sigma", None)
    if state is None:
        obs_dim = int(np.prod(model.observation_space.shape))
        net = SigmaNet(obs_dim, model.action_space.shape[0])
        log_alpha = th.tensor(math.log(0.01), requires_grad=True)
        state = dict(
            net=net,
            opt=th.optim.Adam(net.parameters(), lr=1e-3),
            log_alpha=log_alpha,
            alpha_opt=th.optim.Adam([log_alpha], lr=3e-2),
            updates=0,
        )
        model._critic_sigma = state
    return state


def _obs_tensor(model: DENFAC, obs) -> th.Tensor:
    tensor, _ = model.policy.obs_to_tensor(obs)
    return model.policy.critic.extract_features(tensor, model.policy.critic.features_extractor)


def fit_sigma(model: DENFAC) -> None:
    state = _state(model)
    net, opt, log_alpha, alpha_opt = state["net"], state["opt"], state["log_alpha"], state["alpha_opt"]
    data = model.replay_buffer.all_samples(env=model._vec_normalize_env)
    obs = data.observations
    n = obs.shape[0]
    critic, actor = model.policy.critic, model.policy.actor
    critic.set_training_mode(False)
    actor.set_training_mode(False)
    critic.requires_grad_(False)
    target = model.action_space.shape[0] * math.log(SIGMA0)
    for _ in range(STEPS):
        o = obs[th.randint(n, (min(BATCH, n),))]
        with th.no_grad():
            mu = actor(o)
            scale = critic(o, mu.clamp(-1.0, 1.0)).std() + 1e-6 if o.shape[0] > 1 else th.ones(())
        log_sigma = net(o.flatten(1))
        eps = th.randn_like(mu)
        a = (mu + log_sigma.exp() * eps).clamp(-1.0, 1.0)
        entropy = log_sigma.sum(dim=1).mean()
        loss = -(critic(o, a).mean() / scale) - log_alpha.exp().detach() * entropy
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        alpha_loss = log_alpha * (entropy.detach() - target)
        alpha_opt.zero_grad(set_to_none=True)
        alpha_loss.backward()
        alpha_opt.step()
    critic.requires_grad_(True)
    state["updates"] += 1
    if state["updates"] % 10 == 0:
        with th.no_grad():
            sig = net(obs.flatten(1)).exp()
        record = dict(
            update=state["updates"],
            timesteps=model.num_timesteps,
            alpha=log_alpha.exp().item(),
            sigma_geo_mean=float(sig.log().mean().exp()),
            sigma_q=[float(x) for x in th.quantile(sig.flatten(), th.tensor([0.05, 0.25, 0.5, 0.75, 0.95]))],
            sigma_dim_geo=[float(x) for x in sig.log().mean(0).exp()],
        )
        STATS.mkdir(parents=True, exist_ok=True)
        env_id = model.env.envs[0].spec.id if hasattr(model.env, "envs") else "env"
        name = f"{env_id.split('/')[-1]}_{model.seed}.jsonl"
        with open(STATS / name, "a") as f:
            f.write(json.dumps(record) + "\n")


def train(self, gradient_steps: int, batch_size=None) -> None:
    _train(self, gradient_steps, batch_size)
    if self.replay_buffer.size() > 1:
        fit_sigma(self)


def sample_action(self, learning_starts, action_noise=None, n_envs=1):
    state = getattr(self, "_critic_sigma", None)
    if state is None or self.num_timesteps < learning_starts:
        return _sample_action(self, learning_starts, action_noise, n_envs)
    mean = self._exploration_mean(self._last_obs).astype(np.float64)
    with th.no_grad():
        sigma = state["net"](_obs_tensor(self, self._last_obs).flatten(1)).exp().cpu().numpy().reshape(mean.shape)
    sigma = sigma.astype(np.float64)
    clamped = np.clip(mean, -1.0 - 3 * sigma, 1.0 + 3 * sigma)
    alpha, beta = (-1.0 - clamped) / sigma, (1.0 - clamped) / sigma
    lo, hi = special.ndtr(alpha), special.ndtr(beta)
    z = special.ndtri(lo + np.random.random_sample(mean.shape) * (hi - lo))
    buffer_action = np.clip(clamped + sigma * z, -1.0, 1.0).astype(np.float32)
    self._last_behaviour_mean = mean.astype(np.float32)
    return self.policy.unscale_action(buffer_action), buffer_action


if __name__ == "__main__":
    DENFAC.train = train
    DENFAC._sample_action = lambda self, learning_starts, action_noise=None, n_envs=1: sample_action(
        self, learning_starts, action_noise, n_envs
    )
    sys.exit(run.main(sys.argv[1:]))
