"""DENFAC's target options of eq. (4): ``critic_target`` (how the Q networks make the bootstrap value),
``target_policy_noise`` / ``target_noise_clip`` (TD3's target policy smoothing of the next action) and
``bootstrap_bounds`` (the bootstrap value clipped to what the rewards allow); both updaters, validation, save/load, and
files of earlier versions."""

from __future__ import annotations

import copy

import pytest
import torch as th

from sb3_denfac.denfac import DENFAC
from sb3_denfac.denfac.policies import combine_critics
from sb3_denfac.denfac.update_paths import make_updater
from sb3_denfac.denfac.updaters import FitSettings

SMALL = dict(n_fitted_iterations=1, critic_steps=5, actor_steps=5, seed=3, gamma=0.9)
EXACT = dict(SMALL, target_policy_noise=0.0)  # deterministic next actions: the targets the tests recompute


def _expected_targets(before, data, gamma, combine):
    with th.no_grad():
        next_actions = before.actor(data.next_observations).clamp(-1.0, 1.0)
        values = th.cat(before.critic.all_q(data.next_observations, next_actions), dim=1)
    return data.rewards + gamma * (1.0 - data.dones) * combine(values)


def test_combine_critics():
    values = [th.tensor([[1.0], [4.0]]), th.tensor([[3.0], [2.0]])]
    # float32 defaults: small integers, exact in binary
    th.testing.assert_close(combine_critics(values, "min"), th.tensor([[1.0], [2.0]]))
    th.testing.assert_close(combine_critics(values, "mean"), th.tensor([[2.0], [3.0]]))
    assert combine_critics(values[:1], "mean") is values[0]


@pytest.mark.parametrize("update_path", ["fast", "plain"])
def test_mean_critic_target(target_action_env, update_path):
    """critic_target="mean": q = r + gamma (1 - done) 1/n sum_j Q_j(s', pi(s')), on both updaters."""
    model = DENFAC("MlpPolicy", target_action_env(), critic_target="mean", update_path=update_path, **EXACT).learn(30)
    before = copy.deepcopy(model.policy)
    before.set_training_mode(False)
    model._update()
    data = model.replay_buffer.all_samples()
    expected = _expected_targets(before, data, 0.9, lambda v: v.mean(dim=1, keepdim=True))
    # rtol 1e-4, atol 1e-5: the update's targets (either updater) against autograd modules in eval mode (a few ulps)
    th.testing.assert_close(model.last_update.q_targets, expected, rtol=1e-4, atol=1e-5)
    minimum = _expected_targets(before, data, 0.9, lambda v: v.min(dim=1, keepdim=True).values)
    assert (expected > minimum + 1e-6).any()  # the default's minimum would give other targets


def test_updaters_agree_on_the_mean(target_action_env):
    model = DENFAC("MlpPolicy", target_action_env(), critic_target="mean", **SMALL).learn(30)
    obs = model.replay_buffer.all_samples().observations
    actions = model.actor(obs).detach()
    settings = FitSettings.of(model)
    assert settings.critic_target == "mean"
    fast, plain = (make_updater(model.policy, settings, path).updater for path in ("fast", "plain"))
    with th.no_grad():
        # rtol 1e-4, atol 1e-5: the fast updater's folded networks against the modules; the plain one is the modules
        th.testing.assert_close(fast.critic(obs, actions), plain.critic(obs, actions), rtol=1e-4, atol=1e-5)
        th.testing.assert_close(plain.critic(obs, actions), model.critic.target_q(obs, actions, "mean"))


def test_target_policy_noise_is_clipped_and_redrawn(target_action_env):
    model = DENFAC("MlpPolicy", target_action_env(), target_policy_noise=0.5, target_noise_clip=0.1, **SMALL).learn(30)
    updater = model.make_updater()
    next_obs = model.replay_buffer.all_samples().next_observations
    with th.no_grad():
        clean = updater.actor(next_obs)
        first, second = model._next_actions(updater, next_obs)[0], model._next_actions(updater, next_obs)[0]
    noise = first - clean.clamp(-1.0, 1.0)
    inside = (clean.abs() < 0.9).squeeze(1)  # away from the bounds, where the clamp cuts nothing
    assert inside.any()
    assert noise[inside].abs().max() <= 0.1 + 1e-6  # clipped to +-target_noise_clip
    assert noise[inside].abs().max() > 0.05  # std 0.5: most draws reach the clip
    assert not th.equal(first, second)  # a fresh draw at every fitted iteration
    assert first.min() >= -1.0 and first.max() <= 1.0


