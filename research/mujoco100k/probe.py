"""Probe runs for issue #44: DENFAC configurations at the field's budget (Gymnasium MuJoCo, 100k env steps).

A study, not a product feature: it picks which ingredients the data-efficient preset needs before the benchmark's
``mujoco100k`` suite runs them at 5 seeds. It uses the library's public API, and the benchmark's reader of row files
(``benchmarks.rows``) for ``rows.yml``.

Each run trains ``DENFAC("MlpPolicy", env, seed=seed, **row)`` for ``--steps`` env steps and evaluates the policy
deterministically on its own env (``--eval-episodes`` episodes, seeded 10_000 + seed) at the first episode end at or
after every ``--eval-every`` steps (DENFAC's policy only changes at episode ends) and once more at the budget. CPU
seconds are the training process's, evaluations left out. One JSON line per finished run in ``--out``; a rerun skips
the (row, env, seed) cells already there.

    python -m research.mujoco100k.probe --rows default utd1 --envs HalfCheetah-v5 Hopper-v5 --seeds 0
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

from benchmarks.rows import algorithm, load_rows, read_rows

HERE = Path(__file__).parent
ROWS = HERE / "rows.yml"  # rows as data: each is ``base`` (another row, optional) plus its own constructor arguments


class StepEvaluations(BaseCallback):
    """Deterministic evaluations at the first rollout start (after the update) past every ``every`` steps."""

    def __init__(self, env: gym.Env, every: int, episodes: int) -> None:
        super().__init__()
        self.env, self.every, self.episodes = env, every, episodes
        self.next_at = every
        self.evaluations: list[dict[str, Any]] = []
        self.eval_cpu = 0.0
        self.n_episodes = 0

    def mean_return(self, env: gym.Env) -> float:
        """The model's mean deterministic return over ``episodes`` episodes of ``env``; its CPU time goes to
        ``eval_cpu`` (left out of the run's)."""
        before = time.process_time()
        returns, _ = evaluate_policy(self.model, env, n_eval_episodes=self.episodes, deterministic=True)
        self.eval_cpu += time.process_time() - before
        return float(np.mean(returns))

    def evaluate(self) -> None:
        mean = self.mean_return(self.env)
        self.evaluations.append({"timesteps": int(self.model.num_timesteps), "episodes": self.n_episodes, "mean": mean})

    def _on_step(self) -> bool:
        self.n_episodes += int(np.sum(self.locals.get("dones", [False])))
        return True

    def record(self) -> dict[str, Any]:
        """What a study's subclass adds to the run's record (nothing here)."""
        return {}

    def _on_rollout_start(self) -> None:
        if self.model.num_timesteps >= self.next_at:
            self.evaluate()
            while self.next_at <= self.model.num_timesteps:
                self.next_at += self.every


def git_commit() -> str:
    try:
        commit = subprocess.check_output(["git", "rev-parse", "--short", "HEAD"], text=True).strip()
        dirty = subprocess.run(["git", "diff", "--quiet", "--", "sb3_denfac"]).returncode != 0
        return commit + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_one(
    name: str,
    row: dict[str, Any],
    env_id: str,
    seed: int,
    steps: int,
    every: int,
    episodes: int,
    log: Path | None = None,
    algorithm: type | None = None,
    evaluations: type[StepEvaluations] = StepEvaluations,
) -> dict:
    """One run of ``row`` (module docstring); ``algorithm``: a class to build instead of the one its ``algo`` names
    (a study's subclass, e.g. with its own ``updater_classes``), the record keeping the row's ``algo``;
    ``evaluations``: the evaluation callback's class (a study's subclass that evaluates more than the policy)."""
    import torch as th

    import sb3_denfac  # noqa: F401 (registers the envs)

    th.set_num_threads(1)
    row = dict(row)
    algo = row.pop("algo", "denfac")
    env = Monitor(gym.make(env_id))  # the training episodes' returns, for episodes to a level
    eval_env = Monitor(gym.make(env_id))
    eval_env.reset(seed=10_000 + seed)
    if algorithm is not None:
        model = algorithm("MlpPolicy", env, seed=seed, **row)
    elif algo == "denfac":
        from sb3_denfac import DENFAC

        model = DENFAC("MlpPolicy", env, seed=seed, **row)
    elif algo == "soft_denfac":
        from sb3_denfac import SoftDENFAC

        model = SoftDENFAC("MlpPolicy", env, seed=seed, **row)
    elif algo == "sac":
        from stable_baselines3 import SAC

        model = SAC("MlpPolicy", env, seed=seed, **row)
    else:
        raise ValueError(f"unknown algo {algo!r} in row {name!r}")
    if log is not None:  # SB3's logger as CSV: the train/ keys of every update (alpha, losses, K), for diagnostics
        from stable_baselines3.common.logger import configure

        model.set_logger(configure(str(log / f"{name}_{env_id}_{seed}"), ["csv"]))
    callback = evaluations(eval_env, every, episodes)
    cpu, wall = time.process_time(), time.time()
    model.learn(steps, callback=callback)
    cpu, wall = time.process_time() - cpu, time.time() - wall
    if not callback.evaluations or callback.evaluations[-1]["timesteps"] < model.num_timesteps:
        callback.evaluate()
    load = Path("/proc/loadavg").read_text().split()[:3] if Path("/proc/loadavg").exists() else None
    return {
        "row": name,
        "algo": algo,
        "env": env_id,
        "seed": seed,
        "steps": int(model.num_timesteps),
        "episodes": callback.n_episodes,
        "cpu_time": cpu - callback.eval_cpu,
        "wall_time": wall,
        "evaluations": callback.evaluations,
        "episode_returns": [round(float(r), 2) for r in env.get_episode_rewards()],
        "settings": {k: repr(v) for k, v in row.items()},
        "commit": git_commit(),
        "machine": platform.processor() or platform.machine(),
        "load": load,
        **callback.record(),
    }


def done_cells(path: Path) -> set[tuple[str, str, int]]:
    if not path.exists():
        return set()
    cells = set()
    for line in path.read_text().splitlines():
        if line.strip():
            r = json.loads(line)
            cells.add((r["row"], r["env"], r["seed"]))
    return cells


def main(
    argv: list[str] | None = None,
    evaluations: type[StepEvaluations] = StepEvaluations,
    out: Path = HERE / "runs.jsonl",
    description: str | None = None,
) -> None:
    """The command line (module docstring); a study's script passes its own evaluation callback, runs file and
    description."""
    parser = argparse.ArgumentParser(description=description or __doc__.split("\n\n")[0])
    parser.add_argument("--rows", nargs="+", required=True)
    parser.add_argument("--envs", nargs="+", default=["HalfCheetah-v5", "Hopper-v5"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--eval-every", type=int, default=10_000)
    parser.add_argument("--eval-episodes", type=int, default=10)
    parser.add_argument("--out", type=Path, default=out)
    parser.add_argument("--log", type=Path, default=None, help="a folder for each run's SB3 logger output (CSV)")
    parser.add_argument("--rows-file", type=Path, default=ROWS, help="the rows' YAML file (another study's)")
    args = parser.parse_args(argv)
    rows = load_rows(args.rows_file)
    raw = read_rows(args.rows_file)
    for name in rows:  # the algorithm of each row (``algo``, inherited from its base)
        rows[name]["algo"] = algorithm(raw, name)
    unknown = [r for r in args.rows if r not in rows]
    if unknown:
        parser.error(f"unknown rows {unknown}; {args.rows_file} has {sorted(rows)}")
    done = done_cells(args.out)
    for seed in args.seeds:
        for env_id in args.envs:
            for name in args.rows:
                if (name, env_id, seed) in done:
                    continue
                record = run_one(
                    name,
                    rows[name],
                    env_id,
                    seed,
                    args.steps,
                    args.eval_every,
                    args.eval_episodes,
                    args.log,
                    evaluations=evaluations,
                )
                with args.out.open("a") as f:
                    f.write(json.dumps(record) + "\n")
                evals = [round(e["mean"]) for e in record["evaluations"]]
                print(f"{name} {env_id} {seed}: cpu {record['cpu_time']:.0f} s, evals {evals}", flush=True)


if __name__ == "__main__":
    main()
