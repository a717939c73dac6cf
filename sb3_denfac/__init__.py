"""sb3-denfac: the data-efficient Neural Fitted Actor-Critic family (DENFAC) for Stable-Baselines3.

Importing the package registers the paper's environments with Gymnasium (ids under ``sb3_denfac/``):
``sb3_denfac/ContinuousAcrobot-v0``, ``sb3_denfac/ContinuousCartPole-v0`` and ``sb3_denfac/HalfCheetahPaper-v0``
(and their variants: ``sb3_denfac.envs.ALL_ENV_IDS``).

The algorithms are imported on first use (``from sb3_denfac import DENFAC`` imports DENFAC's modules, torch and SB3;
CMA-ES's ``cma``, which pulls in scipy.stats and matplotlib, only when CMA-ES is used), so ``import sb3_denfac`` and the
``sb3-denfac-zoo --help`` command stay fast.
"""

from __future__ import annotations

import importlib
from typing import Any

from sb3_denfac.envs import register_envs

register_envs()

__version__ = "0.5.0"  # the one place of the version (pyproject.toml reads it)

#: Public name -> the module that defines it (imported on first access, :func:`__getattr__`).
_LAZY: dict[str, str] = {
    "CACLA": "sb3_denfac.cacla",
    "CMAES": "sb3_denfac.cmaes",
    "DDPG": "sb3_denfac.ddpg",
    "DENFAC": "sb3_denfac.denfac",
    "NFAC": "sb3_denfac.nfac",
    "SoftDENFAC": "sb3_denfac.soft_denfac",
    "EpisodePerformanceCallback": "sb3_denfac.common.callbacks",
    "UpdateStatsCallback": "sb3_denfac.common.callbacks",
}
#: Public modules imported on first access: ``from sb3_denfac import presets`` (PAPER, DATA_EFFICIENT...).
_LAZY_MODULES: dict[str, str] = {"presets": "sb3_denfac.denfac.presets"}

__all__ = [
    "CACLA",
    "CMAES",
    "DDPG",
    "DENFAC",
    "NFAC",
    "SoftDENFAC",
    "EpisodePerformanceCallback",
    "UpdateStatsCallback",
    "presets",
    "register_envs",
]


def __getattr__(name: str) -> Any:
    if name in _LAZY or name in _LAZY_MODULES:
        module = importlib.import_module(_LAZY.get(name) or _LAZY_MODULES[name])
        value = module if name in _LAZY_MODULES else getattr(module, name)
        globals()[name] = value  # later accesses skip this function
        return value
    raise AttributeError(f"module 'sb3_denfac' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY, *_LAZY_MODULES})
