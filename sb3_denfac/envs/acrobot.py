"""Continuous Acrobot (double swing-up) of the DENFAC paper.

Zimmer, Boniface, Dutech, "Off-Policy Neural Fitted Actor-Critic", section 4: "+1 if the goal is reached (arm
straight up), the normalized max height of end effector if 500 steps are reached, and 0 otherwise"; gamma = 0.9;
performance = number of steps to reach the goal (lower is better).

Id ``sb3_denfac/ContinuousAcrobot-v0`` = :class:`AcrobotSwingUpReward` around :class:`ContinuousAcrobotEnv`.
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.envs.classic_control import utils
from gymnasium.envs.classic_control.acrobot import AcrobotEnv, bound, rk4, wrap

from sb3_denfac.envs.common import DEFAULT_EPISODE_LENGTH, EpisodeRewardWrapper, PaperEnv, as_action_vector

OBS_TYPES = ("paper", "gymnasium")


def acrobot_tip_height(env: gym.Env) -> float:
    """Normalised tip height in [0, 1] (0: hanging down, 1: straight up) of any gymnasium ``AcrobotEnv``."""
    acrobot = env.unwrapped
    th1, th2 = float(acrobot.state[0]), float(acrobot.state[1])
    l1, l2 = acrobot.LINK_LENGTH_1, acrobot.LINK_LENGTH_2
    height = -l1 * np.cos(th1) - l2 * np.cos(th1 + th2)
    return float((height + l1 + l2) / (2.0 * (l1 + l2)))


class ContinuousAcrobotEnv(AcrobotEnv):
    """Gymnasium's Acrobot dynamics (book equations, RK4, ``dt`` = 0.2 s) with one continuous elbow torque.

    Action: ``Box(-1, 1, (1,), float32)``; the torque is ``clip(a, -1, 1) * max_torque`` N m.
    Observation (``obs_type="paper"``, default): ``[theta1, dtheta1, theta2, dtheta2]`` float32 (the paper's 4-d
    state; angles wrapped to [-pi, pi], velocities bounded by 4 pi and 9 pi as in gymnasium);
    ``obs_type="gymnasium"``: gymnasium's 6-d ``[cos th1, sin th1, cos th2, sin th2, dth1, dth2]``.
    Reward: the normalised tip height (placeholder; the paper's reward is :class:`AcrobotSwingUpReward`).
    Never terminates by itself; ``info["tip_height"]`` is the normalised tip height.

    :param max_torque: Torque (N m) of action 1. Default 1.5 N m, the authors' value (gymnasium's discrete
        Acrobot uses 1 N m). With gymnasium's links (unit inertia about each centre of mass) and dt = 0.2 s, the
        bang-bang controller ``a = sign(dtheta2)`` reaches the straight-up goal (normalised height >= 0.99) from
        rest in 192 steps (304 with 1 N m, 159 with 2 N m): see ``scripts/acrobot_reachability.py``.
    :param random_start: False (authors): start hanging at rest; True: gymnasium's uniform start in [-0.1, 0.1]
        (``reset(options={"low": ..., "high": ...})`` changes the bounds).
    :param obs_type: "paper" (4-d) or "gymnasium" (6-d).
    :param n_substeps: RK4 steps per ``dt`` (gymnasium uses 1).
    :param render_mode: Gymnasium render mode.
    """

    def __init__(
        self,
        max_torque: float = 1.5,
        random_start: bool = False,
        obs_type: str = "paper",
        n_substeps: int = 1,
        render_mode: str | None = None,
    ) -> None:
        super().__init__(render_mode=render_mode)
        if max_torque <= 0:
            raise ValueError(f"max_torque must be > 0, got {max_torque}")
        if obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {OBS_TYPES}, got {obs_type!r}")
        if n_substeps < 1:
            raise ValueError(f"n_substeps must be >= 1, got {n_substeps}")
        self.max_torque = float(max_torque)
        self.random_start = random_start
        self.obs_type = obs_type
        self.n_substeps = n_substeps
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        if obs_type == "paper":
            high = np.array([np.pi, self.MAX_VEL_1, np.pi, self.MAX_VEL_2], dtype=np.float32)
            self.observation_space = spaces.Box(-high, high, dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        gym.Env.reset(self, seed=seed)
        if self.random_start:
            low, high = utils.maybe_parse_reset_bounds(options, -0.1, 0.1)
            self.state = self.np_random.uniform(low=low, high=high, size=(4,))
        else:
            self.state = np.zeros(4)
        if self.render_mode == "human":
            self.render()
        return self._get_ob(), {"tip_height": acrobot_tip_height(self)}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        assert self.state is not None, "Call reset before using step."
        torque = float(as_action_vector(action, self.action_space)[0]) * self.max_torque
        s_augmented = np.append(np.asarray(self.state, dtype=np.float64), torque)
        ns = rk4(self._dsdt, s_augmented, np.linspace(0.0, self.dt, self.n_substeps + 1))
        ns[0] = wrap(ns[0], -np.pi, np.pi)
        ns[1] = wrap(ns[1], -np.pi, np.pi)
        ns[2] = bound(ns[2], -self.MAX_VEL_1, self.MAX_VEL_1)
        ns[3] = bound(ns[3], -self.MAX_VEL_2, self.MAX_VEL_2)
        self.state = ns
        height = acrobot_tip_height(self)
        if self.render_mode == "human":
            self.render()
        return self._get_ob(), height, False, False, {"tip_height": height}

    def _get_ob(self) -> np.ndarray:
        s = self.state
        assert s is not None, "Call reset before using step."
        if self.obs_type == "paper":
            obs = np.array([s[0], s[2], s[1], s[3]], dtype=np.float32)
            return np.clip(obs, self.observation_space.low, self.observation_space.high)
        return super()._get_ob()


class AcrobotSwingUpReward(EpisodeRewardWrapper):
    """The paper's Acrobot reward, for any env whose ``unwrapped`` is a gymnasium ``AcrobotEnv``.

    Per step ``t`` (1-based), with ``h`` the normalised tip height after the step (0 down, 1 straight up):
    ``+1`` and ``terminated`` if ``h >= goal_height``; otherwise, on the time-limit step (``t == max_episode_steps``
    or an inner truncation) the maximum of ``h`` over the episode (reset state included); ``0`` otherwise.
    The inner env's own termination is ignored (use a base env that does not terminate).
    ``info["paper_performance"]`` on the last step: ``t`` if the goal was reached, else ``max_episode_steps``.

    :param env: Acrobot environment.
    :param goal_height: Normalised tip height counted as "straight up" (paper: 0.99).
    :param max_episode_steps: Episode length (paper: 500).
    """

    def __init__(self, env: gym.Env, goal_height: float = 0.99, max_episode_steps: int | None = 500) -> None:
        super().__init__(env, max_episode_steps)
        if not 0.0 < goal_height <= 1.0:
            raise ValueError(f"goal_height must be in (0, 1], got {goal_height}")
        self.goal_height = goal_height
        self.max_height = 0.0

    def _on_reset(self, obs: Any, info: dict[str, Any]) -> None:
        self.max_height = acrobot_tip_height(self.env)

    def _reward(self, action: Any, info: dict[str, Any], base_terminated: bool, last_by_time: bool) -> tuple[float, bool]:
        height = acrobot_tip_height(self.env)
        self.max_height = max(self.max_height, height)
        info["max_tip_height"] = self.max_height
        if height >= self.goal_height:
            return 1.0, True
        if last_by_time:
            return self.max_height, False
        return 0.0, False

    def _performance(self, terminated: bool) -> float:
        if terminated:
            return float(self.elapsed_steps)
        return float(self.max_episode_steps if self.max_episode_steps is not None else self.elapsed_steps)


class ContinuousAcrobotPaperEnv(PaperEnv):
    """``sb3_denfac/ContinuousAcrobot-v0``: the paper's Acrobot double swing-up (gamma 0.9, 500 steps).

    Observation ``Box(4,)`` float32 ``[th1, dth1, th2, dth2]``, action ``Box(-1, 1, (1,))`` float32 (torque
    ``a * max_torque``), reward of :class:`AcrobotSwingUpReward`, ``paper_performance`` = steps to reach the goal
    (500 if not reached; lower is better). Arguments are those of :class:`ContinuousAcrobotEnv` and
    :class:`AcrobotSwingUpReward`, except ``episode_length`` (the wrapper's ``max_episode_steps``, see
    :class:`~sb3_denfac.envs.common.PaperEnv`).
    """

    metadata = ContinuousAcrobotEnv.metadata

    def __init__(
        self,
        max_torque: float = 1.5,
        goal_height: float = 0.99,
        episode_length: int | None = None,
        random_start: bool = False,
        obs_type: str = "paper",
        n_substeps: int = 1,
        render_mode: str | None = None,
    ) -> None:
        base = ContinuousAcrobotEnv(max_torque, random_start, obs_type, n_substeps, render_mode)
        length = DEFAULT_EPISODE_LENGTH if episode_length is None else episode_length
        super().__init__(AcrobotSwingUpReward(base, goal_height, length), episode_length_given=episode_length is not None)