def test_defaults_and_no_target_noise_is_the_deterministic_next_action(target_action_env):
    default = DENFAC("MlpPolicy", target_action_env())
    assert (default.critic_target, default.target_policy_noise, default.target_noise_clip) == ("mean", 0.2, 0.5)
    model = DENFAC("MlpPolicy", target_action_env(), **EXACT).learn(30)
    updater = model.make_updater()
    next_obs = model.replay_buffer.all_samples().next_observations
    with th.no_grad():
        # float32 defaults: the same forward pass twice (exact in practice): no noise is added
        th.testing.assert_close(model._next_actions(updater, next_obs)[0], updater.actor(next_obs).clamp(-1.0, 1.0))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(critic_target="max"), "critic_target must be one of"),
        (dict(target_policy_noise=-0.1), "target_policy_noise"),
        (dict(target_noise_clip=-1), "target_noise_clip"),
        (dict(bootstrap_bounds=1), "bootstrap_bounds must be True or False"),
        (dict(bootstrap_bounds="False"), "bootstrap_bounds must be True or False"),
    ],
)
def test_invalid_target_options(target_action_env, kwargs, message):
    with pytest.raises(ValueError, match=message):
        DENFAC("MlpPolicy", target_action_env(), **kwargs)


def test_save_load_keeps_the_target_options(tmp_path, target_action_env):
    model = DENFAC(
        "MlpPolicy", target_action_env(), critic_target="mean", target_policy_noise=0.3, target_noise_clip=0.4, **SMALL
    ).learn(30)
    model.save(tmp_path / "model.zip")
    loaded = DENFAC.load(tmp_path / "model.zip", env=target_action_env())
    assert (loaded.critic_target, loaded.target_policy_noise, loaded.target_noise_clip) == ("mean", 0.3, 0.4)


def test_files_without_the_target_options_take_the_settings_they_ran_with(tmp_path, target_action_env):
    """A file of 0.4 or earlier saved neither option: it loads with the minimum and deterministic next actions."""
    model = DENFAC("MlpPolicy", target_action_env(), critic_target="mean", target_policy_noise=0.3, **SMALL)
    for key in ("critic_target", "target_policy_noise", "target_noise_clip"):
        delattr(model, key)  # as if the class had no such attribute when the file was written
    model.save(tmp_path / "old.zip")
    loaded = DENFAC.load(tmp_path / "old.zip", env=target_action_env())
    assert (loaded.critic_target, loaded.target_policy_noise, loaded.target_noise_clip) == ("min", 0.0, 0.5)


@pytest.mark.parametrize("update_path", ["fast", "plain"])
def test_targets_on_the_mini_batches_rows_are_those_of_all_of_d(target_action_env, update_path):
    """With mini-batches, q_k is computed for the rows the iteration's batches draw only: the same values as over D."""
    model = DENFAC("MlpPolicy", target_action_env(), batch_size=8, update_path=update_path, **EXACT).learn(40)
    before = copy.deepcopy(model.policy)
    before.set_training_mode(False)
    model._update()
    rows = model.last_update.rows
    data = model.replay_buffer.all_samples()
    assert rows is not None and len(rows) == 5 * 8  # 5 critic steps x 8 draws out of the 40 transitions
    expected = _expected_targets(before, data, 0.9, lambda v: v.mean(dim=1, keepdim=True))
    # rtol 1e-4, atol 1e-5: the update's targets (either updater) against autograd modules in eval mode (a few ulps)
    th.testing.assert_close(model.last_update.q_targets, expected[rows], rtol=1e-4, atol=1e-5)


def test_iteration_sample(target_action_env):
    model = DENFAC("MlpPolicy", target_action_env(), batch_size=8, critic_steps=6, actor_steps=4, seed=0)
    updater = model.make_updater()
    sample = updater.iteration_sample(100)
    assert sample.critic_rows.shape == (48,) and sample.actor_rows.shape == (32,)
    assert sample.critic_batches.shape == (6, 8) and sample.actor_batches.shape == (4, 8)
    for rows, batches in ((sample.critic_rows, sample.critic_batches), (sample.actor_rows, sample.actor_batches)):
        assert rows.min() >= 0 and rows.max() < 100
        assert th.equal(batches.flatten(), th.arange(len(rows)))  # step i reads its own 8 draws
    draws = th.cat([updater.iteration_sample(100).critic_rows for _ in range(200)])
    counts = th.bincount(draws, minlength=100).float()
    assert counts.min() > 0 and counts.std() < 0.2 * counts.mean()  # uniform over the buffer
    assert updater.iteration_sample(8) is None  # the batch is the whole buffer
    assert DENFAC("MlpPolicy", target_action_env(), batch_size=None).make_updater().iteration_sample(100) is None
    no_actor = DENFAC("MlpPolicy", target_action_env(), batch_size=8, actor_steps=0).make_updater().iteration_sample(50)
    assert no_actor.actor_rows is None and no_actor.actor_batches is None


