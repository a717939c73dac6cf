"""RL Zoo 3 command line: train, tune, enjoy and record this package's algorithms with the zoo's own scripts.

Usage (``sb3-denfac-zoo`` is the same as ``python -m sb3_denfac.zoo``)::

    python -m sb3_denfac.zoo train --algo denfac --env sb3_denfac/ContinuousCartPole-v0 -tb runs/
    python -m sb3_denfac.zoo train --algo denfac --env sb3_denfac/ContinuousCartPole-v0 -optimize --n-trials 20
    python -m sb3_denfac.zoo enjoy --algo denfac --env sb3_denfac/ContinuousCartPole-v0 -f logs/
    python -m sb3_denfac.zoo record_video --algo denfac --env sb3_denfac/ContinuousCartPole-v0 -f logs/

Nothing of the zoo is rebuilt: :func:`~sb3_denfac.zoo.config.register` adds this package's algorithms and samplers to
the zoo's tables, then the command goes to ``rl_zoo3.train.train``, ``rl_zoo3.enjoy.enjoy`` or the
``rl_zoo3.record_video`` script with the same command line; the zoo parses it. ``train`` runs with
:class:`~.experiment.CheckedExperimentManager`, the zoo's ExperimentManager with what the zoo cannot guess:

- ``--conf-file`` defaults to this package's ``hyperparams/<algo>.yml`` (for td3/sac/crossq only when that
  file has an entry for the env; otherwise the zoo's own file is used);
- with ``-optimize`` and no ``--storage``, the study is kept in ``sqlite:///<log-folder>/optuna.db`` under the study
  name ``<algo>-<env>`` (``--study-name`` overrides it), so a killed or repeated run resumes the same study; a study
  records its budget (``n_timesteps``) and a run with another budget is refused rather than mixed into it;
- with ``-optimize``, no run folder ``<log-folder>/<algo>/<env>_<n>`` is made (the trials keep their results in the
  study; the zoo left an empty one, which ``enjoy`` then took for the latest run);
- ``enjoy`` without ``-f`` reads ``logs/`` (``train``'s default) for this package's algorithms; a run folder without
  a model is named with the runs that have one (``--exp-id``); without a display it plays with ``--no-render`` and
  says so (the zoo's ``render_mode="human"`` would open a window; PyBullet's waits for an X server forever);
  ``--trial-id`` reads the same study by default;
- an entry's ``preset`` (e.g. ``preset: paper``) is expanded (:func:`~sb3_denfac.zoo.config.expand_preset`), after the
  zoo's own reading, so ``-params`` and ``--trial-id`` values override the preset too;
- the selected YAML entry (after ``-params`` overrides) is checked (:func:`~sb3_denfac.zoo.validation.validate_entry`), so
  a typo fails with a clear :class:`~sb3_denfac.zoo.config.ZooConfigError` before any log folder is created;
- this package's samplers keep the entry's ``policy_kwargs`` (see :mod:`sb3_denfac.zoo.samplers`).

Before the zoo parses the command line, :func:`prepare_train_args` adds ``--num-threads 1`` and the default
``--algo``/``--env`` and checks the env id (the zoo's own check names no package env).

``ddpg`` means :class:`sb3_denfac.ddpg.DDPG` (SB3's DDPG with inverting gradients, batch norm and truncated-Gaussian
exploration); SB3's original stays available as ``sb3_ddpg``. SB3's TD3/SAC and sb3-contrib's CrossQ keep their zoo names.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import importlib.util
import io
import os
import runpy
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from rl_zoo3.exp_manager import ExperimentManager

from sb3_denfac.zoo.config import (
    ALGORITHMS,
    ZooConfigError,
    check_action_space_fits,
    check_env_id,
    register,
)
from sb3_denfac.zoo.experiment import CheckedExperimentManager

DEFAULT_ALGO = "denfac"
DEFAULT_ENV = "sb3_denfac/ContinuousCartPole-v0"

#: torch threads of ``sb3-denfac-zoo train``/``enjoy`` unless ``--num-threads`` is given: the paper's networks are
#: tiny, and several threads on a loaded machine made DENFAC's updates many times slower (benchmarks/results/).
DEFAULT_NUM_THREADS = 1


# --------------------------------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------------------------------


def _options_read_first(argv: Sequence[str]) -> argparse.Namespace:
    """The three train options needed before the zoo parses the command line: ``--algo`` and ``--env`` to default them,
    ``--gym-packages`` to import before the env id is checked. (rl_zoo3.train.train builds its parser inside the
    function, so it cannot be reused; the zoo parses everything, these three included, after this.)"""
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--algo")
    parser.add_argument("--env")
    parser.add_argument("--gym-packages", nargs="+", default=[])
    return parser.parse_known_args(argv)[0]


def with_default_threads(argv: Sequence[str]) -> list[str]:
    """``argv`` with ``--num-threads DEFAULT_NUM_THREADS`` added unless it sets ``--num-threads`` itself."""
    argv = list(argv)
    if any(a == "--num-threads" or a.startswith("--num-threads=") for a in argv):
        return argv
    return [*argv, "--num-threads", str(DEFAULT_NUM_THREADS)]


def prepare_train_args(argv: Sequence[str]) -> list[str]:
    """A ``train`` command line with this package's defaults (threads, algo, env) and a checked env id."""
    argv = list(argv)
    if any(a in ("-h", "--help") for a in argv):
        return argv
    argv = with_default_threads(argv)
    first = _options_read_first(argv)
    for module in first.gym_packages:
        importlib.import_module(module)
    if first.algo is None:
        argv += ["--algo", DEFAULT_ALGO]
    if first.env is None:
        argv += ["--env", DEFAULT_ENV]
    check_env_id(first.env or DEFAULT_ENV)
    check_action_space_fits(first.algo or DEFAULT_ALGO, first.env or DEFAULT_ENV)
    return argv


