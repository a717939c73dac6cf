"""The RL Zoo's hyperparameter files for this package: registration, loading, checking, and a model built from an entry.

- :func:`register` adds this package's algorithms to ``rl_zoo3.ALGOS`` (the SBX pattern) and their Optuna samplers to
  ``rl_zoo3.hyperparams_opt.HYPERPARAMS_SAMPLER`` / ``HYPERPARAMS_CONVERTER``.
- :func:`load_config_file` reads a zoo YAML file; malformed YAML names the file and the line.
- :func:`select_entry` picks the entry of an env and expands its ``preset`` (:data:`PRESETS`: ``preset: paper`` starts
  a DENFAC entry from :data:`sb3_denfac.denfac.presets.PAPER`), so no constructor ever sees ``preset``.
- :func:`~.validation.validate_entry` (:mod:`.validation`) checks one entry the way the zoo will use it.
- :func:`make_model` builds the env and the model exactly as the zoo's ``ExperimentManager`` does, outside a zoo run.

rl_zoo3 makes the step from a YAML entry to constructor arguments only in two private ``ExperimentManager`` methods
(its public ``setup_experiment`` also creates log folders, writes config files and needs a file on disk).
:func:`_zoo_preprocess` is the one place that calls them, and says so if an rl_zoo3 release drops them.
"""

from __future__ import annotations

import argparse
import copy
import difflib
import importlib
import importlib.util
import os
from pathlib import Path
from typing import Any

import yaml

from sb3_denfac.envs import ALL_ENV_IDS, ENV_IDS

#: This package's algorithms, imported lazily by :func:`algorithm_class` ("zoo name" -> "module:Class").
ALGORITHMS: dict[str, str] = {
    "denfac": "sb3_denfac.denfac:DENFAC",
    "soft_denfac": "sb3_denfac.soft_denfac:SoftDENFAC",
    "ddpg": "sb3_denfac.ddpg:DDPG",
    "nfac": "sb3_denfac.nfac:NFAC",
    "cacla": "sb3_denfac.cacla:CACLA",
    "cmaes": "sb3_denfac.cmaes:CMAES",
}

_SPEC = importlib.util.find_spec("sb3_denfac.hyperparams")
# Installed (also editable): the package data of sb3_denfac.hyperparams. Run from a source tree on PYTHONPATH, with no
# install (a machine with no package index): the checkout's own hyperparams/ folder beside the package.
HYPERPARAMS_DIR = (
    Path(_SPEC.submodule_search_locations[0]) if _SPEC is not None else Path(__file__).resolve().parents[2] / "hyperparams"
)
"""The zoo YAML files: ``hyperparams/`` of the repository, installed as the package data of ``sb3_denfac.hyperparams``."""

#: Ids of the paper's environments registered by ``import sb3_denfac`` (their one list: ``sb3_denfac.envs``).
PACKAGE_ENV_IDS = ENV_IDS

#: The env a file's ``default`` entry is checked on (any continuous-action env would do; this one is the cheapest).
DEFAULT_ENTRY_ENV = "sb3_denfac/ContinuousCartPole-v0"

#: The private ExperimentManager steps :func:`_zoo_preprocess` relies on (present in rl_zoo3 2.3 to 2.9.2 at least).
ZOO_PREPROCESSING_STEPS = ("_preprocess_hyperparams", "_preprocess_action_noise")


class ZooConfigError(ValueError):
    """A hyperparameter file or command line that cannot work; raised before anything is trained."""


#: ``preset: <name>`` in a YAML entry: the constructor arguments the entry starts from; the entry's own keys override
#: them, ``policy_kwargs`` merged key by key (:func:`expand_preset`). Name -> (its algorithm, "module:attribute"); the
#: algorithm is the preset's owner (:data:`sb3_denfac.denfac.presets.OWNERS`, written here by zoo name so that reading a
#: YAML file imports no torch).
PRESETS: dict[str, tuple[str, str]] = {
    "paper": ("denfac", "sb3_denfac.denfac.presets:PAPER"),
    "data_efficient": ("soft_denfac", "sb3_denfac.denfac.presets:DATA_EFFICIENT"),
    "denfac_data_efficient": ("denfac", "sb3_denfac.denfac.presets:DENFAC_DATA_EFFICIENT"),
}


