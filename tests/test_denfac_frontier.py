"""The frontier's critics as DENFAC options: CrossQ's joint bootstrapping with batch renormalisation, REDQ's target
subset, DroQ's dropout and layer norm, periodic resets (docs/algorithms.md, "The frontier's critics")."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from torch import nn

from sb3_denfac import DENFAC, SoftDENFAC
from sb3_denfac.common.networks import BatchRenorm1d, ResidualBlock
from sb3_denfac.denfac.buffers import n_rows
from sb3_denfac.denfac.updaters import AutogradUpdater

#: Small library-default DENFAC (mini-batches, two critics, proximal actor) for these tests.
SMALL = dict(
    buffer_size=500,
    batch_size=32,
    n_fitted_iterations=2,
    critic_steps=3,
    actor_steps=2,
    policy_kwargs=dict(net_arch=dict(pi=[16], qf=[16, 16])),
)


def make(**kwargs) -> DENFAC:
    params = {**SMALL, **kwargs}
    params["policy_kwargs"] = {**SMALL["policy_kwargs"], **kwargs.get("policy_kwargs", {})}
    return DENFAC("MlpPolicy", gym.make("Pendulum-v1", max_episode_steps=50), seed=0, **params)


def layer_types(net: nn.Module) -> list[type]:
    return [type(m) for m in net]


def test_critic_layers_of_droq_and_crossq():
    droq = make(policy_kwargs=dict(dropout=0.01, layer_norm=True)).critic.qf
    assert layer_types(droq) == [nn.Linear, nn.Dropout, nn.LayerNorm, nn.LeakyReLU] * 2 + [nn.Linear]
    crossq = make(policy_kwargs=dict(batch_renorm=True)).critic.qf
    assert layer_types(crossq) == [BatchRenorm1d, nn.Linear, nn.LeakyReLU] * 2 + [BatchRenorm1d, nn.Linear]  # CrossQ
    simba = make(policy_kwargs=dict(residual=True)).critic.qf
    assert layer_types(simba) == [nn.Linear, ResidualBlock, ResidualBlock, nn.LayerNorm, nn.Linear]
    actor = make(policy_kwargs=dict(batch_renorm=True, dropout=0.01, residual=True)).actor
    assert not any(isinstance(m, (BatchRenorm1d, nn.Dropout, ResidualBlock)) for m in actor.modules())  # critic only


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(policy_kwargs=dict(n_critics=2, target_subset=3)), "target_subset must be an integer >= 1 and <= 2"),
        (dict(policy_kwargs=dict(dropout=1.0)), "dropout must be a number >= 0 and <= 0.9"),
        (dict(policy_kwargs=dict(batch_renorm=1)), "batch_renorm must be True or False"),
        (dict(frozen_targets="no"), "frozen_targets must be True or False"),
        (dict(reset_every=0), "reset_every must be an integer >= 1"),
        (dict(frozen_targets=False, update_path="fast"), "does not support frozen_targets=False"),
    ],
)
def test_bad_frontier_settings_are_refused_by_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "reason"),
    [
        (dict(policy_kwargs=dict(n_critics=4, target_subset=2)), "target_subset"),
        (dict(frozen_targets=False), "frozen_targets=False"),
        (dict(policy_kwargs=dict(dropout=0.01)), "default MLP networks"),
        (dict(policy_kwargs=dict(batch_renorm=True)), "default MLP networks"),
        (dict(policy_kwargs=dict(residual=True)), "default MLP networks"),
    ],
)
def test_the_fast_updater_refuses_the_options_it_does_not_implement(kwargs, reason):
    """ "auto" takes the autograd updater for them; "fast" says why not, at construction or at the first update."""
    assert isinstance(make(**kwargs).make_updater(), AutogradUpdater)
    with pytest.raises(ValueError, match=reason):
        model = make(update_path="fast", **kwargs)
        model.make_updater()


def test_redq_targets_take_a_random_subset_and_the_actor_the_mean():
    critic = make(policy_kwargs=dict(n_critics=5, target_subset=2)).critic
    values = [th.full((3, 1), float(j)) for j in range(5)]
    th.manual_seed(0)
    draws = {tuple(critic.combine(values, "min").flatten().tolist()) for _ in range(50)}
    # the minimum of two distinct networks of five: any of 0..3, never 4, and not always the ensemble's minimum 0
    assert {d[0] for d in draws} <= {0.0, 1.0, 2.0, 3.0} and len(draws) > 1
    obs, actions = th.randn(4, 3), th.rand(4, 1) * 2 - 1
    expected = th.stack(critic.all_q(obs, actions)).mean(dim=0)
    # float32, the same operations in the same order: equal to rounding (1e-6)
    th.testing.assert_close(critic(obs, actions), expected, rtol=1e-6, atol=1e-6)
    plain = make(policy_kwargs=dict(n_critics=5)).critic
    th.testing.assert_close(plain(obs, actions), plain.qf(plain.q_inputs(obs, actions)), rtol=1e-6, atol=1e-6)


def filled(model: DENFAC, steps: int = 120) -> DENFAC:
    """``model`` with ``steps`` env steps in D (warm-up only: no update)."""
    model.learning_starts = steps
    model.learn(steps)
    return model


def one_critic_fit(model: DENFAC, frozen: bool) -> tuple[dict[str, th.Tensor], th.Tensor]:
    """The critic's parameters after one fitted iteration's critic steps on D, with targets frozen or joint, and the
    steps' mini-batches (rows of D)."""
    th.manual_seed(1)
    model.frozen_targets = frozen
    updater = model.make_updater()
    data = model.replay_buffer.all_samples()
    n = n_rows(data.rewards)
    with th.no_grad():
        next_actions = model.actor(data.next_observations).clamp(-1, 1)
        discounts = model.gamma * (1.0 - data.dones)
        targets = data.rewards + discounts * model.critic.target_q(data.next_observations, next_actions, "mean")
    weights = th.ones(n, 1)
    batches = th.randint(n, (model.critic_steps, 32))
    if frozen:
        updater.fit_critic(data.observations, data.actions, targets, weights, batches)
    else:
        o, a, o2 = data.observations, data.actions, data.next_observations
        updater.fit_critic_joint(o, a, o2, next_actions, data.rewards, discounts, weights, batches, None)
    return {k: v.clone() for k, v in model.critic.state_dict().items()}, batches


