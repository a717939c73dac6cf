"""Figure 3 data-efficiency benchmark: algorithms x envs x seeds, each for a budget of episodes; one runner, resumable.

Runs are chosen by a suite (``--suite figure3``, ``--suite generalisation``: see ``figure3_suites.py``) and/or by
``--algos/--envs/--seeds``; each run (``figure3_run.run_one``) trains ``ALGO("MlpPolicy", env, **hyperparams)`` with the
YAML entry of its row for ``--episodes`` episodes (the env's budget by default) and writes, at its end and atomically,
``runs/<algo>/<env>/seed_<k>.csv`` (one line per episode) then ``seed_<k>.json`` (metadata: hyperparameters and their
source, commit, machine, load, CPU and wall seconds, the deterministic evaluations). A rerun skips runs whose ``.json``
exists, so an interrupted sweep resumes. The zoo's ``evaluations.npz`` is written under ``zoo/<algo>/<env-id>_<seed>/``.
At the end, ``figure3_analysis.py`` writes the tables, the verdicts and the plots of every suite.

Examples::

    python benchmarks/figure3.py --suite figure3 --workers 0                 # the whole sweep, in this process
    python benchmarks/figure3.py --suite generalisation --envs pendulum      # one env of a suite
    python benchmarks/figure3.py --algos td3 sac --envs cartpole --seeds 0 1 --episodes 50 --workers 2
    python benchmarks/figure3.py --suite figure3 --ray-address auto          # on a Ray cluster (pip install ray)
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

_HERE = Path(__file__).resolve().parent
_REPO = _HERE.parent
for _p in (str(_HERE), str(_REPO)):  # run from a checkout without installing the package
    if _p not in sys.path:
        sys.path.insert(0, _p)

import figure3_analysis as fa  # noqa: E402
import figure3_run  # noqa: E402
import figure3_suites as suites  # noqa: E402

DEFAULT_RESULTS_DIR = _HERE / "results" / "sweep"
EPISODE_FIELDS = ("episode", "performance", "best_so_far", "return", "length", "timesteps", "wall_time", "cpu_time")


# ---------------------------------------------------------------------------------------------------------------- files


def run_paths(results_dir: Path, algo: str, env: str, seed: int) -> tuple[Path, Path]:
    base = results_dir / "runs" / algo / env / f"seed_{seed}"
    return base.with_suffix(".csv"), base.with_suffix(".json")


def _atomic_write(path: Path, write: Callable[[io.TextIOBase], None]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with tmp.open("w", newline="") as f:
        write(f)
    os.replace(tmp, path)


def save_result(result: dict[str, Any], results_dir: Path, zoo_logs: bool = True) -> None:
    """Write a finished run (CSV first, JSON last: the JSON marks the run as done) or its error log."""
    import csv

    task = result["task"]
    csv_path, json_path = run_paths(results_dir, task["algo"], task["env"], task["seed"])
    log_path = results_dir / "logs" / f"{task['algo']}__{task['env']}__seed_{task['seed']}.log"
    log_path.parent.mkdir(parents=True, exist_ok=True)
    log_path.write_text(result.get("log", "") + (("\n" + result["error"]) if "error" in result else ""))
    if "error" in result:
        return

    def write_csv(f: io.TextIOBase) -> None:
        writer = csv.DictWriter(f, fieldnames=EPISODE_FIELDS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(result["episodes"])

    _atomic_write(csv_path, write_csv)
    if zoo_logs:
        write_zoo_evaluations(result, results_dir / "zoo")
    _atomic_write(json_path, lambda f: json.dump(result["meta"], f, indent=1))


def write_zoo_evaluations(result: dict[str, Any], zoo_dir: Path) -> None:
    """``evaluations.npz`` in the zoo's layout (``<algo>/<env-id>_<seed>/``) so ``rl_zoo3.plots.all_plots`` reads it.

    ``results`` holds each *training* episode's paper measure (one column), ``ep_lengths`` its length, ``timesteps``
    the step count at its end; ``best_so_far`` (use ``--key best_so_far``) is the Figure 3 measure.
    """
    import numpy as np

    meta, eps = result["meta"], result["episodes"]
    folder = zoo_dir / meta["algo"] / f"{meta['gym_id'].replace('/', '-')}_{meta['seed']}"
    folder.mkdir(parents=True, exist_ok=True)
    np.savez(
        folder / "evaluations.npz",
        timesteps=np.array([e["timesteps"] for e in eps], dtype=np.int64),
        results=np.array([[e["performance"]] for e in eps], dtype=np.float64),
        ep_lengths=np.array([[e["length"]] for e in eps], dtype=np.int64),
        best_so_far=np.array([[e["best_so_far"]] for e in eps], dtype=np.float64),
    )


# ---------------------------------------------------------------------------------------------------------------- sweep


def _init_worker() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)


def _run_local(tasks: list[dict[str, Any]], workers: int, on_result: Callable[[dict[str, Any]], None]) -> None:
    if workers <= 0:
        for task in tasks:
            on_result(figure3_run.run_one(task))
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # spawn: fresh interpreters (no inherited torch thread pools), same behaviour on Linux and macOS
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"), initializer=_init_worker) as pool:
        try:
            futures = [pool.submit(figure3_run.run_one, task) for task in tasks]
            for future in as_completed(futures):
                on_result(future.result())
        except BaseException:  # interrupted (Ctrl-C, SIGTERM): do not leave workers training in the background
            for process in list(getattr(pool, "_processes", {}).values()):
                process.terminate()
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def _run_ray(tasks: list[dict[str, Any]], address: str, on_result: Callable[[dict[str, Any]], None]) -> None:
    try:
        import ray
    except ImportError as e:
        raise SystemExit(
            "--ray-address needs Ray, which is not installed: pip install 'sb3-denfac[distributed]' (or pip install ray). "
            "Every node of the cluster also needs sb3-denfac installed."
        ) from e
    # Ship the run's code by value so cluster nodes need only the installed package, not this checkout.
    with contextlib.suppress(Exception):
        ray.cloudpickle.register_pickle_by_value(figure3_run)
    ray.init(address=None if address == "local" else address, ignore_reinit_error=True)
    try:
        remote = ray.remote(num_cpus=1)(figure3_run.run_one)
        pending = [remote.remote(task) for task in tasks]
        while pending:  # results come back to this driver, which alone writes the files
            done, pending = ray.wait(pending, num_returns=1)
            on_result(ray.get(done[0]))
    finally:
        ray.shutdown()  # disconnects from a cluster; stops a "local" one


def select_cells(
    suite: str | None = None,
    algos: Sequence[str] | None = None,
    envs: Sequence[str] | None = None,
    seeds: Sequence[int] | None = None,
) -> list[tuple[str, str, int]]:
    """The (algo, env, seed) cells of ``suite`` restricted to ``algos/envs/seeds``, or (no suite) their product.

    Ordered seed by seed, so a sweep stopped early has every (algo, env) at its first seeds."""
    if suite is not None:
        if suite not in suites.SUITES:
            raise ValueError(f"unknown --suite {suite!r}; choose from {sorted(suites.SUITES)}")
        cells = suites.SUITES[suite].cells()
        return [
            (a, e, s)
            for a, e, s in cells
            if (algos is None or a in algos) and (envs is None or e in envs) and (seeds is None or s in seeds)
        ]
    if not (algos and envs and seeds is not None):
        raise ValueError("give --suite, or --algos, --envs and --seeds")
    unknown = [a for a in algos if a not in suites.ALGOS]
    if unknown:
        raise ValueError(f"unknown --algos {unknown}; choose from {list(suites.ALGOS)}")
    return [(a, e, int(s)) for s in seeds for e in envs for a in algos]


def sweep(
    algos: Sequence[str] | None = None,
    envs: Sequence[str] | None = None,
    seeds: Sequence[int] | None = None,
    episodes: int | dict[str, int] | None = None,
    suite: str | None = None,
    results_dir: str | Path = DEFAULT_RESULTS_DIR,
    hyperparams_dirs: Sequence[str | Path] = (),
    workers: int = 1,
    ray_address: str | None = None,
    zoo_logs: bool = True,
    analysis: bool = True,
    verbose: int = 1,
) -> dict[str, list]:
    """Run the missing runs of :func:`select_cells`; return ``{"done", "skipped", "failed"}`` task lists.

    ``episodes``: one budget for all envs, ``{env: budget}``, or None for each env's budget (``figure3_suites.BUDGETS``).
    """
    cells = select_cells(suite, algos, envs, seeds)
    if isinstance(episodes, int):
        episodes = {e: episodes for _, e, _ in cells}
    results_dir = Path(results_dir)
    results_dir.mkdir(parents=True, exist_ok=True)
    status: dict[str, list] = {"done": [], "skipped": [], "failed": []}
    tasks = []
    git = figure3_run.git_state()  # the code this sweep loads; a commit made while it runs does not change it
    for algo, env, seed in cells:
        budget = suites.budget(env, (episodes or {}).get(env))
        if budget.episodes < 1:
            raise ValueError(f"--episodes for {env} must be >= 1, got {budget.episodes}")
        hyperparams, source = suites.load_hyperparams(algo, env, hyperparams_dirs)
        task = {
            "algo": algo,
            "zoo_algo": suites.ALGOS[algo].zoo_algo,
            "hyperparams": hyperparams,
            "hyperparams_source": source,
            "git": git,
            "env": env,
            "seed": int(seed),
            "episodes": budget.episodes,
            "eval_every": budget.eval_every,
            "eval_episodes": budget.eval_episodes,
            "eval_kwargs": dict(budget.eval_kwargs),
        }
        done_path = run_paths(results_dir, algo, env, seed)[1]
        (status["skipped"] if done_path.exists() else tasks).append(task)
    tasks.sort(key=lambda t: (t["seed"], suites.estimated_cost(t["algo"], t["env"])))  # stable: seed by seed, cheap first
    if verbose:
        print(f"{len(tasks)} runs to do, {len(status['skipped'])} already finished (skipped)", flush=True)
    sweep_info = {
        "git": git,
        "machine": figure3_run.machine_info(),
        "load_average": os.getloadavg(),
        "suite": suite,
        "cells": [[a, e, s] for a, e, s in cells],
        "episodes": {t["env"]: t["episodes"] for t in tasks + status["skipped"]},
        "workers": workers,
        "ray_address": ray_address,
        "started_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    with (results_dir / "sweeps.jsonl").open("a") as f:
        f.write(json.dumps(sweep_info) + "\n")

    def on_result(result: dict[str, Any]) -> None:
        save_result(result, results_dir, zoo_logs)
        t = result["task"]
        if "error" in result:
            status["failed"].append(t)
            if verbose:
                print(f"FAILED {t['algo']} {t['env']} seed {t['seed']}:\n{result['error']}", flush=True)
        else:
            status["done"].append(t)
            if verbose:
                m = result["meta"]
                best = result["episodes"][-1]["best_so_far"] if result["episodes"] else float("nan")
                print(
                    f"{time.strftime('%H:%M:%S')} done {t['algo']} {t['env']} seed {t['seed']}: {m['episodes']} episodes, "
                    f"{m['timesteps']} steps, {m['cpu_time']:.1f} CPU s, best {best:.4g} ({m['hyperparams_source']})",
                    flush=True,
                )

    if tasks:
        if ray_address:
            _run_ray(tasks, ray_address, on_result)
        else:
            _run_local(tasks, workers, on_result)
    if analysis and (status["done"] or status["skipped"]):
        report = fa.analyse(results_dir)
        if verbose:
            print(report)
    return status


def parse_episodes(values: Sequence[str] | None, envs: Sequence[str] | None = None) -> dict[str, int] | None:
    """``["60", "halfcheetah=20"]`` -> ``{env: 60, ..., "halfcheetah": 20}``; envs without a value keep their budget."""
    if not values:
        return None
    default, per_env = None, {}
    for value in values:
        name, sep, number = value.rpartition("=")
        if not number.isdigit():
            raise ValueError(f"--episodes: expected N or ENV=N, got {value!r}")
        if sep:
            per_env[name] = int(number)
        else:
            default = int(number)
    names = set(envs or ()) | set(per_env) | set(suites.ENVS)
    return {env: per_env.get(env, default) for env in names if per_env.get(env, default) is not None}


def _exit_on_sigterm(signum: int, frame: Any) -> None:
    raise SystemExit(f"interrupted by signal {signum}; finished runs are kept, rerun the same command to resume")


def main(argv: Sequence[str] | None = None) -> int:
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--suite", default=None, help=f"one of {list(suites.SUITES)}")
    parser.add_argument("--algos", nargs="+", default=None, help=f"subset of {list(suites.ALGOS)}")
    parser.add_argument("--envs", nargs="+", default=None, help=f"short names {suites.ENVS} or any Gymnasium id")
    parser.add_argument("--seeds", nargs="+", type=int, default=None)
    parser.add_argument(
        "--episodes", nargs="+", default=None, help="override the budgets: N for all envs, ENV=N for one (e.g. 5 pendulum=3)"
    )
    parser.add_argument("--results", default=str(DEFAULT_RESULTS_DIR), help="results folder")
    parser.add_argument("--hyperparams", nargs="*", default=[], help="folders searched first for <algo>.yml")
    parser.add_argument("--workers", type=int, default=1, help="process pool size (0: in this process)")
    parser.add_argument("--ray-address", default=None, help="run on a Ray cluster ('auto', 'ray://host:10001', 'local')")
    parser.add_argument("--no-zoo-logs", action="store_true", help="do not write the zoo's evaluations.npz files")
    parser.add_argument("--no-analysis", action="store_true", help="skip the tables and plots at the end")
    args = parser.parse_args(argv)
    status = sweep(
        args.algos,
        args.envs,
        args.seeds,
        parse_episodes(args.episodes, args.envs),
        suite=args.suite,
        results_dir=args.results,
        hyperparams_dirs=args.hyperparams,
        workers=args.workers,
        ray_address=args.ray_address,
        zoo_logs=not args.no_zoo_logs,
        analysis=not args.no_analysis,
    )
    print(f"finished: {len(status['done'])} done, {len(status['skipped'])} skipped, {len(status['failed'])} failed")
    return 1 if status["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
