"""The data-efficient presets: :data:`sb3_denfac.denfac.presets.DATA_EFFICIENT` (SoftDENFAC with CrossQ's critic at
1.5 critic steps per env step), :data:`~sb3_denfac.denfac.presets.DENFAC_DATA_EFFICIENT` (the compute dial at 4 critic
steps per env step on DENFAC's networks, at least K iterations per episode, bootstrap bounds), and the critics' layer
norm option (``policy_kwargs=dict(layer_norm=True)``, measured and left out of the presets: docs/denfac.md)."""

from __future__ import annotations

import numpy as np
import pytest
import torch as th
from torch import nn

from sb3_denfac.common.networks import BatchRenorm1d
from sb3_denfac.denfac import DENFAC
from sb3_denfac.denfac.presets import DATA_EFFICIENT, DENFAC_DATA_EFFICIENT, OWNERS, data_efficient, with_overrides
from sb3_denfac.denfac.update_paths import make_updater
from sb3_denfac.denfac.updaters import FitSettings
from sb3_denfac.soft_denfac import SoftDENFAC
from sb3_denfac.zoo.config import ZooConfigError, select_entry

SMALL = dict(critic_steps=5, actor_steps=5, batch_size=32, seed=1)


def _layer_norms(net: nn.Module) -> list[nn.LayerNorm]:
    return [m for m in net.modules() if isinstance(m, nn.LayerNorm)]


def test_layer_norm_is_in_every_hidden_layer_of_each_critic_only(target_action_env):
    model = DENFAC("MlpPolicy", target_action_env(), policy_kwargs=dict(layer_norm=True, net_arch=[16, 8]))
    for q_net in model.critic.q_networks:
        assert [ln.normalized_shape for ln in _layer_norms(q_net)] == [(16,), (8,)]
        layers = list(q_net)
        for i, layer in enumerate(layers[:-1]):  # Linear -> LayerNorm -> activation
            if isinstance(layer, nn.LayerNorm):
                assert isinstance(layers[i - 1], nn.Linear) and isinstance(layers[i + 1], nn.LeakyReLU)
    assert _layer_norms(model.actor) == []
    assert _layer_norms(DENFAC("MlpPolicy", target_action_env()).critic) == []  # off by default


def test_layer_norm_runs_on_the_autograd_updater_and_says_why(target_action_env):
    model = DENFAC("MlpPolicy", target_action_env(), policy_kwargs=dict(layer_norm=True))
    choice = make_updater(model.policy, FitSettings.of(model), "auto")
    assert type(choice.updater).__name__ == "AutogradUpdater" and "default MLP networks" in choice.fast_refused
    fast = DENFAC("MlpPolicy", target_action_env(), policy_kwargs=dict(layer_norm=True), update_path="fast", **SMALL)
    with pytest.raises(ValueError, match="default MLP networks"):
        fast.learn(10)  # the first update


def test_layer_norm_checks_its_value(target_action_env):
    with pytest.raises(ValueError, match="layer_norm must be True or False"):
        DENFAC("MlpPolicy", target_action_env(), policy_kwargs=dict(layer_norm="yes"))


def test_critic_reset_reinitialises_the_layer_norms(target_action_env):
    model = DENFAC("MlpPolicy", target_action_env(), policy_kwargs=dict(layer_norm=True), reset_critic=True, **SMALL)
    model.learn(20)  # two updates, each resetting the critic at every fitted iteration before fitting it
    ln = _layer_norms(model.critic)[0]
    assert not th.equal(ln.weight, th.ones_like(ln.weight))  # fitted since the last reset
    model.policy.reset_critic()
    # exact: a reset writes the initial constants
    assert th.equal(ln.weight, th.ones_like(ln.weight)) and th.equal(ln.bias, th.zeros_like(ln.bias))


def test_save_load_keeps_the_layer_norm(tmp_path, target_action_env):
    kwargs = with_overrides(DENFAC_DATA_EFFICIENT, dict(policy_kwargs=dict(layer_norm=True), **SMALL))
    model = DENFAC("MlpPolicy", target_action_env(), **kwargs).learn(20)
    model.save(tmp_path / "model.zip")
    loaded = DENFAC.load(tmp_path / "model.zip", env=target_action_env())
    assert loaded.policy.layer_norm and len(_layer_norms(loaded.critic)) == 4
    obs = np.stack([target_action_env().observation_space.sample() for _ in range(8)])
    # exact: the same bits saved and read back, evaluated by the same kernels in one process
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])


def test_denfac_preset_is_the_dial_with_a_floor_and_bounds(target_action_env):
    model = DENFAC("MlpPolicy", target_action_env(), **DENFAC_DATA_EFFICIENT)
    assert tuple(model.n_fitted_iterations) == (10, None) and model.update_to_data_ratio == 4.0
    assert model.bootstrap_bounds and not model.policy.layer_norm