def algorithm_class(name: str) -> type:
    """The class registered under zoo name ``name`` (this package's algorithms are imported on first use)."""
    if name in ALGORITHMS:
        module_name, class_name = ALGORITHMS[name].split(":")
        return getattr(importlib.import_module(module_name), class_name)
    import rl_zoo3

    if name not in rl_zoo3.ALGOS:
        raise ZooConfigError(f"Unknown algorithm {name!r}; known: {', '.join(sorted(set(rl_zoo3.ALGOS) | set(ALGORITHMS)))}")
    return rl_zoo3.ALGOS[name]


def register() -> None:
    """Register the envs (``import sb3_denfac``), the algorithms and their Optuna samplers with the RL Zoo. Idempotent."""
    import rl_zoo3
    from rl_zoo3.hyperparams_opt import HYPERPARAMS_CONVERTER, HYPERPARAMS_SAMPLER
    from stable_baselines3 import DDPG as SB3DDPG

    import sb3_denfac  # noqa: F401  (registers the environments)
    from sb3_denfac.zoo import samplers as zoo_samplers

    rl_zoo3.ALGOS.setdefault("sb3_ddpg", SB3DDPG)
    HYPERPARAMS_SAMPLER.setdefault("sb3_ddpg", HYPERPARAMS_SAMPLER["ddpg"])
    HYPERPARAMS_CONVERTER.setdefault("sb3_ddpg", HYPERPARAMS_CONVERTER["ddpg"])
    for name in ALGORITHMS:
        rl_zoo3.ALGOS[name] = algorithm_class(name)
    HYPERPARAMS_SAMPLER.update(zoo_samplers.SAMPLERS)
    HYPERPARAMS_CONVERTER.update(zoo_samplers.CONVERTERS)


# --------------------------------------------------------------------------------------------------------------------
# Files and entries
# --------------------------------------------------------------------------------------------------------------------


def default_config_path(algo: str) -> Path:
    return HYPERPARAMS_DIR / f"{algo}.yml"


def load_config_file(path: str | os.PathLike) -> dict[str, dict[str, Any]]:
    """Read a zoo YAML file (``{env id: {key: value}}``); malformed YAML names the file and the line."""
    path = Path(path)
    if not path.is_file():
        raise ZooConfigError(f"Hyperparameter file not found: {path}")
    try:
        content = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None) or getattr(e, "context_mark", None)
        where = f"{path}, line {mark.line + 1}, column {mark.column + 1}" if mark is not None else str(path)
        problem = getattr(e, "problem", None) or str(e)
        raise ZooConfigError(f"Malformed YAML in {where}: {problem}") from e
    if content is None:
        content = {}
    if not isinstance(content, dict):
        raise ZooConfigError(f"{path}: expected a mapping from env ids to hyperparameters, got {type(content).__name__}")
    for env_id, entry in content.items():
        if not isinstance(entry, dict):
            raise ZooConfigError(f"{path}: the entry for {env_id!r} must be a mapping of hyperparameters, got {entry!r}")
    return content


#: env ids of hyperparams/ entries that an optional package registers: (its module for --gym-packages, the extra)
OPTIONAL_ENV_PACKAGES = {"PandaReach-v3": ("panda_gym", "robotics"), "PandaPush-v3": ("panda_gym", "robotics")}


def register_optional_env(env_id: str) -> None:
    """Import the package that registers ``env_id`` (:data:`OPTIONAL_ENV_PACKAGES`; the zoo's ``--gym-packages`` does
    this on the command line), or fail naming the extra that installs it. Any other id: nothing to do."""
    if env_id not in OPTIONAL_ENV_PACKAGES:
        return
    module, extra = OPTIONAL_ENV_PACKAGES[env_id]
    try:
        importlib.import_module(module)
    except ImportError as error:
        raise ZooConfigError(f"{env_id!r} is registered by {module}: pip install 'sb3-denfac[{extra}]' ({error})") from error


