"""SB3's plugin contract for the package's five algorithms (after SB3's own tests: save/load, set_env, predict, batch
norm train/eval mode, determinism, TensorBoard, callbacks, float64 actions, VecNormalize, progress bar).

Every case is tiny: Pendulum-v1 cut to ``EPISODE`` steps, networks of a few units, one or two gradient steps per
update. ``tests/test_reliability.py`` imports ``ALGOS``, ``algo_class``, ``make_model`` and ``make_env`` from here.
"""

from __future__ import annotations

import importlib
import io
import pathlib
from copy import deepcopy
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import (
    BaseCallback,
    CallbackList,
    CheckpointCallback,
    EvalCallback,
    StopTrainingOnMaxEpisodes,
)
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

import sb3_denfac  # noqa: F401  (registers the paper envs)

EPISODE = 20  # steps per episode of every test env
#: "denfac_plain" is DENFAC on its plain (autograd) update path; "denfac" takes the default (fast when possible).
ALGOS = ["denfac", "denfac_plain", "ddpg", "nfac", "cacla", "cmaes"]
CLASS_PATHS = {
    "denfac": "sb3_denfac.denfac:DENFAC",
    "denfac_plain": "sb3_denfac.denfac:DENFAC",
    "ddpg": "sb3_denfac.ddpg:DDPG",
    "nfac": "sb3_denfac.nfac:NFAC",
    "cacla": "sb3_denfac.cacla:CACLA",
    "cmaes": "sb3_denfac.cmaes:CMAES",
}
#: Tiny configurations: every update is a handful of gradient steps on networks of a few units.
TINY_KWARGS: dict[str, dict[str, Any]] = {
    "denfac": dict(
        buffer_size=5 * EPISODE,
        n_fitted_iterations=1,
        critic_steps=2,
        actor_steps=2,
        policy_kwargs=dict(net_arch=dict(pi=[4], qf=[8, 4])),
    ),
    "denfac_plain": dict(
        update_path="plain",
        buffer_size=5 * EPISODE,
        n_fitted_iterations=1,
        critic_steps=2,
        actor_steps=2,
        policy_kwargs=dict(net_arch=dict(pi=[4], qf=[8, 4])),
    ),
    "ddpg": dict(
        buffer_size=5 * EPISODE,
        learning_starts=10,
        batch_size=8,
        policy_kwargs=dict(net_arch=dict(pi=[4], qf=[8, 4])),
    ),
    "nfac": dict(
        n_fitted_iterations=1,
        critic_steps=2,
        actor_steps=2,
        policy_kwargs=dict(net_arch=dict(pi=[4], vf=[8, 4])),
    ),
    "cacla": dict(n_steps=EPISODE, bn_window=4, policy_kwargs=dict(net_arch=dict(pi=[4], vf=[8, 4]))),
    "cmaes": dict(population_size=2, policy_kwargs=dict(net_arch=[4])),
}
OFF_POLICY = ["denfac", "denfac_plain", "ddpg"]
#: predict(deterministic=False) samples the truncated Gaussian exploration policy.
EXPLORING_PREDICT = ["denfac", "denfac_plain", "nfac", "cacla"]


def algo_class(name: str) -> type[BaseAlgorithm]:
    module_name, class_name = CLASS_PATHS[name].split(":")
    return getattr(importlib.import_module(module_name), class_name)


def make_env(episode: int = EPISODE) -> gym.Env:
    return gym.make("Pendulum-v1", max_episode_steps=episode)


def make_model(name: str, env: Any = None, **overrides: Any) -> BaseAlgorithm:
    kwargs = deepcopy(TINY_KWARGS[name])
    kwargs.update(overrides)
    return algo_class(name)("MlpPolicy", make_env() if env is None else env, **kwargs)


def sample_observations(space: spaces.Space, n: int = 10, seed: int = 0) -> np.ndarray:
    space = deepcopy(space)
    space.seed(seed)
    return np.stack([space.sample() for _ in range(n)])


def float_perturbation(state: dict[str, th.Tensor]) -> dict[str, th.Tensor]:
    """A different value for every floating-point entry (positive shift: BN running variances stay > 0);
    integer entries (BN ``num_batches_tracked``) are kept."""
    return {
        key: value + 0.1 + th.rand_like(value) if th.is_floating_point(value) else value.clone()
        for key, value in state.items()
    }


