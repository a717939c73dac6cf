"""Critic-fit diagnostics of the DENFAC ablation (suite ``ablation``, ``configs/ablation.yml``): how well Q fits its
targets and tracks the Monte-Carlo returns of the stored trajectories, measured on the buffer after an update."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th


class Diagnostics:
    """Critic-fit measurements on the buffer after an update (eval mode, no gradient).

    Q is ``model.critic``, i.e. Q_1 with ``n_critics`` > 1, and so are the one-step targets y here: for several critics
    ``fit_r2`` is Q_1's fit to its own one-step targets, not to the minimum the update fits it to.

    With two or more Q networks, ``grad_sign_agreement`` is the share of (transition, action dimension) pairs of D where
    dQ_1/da and dQ_2/da have the same sign at the actor's action a = clip(pi(s), -1, 1): the direction eq. (5) ascends,
    as a second critic fitted to the same targets on the same data reproduces it (0.5: chance; 1: always).
    ``grad_sign_agreement_data`` is the same at the stored actions, where the data are."""

    def __init__(self, every: int = 5):
        self.every = every
        self.rows: list[dict[str, float]] = []

    def measure(self, model: Any, episode: int) -> None:
        rb = model.replay_buffer
        data = rb.all_samples(env=model._vec_normalize_env)
        model.policy.set_training_mode(False)
        with th.no_grad():
            q = model.critic(data.observations, data.actions).squeeze(1)
            na = model.actor(data.next_observations).clamp(-1, 1)
            qn = model.critic(data.next_observations, na).squeeze(1)
            term = data.dones.squeeze(1)
            if not model.bootstrap_on_timeout:
                term = th.clamp(term + data.timeouts.squeeze(1), max=1.0)
            y = data.rewards.squeeze(1) + model.gamma * (1 - term) * qn
            # Monte-Carlo returns of the stored trajectories, bootstrapped by Q only at a time-limit end
            r = data.rewards.squeeze(1).numpy()
            d = data.dones.squeeze(1).numpy()
            to = data.timeouts.squeeze(1).numpy()
            n = len(r)
            order = np.arange(n)
            if rb.full:  # chronological order of a wrapped FIFO
                order = np.roll(order, -rb.pos)
            mc = np.zeros(n)
            g = 0.0
            qn_np = qn.numpy()
            for j in range(n - 1, -1, -1):
                i = order[j]
                end = d[i] > 0 or to[i] > 0 or j == n - 1
                if end:
                    g = 0.0 if (d[i] > 0 and to[i] == 0) else float(qn_np[i])
                g = r[i] + model.gamma * g
                mc[i] = g
            qnp = q.numpy()
            var_y = float(y.var())
            row = dict(
                episode=episode,
                n=n,
                td_mse=float(((q - y) ** 2).mean()),
                target_var=var_y,
                fit_r2=1.0 - float(((q - y) ** 2).mean()) / max(var_y, 1e-12),
                q_mean=float(q.mean()),
                q_std=float(q.std()),
                mc_mean=float(mc.mean()),
                mc_std=float(mc.std()),
                q_mc_corr=float(np.corrcoef(qnp, mc)[0, 1]) if qnp.std() > 0 and mc.std() > 0 else float("nan"),
                q_mc_bias=float((qnp - mc).mean()),
            )
            stats = getattr(model, "last_update", None)  # DENFAC's UpdateStats
        if hasattr(model.critic, "all_q") and len(model.critic.q_networks) >= 2:  # DENFAC's critics
            with th.no_grad():
                own = model.actor(data.observations).clamp(-1, 1)
            for key, actions in (("grad_sign_agreement", own), ("grad_sign_agreement_data", data.actions)):
                row[key] = action_gradient_sign_agreement(model.critic, data.observations, actions)
        if stats is not None:
            row["iw_mean"] = float(stats.weights.mean())
        self.rows.append(row)


def action_gradient_sign_agreement(critic: Any, obs: th.Tensor, actions: th.Tensor, chunk: int = 16_384) -> float:
    """Share of (row, action dimension) pairs where dQ_1/da and dQ_2/da at ``actions`` have the same (non-zero) sign;
    rows in chunks (one chunk's graph at a time), the critic's parameters untouched."""
    q1_net, q2_net = critic.q_networks[:2]
    agree, total = 0, 0
    wanted = [p.requires_grad for p in critic.parameters()]
    critic.requires_grad_(False)
    try:
        for start in range(0, obs.shape[0], chunk):
            a = actions[start : start + chunk].detach().clone().requires_grad_(True)
            inputs = critic.q_inputs(obs[start : start + chunk], a)
            (g1,) = th.autograd.grad(q1_net(inputs).sum(), a, retain_graph=True)
            (g2,) = th.autograd.grad(q2_net(inputs).sum(), a)
            agree += int((g1.sign() * g2.sign() > 0).sum())
            total += g1.numel()
    finally:
        for p, flag in zip(critic.parameters(), wanted, strict=True):
            p.requires_grad_(flag)
    return agree / total
