"""DENFAC-specific tests (Algorithm 1 as an SB3 algorithm). Shared pieces are tested in tests/test_common.py."""

from __future__ import annotations

import copy
import os

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from scipy import stats
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
from torch import nn
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_leaves

from sb3_denfac.common.inverting_gradients import invert_gradients_unit_box
from sb3_denfac.denfac import DENFAC, DENFACReplayBuffer, eager_steps
from sb3_denfac.denfac.fast import FastUpdate, supported_networks

SMALL = dict(
    buffer_size=200,
    n_fitted_iterations=2,
    critic_steps=3,
    actor_steps=4,
    policy_kwargs=dict(net_arch=dict(pi=[8], qf=[16, 4])),
)


class TargetActionEnv(gym.Env):
    """Bandit-like episodes of 10 steps: obs ~ U(-1, 1)^2, reward -(a - 0.6)^2, gamma irrelevant (time limit)."""

    def __init__(self, low: float = -1.0, high: float = 1.0, episode_length: int = 10):
        self.observation_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.action_space = spaces.Box(low, high, (1,), np.float32)
        self.target = low + 0.8 * (high - low)  # 0.6 in the scaled space
        self.episode_length = episode_length

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self.np_random.uniform(-1, 1, 2).astype(np.float32), {}

    def step(self, action):
        self.t += 1
        scaled = 2 * (float(action[0]) - self.action_space.low[0]) / (self.action_space.high[0] - self.action_space.low[0]) - 1
        reward = -((scaled - 0.6) ** 2)
        truncated = self.t >= self.episode_length
        return self.np_random.uniform(-1, 1, 2).astype(np.float32), reward, False, truncated, {}


