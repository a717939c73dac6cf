"""Which change lets the asynchronous update hold the return where an update outlasts an episode? Without a thread:
DENFAC's updates run in place, and the episodes are played by the policy the asynchronous update would publish
(subclasses overriding the documented ``train``, ``_explore`` and ``make_updater`` hooks).

    python -m research.several_envs.async_fix [--variants sync stale anchor publish] [--seeds 0 1 2 3 4]
                                              [--n-envs 1] [--episodes 24] [--lag 1]

The asynchronous timeline when the update (a batch of back-to-back updates, with several envs) outlasts an episode:
the update at the end of episode k starts from P_{k-1}, the policy published at that hand-off, and its newest data
was played by P_{k-2}; episode k+1 is played by P_{k-1} (the update's start), and P_k is published at the end of
episode k+1. ``lag`` counts the updates (jobs, with several envs) between the policy that plays and the newest one:
1 is that timeline; ``async_lag.py``'s ``Stale`` played the actor from before the update before last (``lag`` 2).

- ``sync``: DENFAC as it is (the update in place, lag 0);
- ``stale``: the asynchronous timeline (the episodes played ``lag`` updates behind);
- ``anchor`` (a): as ``stale``, and the proximal actor's pi_old is the policy that played the newest data (the one
  published at the hand-off) instead of the update's start;
- ``both``: ``publish`` with ``anchor``'s pi_old, the last snapshot that played;
- ``publish`` (b): as ``stale``, and the learner publishes a snapshot after each fitted iteration (``lag`` 1 only);
  the update is taken to last ``--duration`` episodes (1.8: 4 Reacher updates of about 0.45 s against a 1 s episode
  at 20 ms per step), so the snapshot after iteration i of K plays from step i/K * duration * T of the episode.

After every ``--every`` episodes: the newest policy's deterministic return on 5 Reacher-v5 episodes (seed 9), and the
diagnostic on D's states: the mean |pi(s)| of the actor's unclipped output, the fraction of the action components
at or past the bounds (|pi(s)| >= 0.99), and the mean ||pi(s) - mu_play(s)|| to the policy that plays next.
Results: ``async_fix.json`` and the README beside this file.
"""

from __future__ import annotations

import argparse
import copy
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_denfac import DENFAC
from sb3_denfac.common.truncated_normal import clamp_mean, sample_truncated_normal
from sb3_denfac.denfac.fast import FastUpdater, parse_bn_mlp


@th.no_grad()
def eval_affines(net: th.nn.Module) -> list[tuple[th.Tensor, th.Tensor]]:
    """The eval-mode affines of a ``create_bn_mlp`` network, batch norm folded in (what the fast updater's frozen
    ``old_actor_affines`` hold), copied."""
    out = []
    for layer in parse_bn_mlp(net) or []:
        weight, bias = layer.linear.weight, layer.linear.bias
        if layer.bn is not None:
            bn = layer.bn
            scale = bn.weight * th.rsqrt(bn.running_var + bn.eps)
            weight, bias = weight * scale, bias + weight @ (bn.bias - bn.running_mean * scale)
        out.append((weight.detach().clone(), bias.detach().clone()))
    return out


def frozen(actor: th.nn.Module) -> th.nn.Module:
    """A frozen, eval-mode copy of ``actor``."""
    copied = copy.deepcopy(actor)
    copied.optimizer = None
    copied.set_training_mode(False)
    copied.requires_grad_(False)
    return copied


class Stale(DENFAC):
    """Episodes played by the policy ``lag`` updates (jobs) behind the newest: the asynchronous timeline."""

    lag: int = 1
    #: the actors at the start of the last ``lag`` jobs, oldest first (the players to come)
    starts: list[th.nn.Module]
    #: the actor that plays now (None: the newest, as before the first update)
    player: th.nn.Module | None = None
    #: the player of the newest data at the start of the running job (the anchor of ``Anchor``)
    newest_player: th.nn.Module | None = None

    def train(self, gradient_steps: int, batch_size: int | None = None) -> None:
        if self._finished is not None and not self._finished:
            return  # several envs: no episode ended at this step
        self.newest_player = self.player
        self.starts = [*getattr(self, "starts", []), frozen(self.policy.actor)][-self.lag :]
        super().train(gradient_steps, batch_size)
        if len(self.starts) == self.lag:
            self.player = self.starts[0]

    def _actor_for_step(self) -> th.nn.Module:
        return self.player or self.policy.actor

    def _explore(self, observation: Any) -> tuple[np.ndarray, np.ndarray]:
        actor = self._actor_for_step()
        actor.set_training_mode(False)
        obs, _ = self.policy.obs_to_tensor(observation)
        with th.no_grad():
            mean = actor(obs).cpu().numpy().reshape((-1, *self.action_space.shape)).astype(np.float32)
        return sample_truncated_normal(mean, self.sigma, -1.0, 1.0), clamp_mean(mean, -1.0, 1.0, self.sigma)


