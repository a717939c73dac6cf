"""The benchmark runner: (row, env, seed) cells, each trained for a budget of episodes; resumable, local or on Ray.

Cells come from a suite (``--suite figure3``, ``generalisation``, ``matched``, ``ablation``...:
``benchmarks/runner/suites.py``; the rows: ``benchmarks/runner/algos.py``) and/or ``--algos/--envs/--seeds``. Each run
is appended, when it ends, to the study's compact runs file ``<results>/runs.jsonl.gz``; a rerun skips the cells
already there, so an interrupted sweep resumes
where it stopped (the sweep: ``benchmarks/runner/sweep.py``). The console gets a line per finished cell and a short
summary; the report of the suite run (``<results>/<suite>.md`` and its figures; ``all_runs.md`` for cells outside a
suite) goes to its file, and the study's other reports are left as they are (``python -m benchmarks.reports.analysis``
rewrites them all).

``<results>`` is by default ``runs/<the suite's study>/`` under the current directory, a folder of your own (git
ignores ``/runs/``): the committed studies (``benchmarks/results/<study>/``) grow only when ``--results`` names them.

Examples::

    python -m benchmarks.run --suite figure3 --workers 0                  # the whole sweep, in this process
    python -m benchmarks.run --suite generalisation --envs pendulum       # one env of a suite
    python -m benchmarks.run --algos td3 sac --envs cartpole --seeds 0 1 --episodes 50 --workers 2
    python -m benchmarks.run --suite ablation --algos abl:default abl:faithful   # part of the ablation study
    python -m benchmarks.run --suite figure3 --ray-address HOST:6379      # on a Ray cluster (pip install ray)
    python -m benchmarks.run --suite matched --results benchmarks/results/sweep   # into the committed study
"""

from __future__ import annotations

import argparse
import signal
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from benchmarks.reports.analysis import report_of_run
from benchmarks.runner import suites
from benchmarks.runner.algos import ALGOS
from benchmarks.runner.sweep import check_device, default_results_dir, parse_episodes, select_cells, sweep


def run(
    algos: Sequence[str] | None = None,
    envs: Sequence[str] | None = None,
    seeds: Sequence[int] | None = None,
    episodes: int | dict[str, int] | None = None,
    *,
    suite: str | None = None,
    results_dir: str | Path | None = None,
    analysis: bool = True,
    verbose: int = 1,
    **settings: Any,
) -> dict[str, list]:
    """:func:`benchmarks.runner.sweep.sweep` (same arguments, same ``{"done", "skipped", "failed"}``), then, if
    ``analysis`` and a cell is finished, the report of the suite run alone
    (:func:`benchmarks.reports.analysis.report_of_run`)."""
    results_dir = Path(results_dir) if results_dir is not None else default_results_dir(suite)
    status = sweep(algos, envs, seeds, episodes, suite=suite, results_dir=results_dir, verbose=verbose, **settings)
    if analysis and (status["done"] or status["skipped"]):
        written = report_of_run(results_dir, suite)
        if verbose:
            print(f"report: {', '.join(str(path) for path in written)}", flush=True)
    return status


def _exit_on_sigterm(signum: int, frame: Any) -> None:
    raise SystemExit(f"interrupted by signal {signum}; finished runs are kept, rerun the same command to resume")


def main(argv: Sequence[str] | None = None) -> int:
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--suite", default=None, help=f"one of {list(suites.SUITES)}")
    rows = [a for a, row in ALGOS.items() if row.family != "ablation"]
    parser.add_argument(
        "--algos", nargs="+", default=None, help=f"rows: {rows}, or abl:<config> (benchmarks/configs/ablation.yml)"
    )
    parser.add_argument("--envs", nargs="+", default=None, help=f"short names {suites.ENVS} or any Gymnasium id")
    parser.add_argument("--seeds", nargs="+", type=int, default=None)
    parser.add_argument(
        "--episodes", nargs="+", default=None, help="override the budgets: N for all envs, ENV=N for one (e.g. 5 pendulum=3)"
    )
    parser.add_argument(
        "--timesteps", type=int, default=None, help="a budget of N env steps for every env instead of episodes"
    )
    parser.add_argument(
        "--results",
        default=None,
        help="results folder (default: runs/<the suite's study>/ here; the committed ones: benchmarks/results/<study>)",
    )
    parser.add_argument("--hyperparams", nargs="*", default=[], help="folders searched first for <algo>.yml")
    parser.add_argument("--workers", type=int, default=1, help="process pool size (0: in this process)")
    parser.add_argument("--ray-address", default=None, help="run on a Ray cluster ('auto', 'ray://host:10001', 'local')")
    parser.add_argument("--zoo-logs", default=None, help="also write the RL Zoo's evaluations.npz files under this folder")
    parser.add_argument("--no-analysis", action="store_true", help="skip the suite's report (tables and plots) at the end")
    parser.add_argument(
        "--diagnostics-every",
        type=int,
        default=None,
        help="record DENFAC's critic-fit diagnostics every N episodes (0: none; default: the suite's, else none)",
    )
    parser.add_argument("--device", default="cpu", help="torch device of the runs: cpu (default), or cuda on a GPU machine")
    parser.add_argument(
        "--checkpoint-every",
        type=float,
        default=600.0,
        help="seconds between a run's checkpoints, from which a rerun resumes it (default 600; 0: none)",
    )
    args = parser.parse_args(argv)
    if args.checkpoint_every < 0:
        parser.error(f"--checkpoint-every must be >= 0 seconds (0: none), got {args.checkpoint_every}")
    try:
        check_device(args.device)
        episodes = parse_episodes(args.episodes, args.envs)
        select_cells(args.suite, args.algos, args.envs, args.seeds)  # bad names: a usage error, before any run
    except ValueError as error:
        parser.error(str(error))
    if args.diagnostics_every is not None and args.diagnostics_every < 0:
        parser.error(f"--diagnostics-every must be >= 0 (0: none), got {args.diagnostics_every}")
    status = run(
        args.algos,
        args.envs,
        args.seeds,
        episodes,
        suite=args.suite,
        results_dir=args.results,
        analysis=not args.no_analysis,
        hyperparams_dirs=args.hyperparams,
        workers=args.workers,
        ray_address=args.ray_address,
        zoo_logs=args.zoo_logs,
        diagnostics_every=args.diagnostics_every,
        device=args.device,
        checkpoint_every=args.checkpoint_every,
        timesteps=args.timesteps,
    )
    print(f"finished: {len(status['done'])} done, {len(status['skipped'])} skipped, {len(status['failed'])} failed")
    return 1 if status["failed"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
