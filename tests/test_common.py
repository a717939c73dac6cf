"""Shared numerical pieces: truncated Gaussian (against scipy), importance weights, inverting gradients, BN MLPs."""

import numpy as np
import pytest
import torch as th
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats
from torch import nn

from sb3_denfac.common.inverting_gradients import (
    invert_gradients,
    invert_gradients_unit_box,
    inverting_gradient_actor_backward,
)
from sb3_denfac.common.networks import create_bn_mlp, flat_parameters, reset_parameters_, set_bn_training_mode
from sb3_denfac.common.truncated_normal import (
    clamp_mean,
    importance_weight_floor,
    sample_truncated_normal,
    truncated_importance_weights,
    truncated_normal_log_prob,
)

means = st.floats(min_value=-3.0, max_value=3.0)
sigmas = st.floats(min_value=0.01, max_value=2.0)


@settings(max_examples=60, deadline=None)
@given(mean=means, sigma=sigmas, action=st.floats(min_value=-1.0, max_value=1.0))
def test_log_prob_matches_scipy_truncnorm(mean, sigma, action):
    clamped = float(clamp_mean(np.float64(mean), -1.0, 1.0, sigma))
    ref = stats.truncnorm.logpdf(action, (-1 - clamped) / sigma, (1 - clamped) / sigma, loc=clamped, scale=sigma)
    got = truncated_normal_log_prob(
        th.tensor([[action]], dtype=th.float64), th.tensor([[mean]], dtype=th.float64), sigma, th.tensor(-1.0), th.tensor(1.0)
    )
    assert got.shape == (1,)
    # rel 1e-6: float64 against scipy's float64 formula (different but accurate evaluations of erf and logs)
    assert got.item() == pytest.approx(ref, rel=1e-6, abs=1e-6)


def test_log_prob_sums_over_action_dims():
    actions = th.tensor([[0.1, -0.3], [0.9, 0.0]])
    mean = th.tensor([[0.0, -0.2], [1.2, 0.05]])
    low, high = th.tensor([-1.0, -1.0]), th.tensor([1.0, 1.0])
    joint = truncated_normal_log_prob(actions, mean, 0.3, low, high)
    per_dim = [truncated_normal_log_prob(actions[:, j : j + 1], mean[:, j : j + 1], 0.3, low[:1], high[:1]) for j in range(2)]
    # float32 defaults (rtol 1.3e-6, atol 1e-5): a sum of the same terms in another order
    th.testing.assert_close(joint, per_dim[0] + per_dim[1])


@settings(max_examples=40, deadline=None)
@given(mean=st.floats(min_value=-20.0, max_value=20.0), sigma=sigmas, seed=st.integers(0, 2**31 - 1))
def test_samples_stay_in_bounds(mean, sigma, seed):
    rng = np.random.default_rng(seed)
    samples = sample_truncated_normal(np.full((64, 2), mean, dtype=np.float32), sigma, -1.0, 1.0, rng)
    assert samples.dtype == np.float32 and samples.shape == (64, 2)
    assert np.all(samples >= -1.0) and np.all(samples <= 1.0)


@pytest.mark.parametrize("mean,sigma", [(0.0, 0.05), (0.97, 0.05), (-1.1, 0.05), (0.3, 0.5)])
def test_samples_follow_scipy_truncnorm(mean, sigma):
    rng = np.random.default_rng(0)
    samples = sample_truncated_normal(np.full(4000, mean), sigma, -1.0, 1.0, rng)
    ref = stats.truncnorm((-1 - mean) / sigma, (1 - mean) / sigma, loc=mean, scale=sigma)
    assert stats.kstest(samples, ref.cdf).pvalue > 1e-3


def test_samples_respect_asymmetric_bounds():
    low, high = np.array([0.0, -2.0]), np.array([0.5, 3.0])
    samples = sample_truncated_normal(np.tile([0.45, 2.9], (1000, 1)), 0.2, low, high, np.random.default_rng(1))
    assert np.all(samples >= low) and np.all(samples <= high)


@pytest.mark.parametrize("sigma", [0.0, -0.1, float("nan")])
def test_bad_sigma_is_rejected(sigma):
    with pytest.raises(ValueError, match="sigma"):
        sample_truncated_normal(np.zeros(1), sigma, -1.0, 1.0)


@settings(max_examples=60, deadline=None)
@given(lp_t=st.floats(-50, 50), lp_b=st.floats(-50, 50))
def test_importance_weights_are_truncated_ratios(lp_t, lp_b):
    w = truncated_importance_weights(th.tensor([lp_t], dtype=th.float64), th.tensor([lp_b], dtype=th.float64)).item()
    assert 0.0 <= w <= 1.0
    assert w == pytest.approx(min(1.0, np.exp(lp_t - lp_b)), rel=1e-9, abs=1e-300)