class Anchor(Stale):
    """(a): the proximal anchor pi_old of every update of a job is the policy that played the newest data."""

    def make_updater(self, policy: Any = None) -> Any:
        updater = super().make_updater(policy)
        anchor = self.newest_player
        if anchor is None:  # the first update: its start played the data
            return updater
        if isinstance(updater, FastUpdater):
            updater.old_actor_affines = eval_affines(anchor.mu)
        else:
            updater.old_actor = anchor
        return updater


class Publish(Stale):
    """(b): a snapshot after every fitted iteration, each published at its share of the update's duration."""

    duration: float = 1.8  # the update's length in episodes
    snapshots: list[th.nn.Module]

    def train(self, gradient_steps: int, batch_size: int | None = None) -> None:
        self.snapshots = []
        super().train(gradient_steps, batch_size)

    def make_updater(self, policy: Any = None) -> Any:
        updater = super().make_updater(policy)
        fit_actor = updater.fit_actor

        def fit_and_snapshot(*args: Any, **kwargs: Any) -> Any:
            result = fit_actor(*args, **kwargs)  # the fast updater's module weights are views of its flat ones
            self.snapshots.append(frozen(self.policy.actor))
            return result

        updater.fit_actor = fit_and_snapshot  # type: ignore[method-assign]
        return updater

    def _actor_for_step(self) -> th.nn.Module:
        snapshots = getattr(self, "snapshots", [])
        if self.player is None or not snapshots:
            return super()._actor_for_step()
        step = int(self._episode_steps[0]) if self._episode_steps is not None else 0
        published = int(step / (self.duration * 50) * len(snapshots))  # Reacher's 50-step episodes
        return self.player if published == 0 else snapshots[min(published, len(snapshots)) - 1]


class Both(Publish, Anchor):
    """(a) and (b): snapshots published during the episode, and the proximal anchor is the last one that played."""

    last_played: th.nn.Module | None = None

    def _actor_for_step(self) -> th.nn.Module:
        actor = super()._actor_for_step()
        self.last_played = None if actor is self.policy.actor else actor
        return actor

    def make_updater(self, policy: Any = None) -> Any:
        self.newest_player = self.last_played
        return super().make_updater(policy)


class Joint(DENFAC):
    """The episodes that end at one step get one update, its K_e from their summed length (K without
    ``update_to_data_ratio``), instead of one update each back to back: a job moves the actor once per batch."""

    def _finished_episodes(self, gradient_steps: int) -> list[int]:
        lengths = super()._finished_episodes(gradient_steps)
        return [sum(lengths)] if lengths else lengths


class PublishJoint(Joint, Publish):
    """``publish`` with one joint update per batch: the job is one update, so it lasts 1/n_envs of ``duration``."""

    def _actor_for_step(self) -> th.nn.Module:
        full, self.duration = self.duration, self.duration / self.n_envs
        try:
            return super()._actor_for_step()
        finally:
            self.duration = full


class JointSum(DENFAC):
    """One update per batch with the batch's summed fitted iterations (n_envs K): the iterations of back-to-back
    updates, with one proximal anchor pi_old and one optimizer state instead of one per episode."""

    def _run_updates(self, iterations: list[int], reset: bool) -> None:
        super()._run_updates([sum(iterations)], reset)


class PublishJointSum(JointSum, Publish):
    """``publish`` with ``sync_joint_sum``'s update: the job's length is unchanged."""


