"""SB3 plugin contract, part 4: training options (DDPG train_freq, learning-rate schedules, several environments, DDPG
target batch-norm statistics, custom features extractors, budgets inside episodes; after SB3's tests/test_run.py,
test_train_eval_mode.py). The tiny variants and helpers: fixtures of ``conftest.py``."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm

import sb3_denfac  # noqa: F401  (registers the paper envs)

# ----- off-policy train frequency (SB3 tests/test_run.py) --------------------------------------------------------------


@pytest.mark.parametrize("train_freq", [4, (2, "step"), (1, "episode")])
def test_ddpg_train_freq(train_freq: Any, episode_steps, make_model) -> None:
    model = make_model("ddpg", train_freq=train_freq, gradient_steps=-1, learning_starts=episode_steps)
    model.learn(2 * episode_steps)
    assert model.num_timesteps == 2 * episode_steps
    assert model._n_updates == episode_steps  # gradient_steps=-1: one update per collected step after learning_starts


# ----- learning-rate schedules and several environments ---------------------------------------------------------------


def _optimizers(model: BaseAlgorithm) -> list[th.optim.Optimizer]:
    """The optimizers, where every algorithm with an actor and a critic keeps them (docs/conventions.md)."""
    return [model.policy.actor.optimizer, model.policy.critic.optimizer]


@pytest.mark.algorithms("with_learning_rate")  # CMA-ES has no learning rate
def test_learning_rate_schedule(name: str, episode_steps, make_model) -> None:
    """A schedule of the remaining progress given as ``learning_rate`` is followed (SB3 semantics), not just read once."""
    model = make_model(name, learning_rate=lambda progress_remaining: 1e-3 * progress_remaining)
    optimizers = _optimizers(model)
    assert optimizers
    assert all(group["lr"] == pytest.approx(1e-3) for opt in optimizers for group in opt.param_groups)
    model.learn(4 * episode_steps)
    for optimizer in _optimizers(model):  # looked up again: a network reset may build a new optimizer
        for group in optimizer.param_groups:
            assert group["lr"] <= 0.5e-3, "learning_rate schedule ignored"


@pytest.mark.parametrize("name", ["denfac", "soft_denfac", "ddpg", "nfac", "cacla"])  # not CMA-ES (one candidate at a time)
def test_several_envs(name: str, episode_steps, make_env, make_model) -> None:
    from stable_baselines3.common.env_util import make_vec_env

    model = make_model(name, env=make_vec_env(make_env, n_envs=2, seed=0))
    model.learn(2 * episode_steps)
    assert model.num_timesteps == 2 * episode_steps
    assert model.n_envs == 2
    actions, _ = model.predict(model.get_env().reset(), deterministic=True)
    assert actions.shape == (2, *model.action_space.shape)


def test_ddpg_target_networks_copy_batch_norm_statistics(episode_steps, batch_norm_buffers, make_model) -> None:
    """As SB3's TD3 (GH#996): running statistics are copied to the targets, weights are Polyak-averaged."""
    model = make_model("ddpg", tau=0.1)
    model.learn(2 * episode_steps)
    policy = model.policy
    for online, target in ((policy.actor, policy.actor_target), (policy.critic, policy.critic_target)):
        online_stats, target_stats = batch_norm_buffers(online), batch_norm_buffers(target)
        assert online_stats
        for key, value in online_stats.items():
            # exact: the statistics are copied, not averaged
            assert th.equal(value, target_stats[key]), key
        online_weights = th.cat([p.flatten() for p in online.parameters()])
        target_weights = th.cat([p.flatten() for p in target.parameters()])
        assert not th.equal(online_weights, target_weights)  # tau < 1: the targets lag


# ----- custom features extractors (SB3 tests/test_train_eval_mode.py::test_a2c_ppo_train_with_batch_norm) --------------


@pytest.mark.parametrize("share", [True, False])
@pytest.mark.parametrize("name", ["nfac", "cacla"])
def test_on_policy_train_features_extractor(
    name: str, share: bool, batch_norm_extractor: type, episode_steps, make_model
) -> None:
    """A custom extractor is trained: its BN bias moves (gradient steps) and its running mean (statistics refresh)."""
    policy_kwargs = dict(net_arch=[16, 16], features_extractor_class=batch_norm_extractor, share_features_extractor=share)
    # Acrobot, not SB3's Pendulum: rewards of 0 give positive TD errors from the start, so the actor is trained too.
    env = gym.make("sb3_denfac/ContinuousAcrobot-v0", max_episode_steps=episode_steps)
    model = make_model(name, env=env, policy_kwargs=policy_kwargs, seed=1)
    extractors = {model.policy.features_extractor, model.policy.vf_features_extractor}
    assert len(extractors) == (1 if share else 2)
    before = [(e.batch_norm.bias.clone(), e.batch_norm.running_mean.clone()) for e in extractors]
    model.learn(200)
    for extractor, (bias, running_mean) in zip(extractors, before, strict=True):
        assert not th.isclose(bias, extractor.batch_norm.bias).all()
        assert not th.isclose(running_mean, extractor.batch_norm.running_mean).all()


# ----- a budget inside an episode: nothing hangs ------------------------------------------------------------------------


@pytest.mark.timeout(60)
@pytest.mark.algorithms("all")
def test_learn_stops_inside_a_never_ending_episode(
    name: str, never_ending_env: type[gym.Env], off_policy_names, tiny_kwargs, make_model
) -> None:
    """learn(64) returns on an env that never ends; episodic learners update on the partial episode, and the next
    learn(reset_num_timesteps=False) continues the same episode."""
    overrides = dict(train_freq=(1, "episode")) if name.startswith("ddpg") else {}
    model = make_model(name, env=never_ending_env(), seed=0, **overrides)
    model.learn(64)
    n_steps = tiny_kwargs[name].get("n_steps", 1)  # CACLA collects whole rollouts of n_steps, as SB3's A2C
    assert 64 <= model.num_timesteps < 64 + n_steps
    if name != "cmaes":  # CMA-ES scores candidates on whole episodes only
        assert model._n_updates >= 1, "no update on the partial episode"
    last_obs = np.array(model._last_obs, copy=True)
    start = model.num_timesteps
    model.learn(16, reset_num_timesteps=False)
    assert start + 16 <= model.num_timesteps < start + 16 + n_steps
    if name in off_policy_names:  # the buffer continues the episode from the stored last observation
        # exact: the stored observation, copied
        np.testing.assert_array_equal(model.replay_buffer.observations[start % model.buffer_size], last_obs)
    assert model.ep_info_buffer is None or len(model.ep_info_buffer) == 0  # no episode was ended


def test_cmaes_resumes_an_evaluation_cut_by_the_budget(episode_steps, assert_same_parameters, make_model) -> None:
    """Budgets that fall inside episodes give the same search as one learn() call: the cut episode is resumed."""
    whole = make_model("cmaes", seed=3)
    whole.learn(6 * episode_steps)
    split = make_model("cmaes", seed=3)
    for budget in (25, 33, 6 * episode_steps - 58):
        split.learn(budget, reset_num_timesteps=False)
    assert split.num_timesteps == whole.num_timesteps and split.generation == whole.generation == 3
    assert split.best_return == whole.best_return
    # exact: the same seed, code and kernels in one process repeat a run bit for bit, whatever the budgets' cuts
    np.testing.assert_array_equal(split.es.mean, whole.es.mean)
    assert_same_parameters(split.get_parameters(), whole.get_parameters())
