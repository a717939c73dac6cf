"""Property-based tests (hypothesis) for the numerical pieces, complementing ``tests/test_common.py``: finiteness of the
importance weights for any actor output (the unbounded actor of DENFAC/DDPG), the behaviour density of warm-up
actions, and inverting gradients with asymmetric bounds."""

from __future__ import annotations

import numpy as np
import pytest
import torch as th
from hypothesis import given, settings
from hypothesis import strategies as st

from sb3_denfac.common.exploration import behaviour_log_prob
from sb3_denfac.common.inverting_gradients import invert_gradients
from sb3_denfac.common.truncated_normal import truncated_importance_weights, truncated_normal_log_prob

sigmas = st.floats(min_value=0.01, max_value=2.0)
any_means = st.floats(min_value=-1e4, max_value=1e4)  # an unbounded actor can output anything
actions = st.floats(min_value=-1.0, max_value=1.0)


@settings(max_examples=80, deadline=None)
@given(action=actions, target_mean=any_means, behaviour_mean=any_means, sigma=sigmas)
def test_importance_weights_stay_finite_for_any_means(action, target_mean, behaviour_mean, sigma):
    """No NaN from far-away means: the log-densities are finite (mean clamping) and c = min(1, ratio) is in [0, 1]."""
    a = th.tensor([[action]], dtype=th.float32)
    low, high = th.tensor([-1.0]), th.tensor([1.0])
    log_target = truncated_normal_log_prob(a, th.tensor([[target_mean]], dtype=th.float32), sigma, low, high)
    log_behaviour = truncated_normal_log_prob(a, th.tensor([[behaviour_mean]], dtype=th.float32), sigma, low, high)
    assert th.isfinite(log_target).all() and th.isfinite(log_behaviour).all()
    weight = truncated_importance_weights(log_target, log_behaviour)
    assert th.isfinite(weight).all() and 0.0 <= weight.item() <= 1.0


@settings(max_examples=40, deadline=None)
@given(
    data=st.lists(st.tuples(actions, actions, st.floats(-3.0, 3.0), st.booleans()), min_size=1, max_size=8),
    sigma=sigmas,
)
def test_behaviour_log_prob_uniform_rows_and_gaussian_rows(data, sigma):
    """Rows with a NaN behaviour mean (uniform warm-up actions) get the uniform density 1/2^d on [-1, 1]^d; the others
    the truncated Gaussian's, summed over dimensions."""
    acts = th.tensor([[a0, a1] for a0, a1, _, _ in data], dtype=th.float32)
    means = th.tensor([[np.nan, np.nan] if warm_up else [m, -m] for _, _, m, warm_up in data], dtype=th.float32)
    warm_up = th.tensor([w for *_, w in data])
    got = behaviour_log_prob(acts, means, sigma)
    assert got.shape == (len(data),) and th.isfinite(got).all()
    gaussian = truncated_normal_log_prob(acts, th.nan_to_num(means), sigma, th.full((2,), -1.0), th.full((2,), 1.0))
    expected = th.where(warm_up, th.full_like(got, -2 * np.log(2.0)), gaussian)
    # float32 defaults (rtol 1.3e-6, atol 1e-5): the same densities, summed over dimensions in another order
    th.testing.assert_close(got, expected)


@settings(max_examples=80, deadline=None)
@given(
    grad=st.floats(-10, 10),
    low=st.floats(-5, 4),
    width=st.floats(0.1, 5),
    position=st.floats(-0.5, 1.5),  # relative position of the action: < 0 below low, > 1 above high
)
def test_inverting_gradients_with_asymmetric_bounds(grad, low, width, position):
    high = low + width
    action = low + position * width
    t = lambda x: th.tensor([x], dtype=th.float64)  # noqa: E731
    out = invert_gradients(t(grad), t(action), t(low), t(high)).item()
    if action >= high:
        assert out <= 0.0
    elif action <= low:
        assert out >= 0.0
    else:
        assert out * grad >= 0.0 and abs(out) <= abs(grad) + 1e-12
    # The scale is the distance to the bound it pushes toward, relative to the span.
    expected = grad * ((high - action) if grad > 0 else (action - low)) / width
    assert out == pytest.approx(expected, rel=1e-9, abs=1e-9)
