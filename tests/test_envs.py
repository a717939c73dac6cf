"""Tests of the paper's environments (sb3_denfac.envs): rewards, termination, paper_performance, checkers."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from gymnasium.wrappers import TimeLimit
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import sb3_denfac  # noqa: F401  (registers the environments)
from sb3_denfac.envs import (
    ENV_IDS,
    AcrobotSwingUpReward,
    CartPoleBalanceReward,
    ContinuousAcrobotEnv,
    ContinuousAcrobotPaperEnv,
    ContinuousCartPoleEnv,
    ContinuousCartPolePaperEnv,
    acrobot_tip_height,
    register_envs,
)

ACROBOT, CARTPOLE, CHEETAH = ENV_IDS


def zero_action(env: gym.Env) -> np.ndarray:
    return np.zeros(env.action_space.shape, dtype=np.float32)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_make_spaces_and_checkers(env_id: str) -> None:
    register_envs()  # idempotent
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id)
        assert env.spec is not None and env.spec.max_episode_steps == 500
        assert isinstance(env.action_space, gym.spaces.Box) and env.action_space.dtype == np.float32
        assert np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)
        assert env.observation_space.dtype == np.float32
        sb3_check_env(env.unwrapped)
        gym_check_env(env.unwrapped, skip_render_check=True)  # headless: no human rendering
        env.close()
        env = gym.make(f"sb3_denfac:{env_id}")
        obs, _ = env.reset(seed=0)
        assert obs in env.observation_space
        env.close()


def test_paper_dimensions() -> None:
    dims = {}
    for env_id in ENV_IDS:
        env = gym.make(env_id)
        dims[env_id] = (env.observation_space.shape, env.action_space.shape)
        env.close()
    assert dims == {ACROBOT: ((4,), (1,)), CARTPOLE: ((4,), (1,)), CHEETAH: ((17,), (6,))}


# ---------------------------------------------------------------- CartPole


def test_cartpole_fail_penalty_depends_on_failing_step() -> None:
    env = gym.make(CARTPOLE)
    env.reset(seed=0)
    push = np.ones(1, dtype=np.float32)
    rewards, t = [], 0
    while True:
        _, reward, terminated, truncated, info = env.step(push)
        t += 1
        rewards.append(reward)
        if terminated or truncated:
            break
    assert terminated and not truncated
    x, _, theta, _ = env.unwrapped.base_env.state
    assert abs(theta) > math.pi / 6 or abs(x) > 2.4
    assert 1 < t < 500
    assert rewards[-1] == -2 * (500 - t)  # last_step = 1-based index of the failing step
    assert set(rewards[:-1]) <= {0.0, -1.0}
    # approx (rel 1e-6): a float64 sum of the same rewards in another order
    assert info["paper_performance"] == pytest.approx(sum(rewards))


def test_cartpole_reward_regions() -> None:
    env = ContinuousCartPolePaperEnv()
    env.reset(seed=0)
    base = env.base_env
    base.state = np.array([0.04, 0.0, 0.9 * math.pi / 60, 0.0])  # inside the box (and stays for one step)
    assert env.step(zero_action(env))[1] == 0.0
    base.state = np.array([0.5, 0.0, 0.0, 0.0])  # outside the box, not failed
    _, reward, terminated, _, _ = env.step(zero_action(env))
    assert reward == -1.0 and not terminated
    base.state = np.array([0.0, 0.0, math.pi / 6 + 0.01, 0.0])  # failed at step 3
    _, reward, terminated, _, info = env.step(zero_action(env))
    assert terminated and reward == -2 * (500 - 3)
    assert info["paper_performance"] == -1.0 - 2 * 497
    env.reset()
    base.state = np.array([2.45, 0.0, 0.0, 0.0])  # cart out of [-2.4, 2.4] on step 1
    _, reward, terminated, _, _ = env.step(zero_action(env))
    assert terminated and reward == -998


def test_cartpole_rest_start_balances_to_time_limit() -> None:
    env = gym.make(CARTPOLE)
    obs, _ = env.reset(seed=0)
    assert np.all(obs == 0)  # authors' start: at rest at 0 (an equilibrium under zero force)
    total, steps = 0.0, 0
    while True:
        _, reward, terminated, truncated, info = env.step(zero_action(env))
        total += reward
        steps += 1
        if terminated or truncated:
            break
    assert truncated and not terminated and steps == 500
    assert total == 0.0 and info["paper_performance"] == 0.0


def test_cartpole_actions_clipped_and_random_start() -> None:
    envs = [ContinuousCartPoleEnv(), ContinuousCartPoleEnv()]
    for env in envs:
        env.reset(seed=0)
    envs[0].step(np.array([1.0], dtype=np.float32))
    envs[1].step(np.array([7.0], dtype=np.float32))
    # rtol 1e-7: float64 dynamics from the same state and the same clipped force (equal in practice)
    np.testing.assert_allclose(envs[0].state, envs[1].state)
    # Force = a * 10 N: from rest, one Euler step gives x_dot = tau * F / M * (1 + m_p l / (M l (4/3 - m_p / M))).
    expected_x_dot = 0.02 * 10.0 / 1.1 * (1 + 0.05 / (1.1 * 0.5 * (4 / 3 - 0.1 / 1.1)))
    assert envs[0].state[1] == pytest.approx(expected_x_dot, rel=1e-9)
    random_env = ContinuousCartPoleEnv(random_start=True)
    obs1, _ = random_env.reset(seed=3)
    obs2, _ = random_env.reset(seed=3)
    assert np.any(obs1 != 0) and np.all(np.abs(obs1) <= 0.05) and np.array_equal(obs1, obs2)


def test_cartpole_wrapper_on_gymnasium_discrete_cartpole() -> None:
    # Reusable on any env with the same state: gymnasium's CartPole-v1 fails at 12 degrees.
    env = CartPoleBalanceReward(gym.make("CartPole-v1").unwrapped)
    env.reset(seed=1)
    t = 0
    while True:
        _, reward, terminated, truncated, _ = env.step(1)
        t += 1
        if terminated or truncated:
            break
    assert terminated and reward == -2 * (500 - t)


# ---------------------------------------------------------------- Acrobot


def test_acrobot_goal_gives_one_and_terminates() -> None:
    env = gym.make(ACROBOT)
    obs, _ = env.reset(seed=0)
    assert np.all(obs == 0)  # hanging at rest
    base = env.unwrapped.base_env
    for _ in range(3):
        _, reward, terminated, truncated, _ = env.step(zero_action(env))
        assert reward == 0.0 and not terminated and not truncated
    base.state = np.array([math.pi, 0.0, 0.0, 0.0])  # straight up, at rest (unstable equilibrium)
    _, reward, terminated, truncated, info = env.step(zero_action(env))
    assert acrobot_tip_height(base) >= 0.99
    assert reward == 1.0 and terminated and not truncated
    assert info["paper_performance"] == 4


def test_acrobot_timeout_reward_is_running_max_height() -> None:
    env = ContinuousAcrobotPaperEnv(episode_length=60)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    heights, rewards = [0.0], []
    while True:
        action = rng.uniform(-1, 1, size=1).astype(np.float32)
        _, reward, terminated, truncated, info = env.step(action)
        heights.append(acrobot_tip_height(env.base_env))
        rewards.append(reward)
        if terminated or truncated:
            break
    assert truncated and not terminated and len(rewards) == 60
    assert all(r == 0.0 for r in rewards[:-1])
    assert 0 < max(heights) < 0.99
    # approx (rel 1e-6): the env's float64 running maximum against heights read from its state
    assert rewards[-1] == pytest.approx(max(heights))
    assert info["paper_performance"] == 60


def test_acrobot_timeout_from_inner_time_limit_and_gym_make() -> None:
    # The last-step reward also fires on an inner TimeLimit truncation (wrapper without its own limit)...
    env = AcrobotSwingUpReward(TimeLimit(ContinuousAcrobotEnv(), 7), max_episode_steps=None)
    env.reset(seed=0)
    push = np.ones(1, dtype=np.float32)
    for _ in range(6):
        assert env.step(push)[1] == 0.0
    _, reward, _, truncated, info = env.step(push)
    # approx (rel 1e-6): the same float64 height, returned and stored
    assert truncated and reward == pytest.approx(env.max_height) and reward > 0
    assert info["paper_performance"] == 7
    # ... and on the 500th step of the registered id (own counter and gymnasium's TimeLimit agree).
    env = gym.make(ACROBOT)
    env.reset(seed=0)
    for t in range(1, 501):
        _, reward, terminated, truncated, info = env.step(zero_action(env))
        assert truncated == (t == 500) and not terminated
    assert reward == 0.0 and info["paper_performance"] == 500  # at rest the max height stays 0
    # A shorter episode through gym.make: change both gymnasium's TimeLimit and the env's own counter.
    env = gym.make(ACROBOT, max_episode_steps=30, episode_length=30)
    env.reset(seed=0)
    for _ in range(30):
        _, reward, _, truncated, info = env.step(push)
    assert truncated and info["paper_performance"] == 30
    assert reward > 0 and reward == pytest.approx(info["max_tip_height"])


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gym_make_max_episode_steps_alone_sets_the_episode_length(env_id: str) -> None:
    """gym.make(id, max_episode_steps=N) without episode_length: the env's own counter follows, so the N-th step is
    its last one (the paper's last-step reward, paper_performance)."""
    env = gym.make(env_id, max_episode_steps=9)
    assert env.unwrapped.episode_length == 9 and env.spec.max_episode_steps == 9
    env.reset(seed=0)
    infos = [env.step(zero_action(env))[4] for _ in range(9)]
    assert "paper_performance" in infos[-1] and not any("paper_performance" in info for info in infos[:-1])
    if env_id == ACROBOT:
        assert infos[-1]["paper_performance"] == 9  # goal not reached: the episode length
    assert gym.make(env_id, max_episode_steps=9, episode_length=5).unwrapped.episode_length == 5  # ends first: allowed
    with pytest.raises(ValueError, match=r"episode_length=12 is longer than the TimeLimit.*max_episode_steps=9"):
        gym.make(env_id, max_episode_steps=9, episode_length=12)
    assert gym.make(env_id).unwrapped.episode_length == 500


def test_acrobot_goal_reachable_with_default_torque() -> None:
    # Bang-bang energy pumping a = sign(dtheta2) reaches the straight-up goal within 500 steps.
    env = gym.make(ACROBOT)
    obs, _ = env.reset(seed=0)
    while True:
        action = np.array([1.0 if obs[3] >= 0 else -1.0], dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    assert terminated and reward == 1.0 and info["paper_performance"] < 500


def test_acrobot_options() -> None:
    env = ContinuousAcrobotEnv(obs_type="gymnasium", random_start=True)
    obs, _ = env.reset(seed=2)
    assert obs.shape == (6,) and obs in env.observation_space and np.any(env.state != 0)
    strong, clipped = ContinuousAcrobotEnv(), ContinuousAcrobotEnv()
    for env in (strong, clipped):
        env.reset(seed=0)
    strong.step(np.array([1.0], dtype=np.float32))
    clipped.step(np.array([5.0], dtype=np.float32))
    # rtol 1e-7: float64 dynamics from the same state and the same clipped torque (equal in practice)
    np.testing.assert_allclose(strong.state, clipped.state)
    with pytest.raises(ValueError, match="obs_type"):
        ContinuousAcrobotEnv(obs_type="pixels")
    with pytest.raises(ValueError, match="max_torque"):
        ContinuousAcrobotEnv(max_torque=0.0)


# ---------------------------------------------------------------- Half-Cheetah


@pytest.fixture(scope="module")
def cheetah():
    from sb3_denfac.envs import HalfCheetahPaperEnv

    env = HalfCheetahPaperEnv(reset_noise_scale=0.0, episode_length=20)
    yield env
    env.close()


def put_head_on_floor(base, vertical_speed: float = 0.0) -> None:
    """Set a HalfCheetah-v5 (unwrapped) state in which the head touches the floor."""
    qpos = base.init_qpos.copy()
    qpos[1], qpos[2] = -0.2, 1.0  # rootz down, torso pitched forward: the head touches the floor
    qvel = np.zeros(base.model.nv)
    qvel[1] = vertical_speed
    base.set_state(qpos, qvel)


def test_cheetah_no_penalty_in_normal_stance(cheetah) -> None:
    cheetah.reset(seed=0)
    for _ in range(10):
        _, reward, terminated, _, info = cheetah.step(zero_action(cheetah))
        assert not info["floor_contact"] and not terminated
        # approx (rel 1e-6): the reward's float64 terms, recomputed from the info the env reports
        assert reward == pytest.approx(info["x_velocity"])
    action = np.full(6, 0.5, dtype=np.float32)
    _, reward, _, _, info = cheetah.step(action)
    assert reward == pytest.approx(info["x_velocity"] - 0.05 * 6 * 0.25 - float(info["floor_contact"]))


def test_cheetah_head_contact_penalty_every_substep(cheetah) -> None:
    from sb3_denfac.envs import floor_contact_geoms

    cheetah.reset(seed=0)
    put_head_on_floor(cheetah.base_env, vertical_speed=5.0)
    _, reward, terminated, _, info = cheetah.step(zero_action(cheetah))
    assert info["head_contact"] and info["floor_contact"] and "head" in info["floor_contact_geoms"]
    # approx (rel 1e-6): the reward's float64 terms, recomputed from the info the env reports
    assert reward == pytest.approx(info["x_velocity"] - 1.0) and not terminated
    # Thrown upwards, the head has left the floor by the last sub-step: only sub-step recording sees the contact.
    base = cheetah.base_env
    assert "head" not in floor_contact_geoms(base.model, base.data, ("head",))


def test_cheetah_terminate_on_head_contact_option() -> None:
    from sb3_denfac.envs import HalfCheetahPaperEnv

    env = HalfCheetahPaperEnv(terminate_on_head_contact=True, reset_noise_scale=0.0)
    env.reset(seed=0)
    put_head_on_floor(env.base_env)
    _, reward, terminated, truncated, info = env.step(zero_action(env))
    assert terminated and not truncated and reward == -1000.0
    assert info["paper_performance"] == -1000.0
    env.close()


def test_cheetah_paper_performance_is_return(cheetah) -> None:
    cheetah.reset(seed=0)
    rng = np.random.default_rng(0)
    total = 0.0
    for t in range(1, 21):
        _, reward, terminated, truncated, info = cheetah.step(rng.uniform(-1, 1, 6).astype(np.float32))
        total += reward
        assert truncated == (t == 20) and not terminated
    # approx (rel 1e-6): a float64 sum of the same rewards in another order
    assert info["paper_performance"] == pytest.approx(total)


def test_cheetah_wrapper_on_plain_half_cheetah_v5() -> None:
    from sb3_denfac.envs import HalfCheetahPaperReward

    env = HalfCheetahPaperReward(gym.make("HalfCheetah-v5", reset_noise_scale=0.0).unwrapped, max_episode_steps=5)
    env.reset(seed=0)
    put_head_on_floor(env.unwrapped)
    _, reward, _, _, info = env.step(zero_action(env))
    assert "floor_contact" in info  # last sub-step only on a plain v5 env
    # approx (rel 1e-6): the reward's float64 terms, recomputed from the info the env reports
    assert reward == pytest.approx(info["x_velocity"] - float(info["floor_contact"]))
    env.close()
