"""SB3's plugin contract for the package's five algorithms, part 1: save/load, set_env, policy and replay-buffer files,
determinism, predict, batch-norm train/eval mode (after SB3's tests/test_save_load.py, test_deterministic.py,
test_predict.py, test_train_eval_mode.py). Parts 2-4: ``test_conformance_{logging,spaces,training}.py``.

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
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv

import sb3_denfac  # noqa: F401  (registers the paper envs)

EPISODE = 20  # steps per episode of every test env
#: Variants: "denfac_plain" is DENFAC on its plain (autograd) update path ("denfac" takes the default, fast when
#: possible); "ddpg_ig" is DDPG with inverting gradients and an unbounded actor ("ddpg": SB3's tanh actor).
ALGOS = ["denfac", "denfac_plain", "ddpg", "ddpg_ig", "nfac", "cacla", "cmaes"]
CLASS_PATHS = {
    "denfac": "sb3_denfac.denfac:DENFAC",
    "denfac_plain": "sb3_denfac.denfac:DENFAC",
    "ddpg": "sb3_denfac.ddpg:DDPG",
    "ddpg_ig": "sb3_denfac.ddpg:DDPG",
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
        policy_kwargs=dict(net_arch=dict(pi=[4], qf=[8, 4]), batch_norm=True),
    ),
    "denfac_plain": dict(
        update_path="plain",
        buffer_size=5 * EPISODE,
        n_fitted_iterations=1,
        critic_steps=2,
        actor_steps=2,
        policy_kwargs=dict(net_arch=dict(pi=[4], qf=[8, 4]), batch_norm=True),
    ),
    "ddpg": dict(
        buffer_size=5 * EPISODE,
        learning_starts=10,
        batch_size=8,
        policy_kwargs=dict(net_arch=dict(pi=[4], qf=[8, 4])),
    ),
    "ddpg_ig": dict(
        inverting_gradients=True,
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
OFF_POLICY = ["denfac", "denfac_plain", "ddpg", "ddpg_ig"]
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
    elif name.startswith("ddpg"):  # SB3's TD3/DDPG semantics: predict() is the deterministic actor, noise is added in learn()
        np.testing.assert_array_equal(stochastic[0], actions)

    with pytest.raises(ValueError, match="Unexpected observation shape"):
        model.predict(np.zeros((2, 7), dtype=np.float32))


# ----- batch norm: train / eval mode (SB3 tests/test_train_eval_mode.py) -----------------------------------------------


@pytest.mark.parametrize("name", ALGOS)
def test_batch_norm_train_eval_mode(name: str) -> None:
    """predict() never moves batch-norm running statistics; training does (CMA-ES: never, by design, as it has no
    gradient steps; its batch norm is optional, off by default)."""
    overrides = {}
    if name == "cmaes":
        overrides = dict(policy_kwargs=dict(TINY_KWARGS["cmaes"]["policy_kwargs"], batch_norm=True))
    model = make_model(name, **overrides)
    model.learn(EPISODE)
    before = batch_norm_buffers(model.policy)
    assert before, f"{name}'s policy has no batch norm"
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
    if name == "cmaes":
        assert not changed, "CMA-ES evaluates candidates in eval mode: its running statistics must stay fixed"
    else:
        assert changed, "training did not update any batch-norm running statistics"


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


def test_denfac_model_saved_with_the_removed_compiled_path_loads(tmp_path: pathlib.Path) -> None:
    """A 0.1 model saved with update_path="compiled" loads, says so, and updates with the fast path."""
    model = make_model("denfac", seed=2)
    model.learn(EPISODE)
    model.update_path = "compiled"  # what a model saved by sb3-denfac 0.1 holds
    model.save(tmp_path / "model.zip")
    with pytest.warns(UserWarning, match="compiled.*removed"):
        loaded = algo_class("denfac").load(tmp_path / "model.zip", env=make_env())
    assert loaded.update_path == "fast"
    loaded.learn(EPISODE, reset_num_timesteps=False)
    assert loaded._n_updates == model._n_updates + 1


@pytest.mark.parametrize("name", ALGOS)
def test_class_documents_every_argument(name: str) -> None:
    """sb3-contrib style: an ``MlpPolicy`` alias and a ``:param name:`` line for every constructor argument."""
    import inspect

    cls = algo_class(name)
    assert "MlpPolicy" in cls.policy_aliases
    parameters = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    missing = [p for p in parameters if f":param {p}:" not in (cls.__doc__ or "")]
    assert not missing, f"{cls.__name__} docstring lacks {missing}"
