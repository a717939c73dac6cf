"""A sweep: (row, env, seed) cells, each trained for a budget of episodes; resumable, local or on Ray.

Cells come from a suite (``figure3``, ``generalisation``, ``matched``, ``ablation``...: ``benchmarks.runner.suites``)
and/or algos, envs and seeds (:func:`select_cells`). Each run (``benchmarks.runner.task.run_one``) trains
``ALGO("MlpPolicy", env, **hyperparams)`` with its row's settings and is appended, when it ends, to the study's compact
runs file ``<results>/runs.jsonl.gz`` (``benchmarks.runner.store``). A rerun skips the cells already there, so an
interrupted sweep resumes where it stopped. The command line, and the suite's report after the sweep:
``python -m benchmarks.run`` (``benchmarks/run.py``).

``<results>`` is by default ``runs/<the suite's study>/`` under the current directory, a folder of your own (git
ignores ``/runs/``): the committed studies (``benchmarks/results/<study>/``) grow only when ``--results`` names them.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from benchmarks.runner import checkpoints, executors, store, suites
from benchmarks.runner import task as task_module
from benchmarks.runner.algos import ALGOS
from benchmarks.runner.hyperparams import load_hyperparams

#: The committed studies (``benchmarks/results/<study>/``): written only when ``--results`` names one of them.
COMMITTED_RESULTS = Path(__file__).resolve().parents[1] / "results"


def default_results_dir(suite: str | None) -> Path:
    """``runs/<study>/`` under the current directory: the study of the suite (suites of one study share their runs),
    else ``runs/sweep``. A folder of the user's own, never the committed ``benchmarks/results/<study>/``."""
    study = suites.SUITES[suite].study if suite in suites.SUITES else "sweep"
    return Path.cwd() / "runs" / study


def write_zoo_evaluations(record: dict[str, Any], zoo_dir: Path) -> None:
    """``evaluations.npz`` in the zoo's layout (``<algo>/<env-id>_<seed>/``) so ``rl_zoo3.plots.all_plots`` reads it.

    ``results`` holds each *training* episode's paper measure (one column), ``ep_lengths`` its length, ``timesteps``
    the step count at its end; ``best_so_far`` (use ``--key best_so_far``) is the Figure 3 measure.
    """
    import numpy as np

    eps = record["episodes"]
    folder = zoo_dir / record["algo"].replace(":", "-") / f"{record['gym_id'].replace('/', '-')}_{record['seed']}"
    folder.mkdir(parents=True, exist_ok=True)
    np.savez(
        folder / "evaluations.npz",
        timesteps=np.array(eps["timesteps"], dtype=np.int64),
        results=np.array(eps["performance"], dtype=np.float64)[:, None],
        ep_lengths=np.array(eps["length"], dtype=np.int64)[:, None],
        best_so_far=np.array(eps["best_so_far"], dtype=np.float64)[:, None],
    )


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
        for flag, asked, position in (("--algos", algos, 0), ("--envs", envs, 1), ("--seeds", seeds, 2)):
            outside = [v for v in asked or () if v not in {c[position] for c in cells}]
            if outside:  # a silent "0 runs to do" hides the cause
                choices = sorted({c[position] for c in cells}, key=str)
                raise ValueError(
                    f"{flag} {outside} not in suite {suite!r} (its {flag[2:]}: {choices}); leave out --suite to run "
                    "any algos, envs and seeds (--diagnostics-every gives the suite's critic diagnostics)"
                )
        return [
            (a, e, s)
            for a, e, s in cells
            if (algos is None or a in algos) and (envs is None or e in envs) and (seeds is None or s in seeds)
        ]
    if not (algos and envs and seeds is not None):
        raise ValueError("give --suite, or --algos, --envs and --seeds")
    unknown = [a for a in algos if a not in ALGOS]
    if unknown:
        raise ValueError(f"unknown --algos {unknown}; choose from {list(ALGOS)}")
    return [(a, e, int(s)) for s in seeds for e in envs for a in algos]


