"""RL Zoo 3 integration: train, tune, enjoy and record this package's algorithms with the zoo's own scripts.

Usage (``sb3-denfac-zoo`` is the same as ``python -m sb3_denfac.zoo``)::

    python -m sb3_denfac.zoo train --algo denfac --env sb3_denfac/ContinuousCartPole-v0 -tb runs/
    python -m sb3_denfac.zoo train --algo denfac --env sb3_denfac/ContinuousCartPole-v0 -optimize --n-trials 20
    python -m sb3_denfac.zoo enjoy --algo denfac --env sb3_denfac/ContinuousCartPole-v0 -f logs/
    python -m sb3_denfac.zoo record_video --algo denfac --env sb3_denfac/ContinuousCartPole-v0 -f logs/

Nothing of the zoo is rebuilt: :func:`register` adds this package's algorithms to ``rl_zoo3.ALGOS`` (the SBX pattern)
and their Optuna samplers to ``rl_zoo3.hyperparams_opt.HYPERPARAMS_SAMPLER`` / ``HYPERPARAMS_CONVERTER``, then the
command is handed to ``rl_zoo3.train.train``, ``rl_zoo3.enjoy.enjoy`` or the ``rl_zoo3.record_video`` script with the
same command line. Before training, :func:`main` adds what the zoo cannot guess and checks the configuration:

- ``--conf-file`` defaults to this package's ``hyperparams/<algo>.yml`` (for td3/sac/crossq only when that
  file has an entry for the env; otherwise the zoo's own file is used);
- with ``-optimize`` and no ``--storage``, the study is kept in ``sqlite:///<log-folder>/optuna.db`` under the study
  name ``<algo>-<env>`` (``--study-name`` overrides it), so a killed or repeated run resumes the same study;
- the selected YAML entry (after ``-params`` overrides) is validated against the algorithm's constructor, so a typo
  fails with a clear :class:`ZooConfigError` before any environment is built.

``ddpg`` means :class:`sb3_denfac.ddpg.DDPG` (SB3's DDPG with inverting gradients, batch norm and truncated-Gaussian
exploration); SB3's original stays available as ``sb3_ddpg``. SB3's TD3/SAC and sb3-contrib's CrossQ keep their zoo names.
"""

from __future__ import annotations

import argparse
import difflib
import importlib
import importlib.util
import inspect
import os
import runpy
import sys
import types
import typing
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import yaml

from sb3_denfac.envs import ENV_IDS

#: This package's algorithms, imported lazily by :func:`algorithm_class` ("zoo name" -> "module:Class").
ALGORITHMS: dict[str, str] = {
    "denfac": "sb3_denfac.denfac:DENFAC",
    "ddpg": "sb3_denfac.ddpg:DDPG",
    "nfac": "sb3_denfac.nfac:NFAC",
    "cacla": "sb3_denfac.cacla:CACLA",
    "cmaes": "sb3_denfac.cmaes:CMAES",
}

#: Folder of the YAML hyperparameter files (shipped as package data).

HYPERPARAMS_DIR = Path(importlib.util.find_spec("sb3_denfac.hyperparams").submodule_search_locations[0])
"""The zoo YAML files: ``hyperparams/`` of the repository, installed as the package data of ``sb3_denfac.hyperparams``."""

#: Ids of the paper's environments registered by ``import sb3_denfac`` (their one list: ``sb3_denfac.envs``).
PACKAGE_ENV_IDS = ENV_IDS

#: YAML keys that the zoo consumes itself (rl_zoo3.exp_manager) instead of passing them to the algorithm.
ZOO_KEYS = frozenset(
    {
        "n_timesteps",
        "normalize",
        "n_envs",
        "env_wrapper",
        "vec_env_wrapper",
        "frame_stack",
        "callback",
        "env_kwargs",
        "monitor_kwargs",
        "noise_type",
        "noise_std",
    }
)
#: Constructor arguments the zoo sets from its command line: a YAML entry must not repeat them.
ZOO_CLI_ARGS = {
    "env": "--env",
    "tensorboard_log": "--tensorboard-log",
    "seed": "--seed",
    "verbose": "--verbose",
    "device": "--device",
}
#: Keys whose string values the zoo evaluates as Python (rl_zoo3.exp_manager._preprocess_hyperparams).
EVAL_KEYS = frozenset({"policy_kwargs", "replay_buffer_class", "replay_buffer_kwargs", "normalize", "monitor_kwargs"})
#: Keys for which the zoo turns "lin_<float>" strings into linear schedules.
SCHEDULE_KEYS = frozenset({"learning_rate", "clip_range", "clip_range_vf", "delta_std"})


