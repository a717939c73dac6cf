"""DENFAC-specific tests (Algorithm 1 as an SB3 algorithm). Shared pieces are tested in tests/test_common.py."""

from __future__ import annotations

import copy
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from scipy import stats
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
from torch import nn

from sb3_denfac.common.truncated_normal import clamp_mean
from sb3_denfac.denfac import DENFAC, DENFACReplayBuffer
from sb3_denfac.denfac.presets import paper
from sb3_denfac.denfac.updaters import AutogradUpdater


def test_buffer_stores_behaviour_means_and_actions_in_bounds(make_denfac):
    model = make_denfac().learn(50)  # one 50-step episode, then one update
    actor = copy.deepcopy(model.actor)
    actor.set_training_mode(False)
    model.learn(50, reset_num_timesteps=False)  # the second episode is played by that actor
    buffer = model.replay_buffer
    n = buffer.size()
    assert n == 100
    actions, means = buffer.actions[:n, 0], buffer.behaviour_means[:n, 0]
    assert np.all(np.abs(actions) <= 1.0)
    assert np.all(np.isfinite(means)) and np.all(np.abs(means) <= 1.0 + 3 * model.sigma)
    # The stored mean is the actor output for the stored observation after the update that preceded it.
    with th.no_grad():
        played = actor(th.as_tensor(buffer.observations[50:100, 0])).numpy()
    np.testing.assert_allclose(means[50:100], clamp_mean(played, -1.0, 1.0, model.sigma), rtol=1e-5, atol=1e-6)


def test_importance_weights_of_the_update_path_match_scipy(make_denfac):
    model = make_denfac(n_fitted_iterations=1, weighting="retrace", sigma=0.2).learn(100)
    actor_before = copy.deepcopy(model.actor)
    data = model.replay_buffer.all_samples()
    model._update()
    weights = model.last_update.weights.squeeze(1).numpy()
    with th.no_grad():
        target_means = actor_before(data.observations).numpy()
    a, mu_b = data.actions.numpy(), data.behaviour_means.numpy()

    def log_density(mean):
        mean = np.clip(mean, -1 - 3 * 0.2, 1 + 3 * 0.2)
        lo, hi = (-1 - mean) / 0.2, (1 - mean) / 0.2
        return stats.truncnorm.logpdf(a, lo, hi, loc=mean, scale=0.2).sum(axis=1)

    expected = np.minimum(1.0, np.exp(log_density(target_means) - log_density(mu_b)))
    np.testing.assert_allclose(weights, expected, rtol=1e-4, atol=1e-6)
    assert weights.min() < 1.0  # the actor moved since the data was played: some samples are down-weighted

    model.weighting = "none"
    model._update()
    assert th.all(model.last_update.weights == 1.0)


class IncreasingQ(nn.Module):
    """A critic whose value always grows with the action: pushes an unbounded actor beyond the upper bound."""

    def forward(self, obs, actions):
        return 100.0 * actions.sum(dim=1, keepdim=True)

    target_q = forward  # the updaters' critic interface (DENFACCritic's): one Q network

    def all_q(self, obs, actions):
        return [self(obs, actions)]

    @property
    def q_networks(self):
        return [self]

    def set_training_mode(self, mode):
        self.train(mode)


@pytest.mark.parametrize("inverting", [True, False])
def test_inverting_gradients_keep_actor_in_bounds(make_denfac, inverting):
    model = make_denfac(inverting_gradients=inverting, actor_steps=300, actor_learning_rate=0.05, max_grad_norm=None)
    model.learn(60)
    model.policy.critic = IncreasingQ()  # not an MLP: the autograd updater runs
    obs = model.replay_buffer.all_samples().observations
    updater = model.make_updater()
    assert isinstance(updater, AutogradUpdater)
    updater.fit_actor(obs)
    with th.no_grad():
        model.actor.set_training_mode(False)
        actions = model.actor(obs)
    if inverting:
        assert actions.max() <= 1.05 and actions.max() > 0.9  # Adam may overshoot by a step
    else:
        assert actions.max() > 1.5  # without inverting gradients the linear output leaves the bounds


