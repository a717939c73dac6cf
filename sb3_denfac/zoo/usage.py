"""The ``sb3-denfac-zoo`` entry point's help, answered without importing rl_zoo3, Optuna or torch (a fast ``--help``).

:func:`main` prints :data:`USAGE` for ``--help``, no command or an unknown one, and hands any other command to
:func:`sb3_denfac.zoo.cli.main` (which imports the zoo).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

#: The commands of ``sb3-denfac-zoo`` (their functions: ``sb3_denfac.zoo.cli.COMMANDS``).
COMMAND_NAMES = ("train", "optimize", "enjoy", "record_video")

USAGE = """usage: sb3-denfac-zoo {train,optimize,enjoy,record_video} [zoo options]

  train         rl_zoo3 train (defaults: --algo denfac --env sb3_denfac/ContinuousCartPole-v0,
                --conf-file hyperparams/<algo>.yml, --num-threads 1); add -optimize to tune
                with Optuna
  optimize      same as train -optimize (default storage sqlite:///<log-folder>/optuna.db, study <algo>-<env>)
  enjoy         rl_zoo3 enjoy (default --num-threads 1)
  record_video  rl_zoo3 record_video

Algorithms: denfac, soft_denfac, ddpg (ours, inverting gradients), nfac, cacla, cmaes,
plus the zoo's (td3, sac, crossq, sb3_ddpg, ...).
Run `sb3-denfac-zoo train --help` for the zoo's options."""


def main(argv: Sequence[str] | None = None) -> None:
    """Console entry point ``sb3-denfac-zoo``: the usage here, the commands in :func:`sb3_denfac.zoo.cli.main`."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMAND_NAMES:
        print(USAGE)
        if argv and argv[0] not in ("-h", "--help"):
            sys.exit(f"sb3-denfac-zoo: unknown command {argv[0]!r}")
        return
    from sb3_denfac.zoo.cli import main as run_command

    run_command(argv)
