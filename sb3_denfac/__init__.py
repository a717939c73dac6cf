"""sb3-denfac: the data-efficient Neural Fitted Actor-Critic family (DENFAC) for Stable-Baselines3.

Importing the package registers the paper's environments with Gymnasium (ids under ``sb3_denfac/``).
"""

from sb3_denfac.envs import register_envs

register_envs()

__version__ = "0.1.0"