@pytest.mark.parametrize("steps", [1, 3])
def test_joint_bootstrapping_is_the_frozen_targets_for_one_step_and_moves_with_the_critic_after(steps):
    """Without batch statistics, CrossQ's first step bootstraps from the critic as it is, the frozen targets' value;
    from the second step its targets follow the critic being fitted (a large step size makes that visible)."""
    states = []
    for frozen in (True, False):
        model = filled(make(critic_steps=steps, target_policy_noise=0.0, learning_rate=0.05))
        states.append(one_critic_fit(model, frozen)[0])
    gap = max((states[0][k] - states[1][k]).abs().max().item() for k in states[0])
    # float32 through the same layers, a mini-batch against all of D for the targets: rounding-sized apart (1e-5);
    # once the targets move, the parameters part by far more than rounding (measured: above 1e-3)
    assert gap < 1e-5 if steps == 1 else gap > 1e-4


def test_joint_bootstrapping_reads_batch_statistics_of_both_halves():
    """With batch renormalisation the critic's training-mode statistics cover (s, a) and (s', a') together."""
    model = filled(make(critic_steps=1, frozen_targets=False, policy_kwargs=dict(batch_renorm=True)))
    first = model.critic.qf[0]
    assert int(first.steps) == 0
    _, batches = one_critic_fit(model, frozen=False)
    assert int(first.steps) == 1  # one joint pass per step
    data = model.replay_buffer.all_samples()
    rows = batches[0]
    next_actions = model.actor(data.next_observations[rows]).clamp(-1, 1).detach()
    pairs = [th.cat([data.observations[rows], data.actions[rows]], 1), th.cat([data.next_observations[rows], next_actions], 1)]
    both = th.cat(pairs)
    # running mean from 0 after one step at momentum 0.01: 0.01 x the joint batch's mean (float32 sums: 1e-6)
    th.testing.assert_close(first.ra_mean, 0.01 * both.mean(dim=0), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(frozen_targets=False, policy_kwargs=dict(batch_renorm=True)),
        dict(critic_target="min", policy_kwargs=dict(n_critics=4, target_subset=2)),
        dict(policy_kwargs=dict(dropout=0.01, layer_norm=True)),
        dict(reset_every=100),
        dict(policy_kwargs=dict(residual=True)),
    ],
    ids=["crossq", "redq", "droq", "resets", "simba"],
)
def test_each_option_trains_saves_and_reloads(tmp_path, kwargs):
    model = make(**kwargs)
    model.learn(300)
    assert model.last_update is not None and th.isfinite(model.last_update.q_targets).all()
    model.save(tmp_path / "model")
    loaded = DENFAC.load(tmp_path / "model")
    obs = np.array([0.3, -0.2, 0.5], dtype=np.float32)
    # exact: the same weights through the same kernels in one process (no training between)
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])
    assert loaded.frozen_targets == model.frozen_targets and loaded.reset_every == model.reset_every
    assert loaded._resets_done == model._resets_done