class MultiActionEnv(gym.Env):
    """4-d observations, 3-d actions, reward -|a - obs[:3] / 2|^2 (for the several-action code paths)."""

    def __init__(self):
        self.observation_space = spaces.Box(-1.0, 1.0, (4,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.obs = self.np_random.uniform(-1, 1, 4).astype(np.float32)
        return self.obs, {}

    def step(self, action):
        reward = -float(np.sum((np.asarray(action) - self.obs[:3] / 2) ** 2))
        self.obs = self.np_random.uniform(-1, 1, 4).astype(np.float32)
        return self.obs, reward, False, False, {}


def make_model(env=None, **kwargs) -> DENFAC:
    params = {**SMALL, **kwargs}
    return DENFAC("MlpPolicy", env or gym.make("Pendulum-v1", max_episode_steps=50), seed=0, **params)


def test_buffer_stores_behaviour_means_and_actions_in_bounds():
    model = make_model().learn(100)
    buffer = model.replay_buffer
    n = buffer.size()
    assert n == 100
    actions, means = buffer.actions[:n, 0], buffer.behaviour_means[:n, 0]
    assert np.all(np.abs(actions) <= 1.0)
    assert np.all(np.isfinite(means)) and np.all(np.abs(means) <= 1.0 + 3 * model.sigma)
    # The stored mean is the actor output for the stored observation after the update that preceded it.
    assert not np.allclose(means, 0.0)


def test_importance_weights_of_the_update_path_match_scipy():
    model = make_model(n_fitted_iterations=1, weighting="retrace", sigma=0.2).learn(100)
    actor_before = copy.deepcopy(model.actor)
    data = model.replay_buffer.all_samples()
    model._update()
    weights = model._last_update_stats["weights"].squeeze(1).numpy()
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
    assert th.all(model._last_update_stats["weights"] == 1.0)


class IncreasingQ(nn.Module):
    """A critic whose value always grows with the action: pushes an unbounded actor beyond the upper bound."""

    def forward(self, obs, actions):
        return 100.0 * actions.sum(dim=1, keepdim=True)

    def set_training_mode(self, mode):
        self.train(mode)


@pytest.mark.parametrize("inverting", [True, False])
def test_inverting_gradients_keep_actor_in_bounds(inverting):
    model = make_model(inverting_gradients=inverting, actor_steps=300, actor_learning_rate=0.05, max_grad_norm=None)
    model.learn(60)
    model.critic = IncreasingQ()
    obs = model.replay_buffer.all_samples().observations
    model._fit_actor(obs)
    with th.no_grad():
        model.actor.set_training_mode(False)
        actions = model.actor(obs)
    if inverting:
        assert actions.max() <= 1.05 and actions.max() > 0.9  # Adam may overshoot by a step
    else:
        assert actions.max() > 1.5  # without inverting gradients the linear output leaves the bounds


def test_one_update_changes_both_networks_and_stays_finite():
    model = make_model(reset_critic=True).learn(60)
    actor_before = copy.deepcopy(model.actor.state_dict())
    critic_before = copy.deepcopy(model.critic.state_dict())
    model._update()
    assert any(not th.equal(actor_before[k], v) for k, v in model.actor.state_dict().items())
    assert any(not th.equal(critic_before[k], v) for k, v in model.critic.state_dict().items())
    values = model.logger.name_to_value
    for key in ("critic_loss", "actor_objective", "importance_weight_mean", "importance_weight_min", "q_mean", "update_time"):
        assert np.isfinite(values[f"train/{key}"]), key
    assert values["train/buffer_size"] == model.replay_buffer.size() and values["train/n_updates"] >= 1


def test_timeouts_bootstrap_or_not():
    model = make_model(gamma=0.9).learn(100)  # Pendulum: episodes of 50 steps end by time limit only
    data = model.replay_buffer.all_samples()
    assert data.timeouts.sum() == 2 and data.dones.sum() == 0
    timeout = data.timeouts.squeeze(1).bool()
    model.bootstrap_on_timeout = True
    model._update()
    assert not th.allclose(model._last_update_stats["q_targets"][timeout], data.rewards[timeout])
    model.bootstrap_on_timeout = False  # paper-era authors' code: time-limit ends are terminal
    model._update()
    th.testing.assert_close(model._last_update_stats["q_targets"][timeout], data.rewards[timeout])


def test_minibatch_and_box_bounds():
    env = TargetActionEnv(low=-3.0, high=5.0)
    model = make_model(env, batch_size=16, buffer_size=50).learn(40)
    obs = np.stack([env.observation_space.sample() for _ in range(32)])
    actions, _ = model.predict(obs, deterministic=True)
    assert np.all(actions >= -3.0) and np.all(actions <= 5.0)
    actions, _ = model.predict(obs, deterministic=False)
    assert np.all(actions >= -3.0) and np.all(actions <= 5.0)


def test_save_load_exact(tmp_path):
    env = gym.make("Pendulum-v1", max_episode_steps=50)
    model = make_model(env).learn(100)
    obs = np.stack([env.observation_space.sample() for _ in range(16)])
    actions, _ = model.predict(obs, deterministic=True)
    model.save(tmp_path / "denfac.zip")
    model.save_replay_buffer(tmp_path / "buffer.pkl")
    loaded = DENFAC.load(tmp_path / "denfac.zip", env=env)
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


def test_vecnormalize_callbacks_progress_bar(tmp_path):
    venv = VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1", max_episode_steps=50)]), gamma=0.99)
    calls = []

    def callback(locals_, globals_):
        calls.append(1)
        return True

    model = make_model(venv, tensorboard_log=str(tmp_path)).learn(100, callback=callback, progress_bar=True)
    assert len(calls) == 100 and model._n_updates == 2
    assert any(tmp_path.rglob("events.out.tfevents*"))


def test_errors():
    with pytest.raises(ValueError, match="Box"):
        DENFAC("MlpPolicy", "CartPole-v1")
    with pytest.raises(ValueError, match="n_envs=2"):
        DENFAC("MlpPolicy", make_vec_env("Pendulum-v1", n_envs=2))
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


def test_learns_target_action():
    """The deterministic actor must move from ~0 to the rewarded action 0.6 (scaled); fails if updates are broken."""
    env = TargetActionEnv()
    model = DENFAC(
        "MlpPolicy",
        env,
        buffer_size=200,
        gamma=0.0,
        sigma=0.3,
        n_fitted_iterations=3,
        critic_steps=20,
        actor_steps=25,
        critic_learning_rate=0.01,
        actor_learning_rate=0.01,
        policy_kwargs=dict(net_arch=dict(pi=[8], qf=[16, 4])),
        seed=1,
    )
    obs = np.stack([env.observation_space.sample() for _ in range(64)])
    start = np.abs(model.predict(obs, deterministic=True)[0] - 0.6).mean()
    model.learn(300)
    end = np.abs(model.predict(obs, deterministic=True)[0] - 0.6).mean()
    assert start > 0.4 and end < 0.15, (start, end)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(),
        dict(reset_critic=True, weighting="retrace_next_state_quirk"),
        dict(inverting_gradients=False, batch_size=32, reset_actor=False),
        # several actions (the critic's action input as a matmul) and a deeper actor (BN backward through the input);
        # PyTorch's init: from N(0, 0.01) weights many actor gradient components are rounding-sized, and Adam with
        # beta1 = 0 turns their sign into lr-sized steps (the gradients themselves agree: test_eager_gradients_...)
        dict(env="multi_action", policy_kwargs=dict(net_arch=dict(pi=[8, 6], qf=[16, 4]), init="default")),
        dict(policy_kwargs=dict(net_arch=dict(pi=[8], qf=[16, 4]), bn_momentum=0.1)),  # running averages kept
        dict(policy_kwargs=dict(net_arch=dict(pi=[8], qf=[16, 4]), batch_norm=False)),
    ],
)
def test_fast_and_plain_paths_agree(kwargs):
    """Speed never changes the algorithm: same seed -> same losses, parameters, BN statistics and Adam moments.

    A moderate step size keeps the comparison meaningful: with beta1 = 0 Adam's first steps are lr * sign(g), so at
    large rates float rounding in near-zero gradient components is amplified (both paths are then equally valid).
    """
    kwargs = dict(kwargs)
    if kwargs.pop("env", None) == "multi_action":
        env = gym.wrappers.TimeLimit(MultiActionEnv(), max_episode_steps=50)
    else:
        env = gym.make("Pendulum-v1", max_episode_steps=50)
    models = {}
    for path in ("plain", "fast"):
        models[path] = make_model(env, update_path=path, learning_rate=0.01, **kwargs).learn(100)
    plain, fast = models["plain"], models["fast"]
    for key in ("train/critic_loss", "train/actor_objective", "train/q_mean", "train/importance_weight_mean"):
        assert plain.logger.name_to_value[key] == pytest.approx(fast.logger.name_to_value[key], rel=1e-4, abs=1e-5), key
    fast_state = fast.policy.state_dict()
    for name, value in plain.policy.state_dict().items():
        th.testing.assert_close(fast_state[name], value, rtol=1e-4, atol=1e-5, msg=name)
    for net in ("actor", "critic"):
        plain_opt = getattr(plain, net).optimizer.state_dict()["state"]
        fast_opt = getattr(fast, net).optimizer.state_dict()["state"]
        assert plain_opt.keys() == fast_opt.keys()
        for i in plain_opt:
            assert float(plain_opt[i]["step"]) == float(fast_opt[i]["step"])
            th.testing.assert_close(fast_opt[i]["exp_avg_sq"], plain_opt[i]["exp_avg_sq"], rtol=1e-3, atol=1e-9)
    # A plain update after fast ones continues from the same Adam state (paths are interchangeable mid-training).
    fast.update_path = "plain"
    fast.learn(50, reset_num_timesteps=False)
    assert np.isfinite(fast.logger.name_to_value["train/critic_loss"])


