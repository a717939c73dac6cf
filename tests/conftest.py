"""Test-wide settings: one torch thread per test process (CI runs pytest -n 2 on a 2-core machine); shared fixtures.

The tiny algorithm variants of the conformance and reliability tests are defined here: a test marked
``@pytest.mark.algorithms("all")`` (or ``"off_policy"``, ``"with_learning_rate"``) runs once per variant of the group,
given as its ``name`` argument; the helpers (``make_model``, ``make_env``, ``algo_class``...) are fixtures of the same
name.
"""

from __future__ import annotations

import importlib
from copy import deepcopy
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3 import TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.preprocessing import get_flattened_obs_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

import sb3_denfac  # noqa: F401  (registers the paper envs)
from sb3_denfac.common.checks import InputChecksMixin
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


# ----- tiny algorithm variants (conformance and reliability tests) ------------------------------------------------------

EPISODE = 20  # steps per episode of every test env
#: Variants: "denfac_plain" is DENFAC on its plain (autograd) update path ("denfac" takes the default, fast when
#: possible); "soft_denfac" is SoftDENFAC; "ddpg_ig" is DDPG with inverting gradients and an unbounded actor ("ddpg":
#: SB3's tanh actor).
ALGOS = ["denfac", "denfac_plain", "soft_denfac", "ddpg", "ddpg_ig", "nfac", "cacla", "cmaes"]
CLASS_PATHS = {
    "denfac": "sb3_denfac.denfac:DENFAC",
    "denfac_plain": "sb3_denfac.denfac:DENFAC",
    "soft_denfac": "sb3_denfac.soft_denfac:SoftDENFAC",
    "ddpg": "sb3_denfac.ddpg:DDPG",
    "ddpg_ig": "sb3_denfac.ddpg:DDPG",
    "nfac": "sb3_denfac.nfac:NFAC",
    "cacla": "sb3_denfac.cacla:CACLA",
    "cmaes": "sb3_denfac.cmaes:CMAES",
}
#: Tiny configurations: every update is a handful of gradient steps on networks of a few units.
_TINY_DENFAC = dict(
    buffer_size=5 * EPISODE,
    n_fitted_iterations=1,
    critic_steps=2,
    actor_steps=2,
    policy_kwargs=dict(net_arch=dict(pi=[4], qf=[8, 4]), batch_norm=True),
)
_TINY_DDPG = dict(
    buffer_size=5 * EPISODE, learning_starts=10, batch_size=8, policy_kwargs=dict(net_arch=dict(pi=[4], qf=[8, 4]))
)
TINY_KWARGS: dict[str, dict[str, Any]] = {
    "denfac": _TINY_DENFAC,
    "denfac_plain": {**_TINY_DENFAC, "update_path": "plain"},
    "soft_denfac": {**_TINY_DENFAC, "policy_kwargs": dict(net_arch=dict(pi=[4], qf=[8, 4]))},  # SAC's actor: no BN
    "ddpg": _TINY_DDPG,
    "ddpg_ig": {**_TINY_DDPG, "inverting_gradients": True},
    "nfac": dict(
        n_fitted_iterations=1,
        critic_steps=2,
        actor_steps=2,
        policy_kwargs=dict(net_arch=dict(pi=[4], vf=[8, 4])),
    ),
    "cacla": dict(n_steps=EPISODE, bn_window=4, policy_kwargs=dict(net_arch=dict(pi=[4], vf=[8, 4]))),
    "cmaes": dict(population_size=2, policy_kwargs=dict(net_arch=[4])),
}
OFF_POLICY = ["denfac", "denfac_plain", "soft_denfac", "ddpg", "ddpg_ig"]


def algo_class(name: str) -> type[BaseAlgorithm]:
    module_name, class_name = CLASS_PATHS[name].split(":")
    return getattr(importlib.import_module(module_name), class_name)


def make_env(episode: int = EPISODE) -> gym.Env:
    return gym.make("Pendulum-v1", max_episode_steps=episode)


def make_model(name: str, env: Any = None, policy: str = "MlpPolicy", **overrides: Any) -> BaseAlgorithm:
    kwargs = deepcopy(TINY_KWARGS[name])
    kwargs.update(overrides)
    return algo_class(name)(policy, make_env() if env is None else env, **kwargs)


def sample_observations(space: spaces.Space, n: int = 10, seed: int = 0) -> np.ndarray:
    space = deepcopy(space)
    space.seed(seed)
    return np.stack([space.sample() for _ in range(n)])


