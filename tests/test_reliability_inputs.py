"""Bad inputs get clear errors: discrete or unbounded action spaces, several envs for episode-wise algorithms, a
missing or mismatched env, NaN/inf observations and rewards (:mod:`sb3_denfac.common.checks`, on the package's
algorithms and on a tiny SB3 TD3 with the mixin). Invalid hyperparameters: ``test_reliability_hyperparameters.py``;
model files and resume: ``test_reliability_model_files.py``; YAML errors: ``test_zoo.py``.
"""

from __future__ import annotations

import pathlib
from copy import deepcopy
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3 import SAC, TD3
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, VecCheckNan, VecNormalize

from sb3_denfac.common.checks import FiniteCheckWrapper, UnsupportedSpaceError, wrap_check_finite

#: Algorithms that learn from whole episodes of a single environment (DENFAC and NFAC take several envs).
EPISODE_WISE = ["cmaes"]


class DiscreteActionEnv(gym.Env):
    """Box observations with a Discrete / MultiDiscrete action space."""

    observation_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)

    def __init__(self, action_space: spaces.Space) -> None:
        self.action_space = action_space

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        return self.observation_space.sample(), 0.0, False, False, {}


@pytest.mark.parametrize("action_space", [spaces.Discrete(3), spaces.MultiDiscrete([3, 2])], ids=["discrete", "multidiscrete"])
@pytest.mark.algorithms("all")
def test_discrete_action_space_is_refused(name: str, action_space: spaces.Space, episode_steps, make_model) -> None:
    env = gym.wrappers.TimeLimit(DiscreteActionEnv(action_space), max_episode_steps=episode_steps)
    with pytest.raises(UnsupportedSpaceError) as error:  # one type for all six algorithms
        make_model(name, env=env)
    assert isinstance(error.value, ValueError) and isinstance(error.value, AssertionError)  # SB3-style callers catch it
    message = str(error.value)
    assert str(action_space) in message, message  # names what was given...
    assert "Box" in message or "continuous" in message, message  # ...and what is needed


@pytest.mark.parametrize("name", EPISODE_WISE)
def test_several_envs_are_refused_by_episode_wise_algorithms(
    tmp_path: pathlib.Path, name: str, algo_class, make_env, make_model
) -> None:
    with pytest.raises(ValueError, match="single (vectorized )?environment"):
        make_model(name, env=make_vec_env(make_env, n_envs=2))
    make_model(name).save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match="single (vectorized )?environment"):
        algo_class(name).load(tmp_path / "model.zip", env=make_vec_env(make_env, n_envs=2))


def test_ddpg_episodic_training_needs_one_env(episode_steps, make_env, make_model) -> None:
    model = make_model("ddpg", env=make_vec_env(make_env, n_envs=2), train_freq=(1, "episode"))
    with pytest.raises(AssertionError, match="only one env when doing episodic training"):
        model.learn(episode_steps)


class UnboundedActionEnv(DiscreteActionEnv):
    def __init__(self) -> None:
        super().__init__(spaces.Box(-np.inf, np.inf, shape=(1,), dtype=np.float32))


@pytest.mark.algorithms("all")
def test_unbounded_action_space_is_refused(name: str, episode_steps, make_model) -> None:
    with pytest.raises(UnsupportedSpaceError, match="finite"):
        make_model(name, env=gym.wrappers.TimeLimit(UnboundedActionEnv(), max_episode_steps=episode_steps))


@pytest.mark.algorithms("all")
def test_load_with_mismatched_env(tmp_path: pathlib.Path, name: str, episode_steps, algo_class, make_model) -> None:
    make_model(name).save(tmp_path / "model.zip")
    cartpole = gym.make("sb3_denfac/ContinuousCartPole-v0", max_episode_steps=episode_steps, episode_length=episode_steps)
    with pytest.raises(ValueError, match="Observation spaces do not match"):
        algo_class(name).load(tmp_path / "model.zip", env=cartpole)


@pytest.mark.algorithms("all")
def test_learn_without_env(tmp_path: pathlib.Path, name: str, episode_steps, algo_class, make_env, make_model) -> None:
    """Loaded without ``env=``: predict works, learn says how to give an environment (needs InputChecksMixin)."""
    make_model(name).save(tmp_path / "model.zip")
    model = algo_class(name).load(tmp_path / "model.zip")
    assert model.get_env() is None
    model.predict(model.observation_space.sample(), deterministic=True)
    with pytest.raises(ValueError, match="needs an environment"):
        model.learn(episode_steps)
    model.set_env(make_env())
    model.learn(episode_steps)


