"""Checks of the RL Zoo's hyperparameter entries for this package, the way the zoo will use them.

:func:`validate_entry` lets the zoo's own preprocessing turn the entry into constructor arguments (so whatever the zoo
consumes itself, ``n_timesteps``, ``normalize``, ``noise_type``..., needs no list here); the arguments left must be the
constructor's (an unknown one is named with the closest valid name), and the constructor itself checks their values
(:mod:`sb3_denfac.common.checks`), without building networks. Two YAML pitfalls that no constructor can explain are
caught before: a float written ``1e-3`` (a string in YAML) and a quoted flag (``'yes'``). :func:`validate_config_file`
checks every entry of a file, :func:`load_hyperparams` reads and checks one.
"""

from __future__ import annotations

import difflib
import inspect
import os
from pathlib import Path
from typing import Any

from sb3_denfac.zoo.config import (
    DEFAULT_ENTRY_ENV,
    OPTIONAL_ENV_PACKAGES,
    ZooConfigError,
    _zoo_preprocess,
    algorithm_class,
    check_action_space_fits,
    check_env_keys,
    default_config_path,
    expand_preset,
    load_config_file,
    register,
    select_entry,
)


def _looks_like_float(value: Any) -> bool:
    try:
        float(value)
    except (TypeError, ValueError):
        return False
    return isinstance(value, str)


def _check_yaml_pitfalls(algo: str, params: dict[str, inspect.Parameter], entry: dict[str, Any], where: str) -> None:
    """Values YAML reads otherwise than they look, before the zoo or a constructor gives a puzzling message."""
    for key, value in entry.items():
        if _looks_like_float(value):
            raise ZooConfigError(
                f"{key!r} of algorithm {algo!r}{where} is the string {value!r}: YAML reads a float without a dot as a "
                f"string; write it with a dot (0.001) or as !!float {value}."
            )
        if key in params and isinstance(params[key].default, bool) and not isinstance(value, bool):
            raise ZooConfigError(
                f"{key!r} of algorithm {algo!r}{where} is a flag: write true or false (a YAML bool), got {value!r}"
            )


def _check_policy_kwargs(algo: str, cls: type, policy: Any, policy_kwargs: Any, where: str) -> None:
    """Unknown ``policy_kwargs`` keys, named against the policy class's signature (the networks are not built here)."""
    policy_cls = cls.policy_aliases.get(policy) if isinstance(policy, str) else policy
    if not isinstance(policy_cls, type) or not isinstance(policy_kwargs, dict):
        return
    params = inspect.signature(policy_cls.__init__).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    for key in policy_kwargs:
        if key not in params:
            valid = sorted(set(params) - {"self", "observation_space", "action_space", "lr_schedule"})
            raise ZooConfigError(
                f"Unknown policy_kwargs key {key!r} for {algo!r} ({policy_cls.__name__}){where}. Valid: {', '.join(valid)}."
            )


#: The constructor arguments besides ``env`` that the zoo passes itself (ExperimentManager.setup_experiment), as given
#: to the constructor by :func:`validate_entry`: an entry repeating one fails there as it would in the zoo.
_SET_BY_THE_ZOO = {"tensorboard_log": None, "seed": 0, "verbose": 0, "device": "cpu"}


