"""DENFAC's options of the paper's future work (``sb3_denfac/denfac/options.py``): prioritised sampling of D by TD
error and the proximal actor. Unit tests of each, the updater choice, save/load, and one learning test each."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch as th

from sb3_denfac.denfac import DENFAC
from sb3_denfac.denfac.fast import FastUpdater
from sb3_denfac.denfac.options import PrioritisedSampler, proximal_actor_backward
from sb3_denfac.denfac.presets import PAPER
from sb3_denfac.denfac.updaters import AutogradUpdater

SMALL = dict(gamma=0.0, n_fitted_iterations=2, critic_steps=20, actor_steps=10, seed=1)
OPTIONS = [dict(prioritized="critic"), dict(prioritized="both"), dict(actor_proximal=1.0)]
AUTOGRAD_ONLY = OPTIONS[:2]  # the fast updater implements the proximal actor too


@pytest.fixture
def small_model(target_action_env):
    """``small_model(**kwargs)``: DENFAC with :data:`SMALL` settings on the target-action env."""

    def make(**kwargs) -> DENFAC:
        return DENFAC("MlpPolicy", target_action_env(), **{**SMALL, **kwargs})

    return make


# ----- prioritised sampling --------------------------------------------------------------------------------------------
def test_priorities_follow_the_td_errors():
    """P(i) = p_i / sum p with p_i = (|delta_i| + eps)^alpha; a huge TD error is drawn far more often than the rest."""
    th.manual_seed(0)
    td = th.full((1000, 1), 0.01)
    td[7] = -100.0  # sign does not matter: |delta|
    sampler = PrioritisedSampler(td, alpha=0.6, beta=0.4, eps=1e-3, batch_size=256)
    p = (td.abs().flatten() + 1e-3) ** 0.6
    # float32 defaults (rtol 1.3e-6): the same formula evaluated here; draw counts below: a sampling tolerance (rel 0.2)
    th.testing.assert_close(sampler.probabilities, p / p.sum())
    counts = th.zeros(1000)
    for _ in range(40):
        idx, w = sampler.batch()
        assert idx.shape == (256,) and w.shape == (256, 1)
        counts += th.bincount(idx, minlength=1000)
    expected_ratio = float(p[7] / p[0])  # ~ (100 / 0.011)^0.6 ~ 236
    others = (counts.sum() - counts[7]) / 999
    assert counts[7] / others == pytest.approx(expected_ratio, rel=0.2)
    assert counts[7] > 0.15 * counts.sum()  # about 19% of all draws for 1 of 1000 transitions


def test_importance_weights_are_in_0_1_with_max_1():
    th.manual_seed(0)
    td = th.randn(500, 1) * 10
    beta = 0.4
    sampler = PrioritisedSampler(td, alpha=0.6, beta=beta, eps=1e-3, batch_size=64)
    n, probs = 500, sampler.probabilities
    raw = (n * probs) ** -beta
    # float32 defaults (rtol 1.3e-6): the same formulas evaluated here
    th.testing.assert_close(sampler.weights.flatten(), raw / raw.max())
    assert sampler.weights.max() == pytest.approx(1.0) and sampler.weights.min() > 0
    assert int(sampler.weights.argmax()) == int(probs.argmin())  # the least likely transition has weight 1
    idx, w = sampler.batch()
    assert (w > 0).all() and (w <= 1).all()
    th.testing.assert_close(w, sampler.weights[idx])
    uniform = PrioritisedSampler(td, alpha=0.0, beta=beta, eps=1e-3, batch_size=64)  # alpha = 0: uniform, w = 1
    th.testing.assert_close(uniform.probabilities, th.full((500,), 1 / 500))
    th.testing.assert_close(uniform.weights, th.ones(500, 1))


def test_updater_sets_priorities_from_its_eval_mode_critic(small_model):
    """delta = q - Q_{k-1}(s, a) with the updater's critic; "critic" draws the critic's batches from P, not the
    actor's; "none" draws uniformly without weights (the library's uniform batches)."""
    model = small_model(prioritized="critic", batch_size=16).learn(20)
    updater = model.make_updater()
    assert isinstance(updater, AutogradUpdater)
    data = model.replay_buffer.all_samples()
    with th.no_grad():
        q = updater.critic(data.observations, data.actions).clone()
    q[3] += 1000.0  # one transition with a huge TD error
    updater.set_priorities(data.observations, data.actions, q)
    assert int(updater.sampler.probabilities.argmax()) == 3 and updater.sampler.probabilities[3] > 0.5
    idx, w = updater.draw(len(q), prioritised=True)
    assert (idx == 3).sum() > 4 and w is not None
    # the actor's mini-batches stay uniform with "critic", and "none" sets no sampler at all
    sampled = th.cat([model.make_updater().batch_indices(len(q)) for _ in range(200)])
    assert th.bincount(sampled, minlength=len(q)).float().std() < 0.2 * th.bincount(sampled).float().mean()
    plain = small_model(batch_size=16, update_path="plain").learn(20).make_updater()
    plain.set_priorities(data.observations, data.actions, q)
    assert plain.sampler is None
    idx, w = plain.draw(len(q), prioritised=False)
    assert w is None and idx.shape == (16,)  # a uniform draw (with replacement, as SB3's replay buffers)


def test_prioritised_critic_loss_uses_the_weights(monkeypatch, small_model):
    """The critic minimises 1/B sum w_i c_i (Q - q)^2 on the prioritised batch."""
    model = small_model(prioritized="critic", batch_size=8, critic_steps=1).learn(20)
    updater = model.make_updater()
    data = model.replay_buffer.all_samples()
    obs, actions = data.observations, data.actions
    with th.no_grad():
        q = updater.critic(obs, actions) + th.linspace(0, 5, len(obs)).unsqueeze(1)
    updater.set_priorities(obs, actions, q)
    idx = th.arange(8)
    w = th.linspace(0.1, 1.0, 8).unsqueeze(1)
    monkeypatch.setattr(updater.sampler, "batch", lambda: (idx, w))
    critic = copy.deepcopy(model.critic)
    critic.set_training_mode(True)
    with th.no_grad():
        expected = (w * (critic(obs[idx], actions[idx]) - q[idx]).pow(2)).mean()
    loss = updater.fit_critic(obs, actions, q, th.ones_like(q))
    # float32 defaults: the same weighted loss, recomputed on a copy of the critic
    th.testing.assert_close(loss, expected)


# ----- proximal actor ----------------------------------------------------------------------------------------------
def test_proximal_loss_gradient():
    """L = -1/B sum ghat . pi + lambda 1/B sum ||pi - pi_old||^2, ghat = g / mean ||g||: dL/dpi by hand."""
    th.manual_seed(0)
    pi = th.randn(5, 2, requires_grad=True)
    pi_old = th.randn(5, 2)
    g = th.randn(5, 2) * 30  # dQ/da of a critic linear in a
    q = (pi * g).sum(1, keepdim=True)
    proximal_actor_backward(q, pi, pi_old, coef=0.7, inverting_gradients=False)
    scale = g.norm(dim=1).mean()
    expected = -g / scale / 5 + 2 * 0.7 * (pi.detach() - pi_old) / 5
    # float32 defaults (rtol 1.3e-6, atol 1e-5): autograd against the gradient by hand, values of order 1
    th.testing.assert_close(pi.grad, expected)
    # inverting gradients: g inverted first (Hausknecht & Stone), then normalised
    from sb3_denfac.common.inverting_gradients import invert_gradients

    pi2 = (th.rand(5, 2) * 2 - 1).requires_grad_(True)
    proximal_actor_backward((pi2 * g).sum(1, keepdim=True), pi2, pi_old, coef=0.0, inverting_gradients=True)
    inv = invert_gradients(g, pi2.detach(), th.full_like(g, -1.0), th.full_like(g, 1.0))
    th.testing.assert_close(pi2.grad, -inv / inv.norm(dim=1).mean() / 5)


def actor_change(small_model, **kwargs) -> float:
    """Mean |pi(s) - pi_old(s)| over fixed states after one update (the first episode), same seed."""
    model = small_model(**kwargs)
    obs = np.stack([model.env.observation_space.sample() for _ in range(64)])
    before = model.predict(obs, deterministic=True)[0]
    model.learn(10)  # one 10-step episode, then one update
    assert model._n_updates == 1
    return float(np.abs(model.predict(obs, deterministic=True)[0] - before).mean())


def test_huge_proximal_coefficient_keeps_the_actor(small_model):
    free = actor_change(small_model, actor_proximal=0.0, update_path="plain", actor_steps=25, actor_learning_rate=0.01)
    held = actor_change(small_model, actor_proximal=1e4, actor_steps=25, actor_learning_rate=0.01)
    assert free > 0.05 and held < 0.1 * free, (free, held)
    held_fast = actor_change(small_model, actor_proximal=1e4, actor_steps=25, actor_learning_rate=0.01, update_path="fast")
    assert held_fast < 0.1 * free, (free, held_fast)
    # the old actor is a frozen copy made when the updater is made: the policy's actor is not it
    model = small_model(actor_proximal=1.0, update_path="plain")
    updater = model.make_updater()
    assert updater.old_actor is not model.actor and not any(p.requires_grad for p in updater.old_actor.parameters())
    fast = small_model(actor_proximal=1.0, update_path="fast").make_updater()  # the fast one: frozen folded affines
    obs = th.zeros((3, 2))
    old_fast = fast.actor_net.eval_forward(obs.t(), fast.old_actor_affines).t()
    with th.no_grad():
        model.actor.mu[-1].bias.add_(1.0)  # moving the actor does not move pi_old
        fast.policy.actor.mu[-1].bias.add_(1.0)
    assert (updater.old_actor(obs) - model.actor(obs)).abs().max() > 0.9
    # float32 defaults: the same frozen affines evaluated twice (exact in practice): pi_old did not move
    th.testing.assert_close(fast.actor_net.eval_forward(obs.t(), fast.old_actor_affines).t(), old_fast)
    assert (fast.actor(obs) - old_fast).abs().max() > 0.9


# ----- updater choice, validation, save/load ---------------------------------------------------------------------------
@pytest.mark.parametrize("option", AUTOGRAD_ONLY, ids=lambda o: "prioritized=" + o["prioritized"])
def test_auto_picks_autograd_and_fast_refuses(option, small_model):
    assert isinstance(small_model(batch_size=16).make_updater(), FastUpdater)  # default: fast
    assert isinstance(small_model(batch_size=16, **option).make_updater(), AutogradUpdater)
    name = next(iter(option))
    with pytest.raises(ValueError, match=f"update_path='fast' does not support {name}"):
        small_model(update_path="fast", **option)
    model = small_model(**option)
    model.update_path = "fast"  # set after construction: refused when the update is made
    with pytest.raises(ValueError, match=name):
        model.make_updater()


def test_auto_picks_fast_for_the_proximal_actor(small_model):
    assert isinstance(small_model(batch_size=16, actor_proximal=1.0).make_updater(), FastUpdater)
    assert isinstance(small_model(actor_proximal=1.0, update_path="plain").make_updater(), AutogradUpdater)


def test_make_updater_says_why_auto_fell_back(small_model):
    """make_updater, the one place the updater is chosen, names the reason "auto" did not take the fast updater."""
    from sb3_denfac.denfac.update_paths import make_updater
    from sb3_denfac.denfac.updaters import FitSettings

    model = small_model(batch_size=16)
    choice = make_updater(model.policy, FitSettings.of(model), "auto")
    assert isinstance(choice.updater, FastUpdater) and choice.fast_refused is None
    prioritised = small_model(batch_size=16, prioritized="critic")
    choice = make_updater(prioritised.policy, FitSettings.of(prioritised), "auto")
    assert isinstance(choice.updater, AutogradUpdater) and "prioritized='critic'" in choice.fast_refused
    sgd = small_model(batch_size=16, policy_kwargs=dict(optimizer_class=th.optim.SGD))
    choice = make_updater(sgd.policy, FitSettings.of(sgd), "auto")
    assert isinstance(choice.updater, AutogradUpdater) and "default MLP networks and Adam" in choice.fast_refused
    plain = make_updater(model.policy, FitSettings.of(model), "plain")
    assert isinstance(plain.updater, AutogradUpdater) and plain.fast_refused is None


def test_invalid_options(small_model):
    for kwargs, match in [
        (dict(prioritized="td"), "prioritized must be one of"),
        (dict(prioritized="critic", batch_size=None), "prioritized='critic' .* needs an int batch_size"),
        (dict(prioritized=dict(on="critic", alpha=-0.5)), "prioritized alpha"),
        (dict(prioritized=dict(on="critic", beta=1.5)), "prioritized beta"),
        (dict(prioritized=dict(on="critic", eps=0.0)), "prioritized eps"),
        (dict(prioritized=dict(on="critic", gamma=0.5)), "prioritized must be one of .* or a dict with keys"),
        (dict(prioritized=dict(on="all")), r"prioritized \(on\) must be one of"),
        (dict(actor_proximal=-1.0), "actor_proximal"),
        (dict(actor_proximal=float("nan")), "actor_proximal"),
    ]:
        with pytest.raises(ValueError, match=match):
            small_model(**kwargs)


def test_option_defaults(small_model):
    """Uniform sampling and the proximal actor with lambda = 1 (the 0.3 default); the paper's preset turns it off."""
    model = small_model()
    assert (model.prioritized, model.actor_proximal) == ("none", 1.0)
    assert small_model(**{k: v for k, v in PAPER.items() if k != "policy_kwargs"}).actor_proximal == 0.0
    assert (model.priority_alpha, model.priority_beta, model.priority_eps) == (0.6, 0.4, 1e-3)