# ----- NaN / inf inputs ------------------------------------------------------------------------------------------------
class CorruptingWrapper(gym.Wrapper):
    """Puts ``value`` into the observation (at reset or at step ``at_step``) or into the reward of step ``at_step``."""

    def __init__(self, env: gym.Env, where: str, value: float, at_step: int = 5) -> None:
        super().__init__(env)
        self.where, self.value, self.at_step, self.steps = where, value, at_step, 0

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict]:
        obs, info = self.env.reset(**kwargs)
        if self.where == "reset":
            obs = obs.copy()
            obs[0] = self.value
        return obs, info

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        if self.steps == self.at_step:
            if self.where == "observation":
                obs = obs.copy()
                obs[1] = self.value
            elif self.where == "reward":
                reward = self.value
        return obs, reward, terminated, truncated, info


FAULTS = [
    ("observation", np.nan, "found nan in observations"),
    ("observation", np.inf, "found inf in observations"),
    ("reward", np.nan, "found nan in rewards"),
    ("reward", -np.inf, "found inf in rewards"),
    ("reset", np.nan, "found nan in observations"),
]


def _all_finite(model: Any) -> bool:
    return all(th.isfinite(p).all() for p in model.policy.state_dict().values() if th.is_floating_point(p))


@pytest.mark.parametrize(("where", "value", "message"), FAULTS, ids=[f"{w}-{v}" for w, v, _ in FAULTS])
@pytest.mark.algorithms("all")
def test_non_finite_inputs_raise(
    name: str, where: str, value: float, message: str, episode_steps, make_env, make_model
) -> None:
    """Needs :class:`~sb3_denfac.common.checks.InputChecksMixin` in the algorithm's bases."""
    model = make_model(name, env=CorruptingWrapper(make_env(), where, value))
    with pytest.raises(ValueError, match=message):
        model.learn(3 * episode_steps)
    assert _all_finite(model), "non-finite input reached the weights"


@pytest.mark.parametrize(("value", "message"), [(np.nan, "found nan in observations"), (np.inf, "found inf in observations")])
@pytest.mark.algorithms("all")
def test_predict_refuses_non_finite_observations(name: str, value: float, message: str, make_env, make_model) -> None:
    """As ``learn`` does; ``allow_non_finite_predict`` lets them through to the policy."""
    model = make_model(name)
    observation = make_env().reset(seed=0)[0]
    observation[1] = value
    with pytest.raises(ValueError, match=rf"{message}. Originated from the observation given to \w+\.predict\(\)"):
        model.predict(observation, deterministic=True)
    with pytest.raises(ValueError, match=message):
        model.predict(np.stack([observation, np.zeros_like(observation)]))  # one bad row of a batch
    model.allow_non_finite_predict = True
    if name == "soft_denfac":  # SAC's squashed Gaussian: torch's distribution refuses a non-finite mean, as in SB3's SAC
        with pytest.raises(ValueError, match="Normal"):
            model.predict(observation, deterministic=True)
    else:
        action, _ = model.predict(observation, deterministic=True)
        assert action.shape == model.action_space.shape


@pytest.mark.algorithms("off_policy")
def test_replay_buffer_extend_as_sb3s_test(tmp_path: pathlib.Path, name: str, episode_steps, make_model) -> None:
    """SB3's ``test_save_load_replay_buffer``: the loaded buffer is extended with its own data (for DENFAC: rows
    without behaviour means), then trained on."""
    model = make_model(name)
    model.learn(2 * episode_steps)
    old_buffer = deepcopy(model.replay_buffer)
    model.save_replay_buffer(tmp_path / "replay_buffer.pkl")
    model.replay_buffer = None
    model.load_replay_buffer(tmp_path / "replay_buffer.pkl")
    size = old_buffer.size()
    arrays = (old_buffer.observations, old_buffer.next_observations, old_buffer.actions, old_buffer.rewards, old_buffer.dones)
    model.replay_buffer.extend(*(array[:size] for array in arrays), [[{}] for _ in range(size)])
    assert model.replay_buffer.size() == 4 * episode_steps
    model.learn(episode_steps, reset_num_timesteps=False)
    assert model.replay_buffer.size() == 5 * episode_steps


