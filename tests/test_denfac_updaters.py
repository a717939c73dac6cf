"""DENFAC's two updaters (``updaters.py``, ``fast.py``): same update, the fast one without per-step allocations,
device-agnostic, with public-op fallbacks for the private kernels, and the choice between them (``update_path``)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from torch import nn
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_leaves

from sb3_denfac.common.inverting_gradients import invert_gradients_unit_box
from sb3_denfac.denfac import eager_steps
from sb3_denfac.denfac.fast import FastUpdater, supported_networks
from sb3_denfac.denfac.updaters import FitSettings

#: Adam with beta1 = 0.9 over the paper preset's beta1 = 0 (``policy_kwargs.optimizer_kwargs``)
ADAM = dict(betas=(0.9, 0.999))


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


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(),
        dict(reset_critic=True, weighting="retrace_next_state_quirk"),
        # mini-batches with a kept actor (beta1 = 0.9: with beta1 = 0 a rounding-sized actor gradient component, whose
        # sign depends on the CPU's float kernels, becomes an lr-sized step; on one Xeon a parameter differed by 46%)
        dict(inverting_gradients=False, batch_size=32, reset_actor=False, policy_kwargs=dict(optimizer_kwargs=ADAM)),
        # several actions (the critic's action input as a matmul) and a deeper actor (BN backward through the input);
        # PyTorch's init: from N(0, 0.01) weights many actor gradient components are rounding-sized, and Adam with
        # beta1 = 0 turns their sign into lr-sized steps (the gradients themselves agree: test_eager_gradients_...)
        dict(env="multi_action", policy_kwargs=dict(net_arch=dict(pi=[8, 6], qf=[16, 4]), init="default")),
        dict(policy_kwargs=dict(net_arch=dict(pi=[8], qf=[16, 4]), bn_momentum=0.1)),  # running averages kept
        dict(policy_kwargs=dict(net_arch=dict(pi=[8], qf=[16, 4]), batch_norm=False)),
        # the proximal actor (options.py): full batch with BN and inverting gradients, mini-batches without BN
        dict(actor_proximal=1.0),
        # TD3's target policy smoothing (the library default's 0.2): the same noise on both paths (two action dims,
        # where a transposed output would get its draws in another order)
        dict(env="multi_action", target_policy_noise=0.2, target_noise_clip=0.5),
        # clipped double Q: three critics, each with its own flat state, on the same mini-batches (beta1 = 0.9: with
        # beta1 = 0, rounding-sized gradient components of a twin become lr-sized steps within the later plain updates)
        dict(
            batch_size=32,
            reset_actor=False,
            policy_kwargs=dict(net_arch=dict(pi=[8], qf=[16, 4]), n_critics=3, optimizer_kwargs=ADAM),
        ),
        # one critic and one actor step per iteration: each step's rows are exactly one mini-batch, with batch norm
        dict(batch_size=16, critic_steps=1, actor_steps=1, actor_proximal=1.0, policy_kwargs=dict(optimizer_kwargs=ADAM)),
        dict(
            actor_proximal=0.5,
            inverting_gradients=False,
            batch_size=32,
            reset_actor=False,
            policy_kwargs=dict(net_arch=dict(pi=[8, 6], qf=[16, 4]), batch_norm=False, init="default"),
        ),
    ],
)
def test_fast_and_plain_paths_agree(make_denfac, kwargs):
    """Speed never changes the algorithm: same state and seed -> same losses, parameters, BN statistics and Adam
    moments after an update (:func:`assert_one_update_agrees`).

    A moderate step size keeps the comparison meaningful: with beta1 = 0 Adam's first steps are lr * sign(g), so at
    large rates float rounding in near-zero gradient components is amplified (both paths are then equally valid).
    """
    kwargs = dict(kwargs)
    multi_action = kwargs.pop("env", None) == "multi_action"

    def make_env():
        if multi_action:
            return gym.wrappers.TimeLimit(MultiActionEnv(), max_episode_steps=50)
        return gym.make("Pendulum-v1", max_episode_steps=50)

    assert_one_update_agrees(lambda path: make_denfac(make_env(), update_path=path, learning_rate=0.01, **kwargs), 50)


def assert_one_update_agrees(make, episode: int, trained: int = 2) -> list:
    """``make(update_path)``: a new model, seeded alike. The fast and plain updaters compute the same update from the
    same state: the first update (each path after the same first ``episode`` steps, from the fresh networks: the fast
    updater starts Adam's state), an update from a trained state (``trained`` episodes; the fast updater reads Adam's
    moments and step counts), and a plain update after that fast one (the fast updater writes its Adam state back: a
    lost state would restart Adam's step count and moments). Returns the (plain, fast) pairs compared.

    One update at a time, from a state that both models reach bit for bit (the plain path, the same seed, one process):
    across several updates float32 rounding of the two op orders is amplified (Adam divides a rounding-sized gradient
    component by its own size), the models then collect other episodes, and how far they drift apart depends on the CPU's
    kernels (after 3 updates one configuration failed under ATEN_CPU_CAPABILITY=default; one update stays within 0.14
    of :func:`assert_same_update`'s tolerances on AMD EPYC native, avx2 and default kernels, measured over all of
    test_fast_and_plain_paths_agree's configurations and several start states)."""
    pairs = [(make("plain").learn(episode), make("fast").learn(episode))]
    assert_same_update(*pairs[0])
    plain, fast = make("plain").learn(trained * episode), make("plain").learn(trained * episode)
    fast.update_path = "fast"
    for seed in (7, 8):  # a fast update, then a plain one after it
        for model in (plain, fast):
            model.set_random_seed(seed)
            model._update()
        assert_same_update(plain, fast)
        pairs.append((plain, fast))
        fast.update_path = "plain"
    return pairs


def assert_same_update(plain, fast) -> None:
    # rtol 1e-4, atol 1e-5: float32 rounding of the two paths' op orders through one update's Adam steps (measured
    # <= 0.14 of it: assert_one_update_agrees); a learning rate 1% off gives >100x it, gamma 0.98 for 0.99 >8x
    for key in ("train/critic_loss", "train/actor_loss", "train/q_target_mean", "train/importance_weight_mean"):
        assert plain.logger.name_to_value[key] == pytest.approx(fast.logger.name_to_value[key], rel=1e-4, abs=1e-5), key
    fast_state = fast.policy.state_dict()
    for name, value in plain.policy.state_dict().items():
        th.testing.assert_close(fast_state[name], value, rtol=1e-4, atol=1e-5, msg=name)
    for net in ("actor", "critic"):
        plain_opt = getattr(plain, net).optimizer.state_dict()["state"]
        fast_opt = getattr(fast, net).optimizer.state_dict()["state"]
        assert plain_opt.keys() == fast_opt.keys()
        for i in plain_opt:
            assert float(plain_opt[i]["step"]) == float(fast_opt[i]["step"])  # exact: counts
            # exp_avg is the last gradients' average, where rounding-sized components keep their relative error:
            # rtol 1e-2 / atol 1e-4; exp_avg_sq averages squares over many steps: rtol 1e-3 (measured <= 0.08 of both)
            th.testing.assert_close(fast_opt[i]["exp_avg"], plain_opt[i]["exp_avg"], rtol=1e-2, atol=1e-4)
            th.testing.assert_close(fast_opt[i]["exp_avg_sq"], plain_opt[i]["exp_avg_sq"], rtol=1e-3, atol=1e-9)


@pytest.mark.parametrize("inverting_gradients", [True, False])
def test_public_op_fallbacks_agree_with_autograd(make_denfac, monkeypatch, inverting_gradients):
    """Without the private kernels (torch._fused_adam_, aten.leaky_relu_backward) the fast updater runs the same
    arithmetic with public ops: it still computes the autograd updater's update."""
    monkeypatch.setattr(eager_steps, "FUSED_ADAM", False)
    monkeypatch.setattr(eager_steps, "LEAKY_RELU_BACKWARD", False)
    monkeypatch.setattr(th, "_fused_adam_", None)  # any call to the private kernel would now fail

    def make(path):
        env = gym.wrappers.TimeLimit(MultiActionEnv(), max_episode_steps=50)
        policy_kwargs = dict(net_arch=dict(pi=[8, 6], qf=[16, 4]), init="default")
        return make_denfac(
            env, update_path=path, learning_rate=0.01, inverting_gradients=inverting_gradients, policy_kwargs=policy_kwargs
        )

    assert_one_update_agrees(make, 50)


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


def _large_allocations_per_update(make_denfac, update_path: str, steps: int, inverting_gradients: bool) -> int:
    model = make_denfac(
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
def test_fast_path_allocates_nothing_per_step(make_denfac, inverting_gradients):
    """The eager fast path writes its (features, N) activations into buffers made once per fit: the number of large
    allocations of an update does not grow with the number of critic and actor steps (fresh per-step tensors made
    the allocator map and fault in pages, which slowed updates 2-3x at random). The plain path shows the counter
    sees per-step allocations."""
    fast = [_large_allocations_per_update(make_denfac, "fast", steps, inverting_gradients) for steps in (2, 6)]
    assert fast[0] == fast[1], fast
    plain = [_large_allocations_per_update(make_denfac, "plain", steps, inverting_gradients) for steps in (2, 6)]
    assert plain[1] > plain[0] + 8, plain


@pytest.mark.parametrize("batch_size", [None, 16])
def test_fast_path_is_device_agnostic(make_denfac, batch_size):
    """The fast update runs on PyTorch's "meta" device (shapes only, no data): a tensor made on the CPU by default,
    a host read of device data or a CPU-only kernel would raise. The stand-in for device="cuda" on GPU-less CI."""
    model = make_denfac(batch_size=batch_size, policy_kwargs=dict(net_arch=dict(pi=[8, 8], qf=[16, 4])))
    policy = model.policy.to("meta")
    settings = FitSettings(3, 3, 10.0, True, batch_size, True, "none", 0.6, 0.4, 1e-3, 0.0, "min", True)
    fast = FastUpdater(policy, settings, *supported_networks(policy))
    n = 64
    obs, actions = th.randn(n, 3, device="meta"), th.randn(n, 1, device="meta")
    q_targets, weights = th.randn(n, 1, device="meta"), th.rand(n, 1, device="meta")
    assert fast.actor(obs).device.type == "meta" and fast.actor(obs).shape == (n, 1)
    assert fast.critic(obs, actions).shape == (n, 1)
    fast.reset_critic()
    loss = fast.fit_critic(obs, actions, q_targets, weights)
    fast.reset_actor()
    objective = fast.fit_actor(obs)
    assert loss.device.type == objective.device.type == "meta"
    if batch_size is not None:  # the mini-batches DENFAC draws for an iteration (iteration_sample) stay on the device
        sample = fast.iteration_sample(n)
        assert sample.critic_rows.device.type == sample.critic_batches.device.type == "meta"
        rows = sample.critic_rows
        loss = fast.fit_critic(obs[rows], actions[rows], q_targets[rows], weights[rows], sample.critic_batches)
        objective = fast.fit_actor(obs[sample.actor_rows], sample.actor_batches)
        assert loss.device.type == objective.device.type == "meta"
    fast.finish()


@pytest.mark.parametrize("inverting_gradients", [True, False])
def test_eager_gradients_equal_autograd(make_denfac, inverting_gradients):
    """One critic and one actor gradient of the eager fast steps equal autograd's on the modules (no Adam in between
    to amplify rounding), with several actions, two BN layers per network and random BN parameters and statistics."""
    th.manual_seed(0)
    env = gym.wrappers.TimeLimit(MultiActionEnv(), max_episode_steps=50)
    policy = make_denfac(env, policy_kwargs=dict(net_arch=dict(pi=[8, 6], qf=[16, 4]))).policy
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
    settings = FitSettings(1, 1, None, inverting_gradients, None, False, "none", 0.6, 0.4, 1e-3, 0.0, "min", True)
    fast = FastUpdater(policy, settings, *supported_networks(policy))
    with th.no_grad():
        x = th.cat([obs, actions], 1).t().contiguous()
        ws = eager_steps.Workspace(fast.critic_net.spec.sizes, n, x)
        # per-step batch statistics (mini-batches) and the input normalised once (full-batch fits)
        for fixed in (None, eager_steps.FixedStats(x, ws.centred, fast.critic_net.spec.eps[0])):
            folds = eager_steps.forward_train(fast.critic_net, ws, x, fixed)
            diff = ws.outputs[-1] - q_targets.t()
            eager_steps.backward(fast.critic_net, ws, x, folds, diff * weights.t() * (2.0 / n))
            # rtol 1e-5, atol 1e-6: one gradient by two op orders (no Adam in between to amplify rounding)
            th.testing.assert_close(fast.critic_net.grad, critic_grad, rtol=1e-5, atol=1e-6)
        affines = fast.critic_net.eval_affines()
        obs_part = th.addmm(affines[0][1].unsqueeze(1), affines[0][0][:, :-3], obs.t())
        critic = eager_steps.EvalCritic(affines, fast.critic_net.spec.slopes, obs_part, 3, fast.critic_net.spec.sizes, n)
        ws = eager_steps.Workspace(fast.actor_net.spec.sizes, n, x)
        obs_t = obs.t().contiguous()
        for fixed in (None, eager_steps.FixedStats(obs_t, ws.centred, fast.actor_net.spec.eps[0])):
            folds = eager_steps.forward_train(fast.actor_net, ws, obs_t, fixed)
            ascent, value = critic.action_gradient(ws.outputs[-1], want_value=True)
            # rel 1e-5: one forward pass by two op orders
            assert value.item() == pytest.approx(q_values.mean().item(), rel=1e-5)
            if inverting_gradients:
                ascent = invert_gradients_unit_box(ascent, ws.outputs[-1])
            eager_steps.backward(fast.actor_net, ws, obs_t, folds, -ascent)
            # rtol 1e-5, atol 1e-6: one gradient by two op orders (no Adam in between to amplify rounding)
            th.testing.assert_close(fast.actor_net.grad, actor_grad, rtol=1e-5, atol=1e-6)


def test_update_path_errors(make_denfac):
    with pytest.raises(ValueError, match="update_path"):
        make_denfac(update_path="turbo")
    with pytest.raises(ValueError, match="compiled.*removed"):
        make_denfac(update_path="compiled")
    sgd = dict(optimizer_class=th.optim.SGD, optimizer_kwargs={})  # without the paper preset's Adam betas
    model = make_denfac(update_path="fast", policy_kwargs=sgd)
    with pytest.raises(ValueError, match="update_path=.fast. needs"):
        model.learn(60)
    # Adam with device-side step counts (fused / capturable): the fast path keeps counts on the host, so refuse it
    fused = dict(net_arch=dict(pi=[8], qf=[16, 4]), optimizer_kwargs=dict(fused=True))
    with pytest.raises(ValueError, match="update_path=.fast. needs"):
        make_denfac(update_path="fast", policy_kwargs=fused).learn(60)
    auto = make_denfac(update_path="auto", policy_kwargs=fused).learn(60)
    assert np.isfinite(auto.logger.name_to_value["train/q_target_mean"])
