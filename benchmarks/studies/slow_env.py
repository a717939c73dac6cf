"""Slow envs: wall-clock time to the level with several envs and the asynchronous update.

    python -m benchmarks.studies.slow_env [--envs Pendulum-v1 Reacher-v5] [--delays 0.02 0.005] [--seeds 0 1 2]
                                  [--rows ...] [--output benchmarks/results/slow_env] [--report-only]

A robot or a slow simulator spends its wall-clock time in the env steps and in waiting, not in DENFAC's update. Here
every env step sleeps a fixed delay (:class:`StepDelay`: 5 ms is a 200 Hz control loop, 20 ms a 50 Hz one), and each
row trains for a budget of finished episodes:

- DENFAC's default with ``n_envs`` 1, 2 and 4 (``SubprocVecEnv`` beyond 1: the delays overlap across processes), with
  the update between episodes or asynchronous (``async_update=True``);
- SB3 SAC on DENFAC's schedule (one env: SB3 refuses episodic training with several), the suites' ``sac_matched``;
- SB3 SAC with 4 envs, ``train_freq=1`` and ``gradient_steps=-1`` (one gradient step per transition collected, the
  ratio of SAC's single-env default), the multi-env peer.

After every step at which an episode ended, the policy that plays next is copied (a state dict, no env step). When
the run ends, each copy is evaluated on 5 deterministic episodes of the env without the delay, so that measuring
costs the run no wall-clock time. The level is the env's threshold (``sb3_denfac.envs.facts``); a run reaches it at
the first copy whose evaluation does, and the wall-clock time, episodes and env steps up to that copy are reported.
``predict()`` latency (the figure a control loop needs) is measured once per env: one thread, a single observation.

Each run is appended to ``<output>/runs.jsonl`` when it ends; a rerun skips the runs there. ``slow_env.md`` is the
report (medians over seeds, ratios to DENFAC with one env in the same table).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

#: (name, algorithm, n_envs, async_update) of every row; SAC's settings come from the suites' rows
ROWS: dict[str, tuple[str, int, bool]] = {
    "denfac_n1": ("denfac", 1, False),
    "denfac_n1_async": ("denfac", 1, True),
    "denfac_n2": ("denfac", 2, False),
    "denfac_n2_async": ("denfac", 2, True),
    "denfac_n4": ("denfac", 4, False),
    "denfac_n4_async": ("denfac", 4, True),
    "sac_matched_n1": ("sac_matched", 1, False),
    "sac_n4": ("sac", 4, False),
}
LABELS = {
    "denfac_n1": "DENFAC, 1 env",
    "denfac_n1_async": "DENFAC, 1 env, async",
    "denfac_n2": "DENFAC, 2 envs",
    "denfac_n2_async": "DENFAC, 2 envs, async",
    "denfac_n4": "DENFAC, 4 envs",
    "denfac_n4_async": "DENFAC, 4 envs, async",
    "sac_matched_n1": "SAC on DENFAC's schedule, 1 env",
    "sac_n4": "SAC, 4 envs, a step per transition",
}
#: finished episodes per run
BUDGETS = {"Pendulum-v1": 30, "Reacher-v5": 100, "Hopper-v5": 40}
EVAL_EPISODES = 5


class StepDelay(gym.Wrapper):
    """Sleeps ``seconds`` in every ``step``: a stand-in for a robot's control period or a slow simulator."""

    def __init__(self, env: gym.Env, seconds: float):
        super().__init__(env)
        self.seconds = seconds

    def step(self, action: Any) -> Any:
        time.sleep(self.seconds)
        return self.env.step(action)


def make_model(row: str, env_id: str, delay: float, seed: int) -> Any:
    """The row's model on ``env_id`` with a ``delay`` per step (its VecEnv: Dummy for one env, Subproc for more)."""
    from stable_baselines3 import SAC
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    from benchmarks.runner.hyperparams import load_hyperparams
    from sb3_denfac import DENFAC

    algo, n_envs, async_update = ROWS[row]
    vec_env_cls = SubprocVecEnv if n_envs > 1 else DummyVecEnv
    env = make_vec_env(
        env_id, n_envs=n_envs, seed=seed, vec_env_cls=vec_env_cls, wrapper_class=StepDelay, wrapper_kwargs=dict(seconds=delay)
    )
    hyperparams, _ = load_hyperparams("denfac_default" if algo == "denfac" else algo, env_id)
    hyperparams = {k: v for k, v in hyperparams.items() if k not in ("n_timesteps", "policy")}
    if algo == "denfac":
        return DENFAC("MlpPolicy", env, seed=seed, async_update=async_update, **hyperparams)
    if n_envs > 1:
        hyperparams.update(train_freq=1, gradient_steps=-1)
    return SAC("MlpPolicy", env, seed=seed, **hyperparams)