@settings(max_examples=60, deadline=None)
@given(log_ratio=st.floats(-200, 0))
def test_importance_weights_below_the_floor_are_exactly_zero(log_ratio):
    """float32 weights are the ratio, or exactly 0 below sqrt(tiny): never a subnormal number."""
    w = truncated_importance_weights(th.tensor([log_ratio]), th.tensor([0.0])).item()
    floor = importance_weight_floor(th.float32)
    tiny = float(th.finfo(th.float32).tiny)
    assert w == 0.0 or w >= tiny
    if np.exp(log_ratio) < floor * 0.999:
        assert w == 0.0
    elif np.exp(log_ratio) > floor * 1.001:
        assert w == pytest.approx(np.exp(log_ratio), rel=1e-5)


@settings(max_examples=80, deadline=None)
@given(grad=st.floats(-10, 10), action=st.floats(-3, 3))
def test_inverting_gradients_never_push_past_a_bound(grad, action):
    out = invert_gradients(th.tensor([grad]), th.tensor([action]), th.tensor([-1.0]), th.tensor([1.0])).item()
    if action >= 1.0:
        assert out <= 0.0  # at or beyond a_max: never pushed further up
    if action <= -1.0:
        assert out >= 0.0
    if -1.0 < action < 1.0:
        assert out * grad >= 0.0 and abs(out) <= abs(grad)  # same direction, never amplified


def test_inverting_gradients_scale_as_hausknecht_and_stone():
    grad = th.tensor([2.0, 2.0, -2.0, -2.0])
    actions = th.tensor([0.5, -0.5, 0.5, -0.5])
    out = invert_gradients(grad, actions, th.tensor(-1.0), th.tensor(1.0))
    # increase: scaled by (a_max - a)/span; decrease: scaled by (a - a_min)/span
    # float32 defaults: the hand-computed values, exact in binary up to a rounding of the scaling
    th.testing.assert_close(out, th.tensor([2 * 0.25, 2 * 0.75, -2 * 0.75, -2 * 0.25]))


@settings(max_examples=80, deadline=None)
@given(grad=st.floats(-10, 10), action=st.floats(-3, 3))
def test_inverting_gradients_unit_box_equals_general_rule(grad, action):
    general = invert_gradients(th.tensor([grad]), th.tensor([action]), th.tensor(-1.0), th.tensor(1.0))
    unit = invert_gradients_unit_box(th.tensor([grad]), th.tensor([action]))
    # rtol 1e-6: the same formula with the bounds folded in (a float32 ulp or two)
    th.testing.assert_close(unit, general, rtol=1e-6, atol=0.0)


def test_inverting_gradient_actor_keeps_actions_in_bounds():
    """An actor maximising a Q that always wants larger actions converges to a_max, not beyond."""
    th.manual_seed(0)
    actor = nn.Linear(3, 1)
    obs = th.randn(256, 3)
    optimizer = th.optim.SGD(actor.parameters(), lr=0.5)
    for _ in range(400):
        optimizer.zero_grad()
        actions = actor(obs)
        inverting_gradient_actor_backward(5.0 * actions.sum(dim=1), actions, th.tensor(-1.0), th.tensor(1.0))
        optimizer.step()
    final = actor(obs).detach()
    assert final.max() <= 1.05
    assert final.mean() > 0.8


def test_bn_mlp_layout_follows_the_paper():
    critic = create_bn_mlp(5, 1, [50, 7])
    kinds = [type(m).__name__ for m in critic]
    assert kinds == ["BatchNorm1d", "Linear", "LeakyReLU", "BatchNorm1d", "Linear", "LeakyReLU", "Linear"]
    actor = create_bn_mlp(4, 1, [5])
    assert [type(m).__name__ for m in actor] == ["BatchNorm1d", "Linear", "LeakyReLU", "Linear"]
    plain = create_bn_mlp(4, 1, [5], batch_norm=False)
    assert not any(isinstance(m, nn.BatchNorm1d) for m in plain)


def test_paper_init_and_in_place_reset():
    net = create_bn_mlp(4, 2, [20, 10], init="paper")
    weights = th.cat([m.weight.reshape(-1) for m in net if isinstance(m, nn.Linear)])
    assert 0.005 < weights.std().item() < 0.02
    assert all(th.all(m.bias == 0) for m in net if isinstance(m, nn.Linear))
    tensors_before = [p.data_ptr() for p in net.parameters()]
    values_before = flat_parameters(net)
    set_bn_training_mode(net, True)
    net(th.randn(32, 4) * 5 + 3)  # moves running statistics
    reset_parameters_(net, init="paper")
    assert [p.data_ptr() for p in net.parameters()] == tensors_before  # optimizer references stay valid
    assert not th.equal(values_before, flat_parameters(net))
    assert th.all(net[0].running_mean == 0)


