"""RL Zoo glue: the ``sb3-denfac-zoo`` command line (:mod:`.cli`), the YAML files and models built from their entries
(:mod:`.config`), and the Optuna samplers (:mod:`.samplers`).

The names below are this package's public interface (the benchmarks and the quickstart use ``make_model``,
``load_config_file``, ``select_entry``, ``load_hyperparams`` and ``algorithm_class``).
"""

from sb3_denfac.zoo.cli import (
    DEFAULT_ALGO,
    DEFAULT_ENV,
    DEFAULT_NUM_THREADS,
    CheckedExperimentManager,
    main,
    prepare_train_args,
)
from sb3_denfac.zoo.config import (
    ALGORITHMS,
    HYPERPARAMS_DIR,
    PACKAGE_ENV_IDS,
    PRESETS,
    ZooConfigError,
    algorithm_class,
    check_env_id,
    default_config_path,
    expand_preset,
    load_config_file,
    load_hyperparams,
    make_model,
    register,
    select_entry,
    validate_config_file,
    validate_entry,
)

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