class _LargeAllocations(TorchDispatchMode):
    """Counts op outputs of at least ``min_numel`` elements that are new memory (not an input, an out= or a view)."""

    def __init__(self, min_numel: int):
        super().__init__()
        self.min_numel, self.count = min_numel, 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        out = func(*args, **kwargs)
        inputs = {t.untyped_storage().data_ptr() for t in tree_leaves((args, kwargs)) if isinstance(t, th.Tensor)}
        for t in tree_leaves(out):
            if isinstance(t, th.Tensor) and t.numel() >= self.min_numel and t.untyped_storage().data_ptr() not in inputs:
                self.count += 1
        return out


def _large_allocations_per_update(update_path: str, steps: int, inverting_gradients: bool) -> int:
    model = make_model(
        gym.make("Pendulum-v1", max_episode_steps=200),
        buffer_size=200,
        critic_steps=steps,
        actor_steps=steps,
        inverting_gradients=inverting_gradients,
        update_path=update_path,
        policy_kwargs=dict(net_arch=dict(pi=[8, 8], qf=[16, 4])),
    )
    model.learn(200)  # one episode: a full buffer
    mode = _LargeAllocations(min_numel=2 * 200)
    with mode:
        model._update()
    return mode.count


@pytest.mark.parametrize("inverting_gradients", [True, False])
def test_fast_path_allocates_nothing_per_step(inverting_gradients):
    """The eager fast path writes its (features, N) activations into buffers made once per fit: the number of large
    allocations of an update does not grow with the number of critic and actor steps (fresh per-step tensors made
    the allocator map and fault in pages, which slowed updates 2-3x at random). The plain path shows the counter
    sees per-step allocations."""
    fast = [_large_allocations_per_update("fast", steps, inverting_gradients) for steps in (2, 6)]
    assert fast[0] == fast[1], fast
    plain = [_large_allocations_per_update("plain", steps, inverting_gradients) for steps in (2, 6)]
    assert plain[1] > plain[0] + 8, plain


