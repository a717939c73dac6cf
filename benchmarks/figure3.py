"""Figure 3 data-efficiency benchmark: algorithms x envs x seeds, each for a budget of EPISODES.

Every run trains ``ALGO("MlpPolicy", env, **hyperparams)`` with the hyperparameters of ``sb3_denfac/hyperparams/<algo>.yml``
(RL Zoo conventions, keyed by env id, ``default:`` fallback; algorithm defaults when missing, recorded in the results)
and stops after ``--episodes`` episodes. Each finished episode's ``info["paper_performance"]`` is recorded by
``sb3_denfac.common.callbacks.EpisodePerformanceCallback``. One run writes, at its end and atomically,
``runs/<algo>/<env>/seed_<k>.csv`` (one line per episode) then ``seed_<k>.json`` (run metadata, wall time);
a rerun skips runs whose ``.json`` exists, so an interrupted sweep resumes. The zoo's ``evaluations.npz`` is written
under ``zoo/<algo>/<env-id>_<seed>/`` (training episodes, not separate evaluations; extra key ``best_so_far``).
At the end, ``figure3_analysis.py`` writes the plot and the tables.

Examples::

    python benchmarks/figure3.py --algos td3 sac --envs cartpole --seeds 0 1 2 --episodes 50 --workers 2
    python benchmarks/figure3.py --ray-address auto          # same sweep on a Ray cluster (pip install ray)
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import json
import os
import platform
import signal
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

_HERE = Path(__file__).resolve().parent
_REPO = _HERE.parent
for _p in (str(_HERE), str(_REPO)):  # run from a checkout without installing the package
    if _p not in sys.path:
        sys.path.insert(0, _p)

import figure3_analysis as fa  # noqa: E402

# Zoo names of the compared algorithms; models are built by sb3_denfac.zoo.make_model (the RL Zoo's preprocessing).
ALGOS: list[str] = ["denfac", "ddpg", "nfac", "cacla", "cmaes", "td3", "sac", "crossq"]
DEFAULT_ENVS = ["acrobot", "cartpole", "halfcheetah"]
# Used only when hyperparams/<algo>.yml has no entry for the env (recorded as "benchmark fallback" in the results):
# the env's paper gamma, plus exploration noise for TD3, whose SB3 default explores with no noise at all.
FALLBACK_HYPERPARAMS: dict[str, dict[str, Any]] = {"td3": {"noise_type": "normal", "noise_std": 0.1}}
DEFAULT_HYPERPARAMS_DIR = _REPO / "sb3_denfac" / "hyperparams"  # the package's zoo YAML files
DEFAULT_RESULTS_DIR = _HERE / "results" / "figure3"


def load_hyperparams(algo: str, env: str, hyperparams_dir: str | Path) -> tuple[dict[str, Any], str]:
    """Zoo-style lookup: ``<dir>/<algo>.yml``, entry for the env id, else ``default``, else the benchmark fallback
    (algorithm defaults + the env's paper gamma + ``FALLBACK_HYPERPARAMS[algo]``). Returns (hyperparams, source)."""
    import yaml

    spec = fa.env_spec(env)
    path = Path(hyperparams_dir) / f"{algo}.yml"
    data: dict[str, Any] = {}
    if path.exists():
        with path.open() as f:
            data = yaml.safe_load(f) or {}
    if spec.gym_id in data:
        return dict(data[spec.gym_id]), f"{path.name}[{spec.gym_id}]"
    if "default" in data:
        return dict(data["default"]), f"{path.name}[default]"
    fallback = dict(FALLBACK_HYPERPARAMS.get(algo, {}))
    if spec.gamma is not None:
        fallback["gamma"] = spec.gamma
    missing = f"no {spec.gym_id} entry in {path.name}" if path.exists() else f"no {path.name}"
    return fallback, f"benchmark fallback ({missing}): algorithm defaults + {fallback}"


def make_model(algo: str, gym_id: str, hyperparams: dict[str, Any], seed: int, device: str = "cpu") -> Any:
    """Build the env and the model exactly as the RL Zoo would from these hyperparameters (no monitor file)."""
    from sb3_denfac.zoo import make_model as zoo_make_model

    return zoo_make_model(algo, gym_id, hyperparams, seed=seed, device=device)


def run_one(task: dict[str, Any]) -> dict[str, Any]:
    """One (algo, env, seed) run. Returns ``{"task", "meta", "episodes", "log"}`` or ``{"task", "error", "log"}``."""
    import torch

    torch.set_num_threads(1)
    log = io.StringIO()
    try:
        with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            import gymnasium as gym

            import sb3_denfac  # noqa: F401  (registers the paper's envs)
            from sb3_denfac.common.callbacks import EpisodePerformanceCallback

            spec = fa.env_spec(task["env"])
            hyperparams, source = load_hyperparams(task["algo"], task["env"], task["hyperparams_dir"])
            start, cpu_start = time.perf_counter(), time.process_time()
            model = make_model(task["algo"], spec.gym_id, hyperparams, task["seed"])
            callback = EpisodePerformanceCallback(max_episodes=task["episodes"], lower_is_better=spec.lower_is_better)
            max_steps = gym.spec(spec.gym_id).max_episode_steps or 10_000
            # The step budget only guards against a run that never ends an episode; the episode budget stops training.
            model.learn(total_timesteps=task["episodes"] * max_steps + 1, callback=callback)
            wall_time, cpu_time = time.perf_counter() - start, time.process_time() - cpu_start
            model.get_env().close()
    except Exception:
        return {"task": task, "error": traceback.format_exc(), "log": log.getvalue()}
    episodes = callback.records[: task["episodes"]]
    meta = {
        **{k: task[k] for k in ("algo", "env", "seed")},
        "gym_id": spec.gym_id,
        "episodes_requested": task["episodes"],
        "episodes": len(episodes),
        "timesteps": int(model.num_timesteps),
        "wall_time": wall_time,
        "cpu_time": cpu_time,
        "hyperparams_source": source,
        "hyperparams": {k: repr(v) for k, v in hyperparams.items()},
        "lower_is_better": spec.lower_is_better,
        "host": platform.node(),
        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    return {"task": task, "meta": meta, "episodes": episodes, "log": log.getvalue()}


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
        fields = [k for k in fa.EPISODE_FIELDS if k not in ("algo", "env", "seed")]
        writer = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
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


def machine_info() -> dict[str, Any]:
    import torch

    cpu = ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    git: dict[str, Any] = {}
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        run = functools.partial(subprocess.run, cwd=_REPO, capture_output=True, text=True, timeout=10, check=True)
        git["commit"] = run(["git", "rev-parse", "HEAD"]).stdout.strip()
        # the code actually run: uncommitted changes to the package are listed
        git["modified"] = run(["git", "status", "--porcelain", "--", "sb3_denfac"]).stdout.splitlines()
    return {
        "git": git,
        "nproc": os.cpu_count(),
        "cpu_model": cpu or platform.processor(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "platform": platform.platform(),
    }


# ---------------------------------------------------------------------------------------------------------------- sweep


def _init_worker() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)


def _run_local(tasks: list[dict[str, Any]], workers: int, on_result: Callable[[dict[str, Any]], None]) -> None:
    if workers <= 0:
        for task in tasks:
            on_result(run_one(task))
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # spawn: fresh interpreters (no inherited torch thread pools), same behaviour on Linux and macOS
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"), initializer=_init_worker) as pool:
        try:
            futures = [pool.submit(run_one, task) for task in tasks]
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
    # Ship this module's code by value so cluster nodes need only the installed package, not this checkout.
    with contextlib.suppress(Exception):
        ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
        ray.cloudpickle.register_pickle_by_value(fa)
    ray.init(address=None if address == "local" else address, ignore_reinit_error=True)
    try:
        remote = ray.remote(num_cpus=1)(run_one)
        pending = [remote.remote(task) for task in tasks]
        while pending:  # results come back to this driver, which alone writes the files
            done, pending = ray.wait(pending, num_returns=1)
            on_result(ray.get(done[0]))
    finally:
        ray.shutdown()  # disconnects from a cluster; stops a "local" one


def sweep(
    algos: Sequence[str],
    envs: Sequence[str],
    seeds: Sequence[int],
    episodes: int | dict[str, int],
    results_dir: str | Path = DEFAULT_RESULTS_DIR,
    hyperparams_dir: str | Path = DEFAULT_HYPERPARAMS_DIR,
    workers: int = 1,
    ray_address: str | None = None,
    zoo_logs: bool = True,
    analysis: bool = True,
    verbose: int = 1,
) -> dict[str, list]:
    """Run the missing (algo, env, seed) runs; return ``{"done", "skipped", "failed"}`` task lists.

    ``episodes`` is one budget for all envs or ``{env: budget}``. Runs are ordered seed by seed, so a sweep stopped
    early has every (algo, env) at the first seeds.
    """
    unknown = [a for a in algos if a not in ALGOS]
    if unknown:
        raise ValueError(f"unknown --algos {unknown}; choose from {sorted(ALGOS)}")
    budgets = {env: episodes for env in envs} if isinstance(episodes, int) else dict(episodes)
    for env in envs:
        if budgets.get(env, 0) < 1:
            raise ValueError(f"--episodes for {env} must be >= 1, got {budgets.get(env)}")
    results_dir = Path(results_dir)
    results_dir.mkdir(parents=True, exist_ok=True)
    status: dict[str, list] = {"done": [], "skipped": [], "failed": []}
    tasks = []
    for seed in seeds:
        for env in envs:
            for algo in algos:
                task = {
                    "algo": algo,
                    "env": env,
                    "seed": int(seed),
                    "episodes": int(budgets[env]),
                    "hyperparams_dir": str(Path(hyperparams_dir).resolve()),
                }
                if run_paths(results_dir, algo, env, seed)[1].exists():
                    status["skipped"].append(task)
                else:
                    tasks.append(task)
    if verbose:
        print(f"{len(tasks)} runs to do, {len(status['skipped'])} already finished (skipped)", flush=True)
    sweep_info = {
        "machine": machine_info(),
        "algos": list(algos),
        "envs": list(envs),
        "seeds": [int(s) for s in seeds],
        "episodes": budgets,
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
                    f"done {t['algo']} {t['env']} seed {t['seed']}: {m['episodes']} episodes, {m['timesteps']} steps, "
                    f"{m['wall_time']:.1f} s, best {best:.4g} ({m['hyperparams_source']})",
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


def parse_episodes(values: Sequence[str], envs: Sequence[str]) -> dict[str, int]:
    """``["60", "halfcheetah=20"]`` -> ``{env: 60, ..., "halfcheetah": 20}`` for the selected envs."""
    default, per_env = None, {}
    for value in values:
        name, sep, number = value.rpartition("=")
        if not number.isdigit():
            raise ValueError(f"--episodes: expected N or ENV=N, got {value!r}")
        if sep:
            per_env[name] = int(number)
        else:
            default = int(number)
    missing = [env for env in envs if env not in per_env and default is None]
    if missing:
        raise ValueError(f"--episodes: no budget for {missing}; give N or ENV=N")
    return {env: per_env.get(env, default) for env in envs}  # type: ignore[misc]


def _exit_on_sigterm(signum: int, frame: Any) -> None:
    raise SystemExit(f"interrupted by signal {signum}; finished runs are kept, rerun the same command to resume")


def main(argv: Sequence[str] | None = None) -> int:
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algos", nargs="+", default=list(ALGOS), help=f"subset of {list(ALGOS)}")
    parser.add_argument(
        "--envs", nargs="+", default=DEFAULT_ENVS, help=f"short names {list(fa.ENV_SPECS)} or any Gymnasium id"
    )
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument(
        "--episodes",
        nargs="+",
        default=["60", "halfcheetah=20"],
        help="episode budget of each run: N for all envs, ENV=N for one env (e.g. 60 halfcheetah=20)",
    )
    parser.add_argument("--results", default=str(DEFAULT_RESULTS_DIR), help="results folder")
    parser.add_argument("--hyperparams", default=str(DEFAULT_HYPERPARAMS_DIR), help="folder of <algo>.yml files")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="process pool size (0: in this process)")
    parser.add_argument("--ray-address", default=None, help="run on a Ray cluster ('auto', 'ray://host:10001', 'local')")
    parser.add_argument("--no-zoo-logs", action="store_true", help="do not write the zoo's evaluations.npz files")
    parser.add_argument("--no-analysis", action="store_true", help="skip the plot and the tables at the end")
    args = parser.parse_args(argv)
    status = sweep(
        args.algos,
        args.envs,
        args.seeds,
        parse_episodes(args.episodes, args.envs),
        results_dir=args.results,
        hyperparams_dir=args.hyperparams,
        workers=args.workers,
        ray_address=args.ray_address,
        zoo_logs=not args.no_zoo_logs,
        analysis=not args.no_analysis,
    )
    print(f"finished: {len(status['done'])} done, {len(status['skipped'])} skipped, {len(status['failed'])} failed")
    return 1 if status["failed"] else 0


if __name__ == "__main__":
    sys.exit(main())
