"""The DENFAC paper's environments (Zimmer, Boniface, Dutech, "Off-Policy Neural Fitted Actor-Critic", section 4).

Registered ids (all with ``Box(-1, 1)`` float32 actions and ``info["paper_performance"]`` on the last step):

- ``sb3_denfac/ContinuousAcrobot-v0``: double swing-up, 500 steps, gamma 0.9, performance = steps to the goal.
- ``sb3_denfac/ContinuousCartPole-v0``: balance in a box, 500 steps, gamma 0.99, performance = episode return.
- ``sb3_denfac/HalfCheetahPaper-v0``: HalfCheetah-v5 with the paper's reward, 500 steps, gamma 0.99,
  performance = episode return.
- ``sb3_denfac/ContinuousAcrobot75-v0``: the Acrobot with the authors' episode length, 75 decisions (their code:
  1500 ODE steps of 0.01 s, one decision per 20); the goal is reachable within it (``python -m benchmarks.acrobot_horizon``
  and its results in ``benchmarks/results/``).

Each registered env is a reward wrapper (reusable on other envs with the same state) around a continuous-action
base env, packed into one ``gymnasium.Env``.
"""

from __future__ import annotations

from typing import Any

import gymnasium
from gymnasium.envs.registration import WrapperSpec

from sb3_denfac.envs.acrobot import (
    AcrobotSwingUpReward,
    ContinuousAcrobotEnv,
    ContinuousAcrobotPaperEnv,
    acrobot_tip_height,
)
from sb3_denfac.envs.cartpole import CartPoleBalanceReward, ContinuousCartPoleEnv, ContinuousCartPolePaperEnv
from sb3_denfac.envs.common import (
    DEFAULT_EPISODE_LENGTH,
    PAPER_PERFORMANCE_KEY,
    EpisodeLengthFromTimeLimit,
    EpisodeRewardWrapper,
    PaperEnv,
)
from sb3_denfac.envs.facts import ENV_FACTS, EnvFacts, env_facts

ENV_IDS = (
    "sb3_denfac/ContinuousAcrobot-v0",
    "sb3_denfac/ContinuousCartPole-v0",
    "sb3_denfac/HalfCheetahPaper-v0",
)
_ENTRY_POINTS = (
    "sb3_denfac.envs.acrobot:ContinuousAcrobotPaperEnv",
    "sb3_denfac.envs.cartpole:ContinuousCartPolePaperEnv",
    "sb3_denfac.envs.half_cheetah:HalfCheetahPaperEnv",
)

#: Added by gym.make outside the TimeLimit: the env takes max_episode_steps as its episode length.
_EPISODE_LENGTH_WRAPPER = WrapperSpec(
    name="EpisodeLengthFromTimeLimit", entry_point="sb3_denfac.envs.common:EpisodeLengthFromTimeLimit", kwargs={}
)

_HALF_CHEETAH_NAMES = (
    "HalfCheetahContactEnv",
    "HalfCheetahPaperEnv",
    "HalfCheetahPaperReward",
    "PENALISED_GEOMS",
    "floor_contact_geoms",
)


def __getattr__(name: str) -> Any:
    # Lazy: importing MuJoCo is only needed for the Half-Cheetah.
    if name in _HALF_CHEETAH_NAMES:
        from sb3_denfac.envs import half_cheetah

        return getattr(half_cheetah, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: Variants of the paper's envs: id -> (entry point, constructor kwargs, episode length).
ENV_VARIANTS = {
    "sb3_denfac/ContinuousAcrobot75-v0": (_ENTRY_POINTS[0], {"episode_length": 75}, 75),
}

#: Every id that :func:`register_envs` registers: the paper's envs and their variants (the list error messages show).
ALL_ENV_IDS = (*ENV_IDS, *ENV_VARIANTS)


def register_envs() -> None:
    """Register the paper's environments and their variants with Gymnasium (idempotent)."""
    for env_id, entry_point in zip(ENV_IDS, _ENTRY_POINTS, strict=True):
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point=entry_point,
                max_episode_steps=DEFAULT_EPISODE_LENGTH,
                additional_wrappers=(_EPISODE_LENGTH_WRAPPER,),
            )
    for env_id, (entry_point, kwargs, length) in ENV_VARIANTS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point=entry_point,
                max_episode_steps=length,
                kwargs=kwargs,
                additional_wrappers=(_EPISODE_LENGTH_WRAPPER,),
            )


__all__ = [
    "ALL_ENV_IDS",
    "ENV_FACTS",
    "ENV_IDS",
    "ENV_VARIANTS",
    "PAPER_PERFORMANCE_KEY",
    "AcrobotSwingUpReward",
    "ContinuousAcrobotEnv",
    "ContinuousAcrobotPaperEnv",
    "CartPoleBalanceReward",
    "ContinuousCartPoleEnv",
    "ContinuousCartPolePaperEnv",
    "EnvFacts",
    "EpisodeLengthFromTimeLimit",
    "EpisodeRewardWrapper",
    "HalfCheetahContactEnv",
    "HalfCheetahPaperEnv",
    "HalfCheetahPaperReward",
    "PENALISED_GEOMS",
    "PaperEnv",
    "acrobot_tip_height",
    "env_facts",
    "floor_contact_geoms",
    "register_envs",
]