def sweep(
    algos: Sequence[str] | None = None,
    envs: Sequence[str] | None = None,
    seeds: Sequence[int] | None = None,
    episodes: int | dict[str, int] | None = None,
    suite: str | None = None,
    results_dir: str | Path | None = None,
    hyperparams_dirs: Sequence[str | Path] = (),
    workers: int = 1,
    ray_address: str | None = None,
    zoo_logs: str | Path | None = None,
    verbose: int = 1,
    diagnostics_every: int | None = None,
    device: str = "cpu",
    checkpoint_every: float = 600.0,
    timesteps: int | None = None,
) -> dict[str, list]:
    """Run the cells of :func:`select_cells` that ``results_dir`` does not hold yet; return ``{"done", "skipped",
    "failed"}`` lists of tasks. It writes no report (``benchmarks.run.run``: the sweep, then the suite's report).

    ``episodes``: one budget for all envs, ``{env: budget}``, or None for each env's budget (the suite's, else
    ``suites.BUDGETS``). ``results_dir``: None for the suite's study folder (:func:`default_results_dir`).
    ``zoo_logs``: a folder to also write the RL Zoo's ``evaluations.npz`` files to (None: none).
    ``diagnostics_every``: record DENFAC's critic-fit diagnostics every that many episodes (0: none; None: the
    suite's, else none).
    ``device``: the torch device of every run (``"cuda"`` on a GPU machine; each worker its own process there).
    ``timesteps``: a budget of that many env steps for every cell instead (evaluated every tenth of it, or at the
    suite's interval where its budget is one of env steps).
    ``checkpoint_every``: a run saves itself (``<results_dir>/checkpoints/``) after the first episode's update past
    every that many seconds, and a rerun resumes it from there (0: no checkpoints; a killed run is then redone).
    """
    if checkpoint_every < 0:
        raise ValueError(f"checkpoint_every must be >= 0 seconds (0: none), got {checkpoint_every!r}")
    cells = select_cells(suite, algos, envs, seeds)
    if isinstance(episodes, int):
        episodes = {e: episodes for _, e, _ in cells}
    the_suite = suites.SUITES.get(suite) if suite else None
    if diagnostics_every is None:
        diagnostics_every = the_suite.diagnostics_every if the_suite else 0
    if isinstance(diagnostics_every, bool) or not isinstance(diagnostics_every, int) or diagnostics_every < 0:
        raise ValueError(f"diagnostics_every must be an int >= 0 (0: none), got {diagnostics_every!r}")
    results_dir = Path(results_dir) if results_dir is not None else default_results_dir(suite)
    results_dir.mkdir(parents=True, exist_ok=True)
    if store.repair(results_dir) and verbose:
        print(f"cut the truncated last record of {store.runs_path(results_dir)} (an interrupted append)", flush=True)
    finished = store.finished_cells(results_dir)
    status: dict[str, list] = {"done": [], "skipped": [], "failed": []}
    tasks = []
    git = task_module.git_state()  # the code this sweep loads; a commit made while it runs does not change it
    for algo, env, seed in cells:
        budget = suites.budget(env, (episodes or {}).get(env), the_suite)
        if timesteps is not None:
            if timesteps < 1 or episodes:
                raise ValueError(f"--timesteps must be >= 1 and without --episodes, got {timesteps} ({episodes=})")
            every = budget.eval_every if budget.timesteps else max(1, timesteps // 10)
            budget = suites.Budget.steps(timesteps, every, budget.eval_episodes)
        if budget.episodes < 1 and budget.timesteps is None:
            raise ValueError(f"--episodes for {env} must be >= 1, got {budget.episodes}")
        hyperparams, source = load_hyperparams(algo, env, hyperparams_dirs)
        task = {
            "algo": algo,
            "zoo_algo": ALGOS[algo].zoo_algo,
            "hyperparams": hyperparams,
            "hyperparams_source": source,
            "git": git,
            "env": env,
            "seed": int(seed),
            "episodes": budget.episodes,
            "timesteps": budget.timesteps,
            "eval_every": budget.eval_every,
            "eval_episodes": budget.eval_episodes,
            "eval_kwargs": dict(budget.eval_kwargs),
            "diagnostics_every": diagnostics_every,
            "device": device,
            "checkpoint_dir": str(results_dir / "checkpoints") if checkpoint_every > 0 else None,
            "checkpoint_every": checkpoint_every if checkpoint_every > 0 else None,
        }
        (status["skipped"] if store.cell_of(task_module.run_key(task)) in finished else tasks).append(task)
    tasks.sort(key=lambda t: (t["seed"], suites.estimated_cost(t["algo"], t["env"])))  # stable: seed by seed, cheap first
    if verbose:
        print(
            f"{len(tasks)} runs to do, {len(status['skipped'])} already finished (skipped); results: {results_dir}", flush=True
        )
    sweep_info = {
        "git": git,
        "machine": task_module.machine_info(device),
        "load_average": os.getloadavg(),
        "suite": suite,
        "cells": [[a, e, s] for a, e, s in cells],
        "episodes": {t["env"]: t["episodes"] for t in tasks + status["skipped"]},
        "timesteps": {t["env"]: t["timesteps"] for t in tasks + status["skipped"] if t["timesteps"]},
        "workers": workers,
        "ray_address": ray_address,
        "started_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    with (results_dir / "sweeps.jsonl").open("a") as f:
        f.write(json.dumps(sweep_info) + "\n")

    def on_result(record: dict[str, Any]) -> None:
        cell = store.cell_of(record)
        if cell in finished:  # a Ray task retried after its first result was written: keep the first
            return
        store.append_record(results_dir, record)
        t = {"algo": cell[0], "env": cell[1], "seed": cell[2], "episodes": cell[3], "timesteps": cell[4]}
        status["done" if record["status"] == "done" else "failed"].append(t)
        progress = f"[{len(status['done']) + len(status['failed'])}/{len(tasks)}]"  # the cells of this sweep ended so far
        if record["status"] != "done":
            if verbose:
                print(f"{progress} FAILED {cell[0]} {cell[1]} seed {cell[2]}:\n{record['error']}", flush=True)
            return
        finished.add(cell)
        # the run is in the runs file: its checkpoint (if any, on this machine) is done with
        folder = checkpoints.checkpoint_folder({**t, "checkpoint_dir": results_dir / "checkpoints"})
        shutil.rmtree(folder, ignore_errors=True)
        if zoo_logs is not None:
            write_zoo_evaluations(record, Path(zoo_logs))
        if verbose:
            best = record["episodes"]["best_so_far"][-1] if record["n_episodes"] else float("nan")
            measure = f"best {best:.4g}"
            if record.get("timesteps_requested") and record["evaluations"]:  # the field's measure: the last evaluation
                scores = record["evaluations"][-1]["scores"]
                measure = f"final evaluation {sum(scores) / len(scores):.4g}"
            print(
                f"{time.strftime('%H:%M:%S')} {progress} done {cell[0]} {cell[1]} seed {cell[2]}: "
                f"{record['n_episodes']} episodes, {record['timesteps']} steps, {record['gradient_steps']} gradient steps, "
                f"{record['cpu_time']:.1f} CPU s, {measure} ({record['hyperparams_source']})",
                flush=True,
            )

    if tasks:
        if ray_address:
            executors.run_ray(tasks, ray_address, on_result)
        else:
            executors.run_local(tasks, workers, on_result)
    return status


def parse_episodes(values: Sequence[str] | None, envs: Sequence[str] | None = None) -> dict[str, int] | None:
    """``["60", "halfcheetah=20"]`` -> ``{env: 60, ..., "halfcheetah": 20}``; envs without a value keep their budget.
    One N at most, and one value per env: ``--episodes 100 40`` (read as one per env) is an error, not the last one."""
    if not values:
        return None
    default, per_env = None, {}
    for value in values:
        name, sep, number = value.rpartition("=")
        if not number.isdigit():
            raise ValueError(f"--episodes: expected N or ENV=N, got {value!r}")
        if sep:
            if name in per_env:
                raise ValueError(f"--episodes: two values for {name!r} ({per_env[name]} and {number})")
            per_env[name] = int(number)
        else:
            if default is not None:
                raise ValueError(
                    f"--episodes: one N applies to every env, got {default} and {number}; give ENV=N for each env's own"
                )
            default = int(number)
    names = set(envs or ()) | set(per_env) | set(suites.ENVS)
    return {env: per_env.get(env, default) for env in names if per_env.get(env, default) is not None}


def check_device(device: str) -> None:
    """A ``--device`` torch can use here, else a ValueError that says why (before any run starts and fails on it)."""
    import torch

    try:
        kind = torch.device(device).type
    except RuntimeError as error:
        raise ValueError(f"--device {device!r} is not a torch device (cpu, cuda, cuda:1...): {error}") from None
    if kind == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"--device {device!r}: torch sees no CUDA GPU here (torch.cuda.is_available() is False)")
    if kind not in ("cpu", "cuda"):
        raise ValueError(f"--device {device!r}: the benchmark runs on cpu or cuda")
