"""Bad inputs get clear errors, and nothing is lost across a checkpoint: discrete action spaces, several envs for
episode-wise algorithms, NaN/inf inputs (:mod:`sb3_denfac.common.checks`), invalid hyperparameters, corrupted or foreign
model zips, checkpoint and resume.

YAML errors and Optuna resume of the zoo integration are tested in ``tests/test_zoo.py``.
"""

from __future__ import annotations

import pathlib
import zipfile
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3 import SAC, TD3
from stable_baselines3.common.callbacks import CheckpointCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, VecCheckNan, VecNormalize
from test_conformance import ALGOS, EPISODE, OFF_POLICY, algo_class, assert_same_parameters, make_env, make_model

from sb3_denfac.common.checks import FiniteCheckWrapper, InputChecksMixin, UnsupportedSpaceError, wrap_check_finite

#: Algorithms that learn from whole episodes of a single environment.
EPISODE_WISE = ["denfac", "denfac_plain", "cmaes"]  # NFAC takes several envs (episodes end at different steps)


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
@pytest.mark.parametrize("name", ALGOS)
def test_discrete_action_space_is_refused(name: str, action_space: spaces.Space) -> None:
    env = gym.wrappers.TimeLimit(DiscreteActionEnv(action_space), max_episode_steps=EPISODE)
    with pytest.raises(UnsupportedSpaceError) as error:  # one type for all five algorithms
        make_model(name, env=env)
    assert isinstance(error.value, ValueError) and isinstance(error.value, AssertionError)  # SB3-style callers catch it
    message = str(error.value)
    assert str(action_space) in message, message  # names what was given...
    assert "Box" in message or "continuous" in message, message  # ...and what is needed


@pytest.mark.parametrize("name", EPISODE_WISE)
def test_several_envs_are_refused_by_episode_wise_algorithms(tmp_path: pathlib.Path, name: str) -> None:
    with pytest.raises(ValueError, match="single (vectorized )?environment"):
        make_model(name, env=make_vec_env(make_env, n_envs=2))
    make_model(name).save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match="single (vectorized )?environment"):
        algo_class(name).load(tmp_path / "model.zip", env=make_vec_env(make_env, n_envs=2))


def test_ddpg_episodic_training_needs_one_env() -> None:
    model = make_model("ddpg", env=make_vec_env(make_env, n_envs=2), train_freq=(1, "episode"))
    with pytest.raises(AssertionError, match="only one env when doing episodic training"):
        model.learn(EPISODE)


class UnboundedActionEnv(DiscreteActionEnv):
    def __init__(self) -> None:
        super().__init__(spaces.Box(-np.inf, np.inf, shape=(1,), dtype=np.float32))


@pytest.mark.parametrize("name", ALGOS)
def test_unbounded_action_space_is_refused(name: str) -> None:
    with pytest.raises(UnsupportedSpaceError, match="finite"):
        make_model(name, env=gym.wrappers.TimeLimit(UnboundedActionEnv(), max_episode_steps=EPISODE))


@pytest.mark.parametrize("name", ALGOS)
def test_load_with_mismatched_env(tmp_path: pathlib.Path, name: str) -> None:
    make_model(name).save(tmp_path / "model.zip")
    cartpole = gym.make("sb3_denfac/ContinuousCartPole-v0", max_episode_steps=EPISODE, episode_length=EPISODE)
    with pytest.raises(ValueError, match="Observation spaces do not match"):
        algo_class(name).load(tmp_path / "model.zip", env=cartpole)


@pytest.mark.parametrize("name", ALGOS)
def test_learn_without_env(tmp_path: pathlib.Path, name: str) -> None:
    """Loaded without ``env=``: predict works, learn says how to give an environment (needs InputChecksMixin)."""
    make_model(name).save(tmp_path / "model.zip")
    model = algo_class(name).load(tmp_path / "model.zip")
    assert model.get_env() is None
    model.predict(model.observation_space.sample(), deterministic=True)
    with pytest.raises(ValueError, match="needs an environment"):
        model.learn(EPISODE)
    model.set_env(make_env())
    model.learn(EPISODE)


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
@pytest.mark.parametrize("name", ALGOS)
def test_non_finite_inputs_raise(name: str, where: str, value: float, message: str) -> None:
    """Needs :class:`~sb3_denfac.common.checks.InputChecksMixin` in the algorithm's bases."""
    model = make_model(name, env=CorruptingWrapper(make_env(), where, value))
    with pytest.raises(ValueError, match=message):
        model.learn(3 * EPISODE)
    assert _all_finite(model), "non-finite input reached the weights"