def _run_with_argv(prog: str, argv: Sequence[str], func: Callable[[], Any]) -> Any:
    saved = sys.argv
    sys.argv = [prog, *argv]
    try:
        return func()
    finally:
        sys.argv = saved


def train(argv: Sequence[str]) -> None:
    """``rl_zoo3.train.train`` on :func:`prepare_train_args` (argv), with :class:`CheckedExperimentManager`.

    ``rl_zoo3.train.train`` creates its manager through its module's name ``ExperimentManager``: the name is pointed
    at the subclass for the call and restored after (the zoo's train script has no other way to take a subclass)."""
    import rl_zoo3.train

    if getattr(rl_zoo3.train, "ExperimentManager", None) is not ExperimentManager:
        raise ZooConfigError("rl_zoo3.train no longer creates rl_zoo3.exp_manager.ExperimentManager by that name")
    argv = prepare_train_args(argv)
    rl_zoo3.train.ExperimentManager = CheckedExperimentManager
    try:
        _run_with_argv("sb3-denfac-zoo train", argv, rl_zoo3.train.train)
    finally:
        rl_zoo3.train.ExperimentManager = ExperimentManager


def check_enjoy_folder(argv: Sequence[str], command: str = "enjoy") -> None:
    """Fail, naming the folder looked in, if ``enjoy``'s ``-f`` folder has no run of ``--algo`` on ``--env`` (the zoo
    itself raises a bare AssertionError). The zoo's default folder ``rl-trained-agents`` is left to the zoo (it
    downloads pretrained agents from the Hugging Face hub)."""
    if any(a in ("-h", "--help") for a in argv):
        return
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("-f", "--folder", default="rl-trained-agents")
    parser.add_argument("--algo", default="ppo")
    parser.add_argument("--env", default="CartPole-v1")
    parser.add_argument("--exp-id", type=int, default=0)
    parser.add_argument("--load-best", action="store_true")
    parser.add_argument("--load-checkpoint", type=int)
    parser.add_argument("--load-last-checkpoint", action="store_true")
    args = parser.parse_known_args(argv)[0]
    if "rl-trained-agents" in args.folder:
        return
    env_name = args.env.replace("/", "-").split(":")[-1]  # the zoo's folder name of an env id (EnvironmentName)
    folder, algo_folder = Path(args.folder), Path(args.folder) / args.algo
    hint = f"pass -f with the log folder given to `sb3-denfac-zoo train -f` (the default of both: {TRAIN_LOG_FOLDER})"
    if not folder.is_dir():
        where = f"working directory {Path.cwd()}"
        raise ZooConfigError(f"{command}: the log folder {str(folder)!r} does not exist ({where}): {hint}")
    if not algo_folder.is_dir():
        found = sorted(p.name for p in folder.iterdir() if p.is_dir())
        raise ZooConfigError(
            f"{command}: no {args.algo!r} runs in {str(folder)!r}: the folder {str(algo_folder)!r} does not exist "
            f"(algorithms found there: {', '.join(found) or 'none'}); {hint}"
        )
    if args.exp_id >= 0:
        runs = sorted(p.name for p in algo_folder.glob(f"{env_name}_*") if p.name.rsplit("_", 1)[-1].isdigit())
        wanted = algo_folder / f"{env_name}_{args.exp_id}" if args.exp_id > 0 else None
        if not runs or (wanted is not None and not wanted.is_dir()):
            what = f"the run folder {str(wanted)!r}" if wanted is not None else f"a run folder {env_name}_<n>"
            others = sorted(p.name for p in algo_folder.iterdir() if p.is_dir())
            raise ZooConfigError(
                f"{command}: {what} of {args.algo} on {args.env} was not found in {str(algo_folder)!r} (found: "
                f"{', '.join(others) or 'nothing'}); check --env and --exp-id (0: the latest run)"
            )
        _check_run_has_a_model(args, command)


