"""DENFAC's ``n_critics`` (clipped double Q, :class:`~sb3_denfac.denfac.policies.DENFACCritic`): the targets of eq. (4)
take the minimum over the Q networks, every Q network is fitted to them, the actor ascends Q_1; updater choice,
validation, save/load, and a learning test."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch as th

from sb3_denfac.denfac import DENFAC
from sb3_denfac.denfac.fast import FastUpdater
from sb3_denfac.denfac.updaters import AutogradUpdater

# the minimum (clipped double Q, critic_target="min") and deterministic next actions: the targets these tests recompute
SMALL = dict(n_fitted_iterations=2, critic_steps=20, actor_steps=10, seed=1, critic_target="min", target_policy_noise=0.0)


@pytest.fixture
def twin_model(target_action_env):
    """``twin_model(n_critics=2, **kwargs)``: DENFAC with :data:`SMALL` settings on the target-action env."""

    def make(n_critics: int = 2, **kwargs) -> DENFAC:
        policy_kwargs = dict(n_critics=n_critics, **kwargs.pop("policy_kwargs", {}))
        return DENFAC("MlpPolicy", target_action_env(), policy_kwargs=policy_kwargs, **{**SMALL, **kwargs})

    return make


def test_target_q_is_the_minimum_and_forward_is_q1(twin_model):
    critic = twin_model(n_critics=3).critic
    assert critic.n_critics == 3 and len(critic.q_networks) == 3 and critic.q_networks[0] is critic.qf
    first, second = (th.cat([p.flatten() for p in q.parameters()]) for q in critic.q_networks[:2])
    assert not th.equal(first, second)  # each Q network has its own initialisation
    obs, actions = th.rand(50, 2) * 2 - 1, th.rand(50, 1) * 2 - 1
    with th.no_grad():
        values = th.cat(critic.all_q(obs, actions), dim=1)
        critic.twin_qfs[0][-1].bias += (values[:, 0] - values[:, 1]).median()  # Q_2 below Q_1 on about half the inputs
        values = th.cat(critic.all_q(obs, actions), dim=1)
        # float32 defaults (rtol 1.3e-6, atol 1e-5): the same forward passes, another call
        th.testing.assert_close(critic.target_q(obs, actions, "min"), values.min(dim=1, keepdim=True).values)
        th.testing.assert_close(critic(obs, actions), values[:, :1])
    assert (values.argmin(dim=1) == 0).any() and (values.argmin(dim=1) != 0).any()  # the minimum is not always Q_1


def test_update_targets_take_the_minimum_over_the_critics(twin_model):
    """q = r + gamma (1 - done) min_j Q_j(s', pi(s')) with the networks of the update's start (K = 1)."""
    model = twin_model(gamma=0.9, n_fitted_iterations=1).learn(30)
    before = copy.deepcopy(model.policy)
    before.set_training_mode(False)
    model._update()
    data = model.replay_buffer.all_samples()
    with th.no_grad():
        next_actions = before.actor(data.next_observations).clamp(-1.0, 1.0)
        q_next = th.cat(before.critic.all_q(data.next_observations, next_actions), dim=1)
    bootstrap = 0.9 * (1.0 - data.dones)
    expected = data.rewards + bootstrap * q_next.min(dim=1, keepdim=True).values
    # float32 defaults (rtol 1.3e-6, atol 1e-5): the update's targets recomputed by autograd modules, values of order 1
    th.testing.assert_close(model.last_update.q_targets, expected)
    assert (expected < data.rewards + bootstrap * q_next[:, :1] - 1e-6).any()  # Q_1 alone would give other targets


def test_every_critic_is_fitted_and_the_actor_ascends_q1(twin_model):
    model = twin_model(update_path="plain").learn(30)  # the fast updater computes the same (test_denfac_updaters)
    before = [copy.deepcopy(q.state_dict()) for q in model.critic.q_networks]
    model._update()
    for q_net, old in zip(model.critic.q_networks, before, strict=True):
        assert any(not th.equal(p, old[name]) for name, p in q_net.state_dict().items())
    updater = model.make_updater()
    assert isinstance(updater, AutogradUpdater)

    def refuse(*args):
        raise AssertionError("Q_2 was evaluated")

    model.critic.twin_qfs[0].forward = refuse
    obs = model.replay_buffer.all_samples().observations
    updater.fit_actor(obs)  # ascends Q_1 only: Q_2 is never evaluated
    with pytest.raises(AssertionError, match="Q_2 was evaluated"):
        updater.critic(obs, model.actor(obs))  # the targets' value uses every critic


def test_the_fast_updater_has_every_critic(twin_model):
    model = twin_model(n_critics=3).learn(30)
    updater = model.make_updater()
    assert isinstance(updater, FastUpdater) and len(updater.critic_nets) == 3
    obs = model.replay_buffer.all_samples().observations
    actions = updater.actor(obs)
    with th.no_grad():
        # float32 defaults: the fast updater's folded eval-mode networks against the modules (a few ulps)
        th.testing.assert_close(updater.critic(obs, actions), model.critic.target_q(obs, actions, model.critic_target))
    updater.fit_critic(obs, actions, th.zeros(len(obs), 1), th.ones(len(obs), 1))
    updater.finish()  # every Q network's Adam state is written back into the one critic optimizer
    assert all(p in model.critic.optimizer.state for p in model.critic.parameters())


@pytest.mark.parametrize("value", [0, 1.5, -2, "2"])
def test_invalid_n_critics(twin_model, value):
    with pytest.raises(ValueError, match="n_critics must be an integer >= 1"):
        twin_model(n_critics=value)


def test_save_load_keeps_every_critic(tmp_path, twin_model, target_action_env):
    model = twin_model().learn(30)
    model.save(tmp_path / "model.zip")
    loaded = DENFAC.load(tmp_path / "model.zip", env=target_action_env())
    assert loaded.critic.n_critics == 2 and loaded.policy_kwargs["n_critics"] == 2
    obs, actions = th.rand(20, 2) * 2 - 1, th.rand(20, 1) * 2 - 1
    with th.no_grad():
        for q, q_loaded in zip(model.critic.all_q(obs, actions), loaded.critic.all_q(obs, actions), strict=True):
            # float32 defaults; the same parameters read back: equal in practice
            th.testing.assert_close(q, q_loaded)
    loaded.learn(20, reset_num_timesteps=False)
    assert loaded._n_updates == model._n_updates + 2


def test_clipped_double_q_learns_target_action(twin_model, target_action_env):
    """With two critics and bootstrapped targets (gamma 0.9) the actor moves to the rewarded action."""
    env = target_action_env()
    model = twin_model(gamma=0.9)
    obs = np.stack([env.observation_space.sample() for _ in range(64)])
    start = env.distance_to_target(model, obs)
    model.learn(200)
    end = env.distance_to_target(model, obs)
    assert end < 0.1 and end < start / 2, (start, end)