class ZooConfigError(ValueError):
    """A hyperparameter file or command line that cannot work; raised before anything is trained."""


# --------------------------------------------------------------------------------------------------------------------
# Registration
# --------------------------------------------------------------------------------------------------------------------


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
    from sb3_denfac import zoo_samplers

    rl_zoo3.ALGOS.setdefault("sb3_ddpg", SB3DDPG)
    HYPERPARAMS_SAMPLER.setdefault("sb3_ddpg", HYPERPARAMS_SAMPLER["ddpg"])
    HYPERPARAMS_CONVERTER.setdefault("sb3_ddpg", HYPERPARAMS_CONVERTER["ddpg"])
    for name in ALGORITHMS:
        rl_zoo3.ALGOS[name] = algorithm_class(name)
    HYPERPARAMS_SAMPLER.update(zoo_samplers.SAMPLERS)
    HYPERPARAMS_CONVERTER.update(zoo_samplers.CONVERTERS)


# --------------------------------------------------------------------------------------------------------------------
# Hyperparameter files: loading and validation
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


def _known_env_ids() -> list[str]:
    import gymnasium as gym

    return sorted(gym.registry.keys())


def check_env_id(env_id: str, where: str = "") -> None:
    """Fail with the package's env ids (and the closest registered one) if ``env_id`` is not a registered Gym id."""
    known = _known_env_ids()
    if env_id in known:
        return
    close = difflib.get_close_matches(env_id, known, n=3, cutoff=0.6)
    hint = f" Did you mean {', '.join(close)}?" if close else ""
    raise ZooConfigError(
        f"Unknown env id {env_id!r}{where}.{hint} This package registers: {', '.join(PACKAGE_ENV_IDS)} "
        f"(plus every Gymnasium id, e.g. Pendulum-v1; {len(known)} ids are registered)."
    )


def select_entry(config: dict[str, dict[str, Any]], env_id: str, path: str | os.PathLike = "") -> dict[str, Any]:
    """The entry the zoo will use for ``env_id``: its own key, else ``default`` (Atari fallback not needed here)."""
    if env_id in config:
        return dict(config[env_id])
    if "default" in config:
        return dict(config["default"])
    raise ZooConfigError(
        f"No hyperparameters for {env_id!r} in {path} and no 'default' entry; entries: {', '.join(map(str, config))}"
    )


def _resolve_annotation(annotation: Any, module_globals: dict[str, Any]) -> Any:
    if isinstance(annotation, str):
        try:
            return eval(annotation, module_globals)
        except Exception:
            return inspect.Parameter.empty
    return annotation


def _matches(value: Any, hint: Any) -> bool:
    """Whether a YAML value can be passed for a parameter annotated ``hint``; unknown hints accept anything."""
    if hint is inspect.Parameter.empty or hint is Any or isinstance(hint, (str, typing.ForwardRef, typing.TypeVar)):
        return True
    origin = typing.get_origin(hint)
    if origin is typing.Union or (hasattr(types, "UnionType") and origin is types.UnionType):
        return any(_matches(value, arg) for arg in typing.get_args(hint))
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is str:
        return isinstance(value, str)
    if origin in (tuple, list, typing.Sequence, Sequence) or hint in (tuple, list):
        return isinstance(value, (list, tuple))
    if origin is dict or hint is dict:
        return isinstance(value, dict)
    if origin is typing.Literal:
        return value in typing.get_args(hint)
    if origin is type or origin is Callable or hint is Callable:  # a float-like string is YAML's 1e-3, not a schedule
        return not isinstance(value, (bool, int, float)) and not (isinstance(value, str) and _looks_like_float(value))
    if isinstance(hint, type):
        # Objects (policies, noise, buffers, schedules): the zoo may build them from strings (class paths, eval).
        return isinstance(value, (hint, str)) if hint.__module__ != "builtins" else isinstance(value, hint)
    return True


