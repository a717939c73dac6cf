"""DENFAC's soft actor (``ent_coef``): SB3 SAC's squashed Gaussian actor and soft targets inside Algorithm 1's fitted
iterations. Construction, bad input, the targets and the temperature step, save/load, and one learning test."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.sac.policies import Actor as SACActor

from sb3_denfac.denfac import DENFAC
from sb3_denfac.denfac.fast import FastUpdater
from sb3_denfac.denfac.policies import DENFACActor, combine_critics

SMALL = dict(gamma=0.0, n_fitted_iterations=2, critic_steps=20, actor_steps=10, seed=1)


@pytest.fixture
def soft_model(target_action_env):
    def make(**kwargs) -> DENFAC:
        return DENFAC("MlpPolicy", target_action_env(), **{**SMALL, "ent_coef": "auto", **kwargs})

    return make


def test_ent_coef_builds_sacs_actor_and_its_temperature(soft_model, target_action_env):
    model = soft_model()
    assert isinstance(model.actor, SACActor) and model.policy.soft_actor
    assert model.policy.entropy_coefficient().item() == pytest.approx(1.0)  # "auto": from 1, as SB3's SAC
    assert model.policy.target_entropy_value == -1.0  # -dim(A)
    assert model.policy.ent_coef_optimizer is not None
    fixed = soft_model(ent_coef=0.05, target_entropy=-3.0)
    assert fixed.policy.ent_coef_optimizer is None and not fixed.policy.log_ent_coef.requires_grad
    assert fixed.policy.entropy_coefficient().item() == pytest.approx(0.05)
    assert soft_model(ent_coef="auto_0.1").policy.entropy_coefficient().item() == pytest.approx(0.1)
    plain = DENFAC("MlpPolicy", target_action_env(), **SMALL)  # the default: the deterministic actor, no alpha
    assert isinstance(plain.actor, DENFACActor) and not plain.policy.soft_actor and plain.ent_coef is None


def test_bad_input_names_the_cause(soft_model):
    for kwargs, match in [
        (dict(ent_coef="autox"), "ent_coef must be"),
        (dict(ent_coef="auto_-1"), "ent_coef must be"),
        (dict(ent_coef=0.0), "ent_coef must be"),
        (dict(ent_coef=True), "ent_coef must be"),
        (dict(weighting="retrace"), "needs weighting='none'"),
        (dict(prioritized="both"), "not implemented for the soft actor"),
        (dict(policy_kwargs=dict(batch_norm=True)), "no batch norm"),
        (dict(target_entropy="high"), "target_entropy must be"),
        (dict(target_entropy=float("nan")), "target_entropy must be"),
        (dict(target_entropy=float("-inf")), "target_entropy must be"),
        (dict(ent_coef=None, policy_kwargs=dict(soft_actor=True)), "the soft actor is DENFAC's ent_coef option"),
    ]:
        with pytest.raises(ValueError, match=match):
            soft_model(**kwargs)


def test_target_entropy_takes_numpy_numbers(soft_model):
    """SAC's usual -np.prod(action_space.shape) is accepted."""
    assert soft_model(target_entropy=-np.prod((1,))).policy.target_entropy_value == -1.0
    assert soft_model(target_entropy=np.float32(-0.5)).policy.target_entropy_value == -0.5


def test_soft_actor_on_a_matrix_action_space(target_action_env):
    """A Box action space of shape (2, 2): the played and predicted actions have its shape."""
    from gymnasium import spaces

    class MatrixActionEnv(target_action_env):
        def __init__(self):
            super().__init__()
            self.action_space = spaces.Box(-2.0, 2.0, (2, 2), np.float32)

        def step(self, action):
            assert action.shape == (2, 2)
            self.t += 1
            reward = -float((action[0, 0] / 2 - 0.6) ** 2)
            obs = self.np_random.uniform(-1, 1, 2).astype(np.float32)
            return obs, reward, False, self.t >= self.episode_length, {}

    model = DENFAC("MlpPolicy", MatrixActionEnv(), **SMALL, ent_coef="auto").learn(30)
    obs = np.zeros((3, 2), np.float32)
    assert model.predict(obs, deterministic=True)[0].shape == (3, 2, 2)
    assert model.replay_buffer.actions.shape[1:] == (1, 4)


def test_soft_actor_explores_by_sampling(soft_model):
    """Played actions are pi's samples (spread around tanh(m(s)), inside [-1, 1]); D's behaviour mean is tanh(m(s))."""
    model = soft_model()
    model.learn(1)  # sets up the env
    obs = np.repeat(model._last_obs, 200, axis=0)
    sampled = np.stack([model._sample_action(0)[1] for _ in range(50)])
    assert np.all(np.abs(sampled) <= 1.0) and sampled.std() > 0.1  # alpha = 1 at the start: wide
    mean = model.actor(th.as_tensor(obs[:1])).detach().numpy()
    np.testing.assert_allclose(model._last_behaviour_mean, mean, rtol=1e-5, atol=1e-6)
    deterministic = {float(model.predict(obs[:1], deterministic=True)[0][0, 0]) for _ in range(3)}
    assert len(deterministic) == 1