def test_periodic_resets_reinitialise_the_networks_and_keep_the_buffer():
    model = make(reset_every=100)
    model.learn(100)  # two episodes of 50: the update after the second is the first at 100 steps
    assert model._resets_done == 1
    model.learn(100, reset_num_timesteps=False)
    assert model._resets_done == 2 and model.replay_buffer.size() == 200
    # the reset itself: fresh weights and Adam states, D untouched
    before = [p.clone() for p in model.critic.parameters()]
    model.policy.reset_critic()
    assert not model.critic.optimizer.state
    assert any(not th.equal(a, b) for a, b in zip(before, model.critic.parameters(), strict=True))


def test_resets_follow_the_env_steps_not_the_updates():
    model = make(reset_every=120)
    calls = []
    original = model._fit_all

    def spy(policy, data, iterations, reset=False):
        calls.append((model.num_timesteps, reset))
        return original(policy, data, iterations, reset)

    model._fit_all = spy  # type: ignore[method-assign]
    model.learn(300)
    assert [t for t, reset in calls if reset] == [150, 250]  # the first episode ends at or past 120 and 240


def test_soft_denfac_takes_the_critic_options():
    model = SoftDENFAC(
        "MlpPolicy",
        gym.make("Pendulum-v1", max_episode_steps=50),
        seed=0,
        **{**SMALL, "policy_kwargs": dict(net_arch=[16], n_critics=4, target_subset=2, dropout=0.01, layer_norm=True)},
    )
    model.learn(100)
    assert model.critic.target_subset == 2 and th.isfinite(model.last_update.q_targets).all()


def test_soft_denfac_takes_periodic_resets_and_the_joint_bootstrap():
    env = gym.make("Pendulum-v1", max_episode_steps=50)
    model = SoftDENFAC("MlpPolicy", env, seed=0, reset_every=100, **SMALL)
    model.learn(150)
    assert model._resets_done == 1 and model.frozen_targets
    crossq = SoftDENFAC("MlpPolicy", env, seed=0, frozen_targets=False, **{**SMALL, "policy_kwargs": dict(batch_renorm=True)})
    crossq.learn(100)
    assert not crossq.frozen_targets and th.isfinite(crossq.last_update.q_targets).all()


def test_joint_bootstrap_subtracts_the_penalty_at_the_next_actions():
    """q = r + g (Q(s', a') - p) is the target of the rewards r - g p without a penalty: the soft value's entropy term
    enters every joint critic step (SoftDENFAC's frozen_targets=False)."""
    states = []
    for shifted in (False, True):
        model = filled(make(critic_steps=3, target_policy_noise=0.0, learning_rate=0.05, frozen_targets=False))
        th.manual_seed(1)
        updater = model.make_updater()
        data = model.replay_buffer.all_samples()
        n = n_rows(data.rewards)
        next_actions = model.actor(data.next_observations).detach().clamp(-1, 1)
        discounts = model.gamma * (1.0 - data.dones)
        penalty = th.linspace(-1.0, 1.0, n).unsqueeze(1)
        rewards = data.rewards - discounts * penalty if shifted else data.rewards
        batches = th.randint(n, (model.critic_steps, 32))
        o, a, o2, w = data.observations, data.actions, data.next_observations, th.ones(n, 1)
        updater.fit_critic_joint(o, a, o2, next_actions, rewards, discounts, w, batches, None, None if shifted else penalty)
        states.append({k: v.clone() for k, v in model.critic.state_dict().items()})
    for key, value in states[0].items():  # rtol 1e-4, atol 1e-5: r + g (Q - p) and (r - g p) + g Q round differently
        th.testing.assert_close(states[1][key], value, rtol=1e-4, atol=1e-5, msg=key)