def test_denfac_preset_updates_at_least_as_much_as_the_default(target_action_env):
    """Critic steps per episode of 10 steps: the default's K = 10 iterations (the floor), not rho n = 40 steps; and on
    1000-step episodes 80 iterations of 50 steps (4 per env step) where the default stays at 10."""
    from sb3_denfac.denfac.options import fitted_iterations

    preset, default = DENFAC_DATA_EFFICIENT["n_fitted_iterations"], 10
    assert fitted_iterations(preset, 50, 4.0, 10) == fitted_iterations(default, 50, None, 10) == 10
    assert fitted_iterations(preset, 50, 4.0, 1000) == 80
    kwargs = with_overrides(DENFAC_DATA_EFFICIENT, dict(critic_steps=5, actor_steps=1, seed=0))
    model = DENFAC("MlpPolicy", target_action_env(), **kwargs)
    model.learn(20)
    assert {int(state["step"]) for state in model.critic.optimizer.state.values()} == {2 * 10 * 5}


def test_the_preset_is_softdenfac_with_crossqs_critic(target_action_env):
    model = SoftDENFAC("MlpPolicy", target_action_env(), **DATA_EFFICIENT)
    assert not model.frozen_targets and model.batch_size == 128 and model.bootstrap_bounds
    assert tuple(model.n_fitted_iterations) == (10, None) and model.update_to_data_ratio == 1.5
    for q_net in model.critic.q_networks:
        assert [m.num_features for m in q_net.modules() if isinstance(m, BatchRenorm1d)][1:] == [256, 256]
    assert data_efficient(update_to_data_ratio=1)["update_to_data_ratio"] == 1
    assert DATA_EFFICIENT["update_to_data_ratio"] == 1.5  # with_overrides copies


def test_the_preset_keeps_algorithm_1s_floor(target_action_env):
    """After a 10-step episode Algorithm 1's K = 10 fitted iterations of 5 critic steps, not ceil(1.5 x 10 / 5) = 3;
    after a 1000-step one 30 iterations of 50 steps (1.5 per env step)."""
    from sb3_denfac.denfac.options import fitted_iterations

    assert fitted_iterations(DATA_EFFICIENT["n_fitted_iterations"], 50, 1.5, 1000) == 30
    model = SoftDENFAC("MlpPolicy", target_action_env(), **data_efficient(critic_steps=5, actor_steps=1, seed=0))
    model.learn(20)
    assert {int(state["step"]) for state in model.critic.optimizer.state.values()} == {2 * 10 * 5}


def test_the_zoo_expands_the_presets():
    entry = select_entry({"Pendulum-v1": {"policy": "MlpPolicy", "preset": "data_efficient"}}, "Pendulum-v1", "f.yml")
    assert entry["update_to_data_ratio"] == 1.5 and entry["policy_kwargs"]["batch_renorm"] is True
    entry = select_entry({"default": {"policy": "MlpPolicy", "preset": "denfac_data_efficient"}}, "Pendulum-v1", "f.yml")
    assert tuple(entry["n_fitted_iterations"]) == (10, None) and entry["update_to_data_ratio"] == 4.0
    with pytest.raises(ZooConfigError, match="preset 'data_efficient'.* sets soft_denfac's arguments, not denfac's"):
        select_entry({"default": {"preset": "data_efficient"}}, "Pendulum-v1", "f.yml", algo="denfac")


def test_the_presets_name_their_owners():
    from sb3_denfac.zoo.config import ALGORITHMS, PRESETS

    for name, (zoo_name, target) in PRESETS.items():
        assert target.endswith(f":{name.upper()}") and ALGORITHMS[zoo_name].endswith(f":{OWNERS[name.upper()]}")


def test_the_denfac_preset_learns_the_target_action(target_action_env):
    """10-step episodes with the preset's floor of K = 10 iterations (of 5 critic steps) and bounded targets: the actor
    moves to the rewarded action."""
    env = target_action_env()
    model = DENFAC("MlpPolicy", env, gamma=0.9, **with_overrides(DENFAC_DATA_EFFICIENT, SMALL))
    obs = np.stack([env.observation_space.sample() for _ in range(64)])
    start = env.distance_to_target(model, obs)
    model.learn(300)
    end = env.distance_to_target(model, obs)
    assert end < 0.1 and end < start / 2, (start, end)


def test_the_preset_learns_the_target_action(target_action_env):
    """10-step episodes, each followed by the floor's 10 fitted iterations of 5 joint critic steps through the
    batch-renormalised critic (64-64 here for the test's time): the soft actor's mean moves to the rewarded action.
    Over seeds 0-5 the mean distance ends at 0.03-0.12 from 0.45-0.67 (so the margin: below 0.25 and half the start)."""
    env = target_action_env()
    small_critic = dict(net_arch=dict(qf=[64, 64]))
    kwargs = data_efficient(critic_steps=5, actor_steps=5, batch_size=32, seed=1, policy_kwargs=small_critic)
    model = SoftDENFAC("MlpPolicy", env, gamma=0.9, **kwargs)
    obs = np.stack([env.observation_space.sample() for _ in range(64)])
    start = env.distance_to_target(model, obs)
    model.learn(200)
    end = env.distance_to_target(model, obs)
    assert end < 0.25 and end < start / 2, (start, end)