def test_denfac_replay_buffer_takes_sb3_add_without_behaviour_means(tmp_path: pathlib.Path, make_model) -> None:
    """SB3's add/extend (demonstrations, logged data) without the behaviour means, where no importance weight reads
    them (the default weighting="none"); the rows are marked unknown, not uniform (NaN: warm-up actions)."""
    model = make_model("denfac", learning_starts=5)
    model.learn(20)
    buffer = model.replay_buffer
    assert np.isnan(buffer.behaviour_means[:5]).all() and np.isfinite(buffer.behaviour_means[5:20]).all()
    obs = np.zeros((1, 3), dtype=np.float32)
    buffer.add(obs, obs, np.zeros((1, 1), dtype=np.float32), np.zeros(1), np.zeros(1), [{}])
    assert np.isposinf(buffer.behaviour_means[20]).all()
    model.learn(20, reset_num_timesteps=False)
    assert model.replay_buffer.size() == 41
    model.save_replay_buffer(tmp_path / "buffer.pkl")

    # weights that read the means: a row without them is refused, naming the setting, and never weighted as uniform
    retrace = make_model("denfac", weighting="retrace")
    retrace.load_replay_buffer(tmp_path / "buffer.pkl")
    with pytest.raises(ValueError, match=r"1 transitions of the replay buffer were added without behaviour means.*"
                                         r"weighting='retrace' needs them"):  # fmt: skip
        retrace.learn(20)


@pytest.mark.parametrize("weighting", ["retrace", "retrace_next_state_quirk"])
def test_denfac_replay_buffer_add_without_behaviour_means_names_the_weighting(weighting: str, make_model) -> None:
    model = make_model("denfac", weighting=weighting)
    model.learn(20)
    buffer = model.replay_buffer
    with pytest.raises(ValueError, match=rf"add needs the behaviour means mu_b\(s\) with weighting='{weighting}'"):
        buffer.extend(buffer.observations[:2], buffer.next_observations[:2], buffer.actions[:2], buffer.rewards[:2],
                      buffer.dones[:2], [[{}], [{}]])  # fmt: skip
    assert buffer.size() == 20
    means = buffer.behaviour_means[:2].copy()
    buffer.add(buffer.observations[0], buffer.next_observations[0], buffer.actions[0], buffer.rewards[0],
               buffer.dones[0], [{}], behaviour_means=means[0])  # fmt: skip
    model.learn(20, reset_num_timesteps=False)


# ----- the shared check itself (sb3_denfac/common/checks.py), on a tiny SB3 algorithm (CheckedTD3, conftest.py) -------
@pytest.mark.parametrize(("where", "value", "message"), FAULTS, ids=[f"{w}-{v}" for w, v, _ in FAULTS])
def test_finite_inputs_mixin(where: str, value: float, message: str, episode_steps, make_checked_td3, make_env) -> None:
    model = make_checked_td3(CorruptingWrapper(make_env(), where, value))
    with pytest.raises(ValueError, match=message):
        model.learn(2 * episode_steps)
    plain = TD3("MlpPolicy", CorruptingWrapper(make_env(), where, value), learning_starts=5, policy_kwargs=dict(net_arch=[4]))
    if where != "reset":
        plain.learn(10)  # without the mixin, SB3 takes the bad value silently


