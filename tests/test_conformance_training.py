"""SB3 plugin contract, part 4: training options (DDPG train_freq, learning-rate schedules, several environments, DDPG
target batch-norm statistics; after SB3's tests/test_run.py, test_train_eval_mode.py). Helpers: ``test_conformance.py``."""

from __future__ import annotations

from typing import Any

import pytest
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from test_conformance import (
    ALGOS,
    EPISODE,
    batch_norm_buffers,
    make_env,
    make_model,
)

import sb3_denfac  # noqa: F401  (registers the paper envs)

# ----- off-policy train frequency (SB3 tests/test_run.py) --------------------------------------------------------------


@pytest.mark.parametrize("train_freq", [4, (2, "step"), (1, "episode")])
def test_ddpg_train_freq(train_freq: Any) -> None:
    model = make_model("ddpg", train_freq=train_freq, gradient_steps=-1, learning_starts=EPISODE)
    model.learn(2 * EPISODE)
    assert model.num_timesteps == 2 * EPISODE
    assert model._n_updates == EPISODE  # gradient_steps=-1: one update per collected step after learning_starts


# ----- learning-rate schedules and several environments ---------------------------------------------------------------


def _optimizers(model: BaseAlgorithm) -> list[th.optim.Optimizer]:
    policy = model.policy
    candidates = [getattr(policy, "optimizer", None), getattr(policy, "actor_optimizer", None)]
    candidates += [getattr(policy, "critic_optimizer", None)]
    candidates += [getattr(getattr(policy, net, None), "optimizer", None) for net in ("actor", "critic")]
    found: list[th.optim.Optimizer] = []
    for optimizer in candidates:
        if isinstance(optimizer, th.optim.Optimizer) and all(optimizer is not seen for seen in found):
            found.append(optimizer)
    return found


@pytest.mark.parametrize("name", [name for name in ALGOS if name != "cmaes"])  # CMA-ES has no learning rate
def test_learning_rate_schedule(name: str) -> None:
    """A schedule of the remaining progress given as ``learning_rate`` is followed (SB3 semantics), not just read once."""
    model = make_model(name, learning_rate=lambda progress_remaining: 1e-3 * progress_remaining)
    optimizers = _optimizers(model)
    assert optimizers
    assert all(group["lr"] == pytest.approx(1e-3) for opt in optimizers for group in opt.param_groups)
    model.learn(4 * EPISODE)
    for optimizer in _optimizers(model):  # looked up again: a network reset may build a new optimizer
        for group in optimizer.param_groups:
            assert group["lr"] <= 0.5e-3, "learning_rate schedule ignored"


@pytest.mark.parametrize("name", ["ddpg", "cacla"])  # step-wise algorithms
def test_several_envs(name: str) -> None:
    from stable_baselines3.common.env_util import make_vec_env

    model = make_model(name, env=make_vec_env(make_env, n_envs=2, seed=0))
    model.learn(2 * EPISODE)
    assert model.num_timesteps == 2 * EPISODE
    assert model.n_envs == 2
    actions, _ = model.predict(model.get_env().reset(), deterministic=True)
    assert actions.shape == (2, *model.action_space.shape)


def test_ddpg_target_networks_copy_batch_norm_statistics() -> None:
    """As SB3's TD3 (GH#996): running statistics are copied to the targets, weights are Polyak-averaged."""
    model = make_model("ddpg", tau=0.1)
    model.learn(2 * EPISODE)
    policy = model.policy
    for online, target in ((policy.actor, policy.actor_target), (policy.critic, policy.critic_target)):
        online_stats, target_stats = batch_norm_buffers(online), batch_norm_buffers(target)
        assert online_stats
        for key, value in online_stats.items():
            assert th.equal(value, target_stats[key]), key
        online_weights = th.cat([p.flatten() for p in online.parameters()])
        target_weights = th.cat([p.flatten() for p in target.parameters()])
        assert not th.equal(online_weights, target_weights)  # tau < 1: the targets lag