def _describe(hint: Any) -> str:
    if isinstance(hint, type):
        return hint.__name__
    return str(hint).replace("typing.", "")


def validate_entry(algo: str, entry: dict[str, Any], source: str = "") -> None:
    """Check one YAML entry (after ``-params`` overrides) against ``algo``'s constructor and the zoo's own keys."""
    cls = algorithm_class(algo)
    where = f" ({source})" if source else ""
    signature = inspect.signature(cls.__init__)
    params = {name: p for name, p in signature.parameters.items() if name != "self"}
    accepts_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    module_globals = vars(sys.modules[cls.__init__.__module__])

    if "n_timesteps" not in entry:
        raise ZooConfigError(f"{algo}{where}: missing 'n_timesteps' (the zoo's training budget in env steps)")
    if "policy" not in entry:
        raise ZooConfigError(f"{algo}{where}: missing 'policy' (e.g. policy: 'MlpPolicy')")
    policy = entry["policy"]
    if isinstance(policy, str) and "." not in policy and policy not in cls.policy_aliases:
        raise ZooConfigError(
            f"Unknown policy {policy!r} for algorithm {algo!r}{where}; available: {', '.join(cls.policy_aliases)} "
            "(or a full class path such as my_package.MyPolicy)"
        )
    for key, value in entry.items():
        if key in ZOO_CLI_ARGS:
            raise ZooConfigError(f"{algo}{where}: {key!r} is set on the command line ({ZOO_CLI_ARGS[key]}), not in the YAML")
        if key in ZOO_KEYS:
            if key == "n_timesteps" and (isinstance(value, bool) or not isinstance(value, (int, float)) or value <= 0):
                raise ZooConfigError(f"{algo}{where}: n_timesteps must be a positive number, got {value!r}")
            if key == "n_envs" and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                raise ZooConfigError(f"{algo}{where}: n_envs must be a positive integer, got {value!r}")
            if key == "monitor_kwargs":
                _validate_monitor_kwargs(algo, value, where)
            continue
        if key not in params and not accepts_any:
            close = difflib.get_close_matches(key, [*params, *ZOO_KEYS], n=1)
            hint = f" Did you mean {close[0]!r}?" if close else ""
            raise ZooConfigError(
                f"Unknown hyperparameter {key!r} for algorithm {algo!r} ({cls.__name__}){where}.{hint} "
                f"Valid: {', '.join(sorted(set(params) - set(ZOO_CLI_ARGS)))} and the zoo keys {', '.join(sorted(ZOO_KEYS))}."
            )
        if key not in params:
            continue
        if key in EVAL_KEYS and isinstance(value, str):
            value = _eval_like_zoo(algo, key, value, where)
        if key in SCHEDULE_KEYS and isinstance(value, str) and value.startswith("lin_"):
            try:
                float(value[4:])
                continue
            except ValueError as e:
                raise ZooConfigError(f"{algo}{where}: {key}: bad linear schedule {value!r} (write lin_0.001)") from e
        hint = _resolve_annotation(params[key].annotation, module_globals)
        if not _matches(value, hint):
            tip = ""
            if isinstance(value, str) and _looks_like_float(value):
                tip = f" YAML reads {value!r} as a string: write it with a dot (0.001) or as !!float {value}."
            raise ZooConfigError(
                f"Wrong type for {key!r} of algorithm {algo!r}{where}: got {value!r} ({type(value).__name__}), "
                f"expected {_describe(hint)}.{tip}"
            )
        if key == "policy_kwargs" and isinstance(value, dict):
            _validate_policy_kwargs(algo, cls, entry.get("policy", "MlpPolicy"), value, where)


