"""Truncated-Gaussian exploration for off-policy SB3 algorithms (paper, section 4).

"The actor policy is a truncated Gaussian policy between [a_min = -1, a_max = 1] with sigma = 0.05 where the mean is
determined by the output of the last linear layer." SB3's off-policy algorithms explore with additive action noise
followed by clipping; :class:`TruncatedGaussianExplorationMixin` replaces that ``_sample_action`` hook with a sample of
N(mu(s), sigma^2) truncated to [-1, 1] around the deterministic actor output mu(s), in the scaled action space.

Usage (the mixin must come first in the bases so its ``_sample_action`` wins)::

    class MyAlgo(TruncatedGaussianExplorationMixin, OffPolicyAlgorithm):
        def __init__(self, ..., sigma: float | None = 0.05, ...):
            ...
            self.sigma = check_sigma(sigma, none_ok=True)  # sb3_denfac.common.checks

Stable API (other algorithms rely on it):

- ``self.sigma``: float > 0 -> truncated Gaussian exploration; ``None`` -> SB3's own ``_sample_action`` (additive
  ``action_noise``, clipped), i.e. the mixin is switched off.
- ``_sample_action(learning_starts, action_noise, n_envs) -> (env_action, buffer_action)`` as in SB3: ``env_action`` in
  the env's [low, high], ``buffer_action`` in the scaled [-1, 1] space.
- ``self._last_behaviour_mean``: np.ndarray (n_envs, action_dim), float32, the behaviour mean mu_b(s) of the last sample
  in the scaled space, as output by the actor (not clamped: clamp with ``truncated_normal.clamp_mean`` or let
  ``truncated_normal_log_prob`` do it). Rows are NaN for uniform warm-up actions (see below). Not updated when
  ``sigma is None`` (SB3's own exploration).
- :func:`exploration_mean`: the deterministic actor output mu(s) in the scaled space, unclipped: the forward pass of
  ``policy.actor`` (SB3's convention for TD3/DDPG actors, whose ``forward`` returns mu(s) while ``_predict`` may clip
  it), in eval mode; :func:`truncated_gaussian_actions` and :func:`warm_up_actions` draw from it or uniformly (the
  episodic base, :mod:`~sb3_denfac.common.episodic`, calls them without the mixin).
- :func:`behaviour_log_prob`: log pi_b(a|s) for stored (action, behaviour mean) pairs, NaN means -> uniform density.

Warm-up: while ``num_timesteps < learning_starts`` actions are drawn uniformly from the action space, like SB3
(``learning_starts=0`` disables this; the paper has no warm-up). Their behaviour density is the uniform one, which the
NaN convention lets :func:`behaviour_log_prob` recover for importance weights.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.noise import ActionNoise

from sb3_denfac.common.truncated_normal import sample_truncated_normal, truncated_normal_log_prob


def behaviour_log_prob(
    actions: th.Tensor, behaviour_means: th.Tensor, sigma: float, low: float = -1.0, high: float = 1.0
) -> th.Tensor:
    """log pi_b(a|s) of scaled ``actions`` (batch, action_dim) under the behaviour policy that produced them.

    Rows of ``behaviour_means`` that are finite use the truncated Gaussian TG(a; mu_b, sigma, [low, high]) (summed over
    dimensions); rows containing NaN (uniform warm-up actions) get the uniform log-density ``-action_dim * log(high-low)``.

    :return: tensor of shape (batch,).
    """
    low_t = th.full_like(actions, low)
    high_t = th.full_like(actions, high)
    uniform_rows = th.isnan(behaviour_means).any(dim=-1)
    safe_means = th.where(th.isnan(behaviour_means), th.zeros_like(behaviour_means), behaviour_means)
    log_prob = truncated_normal_log_prob(actions, safe_means, sigma, low_t, high_t)
    uniform = th.full_like(log_prob, -actions.shape[-1] * float(np.log(high - low)))
    return th.where(uniform_rows, uniform, log_prob)


def exploration_mean(policy: Any, action_space: spaces.Box, observation: Any) -> np.ndarray:
    """The deterministic actor output mu(s) in the scaled [-1, 1] space, unclipped, shape (n_envs, action_dim): the
    forward pass of ``policy.actor`` in eval mode."""
    policy.set_training_mode(False)
    obs_tensor, _ = policy.obs_to_tensor(observation)
    with th.no_grad():
        mean = policy.actor(obs_tensor)
    return mean.cpu().numpy().reshape((-1, *action_space.shape)).astype(np.float32)


def warm_up_actions(policy: Any, action_space: spaces.Box, n_envs: int) -> tuple[np.ndarray, np.ndarray]:
    """Uniform actions of the warm-up (``learning_starts``), as SB3: the actions in the scaled [-1, 1] space, and NaN
    behaviour means that mark them (:func:`behaviour_log_prob`)."""
    unscaled = np.array([action_space.sample() for _ in range(n_envs)])
    buffer_action = policy.scale_action(unscaled).astype(np.float32)
    return buffer_action, np.full_like(buffer_action, np.nan)


def truncated_gaussian_actions(
    policy: Any, action_space: spaces.Box, observation: Any, sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """Actions drawn from N(mu(s), sigma^2) truncated to [-1, 1] (the scaled space), and the behaviour means mu(s)."""
    mean = exploration_mean(policy, action_space, observation)
    return sample_truncated_normal(mean, sigma, -1.0, 1.0), mean


class TruncatedGaussianExplorationMixin:
    """Replace SB3's additive-noise exploration with a truncated Gaussian around the actor output (see module doc).

    Requires the host class to be an SB3 ``OffPolicyAlgorithm`` with a Box action space and to set ``self.sigma``.
    """

    sigma: float | None
    _last_behaviour_mean: np.ndarray | None = None

    # Attributes provided by OffPolicyAlgorithm (declared for type checkers).
    policy: Any
    action_space: spaces.Space
    num_timesteps: int
    _last_obs: Any

    def _sample_action(
        self, learning_starts: int, action_noise: ActionNoise | None = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        if self.sigma is None:
            return super()._sample_action(learning_starts, action_noise, n_envs)  # type: ignore[misc]
        assert isinstance(self.action_space, spaces.Box), "truncated Gaussian exploration needs a Box action space"
        if self.num_timesteps < learning_starts:  # warm-up, as SB3: uniform actions
            buffer_action, mean = warm_up_actions(self.policy, self.action_space, n_envs)
        else:
            assert self._last_obs is not None, "self._last_obs was not set"
            buffer_action, mean = truncated_gaussian_actions(self.policy, self.action_space, self._last_obs, self.sigma)
        self._last_behaviour_mean = mean
        return self.policy.unscale_action(buffer_action), buffer_action
