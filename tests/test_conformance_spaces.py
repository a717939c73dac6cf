"""SB3 plugin contract, part 3: spaces and normalisation (float64 and multi-dimensional Box actions, discrete observations,
VecNormalize, env ids, true terminations; after SB3's tests/test_spaces.py, test_vec_normalize.py). The tiny variants
and helpers: fixtures of ``conftest.py``."""

from __future__ import annotations

import pathlib
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

import sb3_denfac  # noqa: F401  (registers the paper envs)
from sb3_denfac.common.checks import UnsupportedSpaceError

# ----- spaces and normalisation (SB3 tests/test_spaces.py, test_vec_normalize.py) --------------------------------------


class Float64ActionEnv(gym.Env):
    """Observation Box(-1, 1, (2,)) (float32 or float64, as HalfCheetah), action Box([0, -1], [4, 3]) float64."""

    action_space = spaces.Box(np.array([0.0, -1.0]), np.array([4.0, 3.0]), dtype=np.float64)  # asymmetric bounds

    def __init__(self, obs_dtype: type = np.float32) -> None:
        self.observation_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=obs_dtype)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        assert self.action_space.contains(action), action
        return self.observation_space.sample(), -float(np.sum(np.square(action))), False, False, {}


@pytest.mark.parametrize("obs_dtype", [np.float32, np.float64])
@pytest.mark.algorithms("all")
def test_float64_action_space(name: str, obs_dtype: type, episode_steps, make_model) -> None:
    """Box float64 actions work like float32 ones: actions keep the space's dtype and bounds."""
    env = gym.wrappers.TimeLimit(Float64ActionEnv(obs_dtype), max_episode_steps=episode_steps)
    model = make_model(name, env=env)
    model.learn(2 * episode_steps)
    observation, _ = env.reset(seed=0)
    for deterministic in (True, False):
        action, _ = model.predict(observation, deterministic=deterministic)
        assert action.dtype == np.float64
        assert env.action_space.contains(action)


class SpacesEnv(gym.Env):
    """Given observation and action spaces, random observations, reward 0."""

    def __init__(self, observation_space: spaces.Space, action_space: spaces.Space) -> None:
        self.observation_space, self.action_space = observation_space, action_space

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[Any, dict]:
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action: np.ndarray) -> tuple[Any, float, bool, bool, dict]:
        assert self.action_space.contains(action), action
        return self.observation_space.sample(), 0.0, False, False, {}


@pytest.mark.algorithms("all")
def test_multidimensional_action_space(name: str, episode_steps, make_model) -> None:
    """A Box action of shape (2, 2) works as in SB3 (tests/test_spaces.py): actions keep the space's shape."""
    box = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
    env = gym.wrappers.TimeLimit(SpacesEnv(box, spaces.Box(-2.0, 2.0, shape=(2, 2), dtype=np.float32)), episode_steps)
    model = make_model(name, env=env)
    model.learn(2 * episode_steps)
    for deterministic in (True, False):
        action, _ = model.predict(box.sample(), deterministic=deterministic)
        assert action.shape == (2, 2) and env.action_space.contains(action)


@pytest.mark.parametrize(
    "observation_space",
    [spaces.Discrete(5), spaces.MultiDiscrete([4, 3]), spaces.MultiBinary(8), spaces.MultiBinary((3, 2))],
    ids=str,
)
@pytest.mark.algorithms("all")
def test_discrete_observation_spaces(
    name: str, observation_space: spaces.Space, episode_steps, make_model, sample_observations
) -> None:
    """Discrete-like observations are one-hot encoded by SB3's preprocessing and work with every algorithm (SB3's
    test_identity_spaces spaces)."""
    env = gym.wrappers.TimeLimit(SpacesEnv(observation_space, spaces.Box(-1.0, 1.0, shape=(1,))), episode_steps)
    model = make_model(name, env=env)
    model.learn(2 * episode_steps)
    observations = sample_observations(observation_space, n=3)
    for deterministic in (True, False):
        action, _ = model.predict(observations[0], deterministic=deterministic)
        assert action.shape == (1,) and env.action_space.contains(action)
        assert model.predict(observations, deterministic=deterministic)[0].shape == (3, 1)


GOAL_SPACE = spaces.Dict(
    {
        "observation": spaces.Box(-1.0, 1.0, (3,)),
        "achieved_goal": spaces.Box(-1.0, 1.0, (2,)),
        "desired_goal": spaces.Box(-1.0, 1.0, (2,)),
    }
)