def _looks_like_float(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _eval_like_zoo(algo: str, key: str, value: str, where: str) -> Any:
    """Evaluate a string the way rl_zoo3.exp_manager does (same globals), so errors show up now."""
    import rl_zoo3.exp_manager

    try:
        return eval(value, vars(rl_zoo3.exp_manager).copy())
    except Exception as e:
        raise ZooConfigError(
            f"{algo}{where}: cannot evaluate {key}: {value!r} ({type(e).__name__}: {e}). Prefer plain YAML mappings."
        ) from e


def _validate_monitor_kwargs(algo: str, value: Any, where: str) -> None:
    monitor_kwargs = _eval_like_zoo(algo, "monitor_kwargs", value, where) if isinstance(value, str) else value
    if not isinstance(monitor_kwargs, dict):
        raise ZooConfigError(f"{algo}{where}: monitor_kwargs must be a mapping, got {value!r}")
    keywords = monitor_kwargs.get("info_keywords", ())
    if not isinstance(keywords, tuple):
        raise ZooConfigError(
            f"{algo}{where}: monitor_kwargs info_keywords must be a tuple (SB3's Monitor concatenates tuples), got "
            f"{keywords!r}; YAML has no tuples: write monitor_kwargs: \"dict(info_keywords=('paper_performance',))\""
        )


def _validate_policy_kwargs(algo: str, cls: type, policy: Any, policy_kwargs: dict[str, Any], where: str) -> None:
    policy_cls = cls.policy_aliases.get(policy) if isinstance(policy, str) else policy
    if not isinstance(policy_cls, type):
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


def validate_config_file(path: str | os.PathLike, algo: str, check_env_ids: bool = True) -> dict[str, dict[str, Any]]:
    """Load ``path`` and validate every entry for ``algo`` (env ids must be registered unless ``check_env_ids`` is False)."""
    config = load_config_file(path)
    for env_id, entry in config.items():
        if check_env_ids and env_id not in ("default", "atari"):
            check_env_id(str(env_id), where=f" (a key of {path})")
        validate_entry(algo, entry, source=f"{path}, entry {env_id!r}")
    return config


def load_hyperparams(algo: str, env_id: str, conf_file: str | os.PathLike | None = None) -> dict[str, Any]:
    """The validated YAML entry the zoo would use for (``algo``, ``env_id``), from this package's file by default."""
    path = Path(conf_file) if conf_file is not None else default_config_path(algo)
    entry = select_entry(load_config_file(path), env_id, path)
    validate_entry(algo, entry, source=f"{path}, entry {env_id!r}")
    return entry


def make_model(
    algo: str,
    env_id: str,
    hyperparams: dict[str, Any],
    seed: int = 0,
    monitor_dir: str | os.PathLike | None = None,
    **model_kwargs: Any,
) -> Any:
    """Build the env and the model exactly as ``rl_zoo3``'s ExperimentManager does from a YAML entry, outside a zoo run.

    The zoo's own preprocessing is reused (schedules, ``normalize``, ``policy_kwargs``, ``env_wrapper``, ``train_freq``
    lists, ``noise_type``), without its log folders or callbacks. Used by the quickstart and the Figure 3 benchmark.

    :param monitor_dir: where SB3's Monitor writes ``monitor.csv`` (with the entry's ``monitor_kwargs``); None: no file.
    :param model_kwargs: extra constructor arguments (e.g. ``tensorboard_log``, ``verbose``, ``device``).
    """
    from rl_zoo3.exp_manager import ExperimentManager

    register()
    hyperparams = dict(hyperparams)
    hyperparams.setdefault("n_timesteps", 0)  # required by the zoo; callers budget in episodes
    hyperparams.setdefault("policy", "MlpPolicy")
    manager = ExperimentManager(argparse.Namespace(), algo, env_id, log_folder=os.devnull, seed=seed, verbose=0)
    kwargs, manager.env_wrapper, _, manager.vec_env_wrapper = manager._preprocess_hyperparams(hyperparams)
    if monitor_dir is not None:
        manager.save_path = str(monitor_dir)
    env = manager.create_envs(manager.n_envs, no_log=monitor_dir is None)
    kwargs = manager._preprocess_action_noise(kwargs, {}, env)
    return algorithm_class(algo)(env=env, seed=seed, **{"verbose": 0, **kwargs, **model_kwargs})


# --------------------------------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------------------------------

DEFAULT_ALGO = "denfac"
DEFAULT_ENV = "sb3_denfac/ContinuousCartPole-v0"


def _pre_parser() -> argparse.ArgumentParser:
    """The few zoo train options this module needs to see; everything else goes to the zoo untouched."""
    from rl_zoo3.utils import StoreDict

    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--algo", default=None)
    parser.add_argument("--env", default=None)
    parser.add_argument("-conf", "--conf-file", default=None)
    parser.add_argument("-params", "--hyperparams", nargs="+", action=StoreDict, default=None)
    parser.add_argument("-optimize", "--optimize-hyperparameters", action="store_true", default=False)
    parser.add_argument("--storage", default=None)
    parser.add_argument("--study-name", default=None)
    parser.add_argument("-f", "--log-folder", default="logs")
    parser.add_argument("--gym-packages", nargs="+", default=[])
    parser.add_argument("-i", "--trained-agent", default="")
    return parser


#: torch threads of ``sb3-denfac-zoo train``/``enjoy`` unless ``--num-threads`` is given: the paper's networks are
#: tiny, and several threads on a loaded machine made DENFAC's updates many times slower (benchmarks/results/).
DEFAULT_NUM_THREADS = 1


def with_default_threads(argv: Sequence[str]) -> list[str]:
    """``argv`` with ``--num-threads DEFAULT_NUM_THREADS`` added unless it sets ``--num-threads`` itself."""
    argv = list(argv)
    if any(a == "--num-threads" or a.startswith("--num-threads=") for a in argv):
        return argv
    return [*argv, "--num-threads", str(DEFAULT_NUM_THREADS)]


def prepare_train_args(argv: Sequence[str]) -> list[str]:
    """Complete and check a ``train`` command line; returns the arguments to give to ``rl_zoo3.train.train``."""
    argv = list(argv)
    if any(a in ("-h", "--help") for a in argv):
        return argv
    argv = with_default_threads(argv)
    args, _ = _pre_parser().parse_known_args(argv)
    for module in args.gym_packages:
        importlib.import_module(module)
    algo = args.algo or DEFAULT_ALGO
    env_id = args.env or DEFAULT_ENV
    if args.algo is None:
        argv += ["--algo", algo]
    if args.env is None:
        argv += ["--env", env_id]
    import rl_zoo3

    if algo not in rl_zoo3.ALGOS:
        raise ZooConfigError(f"Unknown algorithm {algo!r}; known: {', '.join(sorted(rl_zoo3.ALGOS))}")
    check_env_id(env_id)

    conf = args.conf_file
    if conf is None:
        ours = default_config_path(algo)
        if algo in ALGORITHMS and not ours.is_file():
            raise ZooConfigError(f"No hyperparameter file for {algo!r}: expected {ours}; pass --conf-file")
        if ours.is_file() and (algo in ALGORITHMS or env_id in load_config_file(ours)):
            conf = str(ours)
            argv += ["--conf-file", conf]
    if conf is not None and conf.endswith((".yml", ".yaml")):
        config = load_config_file(conf)
        for key in config:
            if key not in ("default", "atari"):
                check_env_id(str(key), where=f" (a key of {conf})")
        entry = select_entry(config, env_id, conf)
        if args.hyperparams:
            entry.update(args.hyperparams)
        validate_entry(algo, entry, source=f"{conf}, entry {env_id if env_id in config else 'default'!r}")
        policy_kwargs = entry.get("policy_kwargs", {})
        if isinstance(policy_kwargs, str):
            policy_kwargs = _eval_like_zoo(algo, "policy_kwargs", policy_kwargs, "")
        from sb3_denfac.zoo_samplers import SAMPLER_CONTEXT

        SAMPLER_CONTEXT["policy_kwargs"] = dict(policy_kwargs or {})

    if args.optimize_hyperparameters:
        from rl_zoo3.hyperparams_opt import HYPERPARAMS_SAMPLER

        if algo not in HYPERPARAMS_SAMPLER:
            raise ZooConfigError(f"No Optuna sampler for {algo!r}; tunable: {', '.join(sorted(HYPERPARAMS_SAMPLER))}")
        if args.storage is None:
            Path(args.log_folder).mkdir(parents=True, exist_ok=True)
            argv += ["--storage", f"sqlite:///{Path(args.log_folder).resolve() / 'optuna.db'}"]
        if args.study_name is None:
            argv += ["--study-name", f"{algo}-{env_id.replace('/', '-')}"]
    return argv


def _run_with_argv(prog: str, argv: Sequence[str], func: Callable[[], Any]) -> Any:
    saved = sys.argv
    sys.argv = [prog, *argv]
    try:
        return func()
    finally:
        sys.argv = saved


def train(argv: Sequence[str]) -> None:
    """``rl_zoo3.train.train`` on a checked command line (see :func:`prepare_train_args`)."""
    from rl_zoo3.train import train as zoo_train

    _run_with_argv("sb3-denfac-zoo train", prepare_train_args(argv), zoo_train)


def enjoy(argv: Sequence[str]) -> None:
    from rl_zoo3.enjoy import enjoy as zoo_enjoy

    _run_with_argv("sb3-denfac-zoo enjoy", with_default_threads(argv), zoo_enjoy)


def record_video(argv: Sequence[str]) -> None:
    """``rl_zoo3.record_video``, headless: the envs render to ``rgb_array`` (pygame, no display) and moviepy writes the
    mp4; both come with the ``video`` extra. Without a display, MuJoCo (Half-Cheetah) renders with EGL unless
    ``MUJOCO_GL`` says otherwise."""
    missing = [name for name in ("pygame", "moviepy") if importlib.util.find_spec(name) is None]
    if missing and not any(a in ("-h", "--help") for a in argv):
        raise ZooConfigError(
            f"record_video needs {' and '.join(missing)} (rendering and mp4 writing): pip install 'sb3-denfac[video]'"
        )
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # pygame without a display
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("MUJOCO_GL", "egl")  # Half-Cheetah: MuJoCo's headless OpenGL
    # rl_zoo3.record_video is a script (its code runs under `if __name__ == "__main__"`).
    _run_with_argv("sb3-denfac-zoo record_video", argv, lambda: runpy.run_module("rl_zoo3.record_video", run_name="__main__"))


COMMANDS: dict[str, Callable[[Sequence[str]], None]] = {
    "train": train,
    "optimize": lambda argv: train(["-optimize", *argv]),
    "enjoy": enjoy,
    "record_video": record_video,
}

USAGE = """usage: sb3-denfac-zoo {train,optimize,enjoy,record_video} [zoo options]

  train         rl_zoo3 train (defaults: --algo denfac --env sb3_denfac/ContinuousCartPole-v0,
                --conf-file hyperparams/<algo>.yml, --num-threads 1); add -optimize to tune
                with Optuna
  optimize      same as train -optimize (default storage sqlite:///<log-folder>/optuna.db, study <algo>-<env>)
  enjoy         rl_zoo3 enjoy (default --num-threads 1)
  record_video  rl_zoo3 record_video

Algorithms: denfac, ddpg (ours, inverting gradients), nfac, cacla, cmaes, plus the zoo's (td3, sac, crossq, sb3_ddpg, ...).
Run `sb3-denfac-zoo train --help` for the zoo's options."""


def main(argv: Sequence[str] | None = None) -> None:
    """Console entry point ``sb3-denfac-zoo``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMANDS:
        print(USAGE)
        if argv and argv[0] not in ("-h", "--help"):
            sys.exit(f"sb3-denfac-zoo: unknown command {argv[0]!r}")
        return
    register()
    try:
        COMMANDS[argv[0]](argv[1:])
    except ZooConfigError as e:
        sys.exit(f"sb3-denfac-zoo: error: {e}")


if __name__ == "__main__":
    main()
