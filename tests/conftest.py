"""Test-wide settings and shared fixtures.

One torch thread per test process (CI runs pytest -n 2 on a 2-core machine).
"""

from __future__ import annotations

import gymnasium as gym
import pytest
import torch as th

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