def check_env_id(env_id: str, where: str = "") -> None:
    """Fail with the package's env ids (and the closest registered one) if ``env_id`` is not a registered Gym id."""
    import gymnasium as gym

    known = sorted(gym.registry.keys())
    if env_id in known:
        return
    if env_id in OPTIONAL_ENV_PACKAGES:
        module, extra = OPTIONAL_ENV_PACKAGES[env_id]
        raise ZooConfigError(
            f"{env_id!r}{where} is registered by {module}: pip install 'sb3-denfac[{extra}]' and pass --gym-packages {module}"
        )
    close = difflib.get_close_matches(env_id, known, n=3, cutoff=0.6)
    hint = f" Did you mean {', '.join(close)}?" if close else ""
    raise ZooConfigError(
        f"Unknown env id {env_id!r}{where}.{hint} This package registers: {', '.join(ALL_ENV_IDS)} "
        f"(plus every Gymnasium id, e.g. Pendulum-v1; {len(known)} ids are registered)."
    )


def check_action_space_fits(algo: str, env_id: str) -> None:
    """Fail, naming the action space, if ``env_id`` has no continuous action space and ``algo`` is one of this
    package's algorithms (all six need a ``gymnasium.spaces.Box`` with finite bounds). Checked before any YAML entry
    is read, so a Discrete env is not reported as a problem of the entry. Envs that cannot be made with their default
    arguments are left to the zoo."""
    if algo not in ALGORITHMS:
        return
    import gymnasium as gym
    from gymnasium import spaces

    try:
        env = gym.make(env_id)
    except Exception:  # noqa: BLE001 - e.g. an env that needs env_kwargs: the zoo reports its own errors
        return
    try:
        space = env.action_space
    finally:
        env.close()
    import numpy as np

    if isinstance(space, spaces.Box) and np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high)):
        return
    raise ZooConfigError(
        f"{env_id} has the action space {space}, but {algo} needs a continuous action space (gymnasium.spaces.Box with "
        f"finite bounds), as all six algorithms of sb3_denfac ({', '.join(ALGORITHMS)}) do. Pick a continuous-action "
        f"env, e.g. Pendulum-v1 or one of this package's: {', '.join(ALL_ENV_IDS)}"
    )


def check_env_keys(config: dict[str, Any], path: str | os.PathLike) -> None:
    """Every key of a zoo file is a registered env id, ``default`` or ``atari`` (the zoo's fallbacks), or the id of an
    optional package's env (:data:`OPTIONAL_ENV_PACKAGES`), checked when that env is asked for."""
    for key in config:
        if key not in ("default", "atari", *OPTIONAL_ENV_PACKAGES):
            check_env_id(str(key), where=f" (a key of {path})")


def expand_preset(entry: dict[str, Any], where: str = "", algo: str | None = None) -> dict[str, Any]:
    """``entry`` with its ``preset`` (:data:`PRESETS`) expanded: the preset's arguments, overridden by the entry's own
    keys (``policy_kwargs`` and its ``net_arch`` merged key by key); an entry without ``preset`` is returned as it is
    (a copy). ``algo``, when given, must be the preset's algorithm."""
    if "preset" not in entry:
        return dict(entry)
    from sb3_denfac.denfac.presets import with_overrides

    name = entry["preset"]
    if name not in PRESETS:
        raise ZooConfigError(f"Unknown preset {name!r}{where}; presets: {', '.join(PRESETS)}")
    owner, target = PRESETS[name]
    if algo is not None and algo != owner:
        raise ZooConfigError(f"preset {name!r}{where} sets {owner}'s arguments, not {algo}'s")
    overrides = {key: value for key, value in entry.items() if key != "preset"}
    if not isinstance(overrides.get("policy_kwargs", {}), dict):
        raise ZooConfigError(
            f"With preset {name!r}{where}, write policy_kwargs as a YAML mapping (merged key by key into the preset's), "
            f"got {overrides['policy_kwargs']!r}"
        )
    module_name, attribute = target.split(":")
    return with_overrides(getattr(importlib.import_module(module_name), attribute), overrides)


