"""sb3-denfac: the data-efficient Neural Fitted Actor-Critic family (DENFAC) for Stable-Baselines3.

Importing the package registers the paper's environments with Gymnasium (ids under ``sb3_denfac/``):
``sb3_denfac/ContinuousAcrobot-v0``, ``sb3_denfac/ContinuousCartPole-v0`` and ``sb3_denfac/HalfCheetahPaper-v0``.
"""

from sb3_denfac.envs import register_envs

register_envs()

from sb3_denfac.cacla import CACLA  # noqa: E402
from sb3_denfac.cmaes import CMAES  # noqa: E402
from sb3_denfac.common.callbacks import EpisodePerformanceCallback  # noqa: E402
from sb3_denfac.ddpg import DDPG  # noqa: E402
from sb3_denfac.denfac import DENFAC  # noqa: E402
from sb3_denfac.nfac import NFAC  # noqa: E402

__version__ = "0.4.0"
__all__ = ["CACLA", "CMAES", "DDPG", "DENFAC", "NFAC", "EpisodePerformanceCallback", "register_envs"]
