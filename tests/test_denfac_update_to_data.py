"""DENFAC's ``update_to_data_ratio`` (:mod:`sb3_denfac.denfac.options`): the update after n new transitions runs
min(K, ceil(rho n / critic_steps)) fitted iterations; counted on the critics' Adam steps, on both updaters, with a
budget that ends inside an episode; validation, save/load, and a learning test."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3.common.save_util import load_from_zip_file

from sb3_denfac.denfac import DENFAC
from sb3_denfac.denfac.options import fitted_iterations

SMALL = dict(n_fitted_iterations=4, critic_steps=5, actor_steps=5, seed=1)


def _critic_adam_steps(model: DENFAC) -> list[int]:
    return [int(state["step"]) for state in model.critic.optimizer.state.values()]


@pytest.mark.parametrize(
    ("critic_steps", "ratio", "n_new", "expected"),
    [
        (5, None, 1, 10),
        (5, None, 1000, 10),
        (5, 1.0, 10, 2),
        (5, 1.0, 50, 10),
        (5, 1.0, 500, 10),
        (5, 1.0, 1, 1),
        (5, 0.01, 3, 1),
        (5, 2.5, 8, 4),
        (7, 0.07, 100, 1),  # exactly one iteration's steps, not 2 from float rounding (0.07 * 100 / 7 > 1 in floats)
    ],
)
def test_fitted_iterations(critic_steps, ratio, n_new, expected):
    """K = 10: about rho critic steps per new transition, at least 1, at most K."""
    assert fitted_iterations(10, critic_steps, ratio, n_new) == expected


@pytest.mark.parametrize(("ratio", "n_new", "expected"), [(1.0, 500, 100), (4.0, 1000, 800), (0.5, 3, 1), (2.0, 12, 5)])
def test_the_dial_without_a_cap(ratio, n_new, expected):
    """K = None: rho alone sets the update, ceil(rho n / critic_steps) iterations of 5 critic steps, at least 1."""
    assert fitted_iterations(None, 5, ratio, n_new) == expected


@pytest.mark.parametrize(
    ("bounds", "n_new", "expected"), [((10, None), 20, 10), ((10, None), 1000, 200), ((2, 3), 1000, 3), ((2, 3), 1, 2)]
)
def test_the_dial_within_a_range(bounds, n_new, expected):
    """(K_min, K_max): at least K_min iterations after any episode, rho critic steps per env step beyond, at most K_max."""
    assert fitted_iterations(bounds, 5, 1.0, n_new) == expected


@pytest.mark.parametrize(
    ("value", "ratio", "cause"),
    [
        ((10, None), None, "bounds K_e"),
        ((0, None), 1.0, "K_min"),
        ((5, 2), 1.0, "K_max"),
        ((1, 2, 3), 1.0, r"or \(K_min, K_max\)"),
        (0, 1.0, r"n_fitted_iterations \(K\)"),
    ],
)
def test_bad_ranges_name_the_cause(target_action_env, value, ratio, cause):
    with pytest.raises(ValueError, match=cause):
        DENFAC("MlpPolicy", target_action_env(), n_fitted_iterations=value, update_to_data_ratio=ratio)


def test_no_cap_needs_the_ratio(target_action_env):
    with pytest.raises(ValueError, match="n_fitted_iterations=None.*update_to_data_ratio"):
        DENFAC("MlpPolicy", target_action_env(), n_fitted_iterations=None)


@pytest.mark.parametrize("update_path", ["fast", "plain"])
def test_the_dial_grows_the_update_past_k(tmp_path, target_action_env, update_path):
    """rho = 4 without a cap: 10-step episodes get 8 iterations of 5 critic steps (40 steps), past K = 4's 20; the
    saved model keeps its uncapped K and resumes with it."""
    kwargs = {**SMALL, "n_fitted_iterations": None}
    model = DENFAC("MlpPolicy", target_action_env(), update_to_data_ratio=4.0, update_path=update_path, **kwargs)
    model.learn(20)
    assert set(_critic_adam_steps(model)) == {2 * 8 * 5}
    model.save(tmp_path / "model.zip")
    loaded = DENFAC.load(tmp_path / "model.zip", env=target_action_env())
    assert loaded.n_fitted_iterations is None and loaded.update_to_data_ratio == 4.0
    loaded.learn(10, reset_num_timesteps=False)
    assert set(_critic_adam_steps(loaded)) == {3 * 8 * 5}


@pytest.mark.parametrize("update_path", ["fast", "plain"])
def test_updates_scale_with_the_new_transitions(target_action_env, update_path):
    """Episodes of 10 steps, rho = 1, 5 critic steps: 2 fitted iterations (10 critic steps) per episode instead of K = 4;
    a budget ending 5 steps into the third episode updates on those 5 with 1 iteration."""
    model = DENFAC("MlpPolicy", target_action_env(), update_to_data_ratio=1.0, update_path=update_path, **SMALL)
    model.learn(25)
    assert model._n_updates == 3
    assert set(_critic_adam_steps(model)) == {(2 + 2 + 1) * 5}
    paper_count = DENFAC("MlpPolicy", target_action_env(), update_path=update_path, **SMALL).learn(25)
    assert set(_critic_adam_steps(paper_count)) == {3 * 4 * 5}  # None: K iterations at every update


def test_warm_up_steps_are_not_counted(target_action_env):
    """learning_starts = 15: the first update follows the second 10-step episode and counts its 10 steps only."""
    model = DENFAC("MlpPolicy", target_action_env(), update_to_data_ratio=1.0, learning_starts=15, **SMALL)
    model.learn(30)
    assert model._n_updates == 2
    assert set(_critic_adam_steps(model)) == {2 * 2 * 5}


@pytest.mark.parametrize("value", [0, -1.0, "1", float("nan")])
def test_invalid_update_to_data_ratio(target_action_env, value):
    with pytest.raises(ValueError, match="update_to_data_ratio"):
        DENFAC("MlpPolicy", target_action_env(), update_to_data_ratio=value)


def test_save_load_keeps_the_ratio(tmp_path, target_action_env):
    model = DENFAC("MlpPolicy", target_action_env(), update_to_data_ratio=1.0, **SMALL).learn(20)
    model.save(tmp_path / "model.zip")
    data, _, _ = load_from_zip_file(tmp_path / "model.zip", device="cpu", load_data=True)
    assert "gradient_steps" not in data  # always -1 here; an older sb3-denfac would read -1 as one update per step
    loaded = DENFAC.load(tmp_path / "model.zip", env=target_action_env())
    assert loaded.update_to_data_ratio == 1.0 and loaded.gradient_steps == -1
    loaded.learn(10, reset_num_timesteps=False)
    assert set(_critic_adam_steps(loaded)) == {3 * 2 * 5}


def test_update_to_data_ratio_learns_target_action(target_action_env):
    """With half of Algorithm 1's iterations per 10-step episode the actor still moves to the rewarded action. Over
    seeds 0-19 with native and ATEN_CPU_CAPABILITY=default kernels 50 episodes left it 0.01-0.13 off (from 0.42-0.86;
    after 30 episodes, the earlier budget, up to 0.33 off: another CPU's trajectory failed a bound of 0.1)."""
    env = target_action_env()
    model = DENFAC("MlpPolicy", env, update_to_data_ratio=1.0, gamma=0.9, **SMALL)
    obs = np.stack([env.observation_space.sample() for _ in range(64)])
    start = env.distance_to_target(model, obs)
    model.learn(500)
    end = env.distance_to_target(model, obs)
    assert end < 0.2 and end < start / 2, (start, end)
