"""Test-wide settings: one torch thread per test process (CI runs pytest -n 2 on a 2-core machine); shared fixtures."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3.common.preprocessing import get_flattened_obs_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from sb3_denfac.denfac import DENFAC
from sb3_denfac.denfac.presets import paper

th.set_num_threads(1)

#: Small DENFAC settings for fast tests of Algorithm 1 as written (the paper preset, small; overridden by keyword).
SMALL_DENFAC = paper(
    buffer_size=200,
    n_fitted_iterations=2,
    critic_steps=3,
    actor_steps=4,
    policy_kwargs=dict(net_arch=dict(pi=[8], qf=[16, 4])),
)


@pytest.fixture
def make_denfac():
    """``make_denfac(env=None, **kwargs)``: a seeded DENFAC with :data:`SMALL_DENFAC` settings (Pendulum, 50 steps)."""

    def make(env=None, **kwargs) -> DENFAC:
        params = {**SMALL_DENFAC, **kwargs}
        params["policy_kwargs"] = {**SMALL_DENFAC["policy_kwargs"], **kwargs.get("policy_kwargs", {})}
        return DENFAC("MlpPolicy", env or gym.make("Pendulum-v1", max_episode_steps=50), seed=0, **params)

    return make


class NeverEndingEnv(gym.Env):
    """Never terminates nor truncates (no TimeLimit): Box(2,) observations, Box(-1, 1, (1,)) actions, reward -a^2."""

    observation_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
    action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        return self.np_random.uniform(-1, 1, size=2).astype(np.float32), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        observation = self.np_random.uniform(-1, 1, size=2).astype(np.float32)
        return observation, -float(np.square(action).sum()), False, False, {}


class FlattenBatchNormDropoutExtractor(BaseFeaturesExtractor):
    """SB3's tests/test_train_eval_mode.py extractor: flatten, batch norm, dropout."""

    def __init__(self, observation_space: gym.Space) -> None:
        super().__init__(observation_space, get_flattened_obs_dim(observation_space))
        self.flatten = th.nn.Flatten()
        self.batch_norm = th.nn.BatchNorm1d(self._features_dim)
        self.dropout = th.nn.Dropout(0.5)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return self.dropout(self.batch_norm(self.flatten(observations)))


@pytest.fixture
def never_ending_env() -> type[gym.Env]:
    """The class of an env that never ends (see :class:`NeverEndingEnv`)."""
    return NeverEndingEnv


@pytest.fixture
def batch_norm_extractor() -> type[BaseFeaturesExtractor]:
    """SB3's batch-norm + dropout features extractor class."""
    return FlattenBatchNormDropoutExtractor