def test_save_load_keeps_the_options(tmp_path, target_action_env, small_model):
    prioritized = dict(on="both", alpha=0.7, beta=0.5, eps=0.01)
    model = small_model(batch_size=16, prioritized=prioritized, actor_proximal=2.0).learn(20)
    model.save(tmp_path / "model.zip")
    loaded = DENFAC.load(tmp_path / "model.zip", env=target_action_env())
    kept = ("prioritized", "priority_alpha", "priority_beta", "priority_eps", "actor_proximal")
    assert tuple(getattr(loaded, key) for key in kept) == ("both", 0.7, 0.5, 0.01, 2.0)
    settings = loaded.make_updater().settings
    assert (settings.prioritized, settings.actor_proximal) == ("both", 2.0)
    loaded.learn(20, reset_num_timesteps=False)
    assert loaded._n_updates == 4


# ----- learning tests ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("option", [dict(prioritized="critic"), dict(actor_proximal=1.0)], ids=["per-critic", "proximal"])
def test_option_learns_target_action(option, target_action_env):
    """The default configuration with the option on (fewer steps per update) moves the actor to the rewarded action,
    as test_default_configuration_learns_target_action does without it."""
    env = target_action_env()
    model = DENFAC("MlpPolicy", env, **SMALL, **option)
    obs = np.stack([env.observation_space.sample() for _ in range(64)])
    start = env.distance_to_target(model, obs)
    model.learn(200)
    end = env.distance_to_target(model, obs)
    assert end < 0.1 and end < start / 2, (start, end)