def test_files_of_earlier_versions_get_the_target_settings_they_ran_with():
    """What :func:`denfac_attributes_of_old_files` sets before SB3 writes a file's attributes (a file that saved none
    of the three keeps these), whatever the constructor's defaults are."""
    from types import SimpleNamespace

    from sb3_denfac.common.compat import denfac_attributes_of_old_files

    model = SimpleNamespace(critic_target="mean", target_policy_noise=0.2, target_noise_clip=0.1, bootstrap_bounds=True)
    denfac_attributes_of_old_files(model)
    assert (model.critic_target, model.target_policy_noise, model.target_noise_clip) == ("min", 0.0, 0.5)
    assert model.bootstrap_bounds is False


def test_bootstrap_range():
    """The range of every discounted return of at least one reward in [r_min, r_max] (gamma 0.9: 1 / (1 - gamma) = 10)."""
    from sb3_denfac.denfac.options import bootstrap_range

    assert bootstrap_range(th.tensor([[-2.0], [3.0]]), 0.9) == pytest.approx((-20.0, 30.0))  # both signs: the sums
    assert bootstrap_range(th.tensor([[1.0], [1.0]]), 0.9) == pytest.approx((1.0, 10.0))  # +1 per step, can end at once
    assert bootstrap_range(th.tensor([[-3.0], [-0.5]]), 0.9) == pytest.approx((-30.0, -0.5))


@pytest.mark.parametrize("update_path", ["fast", "plain"])
def test_bootstrap_bounds_clip_a_diverged_critic(target_action_env, update_path):
    """With ``bootstrap_bounds``, q = r + gamma (1 - d) clip(Q(s', a'), low, high): a critic whose values have left the
    rewards' range (its output bias set to 1e6) gives targets inside it; without, the same critic's targets are not."""
    from sb3_denfac.denfac.options import bootstrap_range

    targets = {}
    for bounds in (False, True):
        model = DENFAC("MlpPolicy", target_action_env(), bootstrap_bounds=bounds, update_path=update_path, **EXACT)
        model.learn(30)
        with th.no_grad():
            for q_net in model.critic.q_networks:
                q_net[-1].bias.fill_(1e6)
        model._update()
        data = model.replay_buffer.all_samples()
        low, high = bootstrap_range(data.rewards, model.gamma)
        targets[bounds] = model.last_update.q_targets
        bootstrap_max = data.rewards + model.gamma * (1.0 - data.dones) * high
        assert high < 1e3 and (targets[bounds] <= bootstrap_max + 1e-4).all() == bounds
    assert model.logger.name_to_value["train/bootstrap_clip_fraction"] == 1.0  # every value was clipped
    assert (targets[True] >= data.rewards + model.gamma * (1.0 - data.dones) * low - 1e-4).all()


def test_bootstrap_bounds_change_nothing_inside_the_range(target_action_env):
    """Where every bootstrap value lies in the range, an update's targets with the bounds are those without (same
    networks, same draws)."""
    model = DENFAC("MlpPolicy", target_action_env(), **EXACT).learn(30)
    state = copy.deepcopy(model.policy.state_dict())
    targets = []
    for bounds in (False, True):
        model.policy.load_state_dict(state)
        model.bootstrap_bounds = bounds
        th.manual_seed(0)
        model._update()
        targets.append(model.last_update.q_targets)
    assert model.logger.name_to_value["train/bootstrap_clip_fraction"] == 0.0
    # float32 defaults: the same update from the same state and draws, with and without a clamp that cuts nothing
    th.testing.assert_close(targets[0], targets[1])


def test_save_load_keeps_bootstrap_bounds(tmp_path, target_action_env):
    model = DENFAC("MlpPolicy", target_action_env(), bootstrap_bounds=True, **SMALL)
    model.save(tmp_path / "model.zip")
    assert DENFAC.load(tmp_path / "model.zip", env=target_action_env()).bootstrap_bounds is True