def test_soft_targets_subtract_alpha_log_pi(soft_model, monkeypatch):
    """q = r + gamma (1 - d) (Qbar(s', a') - alpha log pi(a'|s')), a' ~ pi(.|s'), Qbar the critics' mean (eq. 4 with SAC's
    soft value): recomputed from the same draw."""
    model = soft_model(gamma=0.9, batch_size=None, n_fitted_iterations=1, ent_coef=0.3)
    model.learn(40)  # a few episodes in D
    draws = {}
    original = model._target_actions

    def recording(updater, next_obs):
        draws["actions"], draws["log_prob"] = original(updater, next_obs)
        return draws["actions"], draws["log_prob"]

    monkeypatch.setattr(model, "_target_actions", recording)
    critic_state = {k: v.clone() for k, v in model.critic.state_dict().items()}
    model._update()
    data = model.replay_buffer.all_samples()
    model.critic.load_state_dict(critic_state)  # Q_{k-1}: the critic before the update
    with th.no_grad():
        q_bar = combine_critics(model.critic.all_q(data.next_observations, draws["actions"]), "mean")
    expected = data.rewards + 0.9 * (1 - data.dones) * (q_bar - 0.3 * draws["log_prob"])
    th.testing.assert_close(model._last_update_stats["q_targets"], expected, rtol=1e-5, atol=1e-5)
    assert draws["log_prob"].shape == (data.rewards.shape[0], 1)


def test_tuned_alpha_follows_the_entropy(soft_model):
    """SAC's eq. 18: alpha falls while the policy's entropy is above the target and rises below it."""
    high = soft_model(target_entropy=-5.0).learn(100)  # far below the starting entropy: alpha falls
    low = soft_model(target_entropy=5.0).learn(100)  # above what a 1-d squashed Gaussian reaches: alpha rises
    assert high.policy.entropy_coefficient().item() < 0.99 < 1.01 < low.policy.entropy_coefficient().item()
    assert high.logger.name_to_value["train/ent_coef"] == pytest.approx(high.policy.entropy_coefficient().item())


def test_fast_updater_fits_the_critic_only(soft_model):
    model = soft_model(update_path="fast")
    updater = model._make_updater()
    assert isinstance(updater, FastUpdater) and updater.actor_net is None and len(updater.critic_nets) == 2


def test_a_fixed_alpha_is_the_models_ent_coef_after_a_load(tmp_path, soft_model, target_action_env):
    """As SB3's SAC: a fixed alpha is not a saved value; ``load(..., ent_coef=x)`` trains on with x."""
    soft_model(ent_coef=0.1).learn(40).save(tmp_path / "model.zip")
    assert DENFAC.load(tmp_path / "model.zip").policy.entropy_coefficient().item() == pytest.approx(0.1)
    loaded = DENFAC.load(tmp_path / "model.zip", env=target_action_env(), ent_coef=0.5)
    assert loaded.policy.entropy_coefficient().item() == pytest.approx(0.5)


def test_save_load_is_exact(tmp_path, soft_model, target_action_env):
    """The file keeps the actor, alpha and alpha's Adam state: a reloaded model continues exactly as the original."""
    model = soft_model(ent_coef="auto_0.5", target_entropy=-0.5).learn(60)
    model.save(tmp_path / "model.zip")
    loaded = DENFAC.load(tmp_path / "model.zip", env=target_action_env())
    assert isinstance(loaded.actor, SACActor) and (loaded.ent_coef, loaded.target_entropy) == ("auto_0.5", -0.5)
    assert loaded.policy.log_ent_coef.item() == model.policy.log_ent_coef.item() != np.log(0.5)
    before = model.policy.ent_coef_optimizer.state_dict()["state"][0]
    after = loaded.policy.ent_coef_optimizer.state_dict()["state"][0]
    assert float(before["step"]) == float(after["step"]) > 0
    th.testing.assert_close(after["exp_avg_sq"], before["exp_avg_sq"])
    for name, value in model.policy.state_dict().items():
        th.testing.assert_close(loaded.policy.state_dict()[name], value, msg=name)
    # the same update from the same state and seed
    loaded.replay_buffer = model.replay_buffer
    loaded.set_logger(model.logger)
    for m in (model, loaded):
        th.manual_seed(3)
        m._update()
    for name, value in model.policy.state_dict().items():
        th.testing.assert_close(loaded.policy.state_dict()[name], value, msg=name)


def test_soft_actor_learns_target_action(target_action_env):
    """The soft actor's deterministic action tanh(m(s)) moves to the rewarded action 0.6, as the deterministic actor
    does in test_default_configuration_learns_target_action. alpha starts at 0.01: from "auto"'s 1 it falls by about
    1e-3 per actor step, and against rewards of order 0.1 the entropy term holds the mean back for the first few
    hundred steps (measured: 0.13-0.16 off at 200 steps, 0.06-0.11 at 400)."""
    env = target_action_env()
    model = DENFAC("MlpPolicy", env, **SMALL, ent_coef="auto_0.01")
    obs = np.stack([env.observation_space.sample() for _ in range(64)])
    start = np.abs(model.predict(obs, deterministic=True)[0] - 0.6).mean()
    model.learn(200)
    end = np.abs(model.predict(obs, deterministic=True)[0] - 0.6).mean()
    assert end < 0.1 and end < start / 2, (start, end)


def test_soft_actor_swings_pendulum_up():
    """Pendulum-v1, 12 episodes of 200 steps with the library settings and the soft actor (bootstrap_bounds, as
    benchmarked): the last deterministic episode swings up (return above -400; a random or untrained policy scores
    -1000 to -1600)."""
    env = gym.make("Pendulum-v1")
    model = DENFAC("MlpPolicy", env, ent_coef="auto", bootstrap_bounds=True, seed=0)
    model.learn(12 * 200)
    eval_env = gym.make("Pendulum-v1")
    returns = []
    for seed in range(3):
        obs, _ = eval_env.reset(seed=100 + seed)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = eval_env.step(model.predict(obs, deterministic=True)[0])
            total, done = total + reward, terminated or truncated
        returns.append(total)
    assert np.median(returns) > -400, returns
