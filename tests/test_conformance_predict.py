"""SB3's plugin contract for the package's six algorithms: deterministic training, predict, batch-norm train/eval
mode (after SB3's tests/test_deterministic.py, test_predict.py, test_train_eval_mode.py), on the tiny variants of
``conftest.py``.
"""

from __future__ import annotations

from copy import deepcopy

import numpy as np
import pytest
import torch as th
from stable_baselines3.common.vec_env import DummyVecEnv

#: predict(deterministic=False) samples the truncated Gaussian exploration policy.
EXPLORING_PREDICT = ["denfac", "denfac_plain", "nfac", "cacla"]


# ----- determinism (SB3 tests/test_deterministic.py) -------------------------------------------------------------------


@pytest.mark.algorithms("all")
def test_deterministic_training(
    name: str, episode_steps, assert_same_parameters, make_env, make_model, sample_observations
) -> None:
    observations = sample_observations(make_env().observation_space)

    def run(seed: int) -> tuple[dict, dict, np.ndarray]:
        model = make_model(name, seed=seed)
        initial = deepcopy(model.get_parameters())
        model.learn(3 * episode_steps)
        return initial, model.get_parameters(), model.predict(observations, deterministic=True)[0]

    initial, params, actions = run(seed=3)
    _, params_again, actions_again = run(seed=3)
    # exact: the same seed, code and kernels in one process repeat a run bit for bit (SB3's test_deterministic)
    assert_same_parameters(params, params_again)
    np.testing.assert_array_equal(actions, actions_again)

    def policy_vector(parameters: dict) -> th.Tensor:
        state = parameters["policy"]
        return th.cat([v.flatten().float() for v in state.values() if th.is_floating_point(v)])

    assert not th.equal(policy_vector(initial), policy_vector(params)), "learn() did not change the policy"
    _, params_other, _ = run(seed=4)
    assert not th.equal(policy_vector(params), policy_vector(params_other)), "the seed has no effect"


# ----- predict (SB3 tests/test_predict.py) -----------------------------------------------------------------------------


@pytest.mark.algorithms("all")
def test_predict_shapes_and_wrapping(name: str, episode_steps, make_env, make_model, sample_observations) -> None:
    model = make_model(name)
    model.learn(episode_steps)
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
    # rtol/atol 1e-6: a batch of one may take another matmul kernel than a batch of three (an ulp); the rest exact
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


@pytest.mark.algorithms("all")
def test_batch_norm_train_eval_mode(
    name: str, episode_steps, tiny_kwargs, batch_norm_buffers, make_model, sample_observations
) -> None:
    """predict() never moves batch-norm running statistics; training does (CMA-ES: never, by design, as it has no
    gradient steps; its batch norm is optional, off by default)."""
    overrides = {}
    if name == "cmaes":
        overrides = dict(policy_kwargs=dict(tiny_kwargs["cmaes"]["policy_kwargs"], batch_norm=True))
    if name == "soft_denfac":  # SAC's actor has no batch norm: refused with the reason
        with pytest.raises(ValueError, match="no batch norm"):
            make_model(name, policy_kwargs=dict(tiny_kwargs[name]["policy_kwargs"], batch_norm=True))
        return
    model = make_model(name, **overrides)
    model.learn(episode_steps)
    before = batch_norm_buffers(model.policy)
    assert before, f"{name}'s policy has no batch norm"
    observations = sample_observations(model.observation_space)
    for deterministic in (True, False):
        model.predict(observations, deterministic=deterministic)
        model.predict(observations[0], deterministic=deterministic)  # a batch of 1 works in eval mode
    after_predict = batch_norm_buffers(model.policy)
    for key, value in before.items():
        # exact: predict() must not write the statistics at all
        assert th.equal(value, after_predict[key]), f"predict() changed the running statistics {key}"

    model.learn(2 * episode_steps, reset_num_timesteps=False)
    after_learn = batch_norm_buffers(model.policy)
    changed = [key for key, value in before.items() if not th.equal(value, after_learn[key])]
    if name == "cmaes":
        assert not changed, "CMA-ES evaluates candidates in eval mode: its running statistics must stay fixed"
    else:
        assert changed, "training did not update any batch-norm running statistics"
