"""Torch threads inside ``learn()``: the README's example with the package's default against explicit one-thread torch.

    python -m research.torch_threads.threads [--steps 2000] [--repeats 3] [--busy] [--output FILE.json]

Each run is a fresh process (torch's thread pool is set once per process) timing
``DENFAC("MlpPolicy", gym.make("Pendulum-v1")).learn(steps)``, in three variants run in rotating order:

- ``default``: the example as written (torch's default threads; DENFAC's ``torch_threads`` default, 1 inside learn);
- ``explicit``: ``torch.set_num_threads(1)`` before the example (what users had to know);
- ``before``: ``torch_threads=None``, torch's default threads inside learn (the behaviour before the setting existed).

``--busy`` starts one CPU-burning process per spare core (``python -c "while True: pass"``) for the measurement and
ends it by its PID. Writes the runs, their medians and the machine's load to ``--output`` (JSON).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

VARIANTS = ("default", "explicit", "before")


def worker(variant: str, steps: int, seed: int) -> dict[str, Any]:
    """One timed ``learn(steps)`` of the README example in ``variant``; returns the seconds and torch's threads."""
    import gymnasium as gym
    import torch

    from sb3_denfac import DENFAC

    if variant == "explicit":
        torch.set_num_threads(1)
    kwargs = {"torch_threads": None} if variant == "before" else {}
    model = DENFAC("MlpPolicy", gym.make("Pendulum-v1"), seed=seed, **kwargs)
    threads_before = torch.get_num_threads()
    start = time.perf_counter()
    model.learn(steps)
    seconds = time.perf_counter() - start
    return {"variant": variant, "seconds": seconds, "threads_outside_learn": threads_before, "seed": seed}


def run_one(variant: str, steps: int, seed: int) -> dict[str, Any]:
    command = [
        sys.executable,
        "-m",
        "research.torch_threads.threads",
        "--worker",
        variant,
        "--steps",
        str(steps),
        "--seed",
        str(seed),
    ]
    env = {key: value for key, value in os.environ.items() if key not in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    out = subprocess.run(command, capture_output=True, text=True, check=True, env=env, cwd=Path(__file__).resolve().parents[2])
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--busy", action="store_true", help="burn the spare cores with processes of our own")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    parser.add_argument("--output", type=Path, default=Path("research/torch_threads/threads.json"))
    parser.add_argument("--worker", choices=VARIANTS, help=argparse.SUPPRESS)
    parser.add_argument("--seed", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        result = worker(args.worker, args.steps, args.seed)
        print(json.dumps(result))
        return result

    from benchmarks.runner.task import git_state, machine_info

    burners: list[subprocess.Popen] = []
    runs: list[dict[str, Any]] = []
    load_start = os.getloadavg()
    try:
        if args.busy:
            burners = [
                subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(max(1, (os.cpu_count() or 2) - 1))
            ]
            time.sleep(1.0)
        for repeat in range(args.repeats):
            order = args.variants[repeat % len(args.variants) :] + args.variants[: repeat % len(args.variants)]
            for variant in order:
                result = run_one(variant, args.steps, seed=repeat)
                result["repeat"] = repeat
                runs.append(result)
                print(f"repeat {repeat} {variant:8s} {result['seconds']:7.2f} s", flush=True)
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()
    medians = {v: statistics.median(r["seconds"] for r in runs if r["variant"] == v) for v in args.variants}
    report = {
        "steps": args.steps,
        "busy": args.busy,
        "burners": len(burners),
        "loadavg_start": load_start,
        "loadavg_end": os.getloadavg(),
        "medians_s": medians,
        "runs": runs,
        "git": git_state(),
        "machine": machine_info(),
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(report, indent=2) + "\n")
    print(json.dumps(medians))
    return report


if __name__ == "__main__":
    main()