def batch_norm_buffers(module: th.nn.Module) -> dict[str, th.Tensor]:
    return {
        f"{name}.{buffer}": getattr(layer, buffer).clone()
        for name, layer in module.named_modules()
        if isinstance(layer, th.nn.modules.batchnorm._BatchNorm)
        for buffer in ("running_mean", "running_var")
    }


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


# ----- save / load (SB3 tests/test_save_load.py) -----------------------------------------------------------------------
@pytest.mark.parametrize("name", ALGOS)
def test_save_load(tmp_path: pathlib.Path, name: str) -> None:
    model = make_model(name, seed=0)
    model.learn(2 * EPISODE)
    observations = sample_observations(model.observation_space)
    original = deepcopy(model.get_parameters())

    invalid = deepcopy(original)
    invalid["not_an_object"] = "not a tensor"
    for exact in (True, False):
        with pytest.raises(ValueError):
            model.set_parameters(invalid, exact_match=exact)
    with pytest.raises(ValueError):
        model.set_parameters(dict(list(original.items())[:-1]), exact_match=True)

    missing_entry = {k: v if "optim" in k else dict(list(v.items())[:-1]) for k, v in original.items()}
    with pytest.raises(RuntimeError):  # torch's strict load_state_dict
        model.set_parameters(missing_entry, exact_match=True)

    perturbed = {k: v if "optim" in k else float_perturbation(v) for k, v in original.items()}
    model.set_parameters(perturbed, exact_match=True)
    params = deepcopy(model.get_parameters())
    for object_name, state in original.items():
        if "optim" in object_name:
            continue
        for key, value in state.items():
            changed = not th.equal(value, params[object_name][key])
            assert changed == th.is_floating_point(value), f"{object_name}.{key}: perturbation not applied as expected"

    actions, _ = model.predict(observations, deterministic=True)
    num_timesteps = model.num_timesteps
    model.save(tmp_path / "model.zip")
    env = model.get_env()
    del model

    model = algo_class(name).load(tmp_path / "model.zip", env=env, device="cpu")
    assert model.num_timesteps == num_timesteps
    assert_same_parameters(params, model.get_parameters())
    new_actions, _ = model.predict(observations, deterministic=True)
    np.testing.assert_allclose(actions, new_actions, rtol=1e-6, atol=1e-6)
    model.learn(EPISODE)  # training goes on after a load


@pytest.mark.parametrize("name", ALGOS)
def test_set_env(tmp_path: pathlib.Path, name: str) -> None:
    model = make_model(name)
    model.learn(EPISODE)

    model.set_env(DummyVecEnv([make_env]), force_reset=True)
    assert model._last_obs is None
    model.learn(2 * EPISODE, reset_num_timesteps=True)
    assert model.num_timesteps == 2 * EPISODE

    model.set_env(make_env())  # a plain gym.Env is wrapped
    model.learn(EPISODE)
    with pytest.raises(AssertionError, match="number of environments"):
        model.set_env(DummyVecEnv([make_env, make_env]))

    model.set_env(model.get_env(), force_reset=False)
    assert model._last_obs is not None
    model.learn(EPISODE, reset_num_timesteps=False)
    assert model.num_timesteps == 2 * EPISODE

    env = model.get_env()
    model.save(tmp_path / "model.zip")
    model = algo_class(name).load(tmp_path / "model.zip", env=env, force_reset=False)
    assert model._last_obs is not None
    model.learn(EPISODE, reset_num_timesteps=False)
    assert model.num_timesteps == 3 * EPISODE

    model = algo_class(name).load(tmp_path / "model.zip", env=make_env(), force_reset=True)
    assert model._last_obs is None
    model.learn(EPISODE, reset_num_timesteps=False)
    assert model.num_timesteps == 3 * EPISODE


@pytest.mark.parametrize("name", ALGOS)
def test_exclude_include_saved_params(tmp_path: pathlib.Path, name: str) -> None:
    model = make_model(name, verbose=2)
    model.save(tmp_path / "model", exclude=["verbose"])
    model = algo_class(name).load(tmp_path / "model.zip")
    assert model.verbose != 2

    model.verbose = 2
    model.save(tmp_path / "model", exclude=["verbose"], include=["verbose"])
    model = algo_class(name).load(tmp_path / "model.zip", custom_objects=dict(learning_rate=2e-5, dummy=1.0))
    assert model.verbose == 2
    assert model.learning_rate == 2e-5
    assert not hasattr(model, "dummy")