def select_entry(
    config: dict[str, dict[str, Any]], env_id: str, path: str | os.PathLike = "", algo: str | None = None
) -> dict[str, Any]:
    """The hyperparameters the zoo will use for ``env_id``: its own entry, else ``default`` (Atari fallback not needed
    here), with its ``preset`` expanded (:func:`expand_preset`; ``algo``, when given, checks the preset's algorithm)."""
    for key in (env_id, "default"):
        if key in config:
            return expand_preset(config[key], f" ({path}, entry {key!r})", algo)
    raise ZooConfigError(
        f"No hyperparameters for {env_id!r} in {path} and no 'default' entry; entries: {', '.join(map(str, config))}"
    )


# --------------------------------------------------------------------------------------------------------------------
# The zoo's preprocessing, and a model built from an entry
# --------------------------------------------------------------------------------------------------------------------


def _zoo_preprocess(algo: str, env_id: str, hyperparams: dict[str, Any], seed: int, monitor_dir: Any) -> tuple:
    """``(manager, env, kwargs)`` as ``ExperimentManager.setup_experiment`` makes them from a YAML entry (schedules,
    ``normalize``, ``policy_kwargs`` strings, wrappers, ``train_freq`` lists, ``noise_type``...), without its log
    folders, config files or callbacks. ``kwargs`` are what the zoo passes to the constructor besides ``env``,
    ``seed``, ``verbose``, ``device`` and ``tensorboard_log``."""
    import rl_zoo3
    from rl_zoo3.exp_manager import ExperimentManager

    missing = [name for name in ZOO_PREPROCESSING_STEPS if not hasattr(ExperimentManager, name)]
    if missing:
        raise ZooConfigError(
            f"rl_zoo3 {rl_zoo3.__version__} has no ExperimentManager.{', '.join(missing)}, which sb3_denfac.zoo.config "
            "uses to build a model from a YAML entry; install a supported rl_zoo3 (constraints-dev.txt: 2.9.2)"
        )
    manager = ExperimentManager(argparse.Namespace(), algo, env_id, log_folder=os.devnull, seed=seed, verbose=0)
    hyperparams = copy.deepcopy(hyperparams)  # the zoo edits nested values too (normalize gets gamma)
    kwargs, manager.env_wrapper, _, manager.vec_env_wrapper = manager._preprocess_hyperparams(hyperparams)
    if monitor_dir is not None:
        manager.save_path = str(monitor_dir)
    env = manager.create_envs(manager.n_envs, no_log=monitor_dir is None)
    return manager, env, manager._preprocess_action_noise(kwargs, {}, env)


def make_model(
    algo: str,
    env_id: str,
    hyperparams: dict[str, Any],
    seed: int = 0,
    monitor_dir: str | os.PathLike | None = None,
    **model_kwargs: Any,
) -> Any:
    """Build the env and the model exactly as ``rl_zoo3``'s ExperimentManager does from a YAML entry, outside a zoo run.

    Used by the quickstart and the Figure 3 benchmark.

    :param monitor_dir: where SB3's Monitor writes ``monitor.csv`` (with the entry's ``monitor_kwargs``); None: no file.
    :param model_kwargs: extra constructor arguments (e.g. ``tensorboard_log``, ``verbose``, ``device``).
    """
    register()
    register_optional_env(env_id)
    hyperparams = {"n_timesteps": 0, "policy": "MlpPolicy", **hyperparams}  # the zoo needs both; callers budget episodes
    _, env, kwargs = _zoo_preprocess(algo, env_id, hyperparams, seed, monitor_dir)
    return algorithm_class(algo)(env=env, seed=seed, **{"verbose": 0, **kwargs, **model_kwargs})
