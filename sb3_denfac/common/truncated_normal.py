"""Truncated Gaussian exploration and Retrace-style importance weights.

The paper (section 4) explores with "a truncated Gaussian policy between [a_min = -1, a_max = 1] with sigma = 0.05 where
the mean is determined by the output of the last linear layer". This is a proper truncated normal (mass renormalised
inside the bounds), not additive noise followed by clipping: clipping would put probability mass on the bounds and
give no density to evaluate in the importance weight of Algorithm 1.

Following the authors' code, the mean is clamped to ``[low - 3 sigma, high + 3 sigma]`` before the density is formed:
an unbounded actor (inverting gradients) may output means far outside the bounds, where the in-bound mass underflows.
"""

from __future__ import annotations

import numpy as np
import torch as th
from scipy import special

from sb3_denfac.common.checks import check_sigma

#: How far outside the bounds (in units of sigma) a mean may lie before it is clamped (authors' code: 3).
MEAN_CLAMP_SIGMAS = 3.0


def clamp_mean(mean, low, high, sigma: float):
    """Clamp a behaviour mean to ``[low - 3 sigma, high + 3 sigma]`` (works for numpy arrays and torch tensors)."""
    lo, hi = low - MEAN_CLAMP_SIGMAS * sigma, high + MEAN_CLAMP_SIGMAS * sigma
    if isinstance(mean, th.Tensor):
        return th.maximum(th.minimum(mean, hi), lo)
    return np.clip(mean, lo, hi)


def sample_truncated_normal(
    mean: np.ndarray, sigma: float, low: np.ndarray, high: np.ndarray, rng: np.random.Generator | None = None
) -> np.ndarray:
    """Draw one action per mean from N(mean, sigma^2) truncated to [low, high] by inverse-CDF sampling.

    :param mean: behaviour means mu_b(s), shape (..., action_dim); clamped as in the authors' code.
    :param sigma: standard deviation sigma of the Gaussian before truncation (paper: 0.05).
    :param low: lower action bound a_min (broadcastable to ``mean``).
    :param high: upper action bound a_max.
    :param rng: numpy random generator; defaults to the global ``np.random`` state, which SB3's ``set_random_seed`` seeds.
    :return: samples, always inside [low, high], same shape and dtype as ``mean``.
    """
    check_sigma(sigma)
    mean64 = clamp_mean(np.asarray(mean, dtype=np.float64), np.asarray(low, np.float64), np.asarray(high, np.float64), sigma)
    alpha = (np.asarray(low, np.float64) - mean64) / sigma
    beta = (np.asarray(high, np.float64) - mean64) / sigma
    u = rng.random(mean64.shape) if rng is not None else np.random.random_sample(mean64.shape)
    # Inverse CDF on [Phi(alpha), Phi(beta)]; ndtri(ndtr(x)) is exact enough for |x| <= 3 + range / sigma in float64.
    cdf_lo, cdf_hi = special.ndtr(alpha), special.ndtr(beta)
    z = special.ndtri(cdf_lo + u * (cdf_hi - cdf_lo))
    sample = np.clip(mean64 + sigma * z, low, high)  # clip only guards against round-off at the bounds
    return sample.astype(np.asarray(mean).dtype if np.asarray(mean).dtype.kind == "f" else np.float32)


def truncated_normal_log_prob(actions: th.Tensor, mean: th.Tensor, sigma: float, low: th.Tensor, high: th.Tensor) -> th.Tensor:
    """Log-density of ``actions`` under N(mean, sigma^2) truncated to [low, high], summed over action dimensions.

    The joint density is the product over dimensions, as the authors' ``p0 = prod_j TG(a_j; mu_j, sigma)``.

    :return: tensor of shape (batch,) with log pi(a|s).
    """
    check_sigma(sigma)
    dtype = th.float64
    a, mu = actions.to(dtype), clamp_mean(mean.to(dtype), low.to(dtype), high.to(dtype), sigma)
    lo, hi = low.to(dtype), high.to(dtype)
    z = (a - mu) / sigma
    log_phi = -0.5 * z**2 - 0.5 * np.log(2 * np.pi) - np.log(sigma)
    log_mass = th.log(th.special.ndtr((hi - mu) / sigma) - th.special.ndtr((lo - mu) / sigma))
    return (log_phi - log_mass).sum(dim=-1).to(actions.dtype)


def importance_weight_floor(dtype: th.dtype) -> float:
    """Smallest importance weight kept: sqrt of the dtype's smallest normal number (about 1.1e-19 in float32).

    Weights below it are set to exactly 0. Such a sample's share of the weighted loss is far below the dtype's
    resolution, but its gradient, a product of the weight with the error and with the backward pass's factors (the
    N(0, 0.01) weights, leaky-ReLU slopes), falls into the subnormal range, where CPU arithmetic is many times slower.
    With sigma = 0.05 this is the common case, not a corner: an action 0.5 away from the target mean has a density
    ratio of about exp(-50).
    """
    return float(th.finfo(dtype).tiny) ** 0.5


def truncated_importance_weights(log_prob_target: th.Tensor, log_prob_behaviour: th.Tensor) -> th.Tensor:
    """Retrace-style truncated importance weight c = min(1, pi_{k-1}(a|s) / pi_b(a|s)) (paper, eq. 4 and Algorithm 1).

    Truncating at 1 (Munos et al. 2016) keeps the weighted critic loss's variance bounded: samples the current policy
    would play more often than the behaviour policy did are not up-weighted, only unlikely ones are down-weighted.
    Computed in log space so tiny densities do not underflow to 0/0; weights below :func:`importance_weight_floor`
    are exactly 0, so no subnormal number enters the critic's fit.
    """
    log_c = th.clamp(log_prob_target - log_prob_behaviour, max=0.0)
    log_floor = float(np.log(importance_weight_floor(log_c.dtype)))
    return th.exp(log_c.masked_fill(log_c < log_floor, -float("inf")))  # exp(-inf) = 0: no subnormal is formed
