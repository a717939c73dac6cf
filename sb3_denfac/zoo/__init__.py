"""RL Zoo glue: the ``sb3-denfac-zoo`` command line (:mod:`.cli`), the YAML files and models built from their entries
(:mod:`.config`, checked by :mod:`.validation`), and the Optuna samplers (:mod:`.samplers`).

The names below are this package's public interface (the benchmarks and the quickstart use ``make_model``,
``load_config_file``, ``select_entry``, ``load_hyperparams`` and ``algorithm_class``).
"""

from __future__ import annotations

import importlib
from typing import Any

from sb3_denfac.zoo.usage import main

#: Public name -> the submodule that defines it, imported on first access (``sb3-denfac-zoo --help`` imports neither
#: rl_zoo3 nor Optuna nor torch).
_LAZY: dict[str, str] = {
    **dict.fromkeys(
        ["DEFAULT_ALGO", "DEFAULT_ENV", "DEFAULT_NUM_THREADS", "prepare_train_args"],
        "sb3_denfac.zoo.cli",
    ),
    **dict.fromkeys(
        [
            "ALGORITHMS",
            "HYPERPARAMS_DIR",
            "PACKAGE_ENV_IDS",
            "PRESETS",
            "ZooConfigError",
            "algorithm_class",
            "check_env_id",
            "default_config_path",
            "expand_preset",
            "load_config_file",
            "make_model",
            "register",
            "select_entry",
        ],
        "sb3_denfac.zoo.config",
    ),
    "CheckedExperimentManager": "sb3_denfac.zoo.experiment",
    **dict.fromkeys(["load_hyperparams", "validate_config_file", "validate_entry"], "sb3_denfac.zoo.validation"),
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'sb3_denfac.zoo' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})


__all__ = [
    "ALGORITHMS",
    "DEFAULT_ALGO",
    "DEFAULT_ENV",
    "DEFAULT_NUM_THREADS",
    "HYPERPARAMS_DIR",
    "PACKAGE_ENV_IDS",
    "PRESETS",
    "CheckedExperimentManager",
    "ZooConfigError",
    "algorithm_class",
    "check_env_id",
    "default_config_path",
    "expand_preset",
    "load_config_file",
    "load_hyperparams",
    "main",
    "make_model",
    "prepare_train_args",
    "register",
    "select_entry",
    "validate_config_file",
    "validate_entry",
]