def test_bad_network_arguments_are_rejected():
    with pytest.raises(ValueError, match="init"):
        create_bn_mlp(4, 1, [5], init="xavier")
    with pytest.raises(ValueError, match="hidden layer sizes"):
        create_bn_mlp(4, 1, [0])


@pytest.mark.parametrize("renorm_phase", [False, True], ids=["warm-up", "renorm"])
def test_batch_renorm_equals_sb3_contribs(renorm_phase):
    """The project's BatchRenorm1d (two-pass variance) computes sb3-contrib's function: outputs, gradients and running
    statistics to float32 rounding (relative 1e-4), in the warm-up (batch statistics) and the renormalised phase."""
    from sb3_contrib.common.torch_layers import BatchRenorm1d as Reference

    from sb3_denfac.common.networks import BatchRenorm1d

    th.manual_seed(0)
    ours, reference = BatchRenorm1d(16), Reference(16)
    x = th.randn(64, 16) * th.linspace(0.1, 10.0, 16) + th.linspace(-5.0, 5.0, 16)  # features of unequal scales
    for layer in (ours, reference):
        with th.no_grad():
            layer.scale.copy_(th.linspace(0.5, 2.0, 16))
            layer.bias.copy_(th.linspace(-1.0, 1.0, 16))
        if renorm_phase:  # past the warm-up, running statistics away from the batch's: r and d are clipped
            layer.steps.fill_(layer.warmup_steps + 1)
            layer.ra_mean.copy_(th.linspace(-8.0, 8.0, 16))
            layer.ra_var.copy_(th.linspace(0.01, 50.0, 16))

    def outcome(layer: th.nn.Module) -> tuple[th.Tensor, ...]:
        inputs = x.clone().requires_grad_(True)
        out = layer(inputs)
        (out * th.linspace(-1.0, 1.0, 64)[:, None]).pow(2).sum().backward()
        grads = (inputs.grad, layer.scale.grad, layer.bias.grad)
        layer.zero_grad()
        return out.detach(), *grads, layer.ra_mean.clone(), layer.ra_var.clone()

    for mode in ("train", "eval"):  # the batch's statistics (and the running ones' update), then the running ones
        for layer in (ours, reference):
            layer.train(mode == "train")
        for ours_t, ref_t in zip(outcome(ours), outcome(reference), strict=True):
            th.testing.assert_close(ours_t, ref_t, rtol=1e-4, atol=1e-4 * float(ref_t.abs().max()))
        assert int(ours.steps) == int(reference.steps)


@pytest.mark.parametrize("renorm_phase", [False, True], ids=["warm-up", "renorm"])
def test_batch_renorm_backward_is_the_gradient(renorm_phase):
    """BatchRenorm1d's hand-written backward is the derivative of its training-mode function: torch's numerical
    gradient check in float64 (gradcheck's tolerances), for the input, the scale and the bias. Past the warm-up the
    running statistics are far from the batch's, so that r and d sit at their clips and are constant, as the layer
    treats them (detached)."""
    from sb3_denfac.common.networks import _BatchRenormTraining

    th.manual_seed(0)
    x = (th.randn(12, 5, dtype=th.float64) * th.linspace(0.5, 1.5, 5)).requires_grad_(True)
    scale = th.linspace(0.5, 2.0, 5, dtype=th.float64).requires_grad_(True)
    bias = th.linspace(-1.0, 1.0, 5, dtype=th.float64).requires_grad_(True)
    ra_mean = th.tensor([-200.0, 200.0, -200.0, 200.0, -200.0], dtype=th.float64)  # |d| = 10 > 5: clipped at d_max
    ra_var = th.full((5,), 400.0, dtype=th.float64)  # r < 0.1: clipped at 1/r_max

    def layer(inputs: th.Tensor, w: th.Tensor, b: th.Tensor) -> th.Tensor:
        return _BatchRenormTraining.apply(inputs, w, b, ra_mean, ra_var, 1e-3, renorm_phase, 3.0, 5.0)[0]

    assert th.autograd.gradcheck(layer, (x, scale, bias))


def test_batch_renorm_constant_feature_has_a_finite_gradient():
    """Past the warm-up a feature constant over the batch (v = 0) gets a finite gradient: the renormalisation's shift
    d sqrt(v) / r has no derivative at v = 0, where autograd (sb3-contrib's layer) returns nan; the layer takes 0."""
    from sb3_denfac.common.networks import BatchRenorm1d

    layer = BatchRenorm1d(3)
    layer.steps.fill_(layer.warmup_steps + 1)
    x = th.randn(32, 3)
    x[:, 1] = 0.5
    x.requires_grad_(True)
    layer(x).pow(2).sum().backward()
    assert th.isfinite(x.grad).all() and th.isfinite(layer.scale.grad).all()