@pytest.mark.parametrize("batch_size", [None, 16])
def test_fast_path_is_device_agnostic(batch_size):
    """The fast update runs on PyTorch's "meta" device (shapes only, no data): a tensor made on the CPU by default,
    a host read of device data or a CPU-only kernel would raise. The stand-in for device="cuda" on GPU-less CI."""
    model = make_model(batch_size=batch_size, policy_kwargs=dict(net_arch=dict(pi=[8, 8], qf=[16, 4])))
    policy = model.policy.to("meta")
    fast = FastUpdate(policy, *supported_networks(policy), batch_size=batch_size)
    n = 64
    obs, actions = th.randn(n, 3, device="meta"), th.randn(n, 1, device="meta")
    q_targets, weights = th.randn(n, 1, device="meta"), th.rand(n, 1, device="meta")

    def batch_indices(size):
        return None if batch_size is None else th.randperm(size, device="meta")[:batch_size]

    assert fast.actor_eval(obs).device.type == "meta" and fast.actor_eval(obs).shape == (n, 1)
    assert fast.critic_eval(obs, actions).shape == (n, 1)
    for net, flat in ((policy.critic, fast.critic), (policy.actor, fast.actor)):
        model._reset_bn_statistics(net, flat)  # as every fit of DENFAC._update does
    loss = fast.fit_critic(obs, actions, q_targets, weights, 3, 10.0, batch_indices)
    objective = fast.fit_actor(obs, 3, 10.0, True, batch_indices)
    fast.write_back()
    assert loss.device.type == objective.device.type == "meta"


@pytest.mark.parametrize("inverting_gradients", [True, False])
def test_eager_gradients_equal_autograd(inverting_gradients):
    """One critic and one actor gradient of the eager fast steps equal autograd's on the modules (no Adam in between
    to amplify rounding), with several actions, two BN layers per network and random BN parameters and statistics."""
    th.manual_seed(0)
    env = gym.wrappers.TimeLimit(MultiActionEnv(), max_episode_steps=50)
    policy = make_model(env, policy_kwargs=dict(net_arch=dict(pi=[8, 6], qf=[16, 4]))).policy
    for module in policy.modules():
        if isinstance(module, nn.Linear):
            nn.init.normal_(module.weight, std=0.5)
            nn.init.normal_(module.bias, std=0.1)
        if isinstance(module, nn.BatchNorm1d):
            nn.init.normal_(module.weight, 1.0, 0.2)
            nn.init.normal_(module.bias, 0.0, 0.2)
            module.running_mean.normal_()
            module.running_var.uniform_(0.5, 2.0)
    n = 64
    obs, actions, q_targets, weights = th.randn(n, 4), th.rand(n, 3) * 2 - 1, th.randn(n, 1), th.rand(n, 1)
    # autograd on the modules (the plain path's losses)
    policy.critic.set_training_mode(True)
    loss = (weights * (policy.critic(obs, actions) - q_targets).pow(2)).mean()
    critic_grad = th.cat([g.reshape(-1) for g in th.autograd.grad(loss, list(policy.critic.qf.parameters()))])
    policy.critic.set_training_mode(False)
    policy.actor.set_training_mode(True)
    pi = policy.actor(obs)
    q_values = policy.critic(obs, pi)
    actor_params = list(policy.actor.mu.parameters())
    if inverting_gradients:
        (dq_da,) = th.autograd.grad(q_values.mean(), pi, retain_graph=True)
        inverted = th.where(dq_da > 0, dq_da * (1 - pi) / 2, dq_da * (pi + 1) / 2).detach()
        actor_grad = th.autograd.grad(pi, actor_params, grad_outputs=-inverted)
    else:
        actor_grad = th.autograd.grad(-q_values.mean(), actor_params)
    actor_grad = th.cat([g.reshape(-1) for g in actor_grad])
    policy.set_training_mode(False)
    # the eager steps' forward and backward
    fast = FastUpdate(policy, *supported_networks(policy))
    with th.no_grad():
        x = th.cat([obs, actions], 1).t().contiguous()
        ws = eager_steps.Workspace(fast.critic.spec.sizes, n, x)
        # per-step batch statistics (mini-batches) and the input normalised once (full-batch fits)
        for fixed in (None, eager_steps.FixedStats(x, ws.centred, fast.critic.spec.eps[0])):
            folds = eager_steps.forward_train(fast.critic, ws, x, fixed)
            diff = ws.outputs[-1] - q_targets.t()
            eager_steps.backward(fast.critic, ws, x, folds, diff * weights.t() * (2.0 / n))
            th.testing.assert_close(fast.critic.grad, critic_grad, rtol=1e-5, atol=1e-6)
        affines = fast.critic.eval_affines()
        obs_part = th.addmm(affines[0][1].unsqueeze(1), affines[0][0][:, :-3], obs.t())
        critic = eager_steps.EvalCritic(affines, fast.critic.spec.slopes, obs_part, 3, fast.critic.spec.sizes, n)
        ws = eager_steps.Workspace(fast.actor.spec.sizes, n, x)
        obs_t = obs.t().contiguous()
        for fixed in (None, eager_steps.FixedStats(obs_t, ws.centred, fast.actor.spec.eps[0])):
            folds = eager_steps.forward_train(fast.actor, ws, obs_t, fixed)
            ascent, value = critic.action_gradient(ws.outputs[-1], want_value=True)
            assert value.item() == pytest.approx(q_values.mean().item(), rel=1e-5)
            if inverting_gradients:
                ascent = invert_gradients_unit_box(ascent, ws.outputs[-1])
            eager_steps.backward(fast.actor, ws, obs_t, folds, -ascent)
            th.testing.assert_close(fast.actor.grad, actor_grad, rtol=1e-5, atol=1e-6)


