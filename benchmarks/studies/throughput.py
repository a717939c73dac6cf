"""Training speed of benchmark rows side by side: what a run costs on this machine, before a sweep is planned on it.

Each listed env starts ``--copies`` processes that train the row (its suite hyperparameters, one torch thread, on
``--device``) at the same time, as a sweep's workers would. After its ``learning_starts`` steps (updates from then
on), each process waits for the others, counts its environment steps for ``--seconds`` and stops. The table gives each
env's median rate (env steps per second of wall time, updates included) and the seconds a ``--steps`` run would take at
it, so the sweep's runs that fit a lease (a GPU machine lent for minutes, a new server) can be chosen before it starts.

    python -m benchmarks.studies.throughput --algo crossq --envs halfcheetah acrobot --copies 5 --device cuda [--output F.json]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import statistics
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from benchmarks.runner import suites
from benchmarks.runner.algos import ALGOS
from benchmarks.runner.hyperparams import load_hyperparams
from benchmarks.runner.task import git_state, machine_info

_BARRIER: Any = None


def _init(barrier: Any) -> None:
    global _BARRIER
    _BARRIER = barrier


def worker(algo: str, env: str, device: str, seconds: float, seed: int) -> dict[str, Any]:
    """Train ``algo`` on ``env``; return the env steps counted over ``seconds`` once every process is past warm-up."""
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from sb3_denfac.envs.facts import env_facts
    from sb3_denfac.zoo import make_model

    torch.set_num_threads(1)
    hyperparams, _ = load_hyperparams(algo, env)
    model = make_model(ALGOS[algo].zoo_algo, env_facts(env).gym_id, hyperparams, seed=seed, device=device)
    warm_up = int(getattr(model, "learning_starts", 0)) + 1

    class Window(BaseCallback):
        start, steps = 0.0, 0

        def _on_step(self) -> bool:
            if self.num_timesteps == warm_up:
                if _BARRIER is not None:
                    _BARRIER.wait(timeout=600)
                self.start, self.steps = time.perf_counter(), self.num_timesteps
            return not (self.start and time.perf_counter() - self.start > seconds)

    window = Window()
    model.learn(total_timesteps=10**9, callback=window)
    elapsed = time.perf_counter() - window.start
    return {"env": env, "seed": seed, "steps": model.num_timesteps - window.steps, "seconds": elapsed}


def measure(algo: str, envs: list[str], copies: int, device: str, seconds: float) -> list[dict[str, Any]]:
    """Every (env, copy) process at once; one record per process."""
    jobs = [(algo, env, device, seconds, seed) for env in envs for seed in range(copies)]
    context = mp.get_context("spawn")
    barrier = context.Barrier(len(jobs))
    with ProcessPoolExecutor(len(jobs), mp_context=context, initializer=_init, initargs=(barrier,)) as pool:
        return list(pool.map(worker, *zip(*jobs, strict=True)))


def table(records: list[dict[str, Any]], steps: int) -> str:
    lines = [
        f"| env | processes | env steps/s (median) | min | s per {steps:,}-step run |",
        "|---|---|---|---|---|",
    ]
    for env in dict.fromkeys(r["env"] for r in records):
        rates = [r["steps"] / r["seconds"] for r in records if r["env"] == env]
        median = statistics.median(rates)
        lines.append(f"| {env} | {len(rates)} | {median:.1f} | {min(rates):.1f} | {steps / median:.0f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algo", default="crossq", choices=[a for a, r in ALGOS.items() if r.family != "ablation"])
    parser.add_argument("--envs", nargs="+", default=["acrobot"], choices=suites.ENVS)
    parser.add_argument("--copies", type=int, default=1, help="processes per env, all side by side")
    parser.add_argument("--device", default="cpu", help="torch device: cpu or cuda")
    parser.add_argument("--seconds", type=float, default=20.0, help="timed window of each process")
    parser.add_argument("--steps", type=int, default=50_000, help="the run length the table prices")
    parser.add_argument("--output", default=None, help="also append the records, machine and table to this JSON file")
    args = parser.parse_args(argv)
    if args.copies < 1 or args.seconds <= 0:
        parser.error("--copies must be >= 1 and --seconds > 0")
    from benchmarks.runner.sweep import check_device

    try:
        check_device(args.device)
    except ValueError as error:
        parser.error(str(error))
    records = measure(args.algo, args.envs, args.copies, args.device, args.seconds)
    report = table(records, args.steps)
    print(f"{args.algo} on {args.device}, {len(records)} processes side by side\n{report}", flush=True)
    if args.output:
        path = Path(args.output)
        runs = json.loads(path.read_text()) if path.exists() else []
        runs.append(
            {
                "algo": args.algo,
                "device": args.device,
                "copies": args.copies,
                "records": records,
                "table": report,
                "machine": machine_info(args.device),
                "git": git_state(),
                "finished_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            }
        )
        path.write_text(json.dumps(runs, indent=1))


if __name__ == "__main__":
    main()