@pytest.mark.parametrize("name", ALGOS)
def test_save_load_policy(tmp_path: pathlib.Path, name: str) -> None:
    model = make_model(name)
    model.learn(EPISODE)
    policy = model.policy
    if not callable(getattr(policy, "save", None)):
        pytest.skip(f"{name}'s policy has no save()")
    observations = sample_observations(model.observation_space)

    params = deepcopy(policy.state_dict())
    policy.load_state_dict(float_perturbation(params))
    params = deepcopy(policy.state_dict())
    actions, _ = policy.predict(observations, deterministic=True)
    policy.save(tmp_path / "policy.pkl")

    loaded = type(policy).load(tmp_path / "policy.pkl", device="cpu")
    assert type(loaded) is type(policy)
    for key, value in loaded.state_dict().items():
        assert th.equal(value, params[key]), key
    new_actions, _ = loaded.predict(observations, deterministic=True)
    np.testing.assert_allclose(actions, new_actions, rtol=1e-6, atol=1e-6)

    actor = getattr(policy, "actor", None)  # off-policy actors are policies of their own (SB3's TD3 test)
    if callable(getattr(actor, "save", None)) and callable(getattr(actor, "predict", None)):
        actor_actions, _ = actor.predict(observations, deterministic=True)
        np.testing.assert_allclose(actions, actor_actions, rtol=1e-6, atol=1e-6)
        actor.save(tmp_path / "actor.pkl")
        loaded_actor = type(actor).load(tmp_path / "actor.pkl", device="cpu")
        np.testing.assert_allclose(actions, loaded_actor.predict(observations, deterministic=True)[0], rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("name", OFF_POLICY)
def test_save_load_replay_buffer(tmp_path: pathlib.Path, name: str) -> None:
    model = make_model(name)
    model.learn(2 * EPISODE)
    assert isinstance(model, OffPolicyAlgorithm)
    old_buffer = deepcopy(model.replay_buffer)
    model.save_replay_buffer(tmp_path / "logs" / "replay_buffer.pkl")
    model.replay_buffer = None
    model.load_replay_buffer(tmp_path / "logs" / "replay_buffer.pkl")
    buffer = model.replay_buffer
    assert type(buffer) is type(old_buffer)
    assert (buffer.pos, buffer.full, buffer.buffer_size) == (old_buffer.pos, old_buffer.full, old_buffer.buffer_size)
    arrays = [key for key, value in vars(old_buffer).items() if isinstance(value, np.ndarray)]
    assert {"observations", "actions", "rewards", "dones", "timeouts"} <= set(arrays)
    for key in arrays:  # includes algorithm-specific fields (DENFAC's behaviour means)
        np.testing.assert_array_equal(getattr(buffer, key), getattr(old_buffer, key), err_msg=key)
    model.learn(EPISODE, reset_num_timesteps=False)
    assert model.replay_buffer.size() == 3 * EPISODE


# ----- determinism (SB3 tests/test_deterministic.py) -------------------------------------------------------------------
@pytest.mark.parametrize("name", ALGOS)
def test_deterministic_training(name: str) -> None:
    observations = sample_observations(make_env().observation_space)

    def run(seed: int) -> tuple[dict, dict, np.ndarray]:
        model = make_model(name, seed=seed)
        initial = deepcopy(model.get_parameters())
        model.learn(3 * EPISODE)
        return initial, model.get_parameters(), model.predict(observations, deterministic=True)[0]

    initial, params, actions = run(seed=3)
    _, params_again, actions_again = run(seed=3)
    assert_same_parameters(params, params_again)
    np.testing.assert_array_equal(actions, actions_again)

    def policy_vector(parameters: dict) -> th.Tensor:
        state = parameters["policy"]
        return th.cat([v.flatten().float() for v in state.values() if th.is_floating_point(v)])

    assert not th.equal(policy_vector(initial), policy_vector(params)), "learn() did not change the policy"
    _, params_other, _ = run(seed=4)
    assert not th.equal(policy_vector(params), policy_vector(params_other)), "the seed has no effect"


# ----- predict (SB3 tests/test_predict.py) -----------------------------------------------------------------------------
@pytest.mark.parametrize("name", ALGOS)
def test_predict_shapes_and_wrapping(name: str) -> None:
    model = make_model(name)
    model.learn(EPISODE)
    low, high = model.action_space.low, model.action_space.high
    obs_space, act_shape = model.observation_space, model.action_space.shape

    for deterministic in (True, False):
        action, state = model.predict(obs_space.sample(), deterministic=deterministic)
        assert action.shape == act_shape and state is None
        assert action.dtype == model.action_space.dtype
        actions, _ = model.predict(sample_observations(obs_space, n=5), deterministic=deterministic)
        assert actions.shape == (5, *act_shape)
        assert np.all(actions >= low) and np.all(actions <= high)

    vec_env = DummyVecEnv([make_env, make_env, make_env])
    vec_obs = vec_env.reset()
    actions, _ = model.predict(vec_obs, deterministic=True)
    assert actions.shape == (3, *act_shape)
    vec_env.step(actions)

    single, _ = model.predict(vec_obs[0], deterministic=True)
    np.testing.assert_allclose(single, actions[0], rtol=1e-6, atol=1e-6)  # batch-norm eval mode: no batch effect
    again, _ = model.predict(vec_obs, deterministic=True)
    np.testing.assert_array_equal(actions, again)
    stochastic = np.stack([model.predict(vec_obs, deterministic=False)[0] for _ in range(5)])
    if name in EXPLORING_PREDICT:
        assert not np.all(stochastic == stochastic[0]), "deterministic=False must sample the exploration policy"
    elif name == "ddpg":  # SB3's TD3/DDPG semantics: predict() is the deterministic actor, noise is added in learn()
        np.testing.assert_array_equal(stochastic[0], actions)

    with pytest.raises(ValueError, match="Unexpected observation shape"):
        model.predict(np.zeros((2, 7), dtype=np.float32))


# ----- batch norm: train / eval mode (SB3 tests/test_train_eval_mode.py) -----------------------------------------------
@pytest.mark.parametrize("name", ALGOS)
def test_batch_norm_train_eval_mode(name: str) -> None:
    model = make_model(name)
    model.learn(EPISODE)
    before = batch_norm_buffers(model.policy)
    if not before:
        pytest.skip(f"{name}'s policy has no batch norm")
    observations = sample_observations(model.observation_space)
    for deterministic in (True, False):
        model.predict(observations, deterministic=deterministic)
        model.predict(observations[0], deterministic=deterministic)  # a batch of 1 works in eval mode
    after_predict = batch_norm_buffers(model.policy)
    for key, value in before.items():
        assert th.equal(value, after_predict[key]), f"predict() changed the running statistics {key}"

    model.learn(2 * EPISODE, reset_num_timesteps=False)
    after_learn = batch_norm_buffers(model.policy)
    changed = [key for key, value in before.items() if not th.equal(value, after_learn[key])]
    assert changed, "training did not update any batch-norm running statistics"


# ----- logging, callbacks, progress bar (SB3 tests/test_tensorboard.py, test_callbacks.py) -----------------------------
@pytest.mark.parametrize("name", ALGOS)
def test_tensorboard(tmp_path: pathlib.Path, name: str) -> None:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    model = make_model(name, tensorboard_log=str(tmp_path))
    model.learn(3 * EPISODE, log_interval=1)
    class_name = type(model).__name__
    run_dirs = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert [p.name for p in run_dirs] == [f"{class_name}_1"], "tb_log_name must default to the class name"
    event_files = list(run_dirs[0].glob("events.out.tfevents.*"))
    assert event_files
    accumulator = EventAccumulator(str(run_dirs[0]))
    accumulator.Reload()
    tags = accumulator.Tags()["scalars"]
    assert any(tag.startswith("train/") for tag in tags), tags
    assert "time/fps" in tags or any(tag.startswith("rollout/") for tag in tags), tags

    model.learn(EPISODE, reset_num_timesteps=False, log_interval=1)  # continues the same run
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{class_name}_1"]


@pytest.mark.parametrize("name", ALGOS)
def test_custom_logger(tmp_path: pathlib.Path, name: str) -> None:
    """A logger set with ``set_logger`` is kept by ``learn`` and receives the train/ keys (SB3 tests/test_logger.py)."""
    from stable_baselines3.common.logger import configure

    model = make_model(name)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(3 * EPISODE, log_interval=1)
    header = (tmp_path / "progress.csv").read_text().splitlines()[0].split(",")
    assert any(key.startswith("train/") for key in header), header


class CountingCallback(BaseCallback):
    def __init__(self) -> None:
        super().__init__()
        self.calls = dict(training_start=0, rollout_start=0, step=0, rollout_end=0, training_end=0)

    def _on_training_start(self) -> None:
        self.calls["training_start"] += 1

    def _on_rollout_start(self) -> None:
        self.calls["rollout_start"] += 1

    def _on_step(self) -> bool:
        self.calls["step"] += 1
        return True

    def _on_rollout_end(self) -> None:
        self.calls["rollout_end"] += 1

    def _on_training_end(self) -> None:
        self.calls["training_end"] += 1


@pytest.mark.parametrize("name", ALGOS)
def test_callbacks(tmp_path: pathlib.Path, name: str) -> None:
    model = make_model(name)
    counting = CountingCallback()
    checkpoint = CheckpointCallback(
        save_freq=2 * EPISODE,
        save_path=str(tmp_path / "checkpoints"),
        save_replay_buffer=name in OFF_POLICY,
    )
    evaluation = EvalCallback(
        make_env(),
        eval_freq=2 * EPISODE,
        n_eval_episodes=1,
        log_path=str(tmp_path / "eval"),
        best_model_save_path=str(tmp_path / "best"),
        warn=False,
    )
    model.learn(4 * EPISODE, callback=CallbackList([counting, checkpoint, evaluation]))

    assert counting.calls["step"] == model.num_timesteps == 4 * EPISODE
    assert counting.calls["training_start"] == counting.calls["training_end"] == 1
    assert counting.calls["rollout_start"] >= 1 and counting.calls["rollout_end"] >= 1
    for steps in (2 * EPISODE, 4 * EPISODE):
        assert (tmp_path / "checkpoints" / f"rl_model_{steps}_steps.zip").exists()
    if name in OFF_POLICY:
        assert (tmp_path / "checkpoints" / f"rl_model_replay_buffer_{2 * EPISODE}_steps.pkl").exists()
    loaded = algo_class(name).load(tmp_path / "checkpoints" / f"rl_model_{2 * EPISODE}_steps.zip")
    assert loaded.num_timesteps == 2 * EPISODE
    evaluations = np.load(tmp_path / "eval" / "evaluations.npz")
    np.testing.assert_array_equal(evaluations["timesteps"], [2 * EPISODE, 4 * EPISODE])
    assert (tmp_path / "best" / "best_model.zip").exists()


class StopAfter(BaseCallback):
    def __init__(self, n_calls: int) -> None:
        super().__init__()
        self.limit = n_calls

    def _on_step(self) -> bool:
        return self.n_calls < self.limit


@pytest.mark.parametrize("name", ALGOS)
def test_callback_stops_training(name: str) -> None:
    model = make_model(name)
    model.learn(10 * EPISODE, callback=StopAfter(EPISODE + 5))
    assert model.num_timesteps == EPISODE + 5


@pytest.mark.parametrize("name", ALGOS)
def test_stop_on_max_episodes(name: str) -> None:
    """SB3's StopTrainingOnMaxEpisodes reads ``locals["dones"]``: every training loop must expose it."""
    model = make_model(name)
    model.learn(10 * EPISODE, callback=StopTrainingOnMaxEpisodes(max_episodes=2))
    assert model.num_timesteps == 2 * EPISODE


@pytest.mark.parametrize("name", ALGOS)
def test_save_load_file_object(name: str) -> None:
    model = make_model(name, seed=0)
    model.learn(EPISODE)
    observations = sample_observations(model.observation_space)
    buffer = io.BytesIO()
    model.save(buffer)
    buffer.seek(0)
    loaded = algo_class(name).load(buffer, device="cpu")
    np.testing.assert_allclose(
        model.predict(observations, deterministic=True)[0], loaded.predict(observations, deterministic=True)[0], atol=1e-6
    )


@pytest.mark.parametrize("name", ALGOS)
def test_progress_bar(name: str) -> None:
    model = make_model(name)
    model.learn(2 * EPISODE, progress_bar=True)
    assert model.num_timesteps == 2 * EPISODE


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
@pytest.mark.parametrize("name", ALGOS)
def test_float64_action_space(name: str, obs_dtype: type) -> None:
    """Box float64 actions work like float32 ones: actions keep the space's dtype and bounds."""
    env = gym.wrappers.TimeLimit(Float64ActionEnv(obs_dtype), max_episode_steps=EPISODE)
    model = make_model(name, env=env)
    model.learn(2 * EPISODE)
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


@pytest.mark.parametrize("name", ALGOS)
def test_multidimensional_action_space(name: str) -> None:
    """A Box action of shape (2, 2) works as in SB3 (tests/test_spaces.py): actions keep the space's shape."""
    box = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
    env = gym.wrappers.TimeLimit(SpacesEnv(box, spaces.Box(-2.0, 2.0, shape=(2, 2), dtype=np.float32)), EPISODE)
    model = make_model(name, env=env)
    model.learn(2 * EPISODE)
    for deterministic in (True, False):
        action, _ = model.predict(box.sample(), deterministic=deterministic)
        assert action.shape == (2, 2) and env.action_space.contains(action)


@pytest.mark.parametrize(
    "observation_space", [spaces.Discrete(5), spaces.MultiDiscrete([3, 2]), spaces.MultiBinary(4)], ids=str
)
@pytest.mark.parametrize("name", ALGOS)
def test_discrete_observation_spaces(name: str, observation_space: spaces.Space) -> None:
    """Discrete-like observations (one-hot encoded by SB3) work, or are refused with a ValueError naming the space."""
    env = gym.wrappers.TimeLimit(SpacesEnv(observation_space, spaces.Box(-1.0, 1.0, shape=(1,))), EPISODE)
    try:
        model = make_model(name, env=env)
    except ValueError as error:
        assert str(observation_space) in str(error)
        return
    model.learn(2 * EPISODE)
    action, _ = model.predict(observation_space.sample(), deterministic=True)
    assert action.shape == (1,)


@pytest.mark.parametrize("name", ALGOS)
def test_vec_normalize(tmp_path: pathlib.Path, name: str) -> None:
    env = VecNormalize(DummyVecEnv([make_env]), gamma=0.9, norm_obs=True, norm_reward=True)
    model = make_model(name, env=env)
    model.learn(2 * EPISODE)
    assert model.get_vec_normalize_env() is env
    assert env.obs_rms.count > 2 * EPISODE
    if isinstance(model, OffPolicyAlgorithm):
        # The replay buffer keeps the original observations (Pendulum: cos^2 + sin^2 = 1), normalised at sampling.
        observations = model.replay_buffer.observations[: model.replay_buffer.size(), 0]
        np.testing.assert_allclose(np.square(observations[:, :2]).sum(axis=1), 1.0, rtol=1e-5)
    env.save(str(tmp_path / "vec_normalize.pkl"))
    model.save(tmp_path / "model.zip")
    loaded_env = VecNormalize.load(str(tmp_path / "vec_normalize.pkl"), DummyVecEnv([make_env]))
    model = algo_class(name).load(tmp_path / "model.zip", env=loaded_env)
    assert model.get_vec_normalize_env() is loaded_env
    model.learn(EPISODE, reset_num_timesteps=False)
    assert model.num_timesteps == 3 * EPISODE


# ----- off-policy train frequency (SB3 tests/test_run.py) --------------------------------------------------------------
@pytest.mark.parametrize("train_freq", [4, (2, "step"), (1, "episode")])
def test_ddpg_train_freq(train_freq: Any) -> None:
    model = make_model("ddpg", train_freq=train_freq, gradient_steps=-1, learning_starts=EPISODE)
    model.learn(2 * EPISODE)
    assert model.num_timesteps == 2 * EPISODE
    assert model._n_updates == EPISODE  # gradient_steps=-1: one update per collected step after learning_starts


# ----- env ids and true terminations ------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ALGOS)
def test_env_id_string(name: str) -> None:
    """An env id is made by SB3 (Pendulum-v1: 200-step episodes)."""
    overrides = dict(buffer_size=200) if name.startswith("denfac") else {}
    model = make_model(name, env="Pendulum-v1", **overrides)
    model.learn(10)
    assert model.num_timesteps >= 10
    assert model.get_env().get_attr("spec")[0].id == "Pendulum-v1"


@pytest.mark.parametrize("name", ALGOS)
def test_true_terminations(name: str) -> None:
    """The paper's CartPole ends early on failure: training runs through terminations and, off-policy, the buffer tells
    failures (dones without timeout) from time limits (timeouts)."""
    horizon = 5 * EPISODE  # a random start fails in about 50 steps
    env = gym.make("sb3_denfac/ContinuousCartPole-v0", max_episode_steps=horizon, episode_length=horizon, random_start=True)
    overrides = dict(buffer_size=4 * horizon) if name in OFF_POLICY else {}
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


# ----- learning-rate schedules and several environments ---------------------------------------------------------------
def _optimizers(model: BaseAlgorithm) -> list[th.optim.Optimizer]:
    policy = model.policy
    candidates = [getattr(policy, "optimizer", None), getattr(policy, "actor_optimizer", None)]
    candidates += [getattr(policy, "critic_optimizer", None)]
    candidates += [getattr(getattr(policy, net, None), "optimizer", None) for net in ("actor", "critic")]
    found: list[th.optim.Optimizer] = []
    for optimizer in candidates:
        if isinstance(optimizer, th.optim.Optimizer) and all(optimizer is not seen for seen in found):
            found.append(optimizer)
    return found


@pytest.mark.parametrize("name", [name for name in ALGOS if name != "cmaes"])  # CMA-ES has no learning rate
def test_learning_rate_schedule(name: str) -> None:
    """A schedule of the remaining progress given as ``learning_rate`` is followed (SB3 semantics), not just read once."""
    model = make_model(name, learning_rate=lambda progress_remaining: 1e-3 * progress_remaining)
    optimizers = _optimizers(model)
    assert optimizers
    assert all(group["lr"] == pytest.approx(1e-3) for opt in optimizers for group in opt.param_groups)
    model.learn(4 * EPISODE)
    for optimizer in _optimizers(model):  # looked up again: a network reset may build a new optimizer
        for group in optimizer.param_groups:
            assert group["lr"] <= 0.5e-3, "learning_rate schedule ignored"


@pytest.mark.parametrize("name", ["ddpg", "cacla"])  # step-wise algorithms
def test_several_envs(name: str) -> None:
    from stable_baselines3.common.env_util import make_vec_env

    model = make_model(name, env=make_vec_env(make_env, n_envs=2, seed=0))
    model.learn(2 * EPISODE)
    assert model.num_timesteps == 2 * EPISODE
    assert model.n_envs == 2
    actions, _ = model.predict(model.get_env().reset(), deterministic=True)
    assert actions.shape == (2, *model.action_space.shape)


def test_ddpg_target_networks_copy_batch_norm_statistics() -> None:
    """As SB3's TD3 (GH#996): running statistics are copied to the targets, weights are Polyak-averaged."""
    model = make_model("ddpg", tau=0.1)
    model.learn(2 * EPISODE)
    policy = model.policy
    for online, target in ((policy.actor, policy.actor_target), (policy.critic, policy.critic_target)):
        online_stats, target_stats = batch_norm_buffers(online), batch_norm_buffers(target)
        assert online_stats
        for key, value in online_stats.items():
            assert th.equal(value, target_stats[key]), key
        online_weights = th.cat([p.flatten() for p in online.parameters()])
        target_weights = th.cat([p.flatten() for p in target.parameters()])
        assert not th.equal(online_weights, target_weights)  # tau < 1: the targets lag


@pytest.mark.slow
def test_denfac_compiled_path_save_and_resume(tmp_path: pathlib.Path) -> None:
    """DENFAC's torch.compile update path keeps the contract: the model saves, loads and resumes exactly."""
    model = make_model("denfac", update_path="compiled", seed=2)
    model.learn(2 * EPISODE)
    model.save(tmp_path / "model.zip")
    model.save_replay_buffer(tmp_path / "buffer.pkl")
    loaded = algo_class("denfac").load(tmp_path / "model.zip", env=make_env())
    loaded.load_replay_buffer(tmp_path / "buffer.pkl")
    assert loaded.update_path == "compiled"
    model.set_env(make_env(), force_reset=True)
    for copy in (model, loaded):
        copy.set_random_seed(7)
        copy.learn(2 * EPISODE, reset_num_timesteps=False)
    assert_same_parameters(model.get_parameters(), loaded.get_parameters())


@pytest.mark.parametrize("name", ALGOS)
def test_class_documents_every_argument(name: str) -> None:
    """sb3-contrib style: an ``MlpPolicy`` alias and a ``:param name:`` line for every constructor argument."""
    import inspect

    cls = algo_class(name)
    assert "MlpPolicy" in cls.policy_aliases
    parameters = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    missing = [p for p in parameters if f":param {p}:" not in (cls.__doc__ or "")]
    assert not missing, f"{cls.__name__} docstring lacks {missing}"
