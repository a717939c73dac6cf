"""Compute cost of one DENFAC end-of-episode update (issue 7), against a reference, the arithmetic floor and DDPG.

For each setting (paper's Acrobot and Half-Cheetah sizes) it times, in the same run and with the same thread count,
DENFAC's own update with ``update_path`` "compiled", "fast" and "plain", against:

(a) ``reference``: a straightforward PyTorch implementation of the same update (Algorithm 1: modules and Adam rebuilt
    at every reset, autograd, ``clip_grad_norm_``), kept in this file;
(b) ``floor``: the update's matrix-multiply FLOPs divided by the GFLOP/s of a large matmul measured in this run;
(c) ``ddpg``: SB3 DDPG's training cost for the same amount of data, i.e. one episode of ``episode_steps`` transitions
    with one gradient step of batch 64 per transition (and the paper's 8 additional updates: x9, computed).

Medians over repeats; results with ratios go to ``benchmarks/results/update_cost.{md,json}``.

Usage: ``python benchmarks/update_cost.py [--repeats 9] [--threads 1 2] [--settings acrobot half_cheetah]``
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th
from gymnasium import spaces
from torch import nn

RESULTS = Path(__file__).resolve().parent / "results"

SETTINGS = {
    # Paper Figure 5 + section 4: Acrobot (4-d state, 1 action, actor 5, D=6000, critic reset, no inverting gradients)
    "acrobot": dict(obs_dim=4, action_dim=1, pi=[5], qf=[50, 7], buffer_size=6000, reset_critic=True, inverting=False),
    # Half-Cheetah sizes (gymnasium's 17-d state, 6 actions, actor 20-10, D=3000, inverting gradients)
    "half_cheetah": dict(
        obs_dim=17, action_dim=6, pi=[20, 10], qf=[50, 7], buffer_size=3000, reset_critic=False, inverting=True
    ),
}
K, CRITIC_STEPS, G, SIGMA, GAMMA, LR, MAX_NORM = 10, 10, 25, 0.05, 0.99, 0.1, 10.0
EPISODE_STEPS = 500
MATMUL_SIZE = 1024  # the "large matmul" whose GFLOP/s defines the arithmetic floor


class RandomEnv(gym.Env):
    def __init__(self, obs_dim: int, action_dim: int):
        self.observation_space = spaces.Box(-np.inf, np.inf, (obs_dim,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (action_dim,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample() * 0, {}

    def step(self, action):
        return np.zeros(self.observation_space.shape, np.float32), 0.0, False, False, {}


def random_data(n: int, obs_dim: int, action_dim: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    f = np.float32
    return dict(
        obs=rng.normal(size=(n, obs_dim)).astype(f),
        next_obs=rng.normal(size=(n, obs_dim)).astype(f),
        actions=rng.uniform(-1, 1, (n, action_dim)).astype(f),
        means=rng.uniform(-1, 1, (n, action_dim)).astype(f),
        rewards=rng.normal(size=(n, 1)).astype(f),
        dones=(rng.random((n, 1)) < 0.01).astype(f),
    )


# ----- (a) straightforward reference implementation ------------------------------------------------------------------
def reference_mlp(in_dim: int, out_dim: int, hidden: list[int]) -> nn.Sequential:
    sizes = [in_dim, *hidden, out_dim]
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        if i < len(sizes) - 2:
            layers += [nn.BatchNorm1d(sizes[i]), nn.Linear(sizes[i], sizes[i + 1]), nn.LeakyReLU(0.01)]
        else:
            layers.append(nn.Linear(sizes[i], sizes[i + 1]))
    for m in layers:
        if isinstance(m, nn.Linear):
            nn.init.normal_(m.weight, std=0.01)
            nn.init.zeros_(m.bias)
    return nn.Sequential(*layers)


def truncnorm_logp(a: th.Tensor, mu: th.Tensor) -> th.Tensor:
    mu = mu.clamp(-1 - 3 * SIGMA, 1 + 3 * SIGMA).double()
    normal = th.distributions.Normal(mu, SIGMA)
    mass = normal.cdf(th.ones_like(mu)) - normal.cdf(-th.ones_like(mu))
    return (normal.log_prob(a.double()) - mass.log()).sum(1).float()


def reference_update(data: dict[str, th.Tensor], cfg: dict, nets: dict) -> None:
    s, a, s2, r, d, mu_b = data["obs"], data["actions"], data["next_obs"], data["rewards"], data["dones"], data["means"]
    obs_dim, act_dim = cfg["obs_dim"], cfg["action_dim"]
    actor, critic = nets["actor"], nets["critic"]
    critic_opt = nets.setdefault("critic_opt", th.optim.Adam(critic.parameters(), lr=LR, betas=(0.0, 0.999)))
    logp_b = truncnorm_logp(a, mu_b)
    for _ in range(K):
        actor.eval()
        critic.eval()
        with th.no_grad():
            q_target = r + GAMMA * (1 - d) * critic(th.cat([s2, actor(s2).clamp(-1, 1)], 1))
            c = th.exp(th.clamp(truncnorm_logp(a, actor(s)) - logp_b, max=0)).unsqueeze(1)
        if cfg["reset_critic"]:
            critic = reference_mlp(obs_dim + act_dim, 1, cfg["qf"])
            critic_opt = th.optim.Adam(critic.parameters(), lr=LR, betas=(0.0, 0.999))
        critic.train()
        for _ in range(CRITIC_STEPS):
            loss = (c * (critic(th.cat([s, a], 1)) - q_target) ** 2).mean()
            critic_opt.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(critic.parameters(), MAX_NORM)
            critic_opt.step()
        actor = reference_mlp(obs_dim, act_dim, cfg["pi"])
        actor_opt = th.optim.Adam(actor.parameters(), lr=LR, betas=(0.0, 0.999))
        actor.train()
        critic.eval()
        for _ in range(G):
            pi = actor(s)
            q = critic(th.cat([s, pi], 1))
            actor_opt.zero_grad()
            if cfg["inverting"]:
                (dq,) = th.autograd.grad(q.mean(), pi)
                dq = th.where(dq > 0, dq * (1 - pi.detach()) / 2, dq * (pi.detach() + 1) / 2)
                pi.backward(-dq)
            else:
                (-q.mean()).backward()
            nn.utils.clip_grad_norm_(actor.parameters(), MAX_NORM)
            actor_opt.step()
    nets["actor"], nets["critic"], nets["critic_opt"] = actor, critic, critic_opt


# ----- (b) arithmetic floor ------------------------------------------------------------------------------------------
def linear_flops(n: int, sizes: list[int], weight_grad: bool, input_grad_from: int | None) -> float:
    """Matmul FLOPs of a forward (+ backward) pass of an MLP with layer sizes ``sizes`` over n samples."""
    flops = 0.0
    for i in range(len(sizes) - 1):
        mac = n * sizes[i] * sizes[i + 1]
        flops += 2 * mac  # forward
        if weight_grad:
            flops += 2 * mac
        if input_grad_from is not None and i >= input_grad_from:
            flops += 2 * mac
    return flops


def update_flops(cfg: dict) -> float:
    n, o, a = cfg["buffer_size"], cfg["obs_dim"], cfg["action_dim"]
    actor, critic = [o, *cfg["pi"], a], [o + a, *cfg["qf"], 1]
    targets = 2 * linear_flops(n, actor, False, None) + linear_flops(n, critic, False, None)
    critic_step = linear_flops(n, critic, True, 1)
    # actor step: actor forward + backward, critic forward + d/d action. The critic's first layer only through its
    # action columns (forward and input gradient): its observation part is fixed over the G steps, once per iteration.
    hidden = cfg["qf"][0]
    critic_obs_part = 2 * n * o * hidden
    actor_step = linear_flops(n, actor, True, 1) + linear_flops(n, critic, False, 1) - critic_obs_part + 2 * n * a * hidden
    return K * (targets + critic_obs_part + CRITIC_STEPS * critic_step + G * actor_step)


# ----- (c) SB3 DDPG ---------------------------------------------------------------------------------------------------
def fill_replay_buffer(rb, cfg: dict) -> None:
    """Fill a single-env SB3 replay buffer with ``cfg["buffer_size"]`` random transitions (DENFAC's also gets means)."""
    data = random_data(cfg["buffer_size"], cfg["obs_dim"], cfg["action_dim"])
    rb.observations[:, 0], rb.next_observations[:, 0], rb.actions[:, 0] = data["obs"], data["next_obs"], data["actions"]
    rb.rewards[:, 0], rb.dones[:, 0] = data["rewards"][:, 0], data["dones"][:, 0]
    if hasattr(rb, "behaviour_means"):
        rb.behaviour_means[:, 0] = data["means"]
    rb.full = True


def ddpg_episode(cfg: dict):
    """A callable running SB3 DDPG's train() for one episode's worth of data."""
    from stable_baselines3 import DDPG
    from stable_baselines3.common.logger import configure

    env = RandomEnv(cfg["obs_dim"], cfg["action_dim"])
    model = DDPG(
        "MlpPolicy",
        env,
        buffer_size=cfg["buffer_size"],
        batch_size=64,
        learning_starts=0,
        policy_kwargs=dict(net_arch=dict(pi=cfg["pi"], qf=cfg["qf"])),
        seed=0,
    )
    model.set_logger(configure(None, []))
    fill_replay_buffer(model.replay_buffer, cfg)
    return lambda: model.train(gradient_steps=EPISODE_STEPS, batch_size=64)


def denfac_update(cfg: dict, path: str):
    """A callable running one DENFAC update on a full buffer of random data, and the first update's time (which
    includes torch.compile for path="compiled")."""
    from stable_baselines3.common.logger import configure

    from sb3_denfac.denfac import DENFAC

    env = gym.wrappers.TimeLimit(RandomEnv(cfg["obs_dim"], cfg["action_dim"]), max_episode_steps=EPISODE_STEPS)
    model = DENFAC(
        "MlpPolicy",
        env,
        buffer_size=cfg["buffer_size"],
        n_fitted_iterations=K,
        critic_steps=CRITIC_STEPS,
        actor_steps=G,
        reset_critic=cfg["reset_critic"],
        inverting_gradients=cfg["inverting"],
        learning_rate=LR,
        sigma=SIGMA,
        gamma=GAMMA,
        update_path=path,
        policy_kwargs=dict(net_arch=dict(pi=cfg["pi"], qf=cfg["qf"])),
        seed=0,
    )
    model.set_logger(configure(None, []))
    fill_replay_buffer(model.replay_buffer, cfg)
    start = time.perf_counter()
    model._update()
    return model._update, time.perf_counter() - start


def time_setting(name: str, repeats: int) -> dict:
    """Interleaved medians of every variant for one setting at the current thread count."""
    cfg = SETTINGS[name]
    compiled_fn, compile_first = denfac_update(cfg, "compiled")
    fast_fn, fast_first = denfac_update(cfg, "fast")
    plain_fn, _ = denfac_update(cfg, "plain")
    data = {k: th.as_tensor(v) for k, v in random_data(cfg["buffer_size"], cfg["obs_dim"], cfg["action_dim"]).items()}
    nets = dict(
        actor=reference_mlp(cfg["obs_dim"], cfg["action_dim"], cfg["pi"]),
        critic=reference_mlp(cfg["obs_dim"] + cfg["action_dim"], 1, cfg["qf"]),
    )
    big = (th.randn(MATMUL_SIZE, MATMUL_SIZE), th.randn(MATMUL_SIZE, MATMUL_SIZE))
    variants = dict(
        compiled=compiled_fn,
        fast=fast_fn,
        plain=plain_fn,
        reference=lambda d=data, c=cfg, n=nets: reference_update(d, c, n),
        ddpg=ddpg_episode(cfg),
        matmul=lambda a=big[0], b=big[1]: a @ b,
    )
    # Interleaved: every repeat times each variant back to back, so load changes on the shared machine hit all.
    times: dict[str, list[float]] = {k: [] for k in variants}
    for fn in variants.values():
        fn()  # warm-up
    for _ in range(repeats):
        for key, fn in variants.items():
            start = time.perf_counter()
            fn()
            times[key].append(time.perf_counter() - start)
    compiled, fast, plain, reference, ddpg, matmul = (float(np.median(times[k])) for k in variants)
    gflops = 2 * MATMUL_SIZE**3 / matmul / 1e9
    flops = update_flops(cfg)
    floor = flops / (gflops * 1e9)
    return dict(
        config=cfg,
        threads=th.get_num_threads(),
        update_gflop=flops / 1e9,
        matmul_gflops_per_s=gflops,
        floor_s=floor,
        compiled_s=compiled,
        compiled_first_update_s=compile_first,
        fast_s=fast,
        fast_first_update_s=fast_first,
        plain_s=plain,
        reference_s=reference,
        ddpg_episode_s=ddpg,
        ddpg_episode_with_8_additional_updates_s=9 * ddpg,
        compiled_speedup_vs_reference=reference / compiled,
        compiled_over_floor=compiled / floor,
        fast_speedup_vs_reference=reference / fast,
        fast_over_floor=fast / floor,
        plain_speedup_vs_reference=reference / plain,
        fast_over_ddpg_episode=fast / ddpg,
        times_s=times,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="torch thread counts, each a full run")
    parser.add_argument("--settings", nargs="+", default=list(SETTINGS))
    args = parser.parse_args()
    th.manual_seed(0)
    commit = os.popen("git rev-parse --short HEAD 2>/dev/null").read().strip() or "unknown"
    results: dict = dict(
        meta=dict(
            threads=args.threads,
            repeats=args.repeats,
            torch=th.__version__,
            commit=commit,
            K=K,
            critic_steps=CRITIC_STEPS,
            G=G,
            machine=f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores (shared with other jobs)",
            load_average=os.getloadavg(),
        ),
        runs=[],
    )
    for threads in args.threads:
        th.set_num_threads(threads)
        for name in args.settings:
            run = dict(setting=name, **time_setting(name, args.repeats))
            results["runs"].append(run)
            print(name, threads, json.dumps({k: v for k, v in run.items() if k != "times_s"}, indent=1), flush=True)
    results["meta"]["load_average_end"] = os.getloadavg()
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "update_cost.json").write_text(json.dumps(results, indent=1))
    meta = results["meta"]
    lines = [
        "# Cost of one DENFAC update (K=10, critic_steps=10, G=25, full batch)",
        "",
        f"{meta['machine']}; torch {th.__version__}; commit {commit}; medians of {args.repeats} interleaved repeats; "
        f"load average {meta['load_average'][0]:.1f} at start, {meta['load_average_end'][0]:.1f} at end.",
        "",
        "| setting | D | threads | fast (s) | compiled (s) | plain (s) | reference (s) | floor (s) | GFLOP/update "
        "| matmul GFLOP/s | reference / fast | fast / floor | reference / compiled | compiled / floor | DDPG episode (s) "
        "| DDPG x9 (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results["runs"]:
        lines.append(
            f"| {r['setting']} | {r['config']['buffer_size']} | {r['threads']} | {r['fast_s']:.3f} | {r['compiled_s']:.3f} | "
            f"{r['plain_s']:.3f} | {r['reference_s']:.3f} | {r['floor_s']:.3f} | {r['update_gflop']:.2f} | "
            f"{r['matmul_gflops_per_s']:.1f} | **{r['fast_speedup_vs_reference']:.1f}x** | **{r['fast_over_floor']:.1f}x** | "
            f"{r['compiled_speedup_vs_reference']:.1f}x | {r['compiled_over_floor']:.1f}x | {r['ddpg_episode_s']:.3f} | "
            f"{r['ddpg_episode_with_8_additional_updates_s']:.3f} |"
        )
    lines += [
        "",
        "- fast / compiled / plain: DENFAC's `update_path` (fast = the default eager steps of `eager_steps.py`; compiled = "
        "`compiled_steps.py` through torch.compile, whose first update compiles: "
        + ", ".join(f"{r['setting']} {r['threads']} thread(s) {r['compiled_first_update_s']:.0f} s" for r in results["runs"])
        + "); reference: straightforward PyTorch in this file (modules and Adam rebuilt at resets, autograd).",
        "- floor: matmul FLOPs of the update (forward, weight and input gradients; elementwise work not counted) / GFLOP/s "
        "of a 1024x1024 float32 matmul timed in the same interleaved repeats (and thread count).",
        f"- DDPG: SB3 DDPG `train()` for one {EPISODE_STEPS}-step episode (one batch-64 gradient step per transition, "
        "same networks without batch norm); x9 = with the paper's 8 additional updates per step.",
        "- Targets (issue 7, paper's Acrobot settings): reference / fast >= 5x and fast / floor <= 4x.",
    ]
    (RESULTS / "update_cost.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