def batch_norm_buffers(module: th.nn.Module) -> dict[str, th.Tensor]:
    return {
        f"{name}.{buffer}": getattr(layer, buffer).clone()
        for name, layer in module.named_modules()
        if isinstance(layer, th.nn.modules.batchnorm._BatchNorm)
        for buffer in ("running_mean", "running_var")
    }


# exact: for runs repeated in one process (same seed, code and kernels) and for values saved and read back
def assert_equal_nested(a: Any, b: Any, where: str = "") -> None:
    """Exact equality of nested dicts / lists of tensors and scalars (optimizer state dicts included)."""
    if isinstance(a, th.Tensor):
        assert isinstance(b, th.Tensor) and th.equal(a, b), f"{where} differs"
    elif isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), f"{where}: keys differ"
        for key in a:
            assert_equal_nested(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), f"{where}: lengths differ"
        for index, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_equal_nested(x, y, f"{where}[{index}]")
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def assert_same_parameters(params_a: dict, params_b: dict) -> None:
    """Same networks, batch-norm buffers and optimizer states."""
    assert params_a.keys() == params_b.keys()
    for object_name, state in params_a.items():
        assert_equal_nested(state, params_b[object_name], object_name)


#: The variant groups of ``@pytest.mark.algorithms(group)``.
ALGORITHM_GROUPS: dict[str, list[str]] = {
    "all": ALGOS,
    "off_policy": OFF_POLICY,
    "with_learning_rate": [name for name in ALGOS if name != "cmaes"],  # CMA-ES has no learning rate
}


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    marker = metafunc.definition.get_closest_marker("algorithms")
    if marker is not None:
        metafunc.parametrize("name", ALGORITHM_GROUPS[marker.args[0]])


@pytest.fixture
def episode_steps() -> int:
    """Steps per episode of every tiny test env (``make_env``)."""
    return EPISODE


@pytest.fixture
def off_policy_names() -> list[str]:
    """The off-policy variants (a replay buffer)."""
    return OFF_POLICY


@pytest.fixture
def tiny_kwargs() -> dict[str, dict[str, Any]]:
    """The constructor arguments of each tiny variant (a copy: tests may edit it)."""
    return deepcopy(TINY_KWARGS)


def _helper_fixture(helper: Any) -> Any:
    """A fixture named and documented as ``helper`` that gives the function itself."""

    def fixture() -> Any:
        return helper

    fixture.__doc__ = helper.__doc__
    return pytest.fixture(name=helper.__name__)(fixture)


#: ``algo_class(name)``, ``make_env(episode)``, ``make_model(name, env=None, **overrides)``,
#: ``sample_observations(space, n, seed)``, ``batch_norm_buffers(module)``, ``assert_same_parameters(a, b)``.
algo_class_fixture = _helper_fixture(algo_class)
make_env_fixture = _helper_fixture(make_env)
make_model_fixture = _helper_fixture(make_model)
sample_observations_fixture = _helper_fixture(sample_observations)
batch_norm_buffers_fixture = _helper_fixture(batch_norm_buffers)
assert_same_parameters_fixture = _helper_fixture(assert_same_parameters)


# ----- a bandit-like env (DENFAC tests) ----------------------------------------------------------------------------------


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

    def distance_to_target(self, model: Any, observations: np.ndarray) -> float:
        """The mean distance of ``model``'s deterministic actions on ``observations`` to the rewarded action."""
        return float(np.abs(model.predict(observations, deterministic=True)[0] - self.target).mean())


@pytest.fixture
def target_action_env() -> type[gym.Env]:
    """The class of :class:`TargetActionEnv` (the best action is 0.6 in the scaled space)."""
    return TargetActionEnv


# ----- a tiny SB3 algorithm with the package's input checks (reliability tests) ------------------------------------------


class CheckedTD3(InputChecksMixin, TD3):
    pass


@pytest.fixture
def checked_td3_class() -> type[TD3]:
    """SB3's TD3 with :class:`~sb3_denfac.common.checks.InputChecksMixin` first in its bases."""
    return CheckedTD3


@pytest.fixture
def make_checked_td3() -> Any:
    """``make_checked_td3(env)``: a tiny :class:`CheckedTD3`."""

    def make(env: Any) -> CheckedTD3:
        return CheckedTD3("MlpPolicy", env, learning_starts=5, batch_size=8, buffer_size=100, policy_kwargs=dict(net_arch=[4]))

    return make