def test_one_update_changes_both_networks_and_stays_finite(make_denfac):
    model = make_denfac(reset_critic=True).learn(60)
    actor_before = copy.deepcopy(model.actor.state_dict())
    critic_before = copy.deepcopy(model.critic.state_dict())
    model._update()
    assert any(not th.equal(actor_before[k], v) for k, v in model.actor.state_dict().items())
    assert any(not th.equal(critic_before[k], v) for k, v in model.critic.state_dict().items())
    values = model.logger.name_to_value
    for key in (
        "critic_loss",
        "actor_loss",
        "importance_weight_mean",
        "importance_weight_min",
        "q_target_mean",
        "update_time",
    ):
        assert np.isfinite(values[f"train/{key}"]), key
    assert values["train/n_transitions"] == model.replay_buffer.size() and values["train/n_updates"] >= 1


def test_timeouts_bootstrap_or_not(make_denfac):
    model = make_denfac(gamma=0.9).learn(100)  # Pendulum: episodes of 50 steps end by time limit only
    data = model.replay_buffer.all_samples()
    assert data.timeouts.sum() == 2 and data.dones.sum() == 0
    timeout = data.timeouts.squeeze(1).bool()
    model.bootstrap_on_timeout = True
    model._update()
    assert not th.allclose(model.last_update.q_targets[timeout], data.rewards[timeout])
    model.bootstrap_on_timeout = False  # paper-era authors' code: time-limit ends are terminal
    model._update()
    th.testing.assert_close(model.last_update.q_targets[timeout], data.rewards[timeout])


def test_minibatch_and_box_bounds(make_denfac, target_action_env):
    env = target_action_env(low=-3.0, high=5.0)
    model = make_denfac(env, batch_size=16, buffer_size=50).learn(40)
    obs = np.stack([env.observation_space.sample() for _ in range(32)])
    actions, _ = model.predict(obs, deterministic=True)
    assert np.all(actions >= -3.0) and np.all(actions <= 5.0)
    actions, _ = model.predict(obs, deterministic=False)
    assert np.all(actions >= -3.0) and np.all(actions <= 5.0)


def test_save_load_exact(make_denfac, tmp_path):
    env = gym.make("Pendulum-v1", max_episode_steps=50)
    model = make_denfac(env).learn(100)
    obs = np.stack([env.observation_space.sample() for _ in range(16)])
    actions, _ = model.predict(obs, deterministic=True)
    model.save(tmp_path / "denfac.zip")
    model.save_replay_buffer(tmp_path / "buffer.pkl")
    loaded = DENFAC.load(tmp_path / "denfac.zip", env=env)
    # exact: the same bits saved and read back, evaluated by the same kernels in one process
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], actions)
    for name, value in model.policy.state_dict().items():  # includes BN running statistics
        assert th.equal(value, loaded.policy.state_dict()[name]), name
    assert any("running_mean" in name for name in model.policy.state_dict())
    assert loaded.n_fitted_iterations == model.n_fitted_iterations and loaded.weighting == model.weighting
    loaded.load_replay_buffer(tmp_path / "buffer.pkl")
    assert isinstance(loaded.replay_buffer, DENFACReplayBuffer)
    np.testing.assert_array_equal(loaded.replay_buffer.behaviour_means, model.replay_buffer.behaviour_means)
    loaded.learn(50, reset_num_timesteps=False)
    assert loaded.num_timesteps == 150 and loaded.replay_buffer.size() == 150


def test_vecnormalize_callbacks_progress_bar(make_denfac, tmp_path):
    venv = VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1", max_episode_steps=50)]), gamma=0.99)
    calls = []

    def callback(locals_, globals_):
        calls.append(1)
        return True

    model = make_denfac(venv, tensorboard_log=str(tmp_path)).learn(100, callback=callback, progress_bar=True)
    assert len(calls) == 100 and model._n_updates == 2
    assert any(tmp_path.rglob("events.out.tfevents*"))


def test_errors():
    with pytest.raises(ValueError, match="Box"):
        DENFAC("MlpPolicy", "CartPole-v1")
    for kwargs, name in [
        (dict(n_fitted_iterations=0), "n_fitted_iterations"),
        (dict(actor_steps=-1), "actor_steps"),
        (dict(critic_steps=0), "critic_steps"),
        (dict(sigma=0.0), "sigma"),
        (dict(weighting="bogus"), "weighting"),
        (dict(buffer_size=100), "max_episode_steps"),  # Pendulum episodes last 200 steps
    ]:
        with pytest.raises(ValueError, match=name):
            DENFAC("MlpPolicy", "Pendulum-v1", **kwargs)


