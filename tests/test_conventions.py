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


def test_one_actor_class() -> None:
    """DENFAC's and DDPG's actors, the NFAC/CACLA policy and the CMA-ES policy are the one DeterministicActor."""
    from sb3_denfac import CMAES
    from sb3_denfac.common.actor import DeterministicActor

    env = gym.make("Pendulum-v1", max_episode_steps=EPISODE)
    actors = [make(name).policy.actor for name in ("denfac", "ddpg")]
    actors += [make(name).policy for name in ("nfac", "cacla")] + [CMAES("MlpPolicy", env).policy]
    assert all(isinstance(actor, DeterministicActor) for actor in actors)
    obs = th.zeros((2, 3))
    for actor in actors:
        actor.set_training_mode(False)
        assert actor.actor_mean(obs).shape == (2, 1) and actor._predict(obs, deterministic=True).abs().max() <= 1.0


def test_parse_net_arch() -> None:
    from sb3_denfac.common.actor import parse_net_arch

    defaults = {"pi": [20], "qf": [50, 7]}
    assert parse_net_arch(None, defaults) == defaults
    assert parse_net_arch([8, 4], defaults) == {"pi": [8, 4], "qf": [8, 4]}
    assert parse_net_arch({"qf": [3]}, defaults) == {"pi": [20], "qf": [3]}
    with pytest.raises(ValueError, match="net_arch keys"):
        parse_net_arch({"pi": [3], "vf": [3]}, defaults)  # a V critic's key given to a Q critic


def test_validators_name_the_parameter_and_return_python_scalars() -> None:
    import numpy as np

    from sb3_denfac.common.checks import check_gamma, check_learning_rate, check_number, check_sigma

    assert type(check_learning_rate("learning_rate", np.float32(1e-3))) is float
    schedule = lambda progress: progress  # noqa: E731
    assert check_learning_rate("actor_learning_rate", schedule) is schedule
    assert check_learning_rate("critic_learning_rate", None) is None
    assert type(check_number("n", np.int64(3), minimum=1, integer=True)) is int
    for call, match in (
        (lambda: check_learning_rate("critic_learning_rate", "1e-3"), "critic_learning_rate"),
        (lambda: check_gamma(1.5), "gamma"),
        (lambda: check_sigma(0.0), "sigma"),
        (lambda: check_number("bn_window", 1, minimum=2, integer=True), "bn_window must be an integer >= 2"),
        (lambda: check_number("n", 2.5, minimum=1, integer=True), "n must be an integer"),
        (lambda: check_number("tau", True, minimum=0), "tau"),  # a bool is not a number
    ):
        with pytest.raises(ValueError, match=match):
            call()
    assert check_sigma(0.0, zero_ok=True) == 0.0 and check_sigma(None, none_ok=True) is None