class Cut(Publish):
    """``publish`` with the job cut at the end of the batch it overlaps: only the fitted iterations published before
    the batch ends (``1 / duration`` of them) are run; the next job starts from the last one."""

    def _run_updates(self, iterations: list[int], reset: bool) -> None:
        budget = max(1, int(sum(iterations) / max(self.duration, 1.0)))
        kept = []
        for n in iterations:
            if budget <= 0:
                break
            kept.append(min(n, budget))
            budget -= kept[-1]
        super()._run_updates(kept, reset)

    def _actor_for_step(self) -> th.nn.Module:
        full, self.duration = self.duration, min(self.duration, 1.0)  # the cut job lasts at most the episode
        try:
            return super()._actor_for_step()
        finally:
            self.duration = full


class CutUpdates(Cut):
    """The library's asynchronous update (``common/episodic.py``): ``cut`` in whole updates, the first always run:
    the updates of the batch not started before the next batch ends are dropped."""

    def _run_updates(self, iterations: list[int], reset: bool) -> None:
        budget = sum(iterations) / max(self.duration, 1.0)
        kept = [iterations[0]]
        for n in iterations[1:]:
            if sum(kept) + n > budget:
                break
            kept.append(n)
        Publish._run_updates(self, kept, reset)


VARIANTS = {
    "sync": DENFAC,
    "stale": Stale,
    "anchor": Anchor,
    "publish": Publish,
    "both": Both,
    "sync_joint": Joint,
    "publish_joint": PublishJoint,
    "sync_joint_sum": JointSum,
    "publish_joint_sum": PublishJointSum,
    "cut": Cut,
    "cut_updates": CutUpdates,
}


def diagnostic(model: Any) -> dict[str, float]:
    """Mean |pi(s)|, the fraction of components at the bounds, and the mean distance to the player, on D's states."""
    buffer = model.replay_buffer
    obs = th.as_tensor(buffer.observations[: buffer.size()].reshape(-1, model.observation_space.shape[0]))
    with th.no_grad():
        model.policy.actor.set_training_mode(False)
        pi = model.policy.actor(obs)
        player = getattr(model, "player", None)
        play = pi if player is None else player(obs)
    return dict(
        mean_abs=round(float(pi.abs().mean()), 3),
        saturated=round(float((pi.abs() >= 0.99).float().mean()), 3),
        to_player=round(float((pi - play).norm(dim=1).mean()), 3),
    )


def run(variant: str, seed: int, n_envs: int, episodes: int, every: int, lag: int) -> dict[str, Any]:
    cls = VARIANTS[variant]
    model = cls("MlpPolicy", make_vec_env("Reacher-v5", n_envs=n_envs, seed=seed), seed=seed)
    if isinstance(model, Stale):
        model.lag = lag
    returns, diagnostics = [], []
    cpu = time.process_time()
    for _ in range(episodes // every):
        model.learn(50 * every, reset_num_timesteps=False)
        mean, _ = evaluate_policy(model, make_vec_env("Reacher-v5", n_envs=1, seed=9), 5)
        returns.append(round(float(mean), 1))
        diagnostics.append(diagnostic(model))
    return dict(returns=returns, diagnostics=diagnostics, cpu=round(time.process_time() - cpu, 1), updates=model._n_updates)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    parser.add_argument("--n-envs", type=int, default=1)
    parser.add_argument("--episodes", type=int, default=24)
    parser.add_argument("--every", type=int, default=4, help="training episodes between evaluations")
    parser.add_argument("--lag", type=int, default=1)
    parser.add_argument("--duration", type=float, default=1.8)
    parser.add_argument("--output", default=str(Path(__file__).with_name("async_fix.json")))
    args = parser.parse_args(argv)
    Publish.duration = args.duration
    out = Path(args.output)
    results = json.loads(out.read_text()) if out.exists() else {}
    th.set_num_threads(1)
    for seed in args.seeds:
        for variant in args.variants:
            key = f"{variant}/n{args.n_envs}/lag{args.lag}/seed{seed}"
            if key in results:
                continue
            results[key] = run(variant, seed, args.n_envs, args.episodes, args.every, args.lag)
            out.write_text(json.dumps(results, indent=1))
            r = results[key]
            print(key, r["returns"], [d["saturated"] for d in r["diagnostics"]], r["cpu"], flush=True)


if __name__ == "__main__":
    main()