def train(model: Any, env_id: str, seed: int, episodes: int) -> dict[str, Any]:
    """One run of ``model`` for ``episodes`` finished episodes: the wall-clock time and the policy after every step at
    which episodes ended, then their evaluation on ``env_id``."""
    import torch as th
    from stable_baselines3.common.callbacks import BaseCallback

    th.set_num_threads(1)
    copies: list[dict[str, Any]] = []
    returns: list[float] = []

    class Watch(BaseCallback):
        ended = False

        def _on_training_start(self) -> None:
            self.start = time.perf_counter()

        def _copy(self) -> None:
            state = {k: v.detach().clone() for k, v in self.model.policy.state_dict().items()}
            wall = time.perf_counter() - self.start
            copies.append(dict(episodes=len(returns), steps=self.num_timesteps, wall=wall, state=state))

        def _on_step(self) -> bool:
            if self.ended:  # the policy that plays after the episode end (sync: updated; async: the last published)
                self._copy()
            infos, dones = self.locals["infos"], self.locals["dones"]
            returns.extend(float(info["episode"]["r"]) for info, done in zip(infos, dones, strict=True) if done)
            self.ended = bool(np.any(dones))
            return len(returns) < episodes

        def _on_training_end(self) -> None:
            self._copy()

    load = os.getloadavg()[0]
    cpu_start = time.process_time()
    model.learn(episodes * 10_000, callback=Watch())
    cpu = time.process_time() - cpu_start
    wall = copies[-1]["wall"]
    model.get_env().close()
    evaluations = evaluate(model, env_id, copies, seed)
    return dict(
        returns=returns,
        evaluations=[
            dict(episodes=c["episodes"], steps=c["steps"], wall=c["wall"], mean=m)
            for c, m in zip(copies, evaluations, strict=True)
        ],
        wall=wall,
        cpu=cpu,
        load=load,
    )


def evaluate(model: Any, env_id: str, copies: list[dict[str, Any]], seed: int) -> list[float]:
    """The mean return of :data:`EVAL_EPISODES` deterministic episodes of each copy, on the env without the delay."""
    from stable_baselines3.common.evaluation import evaluate_policy

    env = gym.make(env_id)
    env.reset(seed=10_000 + seed)
    means = []
    for copy in copies:
        model.policy.load_state_dict(copy["state"])
        mean, _ = evaluate_policy(model, env, n_eval_episodes=EVAL_EPISODES, deterministic=True)
        means.append(float(mean))
    env.close()
    return means


def reached(run: dict[str, Any]) -> dict[str, Any] | None:
    """The first evaluation of ``run`` at the env's level, None if none."""
    from sb3_denfac.envs.facts import env_facts

    facts = env_facts(run["env"])
    return next((e for e in run["evaluations"] if facts.reached(e["mean"])), None)


def predict_latency(env_id: str, calls: int = 2000) -> dict[str, dict[str, float]]:
    """Median and 99th percentile of ``predict(obs, deterministic=True)``, in ms, one thread, one observation."""
    import torch as th
    from stable_baselines3 import SAC

    from sb3_denfac import DENFAC

    th.set_num_threads(1)
    env = gym.make(env_id)
    obs, _ = env.reset(seed=0)
    result = {}
    for name, model in (("denfac", DENFAC("MlpPolicy", env, seed=0)), ("sac", SAC("MlpPolicy", env, seed=0))):
        times = []
        for _ in range(calls):
            start = time.perf_counter()
            model.predict(obs, deterministic=True)
            times.append((time.perf_counter() - start) * 1000)
        result[name] = dict(median_ms=statistics.median(times), p99_ms=float(np.percentile(times, 99)))
    return result