def test_learns_target_action(target_action_env):
    """The deterministic actor must move from ~0 to the rewarded action 0.6 (scaled); fails if updates are broken."""
    env = target_action_env()
    model = DENFAC(
        "MlpPolicy",
        env,
        seed=1,
        **paper(
            buffer_size=200,
            gamma=0.0,
            sigma=0.3,
            n_fitted_iterations=3,
            critic_steps=20,
            actor_steps=25,
            critic_learning_rate=0.01,
            actor_learning_rate=0.01,
            policy_kwargs=dict(net_arch=dict(pi=[8], qf=[16, 4])),
        ),
    )
    obs = np.stack([env.observation_space.sample() for _ in range(64)])
    start = env.distance_to_target(model, obs)
    model.learn(300)
    end = env.distance_to_target(model, obs)
    assert start > 0.4 and end < 0.15, (start, end)


def test_default_configuration_learns_target_action(target_action_env):
    """DENFAC("MlpPolicy", env) with its defaults only (but fewer steps per update) moves the actor to the rewarded
    action: mini-batches, a kept actor and critic, no weights, no batch norm."""
    env = target_action_env()
    model = DENFAC("MlpPolicy", env, gamma=0.0, n_fitted_iterations=2, critic_steps=20, actor_steps=10, seed=1)
    assert model.batch_size == 256 and not model.reset_actor and model.weighting == "none"
    assert not model.policy.actor.batch_norm and model.policy.net_arch == {"pi": [64, 64], "qf": [64, 64]}
    assert model.critic.n_critics == 2 and model.actor_proximal == 1.0
    obs = np.stack([env.observation_space.sample() for _ in range(64)])
    start = env.distance_to_target(model, obs)
    model.learn(200)
    end = env.distance_to_target(model, obs)
    assert end < 0.1 and end < start / 2, (start, end)


@pytest.mark.parametrize("update_path", ["fast", "plain"])
def test_one_transition_buffer_waits_for_the_next_episode(make_denfac, update_path, target_action_env):
    """Batch norm has no statistics for one sample: after a one-step first episode the update waits (no crash)."""

    class OneStepFirstEpisodeEnv(target_action_env):
        """The first episode ends after one step, later ones after ten."""

        def reset(self, *, seed=None, options=None):
            self.episode_length = 1 if not hasattr(self, "_started") else 10
            self._started = True
            return super().reset(seed=seed, options=options)

    model = make_denfac(OneStepFirstEpisodeEnv(), update_path=update_path)
    model.learn(1)
    assert model.replay_buffer.size() == 1 and model._n_updates == 0
    model.learn(10, reset_num_timesteps=False)
    assert model._n_updates == 1


def test_model_saved_by_version_0_1_loads_with_its_own_defaults():
    """sb3-denfac 0.1 saved no net_arch/batch_norm/init when they were defaults: it loads with the paper's
    networks it was built with (not 0.2's defaults) and predicts as when it was saved (to float32 rounding)."""
    data = Path(__file__).parent / "data"
    model = DENFAC.load(data / "denfac_v0.1_pendulum.zip", device="cpu")
    assert model.policy.net_arch == {"pi": [20], "qf": [50, 7]} and model.policy.actor.batch_norm
    assert model.weighting == "retrace" and model.reset_actor and model.batch_size is None
    assert model.actor_proximal == 0.0  # no proximal actor then (the 0.3 default is 1.0)
    obs = np.load(data / "denfac_v0.1_pendulum_obs.npy")
    # rtol 1e-5: one forward pass (BN, two layers) on another CPU's float32 kernels differs by an ulp (1e-7, measured)
    actions = np.load(data / "denfac_v0.1_pendulum_actions.npy")
    np.testing.assert_allclose(model.predict(obs, deterministic=True)[0], actions, rtol=1e-5, atol=1e-6)
    model.set_env(gym.make("Pendulum-v1", max_episode_steps=50))
    model.learn(50, reset_num_timesteps=False)  # and trains on
