"""Continuous CartPole (inverted pendulum) of the DENFAC paper.

Zimmer, Boniface, Dutech, "Off-Policy Neural Fitted Actor-Critic", section 4: reward "0 when the cart position is
between [-0.05; 0.05] and the pole angle between [-pi/60, pi/60], -2 x (500 - last_step) if it exits at last_step
(pole angle not in [-pi/6, pi/6] or cart position not in [-2.4; 2.4]), and -1 otherwise"; gamma = 0.99;
performance = episode return (higher is better).

Id ``sb3_denfac/ContinuousCartPole-v0`` = :class:`CartPoleBalanceReward` around :class:`ContinuousCartPoleEnv`.
"""

from __future__ import annotations

import math
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.classic_control import utils
from gymnasium.envs.classic_control.cartpole import CartPoleEnv

from sb3_denfac.envs.common import DEFAULT_EPISODE_LENGTH, EpisodeRewardWrapper, PaperEnv, as_action_vector


class ContinuousCartPoleEnv(CartPoleEnv):
    """Gymnasium's CartPole dynamics (Euler, tau = 0.02 s) with a continuous force ``a * force_mag``.

    Action: ``Box(-1, 1, (1,), float32)``, force ``clip(a, -1, 1) * 10`` N. Observation: gymnasium's float32
    ``[x, x_dot, theta, theta_dot]`` (the paper's 4-d state). Terminates when ``|x| > x_threshold`` or
    ``|theta| > theta_threshold_radians`` (paper: 2.4 m and pi/6, i.e. 30 degrees, instead of gymnasium's 12).
    Reward: gymnasium's +1 per step (placeholder; the paper's reward is :class:`CartPoleBalanceReward`).

    :param force_mag: Force (N) of action 1 (paper: 10).
    :param theta_threshold_radians: Failure angle (paper: pi/6).
    :param x_threshold: Failure cart position (paper: 2.4).
    :param random_start: False (authors' training setting): start at rest at 0; True: gymnasium's uniform start in
        [-0.05, 0.05] for every state variable (``reset(options={"low": ..., "high": ...})`` changes the bounds).
    :param render_mode: Gymnasium render mode.
    """

    def __init__(
        self,
        force_mag: float = 10.0,
        theta_threshold_radians: float = math.pi / 6,
        x_threshold: float = 2.4,
        random_start: bool = False,
        render_mode: str | None = None,
    ) -> None:
        super().__init__(render_mode=render_mode)
        if force_mag <= 0:
            raise ValueError(f"force_mag must be > 0, got {force_mag}")
        if theta_threshold_radians <= 0 or x_threshold <= 0:
            raise ValueError(
                f"theta_threshold_radians and x_threshold must be > 0, got {theta_threshold_radians}, {x_threshold}"
            )
        self.force_mag = float(force_mag)
        self.theta_threshold_radians = float(theta_threshold_radians)
        self.x_threshold = float(x_threshold)
        self.random_start = random_start
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        # Twice the failure bounds, as gymnasium, so that the failing observation is still in the space.
        big = np.finfo(np.float32).max
        high = np.array([2 * self.x_threshold, big, 2 * self.theta_threshold_radians, big], dtype=np.float32)
        self.observation_space = spaces.Box(-high, high, dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        gym.Env.reset(self, seed=seed)
        if self.random_start:
            low, high = utils.maybe_parse_reset_bounds(options, -0.05, 0.05)
            self.state = self.np_random.uniform(low=low, high=high, size=(4,))
        else:
            self.state = np.zeros(4)
        self.steps_beyond_terminated = None
        if self.render_mode == "human":
            self.render()
        return np.array(self.state, dtype=np.float32), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        assert self.state is not None, "Call reset before using step."
        force = float(as_action_vector(action, self.action_space)[0]) * self.force_mag
        x, x_dot, theta, theta_dot = (float(v) for v in self.state)
        cos_th, sin_th = math.cos(theta), math.sin(theta)
        # Barto, Sutton & Anderson (1983) cart-pole equations, as in gymnasium's CartPoleEnv.
        temp = (force + self.polemass_length * theta_dot**2 * sin_th) / self.total_mass
        theta_acc = (self.gravity * sin_th - cos_th * temp) / (
            self.length * (4.0 / 3.0 - self.masspole * cos_th**2 / self.total_mass)
        )
        x_acc = temp - self.polemass_length * theta_acc * cos_th / self.total_mass
        if self.kinematics_integrator == "euler":
            x, x_dot = x + self.tau * x_dot, x_dot + self.tau * x_acc
            theta, theta_dot = theta + self.tau * theta_dot, theta_dot + self.tau * theta_acc
        else:  # semi-implicit Euler
            x_dot = x_dot + self.tau * x_acc
            x = x + self.tau * x_dot
            theta_dot = theta_dot + self.tau * theta_acc
            theta = theta + self.tau * theta_dot
        self.state = np.array([x, x_dot, theta, theta_dot])
        terminated = bool(abs(x) > self.x_threshold or abs(theta) > self.theta_threshold_radians)
        if self.render_mode == "human":
            self.render()
        return np.array(self.state, dtype=np.float32), 1.0, terminated, False, {}


class CartPoleBalanceReward(EpisodeRewardWrapper):
    """The paper's CartPole reward, for any env whose ``unwrapped.state`` is ``[x, x_dot, theta, theta_dot]``.

    With ``t`` the 1-based index of the step just taken (``last_step`` of the paper: the failing step's index, so a
    failure on the first step gives ``-2 * 499``):

    - failure (``|theta| > theta_threshold`` or ``|x| > x_threshold``, or the inner env terminated):
      ``-fail_scale * (max_episode_steps - t)`` and ``terminated``;
    - inside the box (``|x| <= box_x`` and ``|theta| <= box_theta``): ``0``;
    - otherwise ``-1``.

    ``info["paper_performance"]`` on the last step: the episode return.

    :param env: CartPole environment.
    :param x_threshold: Failure cart position (paper: 2.4).
    :param theta_threshold: Failure pole angle (paper: pi/6).
    :param box_x: Half-width of the target box in x (paper: 0.05).
    :param box_theta: Half-width of the target box in theta (paper: pi/60).
    :param fail_scale: Factor of the failure penalty (paper: 2).
    :param max_episode_steps: Episode length (paper: 500; required: the failure penalty depends on it).
    """

    def __init__(
        self,
        env: gym.Env,
        x_threshold: float = 2.4,
        theta_threshold: float = math.pi / 6,
        box_x: float = 0.05,
        box_theta: float = math.pi / 60,
        fail_scale: float = 2.0,
        max_episode_steps: int = 500,
    ) -> None:
        if max_episode_steps is None:
            raise ValueError("max_episode_steps is required: the failure penalty -2 * (T - t) depends on it")
        super().__init__(env, max_episode_steps)
        self.x_threshold = x_threshold
        self.theta_threshold = theta_threshold
        self.box_x = box_x
        self.box_theta = box_theta
        self.fail_scale = fail_scale

    def _reward(self, action: Any, info: dict[str, Any], base_terminated: bool, last_by_time: bool) -> tuple[float, bool]:
        x, _, theta, _ = (float(v) for v in self.env.unwrapped.state)
        failed = base_terminated or abs(x) > self.x_threshold or abs(theta) > self.theta_threshold
        if failed:
            assert self.max_episode_steps is not None
            return -self.fail_scale * (self.max_episode_steps - self.elapsed_steps), True
        if abs(x) <= self.box_x and abs(theta) <= self.box_theta:
            return 0.0, False
        return -1.0, False


class ContinuousCartPolePaperEnv(PaperEnv):
    """``sb3_denfac/ContinuousCartPole-v0``: the paper's CartPole (gamma 0.99, 500 steps).

    Observation ``Box(4,)`` float32 ``[x, x_dot, theta, theta_dot]``, action ``Box(-1, 1, (1,))`` float32 (force
    ``a * 10`` N), reward of :class:`CartPoleBalanceReward`, ``paper_performance`` = episode return (0 is the
    best, -998 the worst). Arguments are those of :class:`ContinuousCartPoleEnv` and :class:`CartPoleBalanceReward`
    (the failure thresholds are shared by both), except ``episode_length`` (the wrapper's ``max_episode_steps``,
    see :class:`~sb3_denfac.envs.common.PaperEnv`).
    """

    metadata = ContinuousCartPoleEnv.metadata

    def __init__(
        self,
        force_mag: float = 10.0,
        theta_threshold_radians: float = math.pi / 6,
        x_threshold: float = 2.4,
        box_x: float = 0.05,
        box_theta: float = math.pi / 60,
        episode_length: int | None = None,
        random_start: bool = False,
        render_mode: str | None = None,
    ) -> None:
        base = ContinuousCartPoleEnv(force_mag, theta_threshold_radians, x_threshold, random_start, render_mode)
        length = DEFAULT_EPISODE_LENGTH if episode_length is None else episode_length
        wrapped = CartPoleBalanceReward(base, x_threshold, theta_threshold_radians, box_x, box_theta, max_episode_steps=length)
        super().__init__(wrapped, episode_length_given=episode_length is not None)