def report(runs: list[dict[str, Any]], latency: dict[str, Any], header: dict[str, Any]) -> str:
    """``slow_env.md``: per env and delay, each row's medians over seeds and its ratio to DENFAC with one env."""
    from sb3_denfac.envs.facts import env_facts

    lines = [
        "# Slow envs: wall-clock time to the level with several envs and the asynchronous update",
        "",
        "Generated by `python -m benchmarks.studies.slow_env` (module docstring: what is measured). "
        f"Runs at commit {header['commit']}, {header['machine']}, one torch thread per run; load average at each run's start: "
        f"{min(r['load'] for r in runs):.1f}-{max(r['load'] for r in runs):.1f}."
        if runs
        else "No runs yet.",
        "",
        "Level: the env's threshold on 5 deterministic episodes of the policy that played after an episode end. "
        "Wall: seconds from the start of `learn()` to that policy; CPU: this process's seconds for the whole run "
        "(the learner thread included; SubprocVecEnv's workers not). Cells: median over seeds (per seed); "
        "'-' a seed that did not reach the level within the budget. Wall s for the budget: the whole run; last "
        "evaluation: the policy after the last episode (medians over seeds).",
        "",
    ]
    groups = sorted({(r["env"], r["delay"]) for r in runs}, key=lambda g: (g[0], -g[1]))
    for env_id, delay in groups:
        facts = env_facts(env_id)
        lines += [
            f"## {env_id}, {delay * 1000:.0f} ms per step (level {facts.threshold:g}, budget {BUDGETS.get(env_id)} episodes)",
            "",
            "| row | wall s to the level | ratio to 1 env | episodes to the level | env steps | CPU s per run "
            "| seeds at the level | wall s for the budget | last evaluation |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        base = None
        for row in ROWS:
            cell = [r for r in runs if (r["env"], r["delay"], r["row"]) == (env_id, delay, row)]
            if not cell:
                continue
            hits = [reached(r) for r in sorted(cell, key=lambda r: r["seed"])]
            walls = [h["wall"] if h else None for h in hits]
            wall = _median(walls)
            if row == "denfac_n1":
                base = wall
            ratio = f"{wall / base:.2f}" if base and wall else "-"
            episodes = _cell([h["episodes"] if h else None for h in hits], ".0f")
            lines.append(
                f"| {LABELS[row]} | {_cell(walls, '.0f')} | {ratio} | {episodes} "
                f"| {_cell([h['steps'] if h else None for h in hits], '.0f')} | {_median([r['cpu'] for r in cell]):.0f} "
                f"| {sum(h is not None for h in hits)} of {len(hits)} | {_median([r['wall'] for r in cell]):.0f} "
                f"| {_median([r['evaluations'][-1]['mean'] for r in cell]):.1f} |"
            )
        lines.append("")
    if latency:
        lines += ["## predict() latency (ms per call, one observation, one thread)", ""]
        lines += ["| env | algorithm | median | 99th percentile |", "|---|---|---|---|"]
        for env_id, per_algo in latency.items():
            for algo, value in per_algo.items():
                lines.append(f"| {env_id} | {algo} | {value['median_ms']:.3f} | {value['p99_ms']:.3f} |")
        lines.append("")
    return "\n".join(lines)


def _median(values: list[Any]) -> float | None:
    """The median counting a None (not reached) as past everything (``stats.median_reached``); None when half or more
    are None."""
    from benchmarks.reports.stats import median_reached

    middle = median_reached(values)
    return None if np.isnan(middle) else middle


def _cell(values: list[Any], fmt: str) -> str:
    median = _median(values)
    each = ", ".join("-" if v is None else format(v, fmt) for v in values)
    return f"{'-' if median is None else format(median, fmt)} ({each})"


def main(argv: list[str] | None = None) -> None:
    from benchmarks.runner.task import git_state, machine_info

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=["Pendulum-v1", "Reacher-v5"])
    parser.add_argument("--delays", nargs="+", type=float, default=[0.02, 0.005])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--rows", nargs="+", default=list(ROWS), choices=list(ROWS))
    parser.add_argument("--episodes", type=int, default=None, help="finished episodes per run (default: BUDGETS)")
    parser.add_argument("--output", default="runs/slow_env")
    parser.add_argument("--report-only", action="store_true")
    args = parser.parse_args(argv)
    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    runs_file = output / "runs.jsonl"
    runs = [json.loads(line) for line in runs_file.read_text().splitlines()] if runs_file.exists() else []
    done = {(r["env"], r["delay"], r["row"], r["seed"]) for r in runs}
    git = git_state()
    if not args.report_only:
        for env_id in args.envs:  # rows interleaved within a seed, so that the machine's load falls on all of them
            for delay in args.delays:
                for seed in args.seeds:
                    for row in args.rows:
                        if (env_id, delay, row, seed) in done:
                            continue
                        episodes = args.episodes or BUDGETS[env_id]
                        result = train(make_model(row, env_id, delay, seed), env_id, seed, episodes)
                        run = dict(env=env_id, delay=delay, row=row, seed=seed, budget=episodes, git=git, **result)
                        with runs_file.open("a") as handle:
                            handle.write(json.dumps(run) + "\n")
                        runs.append(run)
                        hit = reached(run)
                        print(f"{env_id} {delay} {row} seed {seed}: wall {run['wall']:.0f} s, level at {hit}", flush=True)
    latency_file = output / "latency.json"
    latency = json.loads(latency_file.read_text()) if latency_file.exists() else {}
    if not args.report_only:  # this run's envs measured again, the others' kept
        latency.update({env_id: predict_latency(env_id) for env_id in args.envs})
        latency_file.write_text(json.dumps(latency, indent=1))
    machine = machine_info()

    def commit(state: dict[str, Any]) -> str:  # a run's commit, marked when the code run had uncommitted changes
        return state.get("commit", "?")[:7] + (" (with uncommitted changes)" if state.get("modified") else "")

    commits = sorted({commit(r.get("git") or {}) for r in runs}) or [commit(git)]
    header = dict(commit=", ".join(commits), machine=f"{machine['cpu_model']}, {machine['nproc']} cores")
    (output / "slow_env.md").write_text(report(runs, latency, header))
    print(f"report: {output / 'slow_env.md'}")


if __name__ == "__main__":
    main()