def validate_entry(algo: str, entry: dict[str, Any], source: str = "", env_id: str = DEFAULT_ENTRY_ENV) -> None:
    """Check one YAML entry (after ``-params`` overrides) as the zoo will use it for ``env_id``; see the module doc."""
    cls = algorithm_class(algo)
    where = f" ({source})" if source else ""
    params = {name: p for name, p in inspect.signature(cls.__init__).parameters.items() if name not in ("self", "env")}
    for key, example in (("n_timesteps", "the zoo's training budget in env steps"), ("policy", "e.g. policy: 'MlpPolicy'")):
        if key not in entry:
            raise ZooConfigError(f"{algo}{where}: missing {key!r} ({example})")
    policy = entry["policy"]
    if isinstance(policy, str) and "." not in policy and policy not in cls.policy_aliases:
        raise ZooConfigError(
            f"Unknown policy {policy!r} for algorithm {algo!r}{where}; available: {', '.join(cls.policy_aliases)} "
            "(or a full class path such as my_package.MyPolicy)"
        )
    _check_yaml_pitfalls(algo, params, entry, where)
    register()
    try:
        manager, env, kwargs = _zoo_preprocess(algo, env_id, entry, seed=0, monitor_dir=None)
    except ZooConfigError:
        raise
    except Exception as e:  # the zoo's own messages (bad schedule, wrapper or callback path, eval'd string...)
        raise ZooConfigError(f"{algo}{where}: the zoo cannot read this entry: {type(e).__name__}: {e}") from e
    try:
        if manager.n_timesteps <= 0:
            raise ZooConfigError(f"{algo}{where}: n_timesteps must be a positive number, got {entry['n_timesteps']!r}")
        keywords = manager.monitor_kwargs.get("info_keywords", ())
        if not isinstance(keywords, tuple):
            raise ZooConfigError(
                f"{algo}{where}: monitor_kwargs info_keywords must be a tuple (SB3's Monitor concatenates tuples), got "
                f"{keywords!r}; YAML has no tuples: write monitor_kwargs: \"dict(info_keywords=('paper_performance',))\""
            )
        if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
            for key in kwargs:
                if key not in params:
                    close = difflib.get_close_matches(key, list(params), n=1)
                    hint = f" Did you mean {close[0]!r}?" if close else ""
                    valid = sorted(set(params) - {*_SET_BY_THE_ZOO, "_init_setup_model"})
                    raise ZooConfigError(
                        f"Unknown hyperparameter {key!r} for algorithm {algo!r} ({cls.__name__}){where}.{hint} "
                        f"Valid: {', '.join(valid)}, plus the keys the zoo reads itself (n_timesteps, normalize, "
                        "n_envs, env_kwargs, ...: see rl_zoo3's documentation)."
                    )
        _check_policy_kwargs(algo, cls, kwargs["policy"], kwargs.get("policy_kwargs"), where)
        try:  # the constructor checks the values (no networks built)
            cls(env=env, **_SET_BY_THE_ZOO, _init_setup_model=False, **kwargs)
        except (TypeError, ValueError, AssertionError) as e:
            hint = f" (the zoo sets {', '.join(_SET_BY_THE_ZOO)} from its command line)" if isinstance(e, TypeError) else ""
            raise ZooConfigError(f"{algo}{where}: {cls.__name__} refuses this entry: {e}{hint}") from e
    finally:
        env.close()


def validate_config_file(path: str | os.PathLike, algo: str, check_env_ids: bool = True) -> dict[str, dict[str, Any]]:
    """Load ``path`` and validate every entry for ``algo`` (env ids must be registered unless ``check_env_ids`` is False)."""
    config = load_config_file(path)
    if check_env_ids:
        check_env_keys(config, path)
    import gymnasium as gym

    for env_id, entry in config.items():
        if env_id in OPTIONAL_ENV_PACKAGES and env_id not in gym.registry:
            continue  # its package is not installed: checked when it is and the env is asked for
        target = str(env_id) if env_id not in ("default", "atari") else DEFAULT_ENTRY_ENV
        source = f"{path}, entry {env_id!r}"
        validate_entry(algo, expand_preset(entry, f" ({source})", algo), source=source, env_id=target)
    return config


def load_hyperparams(algo: str, env_id: str, conf_file: str | os.PathLike | None = None) -> dict[str, Any]:
    """The validated YAML entry the zoo would use for (``algo``, ``env_id``), from this package's file by default."""
    path = Path(conf_file) if conf_file is not None else default_config_path(algo)
    check_action_space_fits(algo, env_id)
    config = load_config_file(path)
    entry = select_entry(config, env_id, path, algo)
    validate_entry(algo, entry, source=f"{path}, entry {env_id if env_id in config else 'default'!r}", env_id=env_id)
    return entry