# ----- the shared check itself (sb3_denfac/common/checks.py), on a tiny SB3 algorithm ----------------------------------
class CheckedTD3(InputChecksMixin, TD3):
    pass


def _checked_td3(env: Any) -> CheckedTD3:
    return CheckedTD3("MlpPolicy", env, learning_starts=5, batch_size=8, buffer_size=100, policy_kwargs=dict(net_arch=[4]))


@pytest.mark.parametrize(("where", "value", "message"), FAULTS, ids=[f"{w}-{v}" for w, v, _ in FAULTS])
def test_finite_inputs_mixin(where: str, value: float, message: str) -> None:
    model = _checked_td3(CorruptingWrapper(make_env(), where, value))
    with pytest.raises(ValueError, match=message):
        model.learn(2 * EPISODE)
    plain = TD3("MlpPolicy", CorruptingWrapper(make_env(), where, value), learning_starts=5, policy_kwargs=dict(net_arch=[4]))
    if where != "reset":
        plain.learn(10)  # without the mixin, SB3 takes the bad value silently


def test_finite_inputs_mixin_wraps_every_env(tmp_path: pathlib.Path) -> None:
    vec_normalize = VecNormalize(DummyVecEnv([make_env, make_env]))
    model = _checked_td3(vec_normalize)
    assert model.get_env() is vec_normalize  # the VecEnv keeps its type: each sub-env is checked in place
    assert all(isinstance(sub_env, FiniteCheckWrapper) for sub_env in vec_normalize.venv.envs)
    assert model.get_env().get_attr("spec")[0].max_episode_steps == EPISODE  # attributes still reach the env

    model.set_env(model.get_env(), force_reset=False)
    assert not any(isinstance(sub_env.env, FiniteCheckWrapper) for sub_env in vec_normalize.venv.envs), "wrapped twice"
    model = _checked_td3(make_env())
    model.set_env(CorruptingWrapper(make_env(), "reward", np.nan))
    with pytest.raises(ValueError, match="found nan in rewards"):
        model.learn(EPISODE)

    model.save(tmp_path / "model.zip")
    loaded = CheckedTD3.load(tmp_path / "model.zip", env=CorruptingWrapper(make_env(), "observation", np.inf))
    with pytest.raises(ValueError, match="found inf in observations"):
        loaded.learn(EPISODE)

    warning_only = VecCheckNan(DummyVecEnv([make_env]), raise_exception=False)
    assert wrap_check_finite(warning_only) is warning_only  # a warning-only check is not enough: sub-envs are checked
    assert isinstance(warning_only.venv.envs[0], FiniteCheckWrapper)


def test_finite_inputs_mixin_other_vec_envs() -> None:
    """VecEnvs whose sub-envs live elsewhere (SubprocVecEnv) get SB3's VecCheckNan(raise_exception=True)."""
    from stable_baselines3.common.vec_env import SubprocVecEnv

    env = SubprocVecEnv([lambda: CorruptingWrapper(make_env(), "reward", np.inf)], start_method="fork")
    try:
        model = _checked_td3(env)
        assert isinstance(model.get_env(), VecCheckNan) and model.get_env().raise_exception
        with pytest.raises(ValueError, match="found inf in rewards"):
            model.learn(EPISODE)
    finally:
        env.close()