@pytest.mark.algorithms("all")
def test_dict_observations_get_a_policy_or_a_refusal_with_the_way_around(
    name: str, episode_steps, algo_class, make_model
) -> None:
    """A goal-conditioned env's Dict observation: DENFAC and SoftDENFAC take it with "MultiInputPolicy" (and SB3 tells
    "MlpPolicy" to use it); the others refuse both names with an error that names the cause and the way around (SB3
    said "use MultiInputPolicy", then "Policy MultiInputPolicy unknown": a dead end); flattened, the same env trains."""
    env = gym.wrappers.TimeLimit(SpacesEnv(GOAL_SPACE, spaces.Box(-1.0, 1.0, shape=(2,))), episode_steps)
    if "MultiInputPolicy" in algo_class(name).policy_aliases:
        with pytest.raises(ValueError, match="You must use `MultiInputPolicy`"):
            algo_class(name)("MlpPolicy", env)
        model = make_model(name, env=env, policy="MultiInputPolicy")
        assert model.policy_class.__name__ == "MultiInputPolicy"
        model.learn(2 * episode_steps)
        assert model.predict(GOAL_SPACE.sample())[0].shape == (2,)
        return
    for policy, cause in (("MlpPolicy", "the env's observation space is a Dict with keys"), ("MultiInputPolicy", "Dict")):
        with pytest.raises(UnsupportedSpaceError, match=rf"no MultiInputPolicy: {cause}.*FlattenObservation.*DENFAC"):
            algo_class(name)(policy, env)
    flat = gym.wrappers.FlattenObservation(env)
    model = make_model(name, env=flat)
    model.learn(2 * episode_steps)
    assert model.predict(flat.observation_space.sample())[0].shape == (2,)


@pytest.mark.algorithms("all")
def test_vec_normalize(tmp_path: pathlib.Path, name: str, episode_steps, algo_class, make_env, make_model) -> None:
    env = VecNormalize(DummyVecEnv([make_env]), gamma=0.9, norm_obs=True, norm_reward=True)
    model = make_model(name, env=env)
    model.learn(2 * episode_steps)
    assert model.get_vec_normalize_env() is env
    assert env.obs_rms.count > 2 * episode_steps
    if isinstance(model, OffPolicyAlgorithm):
        # The replay buffer keeps the original observations (Pendulum: cos^2 + sin^2 = 1), normalised at sampling.
        observations = model.replay_buffer.observations[: model.replay_buffer.size(), 0]
        np.testing.assert_allclose(np.square(observations[:, :2]).sum(axis=1), 1.0, rtol=1e-5)
    env.save(str(tmp_path / "vec_normalize.pkl"))
    model.save(tmp_path / "model.zip")
    loaded_env = VecNormalize.load(str(tmp_path / "vec_normalize.pkl"), DummyVecEnv([make_env]))
    model = algo_class(name).load(tmp_path / "model.zip", env=loaded_env)
    assert model.get_vec_normalize_env() is loaded_env
    model.learn(episode_steps, reset_num_timesteps=False)
    assert model.num_timesteps == 3 * episode_steps


# ----- env ids and true terminations ------------------------------------------------------------------------------------


@pytest.mark.algorithms("all")
def test_env_id_string(name: str, make_model) -> None:
    """An env id is made by SB3 (Pendulum-v1: 200-step episodes)."""
    overrides = dict(buffer_size=200) if "denfac" in name else {}
    model = make_model(name, env="Pendulum-v1", **overrides)
    model.learn(10)
    assert model.num_timesteps >= 10
    assert model.get_env().get_attr("spec")[0].id == "Pendulum-v1"


@pytest.mark.algorithms("all")
def test_true_terminations(name: str, episode_steps, off_policy_names, make_model) -> None:
    """The paper's CartPole ends early on failure: training runs through terminations and, off-policy, the buffer tells
    failures (dones without timeout) from time limits (timeouts)."""
    horizon = 5 * episode_steps  # a random start fails in about 50 steps
    env = gym.make("sb3_denfac/ContinuousCartPole-v0", max_episode_steps=horizon, episode_length=horizon, random_start=True)
    overrides = dict(buffer_size=4 * horizon) if name in off_policy_names else {}
    model = make_model(name, env=env, seed=0, **overrides)
    model.learn(2 * horizon)
    assert model.num_timesteps >= 2 * horizon
    lengths = [info["l"] for info in model.ep_info_buffer]
    failures = sum(length < horizon for length in lengths)
    assert failures >= 1, "the test needs early terminations"
    if isinstance(model, OffPolicyAlgorithm):
        size = model.replay_buffer.size()
        dones = model.replay_buffer.dones[:size, 0].astype(bool)
        timeouts = model.replay_buffer.timeouts[:size, 0].astype(bool)
        assert dones.sum() == len(lengths)  # every finished episode ends with done
        assert (dones & ~timeouts).sum() >= failures  # failures are true terminations, not time limits
        assert timeouts.sum() <= len(lengths) - failures


PAPER_ENVS = ["sb3_denfac/ContinuousAcrobot-v0", "sb3_denfac/ContinuousCartPole-v0", "sb3_denfac/HalfCheetahPaper-v0"]


@pytest.mark.parametrize("env_id", PAPER_ENVS)
@pytest.mark.algorithms("all")
def test_paper_envs(name: str, env_id: str, episode_steps, make_model) -> None:
    """Every algorithm runs on every paper environment (short episodes)."""
    env = gym.make(env_id, max_episode_steps=episode_steps, episode_length=episode_steps)
    model = make_model(name, env=env, seed=0)
    model.learn(2 * episode_steps)
    observation, _ = env.reset(seed=1)
    for deterministic in (True, False):
        action, _ = model.predict(observation, deterministic=deterministic)
        assert env.action_space.contains(action), action