def _model_path(args: argparse.Namespace, exp_id: int) -> tuple[str | None, str]:
    """The model file the zoo would load for run ``exp_id`` (rl_zoo3's ``get_model_path``, with the load options of
    ``args``), or None and the zoo's reason."""
    from huggingface_sb3 import EnvironmentName
    from rl_zoo3.utils import get_model_path

    load = (args.load_best, args.load_checkpoint, args.load_last_checkpoint)
    with contextlib.redirect_stdout(io.StringIO()):  # it prints "Loading latest experiment"; the zoo prints it again
        try:
            return get_model_path(exp_id, args.folder, args.algo, EnvironmentName(args.env), *load)[1], ""
        except (AssertionError, ValueError) as e:
            return None, str(e)


def _check_run_has_a_model(args: argparse.Namespace, command: str) -> None:
    """Fail, naming the run folder and the runs that have one, if the run to play holds no model (a run stopped before
    it saved one; earlier versions' ``optimize`` also left empty run folders), instead of the zoo's traceback."""
    from huggingface_sb3 import EnvironmentName
    from rl_zoo3.utils import get_latest_run_id

    algo_folder = Path(args.folder) / args.algo
    env_name = EnvironmentName(args.env)
    exp_id = args.exp_id or get_latest_run_id(str(algo_folder), env_name)
    model, reason = _model_path(args, exp_id)
    if model is not None:
        return
    suffixes = (p.name.rsplit("_", 1)[-1] for p in algo_folder.glob(f"{env_name}_*"))
    ids = sorted((int(suffix) for suffix in suffixes if suffix.isdigit()), reverse=True)
    with_model = [i for i in ids if i != exp_id and _model_path(args, i)[0] is not None]
    run = f"{'the latest run' if args.exp_id == 0 else 'the run'} {str(algo_folder / f'{env_name}_{exp_id}')!r}"
    hint = (
        f"pass --exp-id {with_model[0]} (runs with a model: {', '.join(map(str, with_model))})"
        if with_model
        else f"no other run of {args.algo} on {args.env} in {str(algo_folder)!r} has one: train first"
    )
    raise ZooConfigError(f"{command}: {run} holds no model to load ({reason}); {hint}")


#: ``train``'s default log folder (rl_zoo3's ``-f``), where ``enjoy`` looks for this package's algorithms by default.
TRAIN_LOG_FOLDER = "logs"


def with_default_folder(argv: Sequence[str]) -> list[str]:
    """``enjoy``'s argv with ``-f logs`` (what ``train`` writes by default) when no folder is given and ``--algo`` is
    one of this package's: the zoo's own default, ``rl-trained-agents``, downloads pretrained agents from the Hugging
    Face hub, which has none of them."""
    argv = list(argv)
    if any(a in ("-f", "--folder") or a.startswith("--folder=") for a in argv):
        return argv
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--algo", default="ppo")
    if parser.parse_known_args(argv)[0].algo in ALGORITHMS:
        argv += ["-f", TRAIN_LOG_FOLDER]
    return argv


def has_display() -> bool:
    """Whether a window can be opened: on Linux, an X or Wayland display is set (``DISPLAY``, ``WAYLAND_DISPLAY``)."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def without_display(argv: Sequence[str]) -> list[str]:
    """``enjoy``'s argv with ``--no-render`` added, and a note on stderr, when there is no display (:func:`has_display`):
    the zoo's ``render_mode="human"`` would open a window (PyBullet's, for panda-gym, waits on the X server forever)."""
    argv = list(argv)
    if "--no-render" in argv or any(a in ("-h", "--help") for a in argv) or has_display():
        return argv
    print(
        "sb3-denfac-zoo enjoy: no display (DISPLAY is not set): playing without rendering (--no-render); to see the "
        "agent without a display, write a video: sb3-denfac-zoo record_video",
        file=sys.stderr,
    )
    return [*argv, "--no-render"]


def enjoy(argv: Sequence[str]) -> None:
    from rl_zoo3.enjoy import enjoy as zoo_enjoy

    argv = with_default_folder(argv)
    check_enjoy_folder(argv)
    _run_with_argv("sb3-denfac-zoo enjoy", with_default_threads(without_display(argv)), zoo_enjoy)


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
    argv = with_default_folder(argv)
    check_enjoy_folder(argv, "record_video")
    # rl_zoo3.record_video is a script (its code runs under `if __name__ == "__main__"`).
    _run_with_argv("sb3-denfac-zoo record_video", argv, lambda: runpy.run_module("rl_zoo3.record_video", run_name="__main__"))


COMMANDS: dict[str, Callable[[Sequence[str]], None]] = {
    "train": train,
    "optimize": lambda argv: train(["-optimize", *argv]),
    "enjoy": enjoy,
    "record_video": record_video,
}


def main(argv: Sequence[str]) -> None:
    """Run the command ``argv[0]`` of ``sb3-denfac-zoo`` (the usage and unknown commands: :func:`.usage.main`)."""
    register()
    try:
        COMMANDS[argv[0]](argv[1:])
    except ZooConfigError as e:
        sys.exit(f"sb3-denfac-zoo: error: {e}")
