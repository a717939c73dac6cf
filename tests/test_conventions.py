"""The conventions of docs/conventions.md that hold across the algorithms with an actor and a critic: one meaning of
``learning_rate`` (the rate of each network without its own), per-network rates that take floats or schedules, and the
optimizers at ``policy.actor.optimizer`` / ``policy.critic.optimizer``."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import pytest
import torch as th

from sb3_denfac import CACLA, DDPG, DENFAC, NFAC

EPISODE = 20
SMALL: dict[str, tuple[type, dict[str, Any]]] = {
    "denfac": (DENFAC, dict(buffer_size=100, n_fitted_iterations=1, critic_steps=2, actor_steps=2, batch_size=16)),
    "ddpg": (DDPG, dict(learning_starts=10, batch_size=8)),
    "nfac": (NFAC, dict(n_fitted_iterations=1, critic_steps=2, actor_steps=2)),
    "cacla": (CACLA, dict(n_steps=10)),
}
NETWORKS = ("actor", "critic")


def make(name: str, **kwargs: Any):
    algo, small = SMALL[name]
    env = gym.make("Pendulum-v1", max_episode_steps=EPISODE)
    return algo("MlpPolicy", env, seed=0, policy_kwargs=dict(net_arch=[8]), **{**small, **kwargs})


def rate(model: Any, net: str) -> float:
    (group,) = getattr(model.policy, net).optimizer.param_groups
    return group["lr"]


@pytest.mark.parametrize("name", list(SMALL))
def test_optimizers_live_on_the_networks(name: str) -> None:
    """One optimizer per network, at ``policy.<net>.optimizer``, over exactly that network's parameters."""
    policy = make(name).policy
    for net in NETWORKS:
        optimizer = getattr(policy, net).optimizer
        assert isinstance(optimizer, th.optim.Optimizer)
        params = {id(p) for group in optimizer.param_groups for p in group["params"]}
        assert {id(p) for p in getattr(policy, net).parameters()} <= params
    assert policy.actor.optimizer is not policy.critic.optimizer


@pytest.mark.parametrize("name", ["nfac", "cacla"])
def test_old_optimizer_names_are_read_only_aliases(name: str) -> None:
    policy = make(name).policy
    assert policy.actor_optimizer is policy.actor.optimizer and policy.critic_optimizer is policy.critic.optimizer
    with pytest.raises(AttributeError):
        policy.actor_optimizer = th.optim.SGD(policy.actor.parameters(), lr=0.1)


@pytest.mark.parametrize("name", list(SMALL))
def test_learning_rate_alone_sets_both_networks(name: str) -> None:
    model = make(name, learning_rate=3e-3)
    assert (rate(model, "actor"), rate(model, "critic")) == (3e-3, 3e-3)
    model.learn(3 * EPISODE)
    assert (rate(model, "actor"), rate(model, "critic")) == (3e-3, 3e-3)


@pytest.mark.parametrize("name", list(SMALL))
@pytest.mark.parametrize("net", NETWORKS)
def test_schedule_per_network(name: str, net: str) -> None:
    """A schedule given as ``<net>_learning_rate`` is followed for that network; the other network keeps
    ``learning_rate``."""
    other = "critic" if net == "actor" else "actor"
    model = make(name, learning_rate=5e-4, **{f"{net}_learning_rate": lambda progress: 2e-3 * progress})
    assert (rate(model, net), rate(model, other)) == (pytest.approx(2e-3), 5e-4)
    model.learn(4 * EPISODE)
    progress = model._current_progress_remaining
    assert progress < 1.0
    assert rate(model, net) < 2e-3, f"{net}_learning_rate schedule ignored"
    assert rate(model, net) == pytest.approx(2e-3 * progress, rel=0.3)  # applied before the last update
    assert rate(model, other) == 5e-4