class OneStepFirstEpisodeEnv(TargetActionEnv):
    """The first episode ends after one step, later ones after ten."""

    def reset(self, *, seed=None, options=None):
        self.episode_length = 1 if not hasattr(self, "_started") else 10
        self._started = True
        return super().reset(seed=seed, options=options)


@pytest.mark.parametrize("update_path", ["fast", "plain"])
def test_one_transition_buffer_waits_for_the_next_episode(update_path):
    """Batch norm has no statistics for one sample: after a one-step first episode the update waits (no crash)."""
    model = make_model(OneStepFirstEpisodeEnv(), update_path=update_path)
    model.learn(1)
    assert model.replay_buffer.size() == 1 and model._n_updates == 0
    model.learn(10, reset_num_timesteps=False)
    assert model._n_updates == 1


def test_update_path_errors():
    with pytest.raises(ValueError, match="update_path"):
        make_model(update_path="turbo")
    model = make_model(update_path="fast", policy_kwargs=dict(optimizer_class=th.optim.SGD))
    with pytest.raises(ValueError, match="update_path=.fast. needs"):
        model.learn(60)
    # Adam with device-side step counts (fused / capturable): the fast path keeps counts on the host, so refuse it
    fused = dict(net_arch=dict(pi=[8], qf=[16, 4]), optimizer_kwargs=dict(fused=True))
    with pytest.raises(ValueError, match="update_path=.fast. needs"):
        make_model(update_path="fast", policy_kwargs=fused).learn(60)
    assert np.isfinite(make_model(update_path="auto", policy_kwargs=fused).learn(60).logger.name_to_value["train/q_mean"])


@pytest.mark.skipif(
    not os.environ.get("DENFAC_TEST_COMPILED"),
    reason="torch.compile takes ~1 min of CPU on a cold cache; set DENFAC_TEST_COMPILED=1 to run",
)
def test_compiled_path_agrees_with_fast():
    env = gym.make("Pendulum-v1", max_episode_steps=50)
    models = {}
    for path in ("fast", "compiled"):  # buffer of one episode: the second update runs the compiled full-buffer steps
        models[path] = make_model(env, buffer_size=50, update_path=path, learning_rate=1e-3).learn(100)
    fast, compiled = models["fast"], models["compiled"]
    for key in ("train/critic_loss", "train/actor_objective"):
        assert fast.logger.name_to_value[key] == pytest.approx(compiled.logger.name_to_value[key], rel=1e-4, abs=1e-5)
    compiled_state = compiled.policy.state_dict()
    for name, value in fast.policy.state_dict().items():
        th.testing.assert_close(compiled_state[name], value, rtol=1e-4, atol=1e-5, msg=name)
