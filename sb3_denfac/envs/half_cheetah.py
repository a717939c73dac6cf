"""Half-Cheetah of the DENFAC paper.

Zimmer, Boniface, Dutech, "Off-Policy Neural Fitted Actor-Critic", section 4:
``R(s, a) = v_x(s) - 0.05 ||a||_2^2 - 1 * g(s)``, gamma = 0.99, performance = episode return (higher is better).
The paper's text (garbled) names the heel; the authors' code penalises contacts of the head, the front thigh and
the back thigh with the floor, which is what is implemented (HalfCheetah-v5 has no heel geom). The authors also
ended the episode with -1000 on head contact: optional here (``terminate_on_head_contact``, off by default).

Id ``sb3_denfac/HalfCheetahPaper-v0`` = :class:`HalfCheetahPaperReward` around :class:`HalfCheetahContactEnv`.
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces
from gymnasium.envs.mujoco.half_cheetah_v5 import HalfCheetahEnv

from sb3_denfac.envs.common import DEFAULT_EPISODE_LENGTH, EpisodeRewardWrapper, PaperEnv, as_action_vector

PENALISED_GEOMS = ("head", "fthigh", "bthigh")


def floor_contact_geoms(model: mujoco.MjModel, data: mujoco.MjData, geom_names: tuple[str, ...]) -> set[str]:
    """Names among ``geom_names`` of the geoms in contact with the floor in ``data`` (current contacts only)."""
    floor = model.geom("floor").id
    ids = {model.geom(name).id: name for name in geom_names}
    touching = set()
    for geom1, geom2 in zip(data.contact.geom1[: data.ncon], data.contact.geom2[: data.ncon], strict=True):
        if geom1 == floor and geom2 in ids:
            touching.add(ids[geom2])
        elif geom2 == floor and geom1 in ids:
            touching.add(ids[geom1])
    return touching


class HalfCheetahContactEnv(HalfCheetahEnv):
    """HalfCheetah-v5 that records floor contacts at every physics sub-step, with a float32 observation.

    ``mujoco.mj_step(nstep=frame_skip)`` leaves only the last sub-step's contacts, so this env steps the physics one
    sub-step at a time and records which of ``contact_geoms`` touched the floor during the control step:
    ``info["floor_contact"]`` (bool), ``info["floor_contact_geoms"]`` (sorted tuple of names) and
    ``info["head_contact"]`` (bool). Rewards, observation content (17-d, x position excluded), action space
    ``Box(-1, 1, (6,), float32)``, ``frame_skip`` 5 (dt 0.05 s) and reset noise are HalfCheetah-v5's.

    The observation space is float32 with bounds +-float32 max instead of v5's float64 +-inf (gymnasium's checker
    warns on infinite bounds; SB3 stores float32 anyway).

    :param contact_geoms: Geoms whose floor contacts are recorded (authors: head, fthigh, bthigh).
    :param kwargs: Passed to gymnasium's ``HalfCheetahEnv`` (v5), e.g. ``reset_noise_scale=0`` for the authors'
        deterministic reset, ``exclude_current_positions_from_observation=False`` for an 18-d state with x.
    """

    def __init__(self, contact_geoms: tuple[str, ...] = PENALISED_GEOMS, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        for name in (*contact_geoms, "floor"):
            try:
                self.model.geom(name)
            except KeyError as e:
                raise ValueError(f"contact_geoms: no geom named {name!r} in the model") from e
        self.contact_geoms = tuple(contact_geoms)
        self._touched: set[str] = set()
        big = np.finfo(np.float32).max
        shape = self.observation_space.shape
        self.observation_space = spaces.Box(-big, big, shape=shape, dtype=np.float32)

    def _step_mujoco_simulation(self, ctrl: np.ndarray, n_frames: int) -> None:
        self.data.ctrl[:] = ctrl
        for _ in range(n_frames):
            mujoco.mj_step(self.model, self.data)
            if self.data.ncon:
                self._touched |= floor_contact_geoms(self.model, self.data, self.contact_geoms)
        # As gymnasium's MujocoEnv: force-related quantities (cacc...) are only computed on request.
        mujoco.mj_rnePostConstraint(self.model, self.data)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        self._touched = set()
        obs, reward, terminated, truncated, info = super().step(action)
        info["floor_contact"] = bool(self._touched)
        info["floor_contact_geoms"] = tuple(sorted(self._touched))
        info["head_contact"] = "head" in self._touched
        return obs, reward, terminated, truncated, info

    def _get_obs(self) -> np.ndarray:
        return super()._get_obs().astype(np.float32)


class HalfCheetahPaperReward(EpisodeRewardWrapper):
    """The paper's Half-Cheetah reward ``v_x - ctrl_cost_weight ||a||^2 - contact_cost * g(s)``.

    ``v_x`` is ``info["x_velocity"]`` (HalfCheetah-v5), ``a`` the action clipped to the action space, and ``g(s)``
    is 1 if a penalised geom touched the floor during the step: read from ``info["floor_contact"]``
    (:class:`HalfCheetahContactEnv`, every sub-step); on a plain HalfCheetah-v5 env the contacts of the last
    sub-step only are used. With ``terminate_on_head_contact`` (authors' code), a head contact ends the episode
    with reward ``head_contact_reward`` instead. ``info["paper_performance"]`` on the last step: the episode return.

    :param env: A HalfCheetah-v5 environment.
    :param ctrl_cost_weight: Weight of ``||a||^2`` (paper: 0.05).
    :param contact_cost: Penalty of a floor contact (paper: 1).
    :param terminate_on_head_contact: End the episode on head contact (authors: yes; default False).
    :param head_contact_reward: Reward of that terminal step (authors: -1000).
    :param max_episode_steps: Episode length (paper: 500).
    """

    def __init__(
        self,
        env: gym.Env,
        ctrl_cost_weight: float = 0.05,
        contact_cost: float = 1.0,
        terminate_on_head_contact: bool = False,
        head_contact_reward: float = -1000.0,
        max_episode_steps: int | None = 500,
    ) -> None:
        super().__init__(env, max_episode_steps)
        self.ctrl_cost_weight = ctrl_cost_weight
        self.contact_cost = contact_cost
        self.terminate_on_head_contact = terminate_on_head_contact
        self.head_contact_reward = head_contact_reward

    def _reward(self, action: Any, info: dict[str, Any], base_terminated: bool, last_by_time: bool) -> tuple[float, bool]:
        if "floor_contact" not in info:
            unwrapped = self.env.unwrapped
            touched = floor_contact_geoms(unwrapped.model, unwrapped.data, PENALISED_GEOMS)
            info["floor_contact"] = bool(touched)
            info["head_contact"] = "head" in touched
        if self.terminate_on_head_contact and info["head_contact"]:
            return float(self.head_contact_reward), True
        a = as_action_vector(action, self.action_space)
        reward = float(info["x_velocity"]) - self.ctrl_cost_weight * float(np.sum(a**2))
        reward -= self.contact_cost * float(info["floor_contact"])
        return reward, base_terminated


class HalfCheetahPaperEnv(PaperEnv):
    """``sb3_denfac/HalfCheetahPaper-v0``: the paper's Half-Cheetah (gamma 0.99, 500 steps).

    Observation ``Box(17,)`` float32 (HalfCheetah-v5 content), action ``Box(-1, 1, (6,))`` float32, reward of
    :class:`HalfCheetahPaperReward`, ``paper_performance`` = episode return.

    :param terminate_on_head_contact: See :class:`HalfCheetahPaperReward` (default False).
    :param head_contact_reward: See :class:`HalfCheetahPaperReward` (default -1000).
    :param ctrl_cost_weight: See :class:`HalfCheetahPaperReward` (default 0.05).
    :param contact_cost: See :class:`HalfCheetahPaperReward` (default 1).
    :param episode_length: Episode length (default: the TimeLimit of ``gym.make``, else 500), see
        :class:`~sb3_denfac.envs.common.PaperEnv`.
    :param kwargs: Passed to :class:`HalfCheetahContactEnv` (HalfCheetah-v5 arguments, ``render_mode``...).
    """

    metadata = HalfCheetahContactEnv.metadata

    def __init__(
        self,
        terminate_on_head_contact: bool = False,
        head_contact_reward: float = -1000.0,
        ctrl_cost_weight: float = 0.05,
        contact_cost: float = 1.0,
        episode_length: int | None = None,
        **kwargs: Any,
    ) -> None:
        base = HalfCheetahContactEnv(**kwargs)
        length = DEFAULT_EPISODE_LENGTH if episode_length is None else episode_length
        wrapped = HalfCheetahPaperReward(
            base, ctrl_cost_weight, contact_cost, terminate_on_head_contact, head_contact_reward, length
        )
        super().__init__(wrapped, episode_length_given=episode_length is not None)