def test_finite_inputs_mixin_keeps_eval_callback_quiet() -> None:
    """SB3's EvalCallback warns when the training and eval envs differ in type: the check must not cause that."""
    import warnings

    from stable_baselines3.common.callbacks import EvalCallback

    model = _checked_td3(make_env())
    callback = EvalCallback(make_env(), eval_freq=EPISODE // 2, n_eval_episodes=1)  # warns on a type mismatch
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model.learn(EPISODE, callback=callback)
    mismatches = [str(w.message) for w in caught if "not of the same type" in str(w.message)]
    assert mismatches == []
    assert np.isfinite(callback.last_mean_reward)  # the evaluation ran


def test_finite_inputs_mixin_catches_nan_actions() -> None:
    model = _checked_td3(make_env())
    with th.no_grad():
        for parameter in model.actor.parameters():
            parameter.fill_(np.nan)
    model.learning_starts = 0
    with pytest.raises(ValueError, match="found nan in actions"):
        model.learn(10)


def test_learn_checks_mixin(tmp_path: pathlib.Path) -> None:
    _checked_td3(make_env()).save(tmp_path / "model.zip")
    model = CheckedTD3.load(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=r"CheckedTD3.learn\(\) needs an environment"):
        model.learn(10)


def test_learn_checks_mixin_replay_buffer(tmp_path: pathlib.Path) -> None:
    from sb3_denfac.denfac.buffers import DENFACReplayBuffer

    class CheckedTD3WithOwnBuffer(CheckedTD3):
        pass

    sac = SAC("MlpPolicy", make_env(), learning_starts=5, policy_kwargs=dict(net_arch=[4]))
    sac.learn(10)
    sac.save_replay_buffer(tmp_path / "pendulum.pkl")
    model = CheckedTD3WithOwnBuffer("MlpPolicy", make_env(), replay_buffer_class=DENFACReplayBuffer)
    model.load_replay_buffer(tmp_path / "pendulum.pkl")
    with pytest.raises(ValueError, match="is a ReplayBuffer, it needs a DENFACReplayBuffer"):
        model.learn(10)

    cartpole = gym.make("sb3_denfac/ContinuousCartPole-v0", max_episode_steps=EPISODE, episode_length=EPISODE)
    model = _checked_td3(cartpole)
    model.load_replay_buffer(tmp_path / "pendulum.pkl")
    with pytest.raises(ValueError, match=r"observation shape \(3,\).*does not fit.*observation shape \(4,\)"):
        model.learn(10)


def test_foreign_model_check_mixin(tmp_path: pathlib.Path) -> None:
    SAC("MlpPolicy", make_env(), policy_kwargs=dict(net_arch=[4])).save(tmp_path / "sac.zip")
    with pytest.raises(ValueError, match="SACPolicy"):
        CheckedTD3.load(tmp_path / "sac")  # path without .zip, as SB3 allows
    _checked_td3(make_env()).save(tmp_path / "td3.zip")
    with open(tmp_path / "td3.zip", "rb") as file:
        assert isinstance(CheckedTD3.load(file), CheckedTD3)  # file objects work too
    TD3("MlpPolicy", make_env(), policy_kwargs=dict(net_arch=[4])).save(tmp_path / "sb3_td3.zip")
    assert isinstance(CheckedTD3.load(tmp_path / "sb3_td3.zip"), CheckedTD3)  # same policy family


# ----- invalid hyperparameters -----------------------------------------------------------------------------------------
INVALID = {
    "denfac": [
        (dict(n_fitted_iterations=0), "n_fitted_iterations"),
        (dict(critic_steps=0), "critic_steps"),
        (dict(weighting="importance"), "weighting"),
        (dict(sigma=0.0), "sigma"),
        (dict(buffer_size=EPISODE // 2), "buffer_size"),
        (dict(batch_size=1), "batch_size"),
        (dict(learning_rate=-1e-3), "learning_rate"),
        (dict(actor_learning_rate=0.0), "actor_learning_rate"),
        (dict(gamma=1.5), "gamma"),
        (dict(prioritized="td"), "prioritized"),
        (dict(prioritized="critic", batch_size=None), "prioritized"),
        (dict(priority_alpha=-1.0), "priority_alpha"),
        (dict(priority_beta=2.0), "priority_beta"),
        (dict(priority_eps=0.0), "priority_eps"),
        (dict(actor_proximal=-0.1), "actor_proximal"),
    ],
    "ddpg": [
        (dict(tau=0.0), "tau"),
        (dict(actor_learning_rate=-1.0), "actor_learning_rate"),
        (dict(batch_size=1), "batch_size"),
        (dict(sigma=-0.1), "sigma"),
        (dict(gradient_steps=0), "gradient_steps"),
        (dict(learning_rate=-1e-3), "learning_rate"),
        (dict(gamma=1.5), "gamma"),
    ],
    "nfac": [
        (dict(n_episodes=0), "n_episodes"),
        (dict(n_fitted_iterations=0), "n_fitted_iterations"),
        (dict(critic_steps=0), "critic_steps"),
        (dict(actor_steps=0), "actor_steps"),
        (dict(sigma=0.0), "sigma"),
        (dict(learning_rate=-1e-3), "learning_rate"),
        (dict(critic_learning_rate=0.0), "critic_learning_rate"),
        (dict(gamma=1.5), "gamma"),
    ],
    "cacla": [
        (dict(n_steps=0), "n_steps"),
        (dict(bn_window=1), "bn_window"),
        (dict(sigma=0.0), "sigma"),
        (dict(learning_rate=-1e-3), "learning_rate"),
        (dict(gamma=1.5), "gamma"),
    ],
    "cmaes": [
        (dict(population_size=1), "population_size"),
        (dict(sigma0=0.0), "sigma0"),
        (dict(n_eval_episodes=0), "n_eval_episodes"),
        (dict(sigma=-0.1), "sigma"),
        (dict(incumbent="last"), "incumbent"),
    ],
}
INVALID_CASES = [(name, kwargs, match) for name, cases in INVALID.items() for kwargs, match in cases]


@pytest.mark.parametrize(("name", "kwargs", "match"), INVALID_CASES, ids=[f"{n}-{next(iter(k))}" for n, k, _ in INVALID_CASES])
def test_invalid_hyperparameters(name: str, kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make_model(name, **kwargs)


@pytest.mark.parametrize("name", ALGOS)
def test_invalid_policy_kwargs(name: str) -> None:
    with pytest.raises(ValueError, match="init"):
        make_model(name, policy_kwargs=dict(init="xavier"))
    with pytest.raises(ValueError, match="hidden layer sizes"):
        make_model(name, policy_kwargs=dict(net_arch=[0]))


# ----- corrupted and foreign model files -------------------------------------------------------------------------------
def _corrupted_copies(model_zip: pathlib.Path) -> dict[str, pathlib.Path]:
    """Truncated, random-bytes, 'data'-less and bit-flipped copies of a model zip."""
    content = model_zip.read_bytes()
    paths = {kind: model_zip.with_name(f"{kind}.zip") for kind in ("truncated", "noise", "no_data", "bit_flip")}
    paths["truncated"].write_bytes(content[: len(content) // 2])
    paths["noise"].write_bytes(np.random.default_rng(0).bytes(1000))
    with zipfile.ZipFile(model_zip) as source, zipfile.ZipFile(paths["no_data"], "w") as target:
        for item in source.namelist():
            if item != "data":
                target.writestr(item, source.read(item))
    with zipfile.ZipFile(model_zip) as source:
        info = source.getinfo("data")
        offset = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra) + 2  # inside the entry's bytes
    flipped = bytearray(content)
    flipped[offset] ^= 0xFF
    paths["bit_flip"].write_bytes(bytes(flipped))
    return paths


CORRUPTIONS = ["truncated", "noise", "no_data", "bit_flip"]


@pytest.mark.parametrize("kind", CORRUPTIONS)
def test_model_file_check_mixin(tmp_path: pathlib.Path, kind: str) -> None:
    _checked_td3(make_env()).save(tmp_path / "model.zip")
    path = _corrupted_copies(tmp_path / "model.zip")[kind]
    with pytest.raises(ValueError, match="truncated|corrupted|not a zip"):
        CheckedTD3.load(path)


@pytest.mark.parametrize("name", ALGOS)
def test_corrupted_zip(tmp_path: pathlib.Path, name: str) -> None:
    """Truncated, random or damaged model files: a ValueError that says so (the truncated and 'data'-less cases need
    InputChecksMixin: SB3 itself only asserts "No data found in the saved file")."""
    cls = algo_class(name)
    make_model(name).save(tmp_path / "model.zip")
    for kind, path in _corrupted_copies(tmp_path / "model.zip").items():
        with pytest.raises(ValueError, match="truncated|corrupted|not a zip"):
            cls.load(path)
            pytest.fail(f"{kind} file loaded")


#: A zip of another algorithm with another policy class (NFAC and CACLA share theirs: their zips are interchangeable).
FOREIGN = {
    "denfac": "ddpg",
    "denfac_plain": "nfac",
    "ddpg": "nfac",
    "ddpg_ig": "cacla",
    "nfac": "denfac",
    "cacla": "cmaes",
    "cmaes": "cacla",
}


@pytest.mark.parametrize("name", ALGOS)
def test_foreign_zip(tmp_path: pathlib.Path, name: str) -> None:
    """A zip saved by another algorithm is refused with a message naming its policy (needs InputChecksMixin)."""
    cls = algo_class(name)
    TD3("MlpPolicy", make_env(), policy_kwargs=dict(net_arch=[4])).save(tmp_path / "td3.zip")
    with pytest.raises(ValueError, match="TD3Policy"):
        cls.load(tmp_path / "td3.zip", env=make_env())
    other = FOREIGN[name]
    other_model = make_model(other)
    other_model.save(tmp_path / "other.zip")
    with pytest.raises(ValueError, match=type(other_model.policy).__name__):
        cls.load(tmp_path / "other.zip", env=make_env())


@pytest.mark.parametrize("name", OFF_POLICY)
def test_foreign_replay_buffer(tmp_path: pathlib.Path, name: str) -> None:
    """A replay buffer of another env (or, for DENFAC, of an algorithm without behaviour means) is refused clearly."""
    cartpole = gym.make("sb3_denfac/ContinuousCartPole-v0", max_episode_steps=EPISODE, episode_length=EPISODE)
    other = make_model(name, env=cartpole)
    other.learn(EPISODE)
    other.save_replay_buffer(tmp_path / "cartpole.pkl")
    model = make_model(name)
    model.load_replay_buffer(tmp_path / "cartpole.pkl")
    with pytest.raises(ValueError, match="does not fit"):
        model.learn(EPISODE)
    if name.startswith("denfac"):
        ddpg = make_model("ddpg")
        ddpg.learn(EPISODE)
        ddpg.save_replay_buffer(tmp_path / "ddpg.pkl")
        model.load_replay_buffer(tmp_path / "ddpg.pkl")
        with pytest.raises(ValueError, match="needs a DENFACReplayBuffer"):
            model.learn(EPISODE)


# ----- nothing lost: save and resume ----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ALGOS)
def test_save_and_resume_loses_nothing(tmp_path: pathlib.Path, name: str) -> None:
    """learn; save (+ replay buffer); load; learn(reset_num_timesteps=False) ends where an uninterrupted run ends,
    with the same number of updates and episodes and, off-policy, the same buffer content up to the interruption."""
    half, total = 2 * EPISODE, 4 * EPISODE
    off_policy = name in OFF_POLICY
    uninterrupted = make_model(name, seed=1)
    uninterrupted.learn(total)

    interrupted = make_model(name, seed=1)
    interrupted.learn(half)
    interrupted.save(tmp_path / "model.zip")
    if off_policy:
        interrupted.save_replay_buffer(tmp_path / "buffer.pkl")
    resumed = algo_class(name).load(tmp_path / "model.zip", env=make_env())
    if off_policy:
        resumed.load_replay_buffer(tmp_path / "buffer.pkl")
    resumed.learn(total - half, reset_num_timesteps=False)

    assert resumed.num_timesteps == uninterrupted.num_timesteps == total
    assert resumed._n_updates == uninterrupted._n_updates
    assert resumed._episode_num == uninterrupted._episode_num
    if off_policy:
        assert resumed.replay_buffer.size() == uninterrupted.replay_buffer.size() == total
        for key in ("observations", "actions", "rewards", "dones"):
            np.testing.assert_array_equal(
                getattr(resumed.replay_buffer, key)[:half], getattr(uninterrupted.replay_buffer, key)[:half], err_msg=key
            )


@pytest.mark.parametrize("name", ALGOS)
def test_checkpoint_callback_resume(tmp_path: pathlib.Path, name: str) -> None:
    """Resuming from a CheckpointCallback checkpoint reaches the uninterrupted run's number of timesteps.

    SB3 calls callbacks before storing the step's transition and before the end-of-rollout update, so such a checkpoint
    lacks the last transition (off-policy) or the last episode's update (episode-wise): only the count is compared.
    """
    total = 4 * EPISODE
    off_policy = name in OFF_POLICY
    checkpoint = CheckpointCallback(save_freq=2 * EPISODE, save_path=str(tmp_path), save_replay_buffer=off_policy)
    uninterrupted = make_model(name, seed=1)
    uninterrupted.learn(total, callback=checkpoint)

    resumed = algo_class(name).load(tmp_path / f"rl_model_{2 * EPISODE}_steps.zip", env=make_env())
    assert resumed.num_timesteps == 2 * EPISODE
    if off_policy:
        resumed.load_replay_buffer(tmp_path / f"rl_model_replay_buffer_{2 * EPISODE}_steps.pkl")
        assert resumed.replay_buffer.size() >= 2 * EPISODE - 1
    resumed.learn(total - resumed.num_timesteps, reset_num_timesteps=False)
    assert resumed.num_timesteps == uninterrupted.num_timesteps == total


@pytest.mark.parametrize("name", ALGOS)
def test_resume_is_exact(tmp_path: pathlib.Path, name: str) -> None:
    """Everything that training depends on is saved: from the same seed and a fresh env, a loaded copy (and its replay
    buffer) continues exactly as the original model (weights, optimizer states, batch-norm statistics, search state)."""
    off_policy = name in OFF_POLICY
    model = make_model(name, seed=2)
    model.learn(2 * EPISODE)
    model.save(tmp_path / "model.zip")
    if off_policy:
        model.save_replay_buffer(tmp_path / "buffer.pkl")
    loaded = algo_class(name).load(tmp_path / "model.zip", env=make_env())
    if off_policy:
        loaded.load_replay_buffer(tmp_path / "buffer.pkl")
    model.set_env(make_env(), force_reset=True)
    for copy in (model, loaded):
        copy.set_random_seed(7)
        copy.learn(2 * EPISODE, reset_num_timesteps=False)
    assert loaded.num_timesteps == model.num_timesteps == 4 * EPISODE
    assert_same_parameters(model.get_parameters(), loaded.get_parameters())