def test_finite_inputs_mixin_wraps_every_env(
    tmp_path: pathlib.Path, checked_td3_class, episode_steps, make_checked_td3, make_env
) -> None:
    vec_normalize = VecNormalize(DummyVecEnv([make_env, make_env]))
    model = make_checked_td3(vec_normalize)
    assert model.get_env() is vec_normalize  # the VecEnv keeps its type: each sub-env is checked in place
    assert all(isinstance(sub_env, FiniteCheckWrapper) for sub_env in vec_normalize.venv.envs)
    assert model.get_env().get_attr("spec")[0].max_episode_steps == episode_steps  # attributes still reach the env

    model.set_env(model.get_env(), force_reset=False)
    assert not any(isinstance(sub_env.env, FiniteCheckWrapper) for sub_env in vec_normalize.venv.envs), "wrapped twice"
    model = make_checked_td3(make_env())
    model.set_env(CorruptingWrapper(make_env(), "reward", np.nan))
    with pytest.raises(ValueError, match="found nan in rewards"):
        model.learn(episode_steps)

    model.save(tmp_path / "model.zip")
    loaded = checked_td3_class.load(tmp_path / "model.zip", env=CorruptingWrapper(make_env(), "observation", np.inf))
    with pytest.raises(ValueError, match="found inf in observations"):
        loaded.learn(episode_steps)

    warning_only = VecCheckNan(DummyVecEnv([make_env]), raise_exception=False)
    assert wrap_check_finite(warning_only) is warning_only  # a warning-only check is not enough: sub-envs are checked
    assert isinstance(warning_only.venv.envs[0], FiniteCheckWrapper)


def test_finite_inputs_mixin_other_vec_envs(episode_steps, make_checked_td3, make_env) -> None:
    """VecEnvs whose sub-envs live elsewhere (SubprocVecEnv) get SB3's VecCheckNan(raise_exception=True)."""
    from stable_baselines3.common.vec_env import SubprocVecEnv

    env = SubprocVecEnv([lambda: CorruptingWrapper(make_env(), "reward", np.inf)], start_method="fork")
    try:
        model = make_checked_td3(env)
        assert isinstance(model.get_env(), VecCheckNan) and model.get_env().raise_exception
        with pytest.raises(ValueError, match="found inf in rewards"):
            model.learn(episode_steps)
    finally:
        env.close()


def test_finite_inputs_mixin_keeps_eval_callback_quiet(episode_steps, make_checked_td3, make_env) -> None:
    """SB3's EvalCallback warns when the training and eval envs differ in type: the check must not cause that."""
    import warnings

    from stable_baselines3.common.callbacks import EvalCallback

    model = make_checked_td3(make_env())
    callback = EvalCallback(make_env(), eval_freq=episode_steps // 2, n_eval_episodes=1)  # warns on a type mismatch
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model.learn(episode_steps, callback=callback)
    mismatches = [str(w.message) for w in caught if "not of the same type" in str(w.message)]
    assert mismatches == []
    assert np.isfinite(callback.last_mean_reward)  # the evaluation ran


def test_finite_inputs_mixin_catches_nan_actions(make_checked_td3, make_env) -> None:
    model = make_checked_td3(make_env())
    with th.no_grad():
        for parameter in model.actor.parameters():
            parameter.fill_(np.nan)
    model.learning_starts = 0
    with pytest.raises(ValueError, match="found nan in actions"):
        model.learn(10)


def test_learn_checks_mixin(tmp_path: pathlib.Path, checked_td3_class, make_checked_td3, make_env) -> None:
    make_checked_td3(make_env()).save(tmp_path / "model.zip")
    model = checked_td3_class.load(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=r"CheckedTD3.learn\(\) needs an environment"):
        model.learn(10)


def test_learn_checks_mixin_replay_buffer(
    tmp_path: pathlib.Path, checked_td3_class, episode_steps, make_checked_td3, make_env
) -> None:
    from sb3_denfac.denfac.buffers import DENFACReplayBuffer

    class CheckedTD3WithOwnBuffer(checked_td3_class):
        pass

    sac = SAC("MlpPolicy", make_env(), learning_starts=5, policy_kwargs=dict(net_arch=[4]))
    sac.learn(10)
    sac.save_replay_buffer(tmp_path / "pendulum.pkl")
    model = CheckedTD3WithOwnBuffer("MlpPolicy", make_env(), replay_buffer_class=DENFACReplayBuffer)
    model.load_replay_buffer(tmp_path / "pendulum.pkl")
    with pytest.raises(ValueError, match="is a ReplayBuffer, it needs a DENFACReplayBuffer"):
        model.learn(10)

    cartpole = gym.make("sb3_denfac/ContinuousCartPole-v0", max_episode_steps=episode_steps, episode_length=episode_steps)
    model = make_checked_td3(cartpole)
    model.load_replay_buffer(tmp_path / "pendulum.pkl")
    with pytest.raises(ValueError, match=r"observation shape \(3,\).*does not fit.*observation shape \(4,\)"):
        model.learn(10)
