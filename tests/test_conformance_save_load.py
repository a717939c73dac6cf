"""SB3's plugin contract for the package's six algorithms: save/load, set_env, policy and replay-buffer files, file
objects, an old model's removed option (after SB3's tests/test_save_load.py). The tiny variants and helpers are the
fixtures of ``conftest.py``; the other parts: ``test_conformance_{predict,docs,logging,spaces,training}.py``.
"""

from __future__ import annotations

import io
import pathlib
from copy import deepcopy

import numpy as np
import pytest
import torch as th
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv


def float_perturbation(state: dict[str, th.Tensor]) -> dict[str, th.Tensor]:
    """A different value for every floating-point entry (positive shift: BN running variances stay > 0);
    integer entries (BN ``num_batches_tracked``) are kept."""
    return {
        key: value + 0.1 + th.rand_like(value) if th.is_floating_point(value) else value.clone()
        for key, value in state.items()
    }


# ----- save / load (SB3 tests/test_save_load.py) -----------------------------------------------------------------------


@pytest.mark.algorithms("all")
def test_save_load(
    tmp_path: pathlib.Path, name: str, episode_steps, algo_class, assert_same_parameters, make_model, sample_observations
) -> None:
    model = make_model(name, seed=0)
    model.learn(2 * episode_steps)
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
    # parameters exact (saved and read back); actions to 1e-6, as SB3's test (the same kernels: equal in practice)
    assert_same_parameters(params, model.get_parameters())
    new_actions, _ = model.predict(observations, deterministic=True)
    np.testing.assert_allclose(actions, new_actions, rtol=1e-6, atol=1e-6)
    model.learn(episode_steps)  # training goes on after a load


@pytest.mark.algorithms("all")
def test_set_env(tmp_path: pathlib.Path, name: str, episode_steps, algo_class, make_env, make_model) -> None:
    model = make_model(name)
    model.learn(episode_steps)

    model.set_env(DummyVecEnv([make_env]), force_reset=True)
    assert model._last_obs is None
    model.learn(2 * episode_steps, reset_num_timesteps=True)
    assert model.num_timesteps == 2 * episode_steps

    model.set_env(make_env())  # a plain gym.Env is wrapped
    model.learn(episode_steps)
    with pytest.raises(AssertionError, match="number of environments"):
        model.set_env(DummyVecEnv([make_env, make_env]))

    model.set_env(model.get_env(), force_reset=False)
    assert model._last_obs is not None
    model.learn(episode_steps, reset_num_timesteps=False)
    assert model.num_timesteps == 2 * episode_steps

    env = model.get_env()
    model.save(tmp_path / "model.zip")
    model = algo_class(name).load(tmp_path / "model.zip", env=env, force_reset=False)
    assert model._last_obs is not None
    model.learn(episode_steps, reset_num_timesteps=False)
    assert model.num_timesteps == 3 * episode_steps

    model = algo_class(name).load(tmp_path / "model.zip", env=make_env(), force_reset=True)
    assert model._last_obs is None
    model.learn(episode_steps, reset_num_timesteps=False)
    assert model.num_timesteps == 3 * episode_steps


@pytest.mark.algorithms("all")
def test_exclude_include_saved_params(tmp_path: pathlib.Path, name: str, algo_class, make_model) -> None:
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


@pytest.mark.algorithms("all")
def test_save_load_policy(tmp_path: pathlib.Path, name: str, episode_steps, make_model, sample_observations) -> None:
    model = make_model(name)
    model.learn(episode_steps)
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
    # parameters exact (saved and read back); actions to 1e-6, as SB3's test (the same kernels: equal in practice)
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


@pytest.mark.algorithms("off_policy")
def test_save_load_replay_buffer(tmp_path: pathlib.Path, name: str, episode_steps, make_model) -> None:
    model = make_model(name)
    model.learn(2 * episode_steps)
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
        # exact: stored arrays, pickled and read back
        np.testing.assert_array_equal(getattr(buffer, key), getattr(old_buffer, key), err_msg=key)
    model.learn(episode_steps, reset_num_timesteps=False)
    assert model.replay_buffer.size() == 3 * episode_steps


@pytest.mark.algorithms("all")
def test_save_load_file_object(name: str, episode_steps, algo_class, make_model, sample_observations) -> None:
    model = make_model(name, seed=0)
    model.learn(episode_steps)
    observations = sample_observations(model.observation_space)
    buffer = io.BytesIO()
    model.save(buffer)
    buffer.seek(0)
    loaded = algo_class(name).load(buffer, device="cpu")
    np.testing.assert_allclose(
        model.predict(observations, deterministic=True)[0], loaded.predict(observations, deterministic=True)[0], atol=1e-6
    )


def test_denfac_model_saved_with_the_removed_compiled_path_loads(
    tmp_path: pathlib.Path, episode_steps, algo_class, make_env, make_model
) -> None:
    """A 0.1 model saved with update_path="compiled" loads, says so, and updates with the fast path."""
    model = make_model("denfac", seed=2)
    model.learn(episode_steps)
    model.update_path = "compiled"  # what a model saved by sb3-denfac 0.1 holds
    model.save(tmp_path / "model.zip")
    with pytest.warns(UserWarning, match="compiled.*removed"):
        loaded = algo_class("denfac").load(tmp_path / "model.zip", env=make_env())
    assert loaded.update_path == "fast"
    loaded.learn(episode_steps, reset_num_timesteps=False)
    assert loaded._n_updates == model._n_updates + 1
