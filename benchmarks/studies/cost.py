"""Cost of the benchmark sweep, measured before running it: CPU seconds per run for each algorithm x env, and the plan.

Runs every algorithm on every env for a few episodes with the sweep's own runner (``benchmarks.runner.task.run_one``, one
torch thread, results in ``benchmarks/results/cost/runs.jsonl.gz``, resumable), then extrapolates each run to its full budget:

- ``step`` model (TD3, SAC, CrossQ, DDPG, CACLA+: online updates): a constant cost per environment step once
  learning has started, measured on the episodes after the warm-up;
- ``episode`` model (NFAC+ refits on the last episode, CMA-ES only acts and updates per generation, the SB3 peers on
  DENFAC's schedule take a fixed number of gradient steps at every episode end): an episode costs ``a * steps + c``;
- ``replay`` model (DENFAC): an episode costs ``a * steps + b * |D| + c``, with ``|D| = min(buffer_size, steps so
  far)``: its end-of-episode update sweeps the whole replay memory, so it grows until D is full. Where the short run
  never half-filled D, ``b`` is taken from the same row's largest measured value on another env.
  ``a, b, c`` are fitted by non-negative least squares on the measured episodes.

Both extrapolations assume full-length episodes (an upper bound where episodes end early: CartPole and
InvertedPendulum falls, the Acrobot goal). Writes ``benchmarks/results/cost/sweep_plan.md`` and ``sweep_plan.csv``.

Usage: ``python -m benchmarks.studies.cost [--algos ...] [--envs ...] [--plan-only]``
"""

from __future__ import annotations

import argparse
import inspect
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.reports import analysis as fa
from benchmarks.runner import store, suites
from benchmarks.runner.algos import ALGOS
from benchmarks.runner.sweep import sweep
from sb3_denfac.envs.facts import env_facts

RESULTS = Path(__file__).resolve().parents[1] / "results"
COST_DIR = RESULTS / "cost"
SWEEP_DIR = RESULTS / "sweep"
REPLAY_ALGOS = {"denfac", "denfac_default"}
EPISODE_ALGOS = {"nfac", "cmaes", "sac_matched", "td3_matched"}  # the matched peers train at episode ends
# Episodes measured per env: enough steps past the step algorithms' warm-up, and (DENFAC) past a full D where cheap.
MEASURE_EPISODES = {"acrobot": 3, "cartpole": 10, "halfcheetah": 2, "pendulum": 3, "invertedpendulum": 60, "acrobot75": 10}
MEASURE_EPISODES |= {"hopper": 20, "reacher": 20}
REPLAY_EPISODES = {"acrobot": 14, "cartpole": 20, "halfcheetah": 8, "pendulum": 18, "invertedpendulum": 20, "acrobot75": 20}
REPLAY_EPISODES |= {"hopper": 20, "reacher": 40}
SESSION_CORE_HOURS = 2.5  # one core of one working session, after setup


def measure(algos: list[str], envs: list[str], cost_dir: Path = COST_DIR) -> None:
    for algo in algos:
        table = REPLAY_EPISODES if algo in REPLAY_ALGOS else MEASURE_EPISODES
        sweep([algo], envs, [0], {e: table[e] for e in envs}, results_dir=cost_dir, workers=0)


def _buffer_size(algo: str, hyperparams: dict) -> int:
    if "buffer_size" in hyperparams:
        return int(float(hyperparams["buffer_size"]))
    from sb3_denfac.denfac import DENFAC

    return int(inspect.signature(DENFAC.__init__).parameters["buffer_size"].default)


def extrapolate(episodes: pd.DataFrame, algo: str, env: str, budget: int, hyperparams: dict) -> dict:
    """Estimated CPU seconds of a full run from its measured episodes (see the module docstring)."""
    import ast

    max_steps = _max_steps(env)
    e = episodes.sort_values("episode")
    cpu = e["cpu_time"].to_numpy()
    steps = e["timesteps"].to_numpy()
    lengths = e["length"].to_numpy()
    delta = np.diff(np.concatenate([[0.0], cpu]))
    row = {"algo": algo, "env": env, "budget": budget, "measured_episodes": len(e), "measured_steps": int(steps[-1]),
           "measured_cpu": float(cpu[-1]), "mean_length": float(lengths.mean())}  # fmt: skip
    if algo in REPLAY_ALGOS or algo in EPISODE_ALGOS:
        from scipy.optimize import nnls

        d = _buffer_size(algo, {k: ast.literal_eval(v) for k, v in hyperparams.items()}) if algo in REPLAY_ALGOS else 0
        memory = np.minimum(d, np.concatenate([[0], steps[:-1]]))  # |D| at the update before each episode's end
        coef, _ = nnls(np.column_stack([lengths, memory, np.ones_like(lengths)]), delta)
        full_memory = np.minimum(d, np.arange(budget) * max_steps).sum()
        row.update(
            model=f"replay (D = {d})" if d else "episode",
            per_step=coef[0],
            per_d=coef[1],
            per_episode=coef[2],
            d_fill=float(memory.max() / d) if d else np.nan,
            memory_sum=float(full_memory),
            estimate=float(coef @ [budget * max_steps, full_memory, budget]),
        )
    else:
        starts = int(ast.literal_eval(hyperparams.get("learning_starts", "0")))
        first = int(np.searchsorted(steps, starts, side="right"))  # first episode ending after the warm-up
        first = min(first, len(e) - 2)
        per_step = (cpu[-1] - cpu[first]) / max(steps[-1] - steps[first], 1)
        row.update(
            model="step",
            per_step=per_step,
            per_d=0.0,
            per_episode=0.0,
            d_fill=np.nan,
            estimate=float(per_step * budget * max_steps),
        )
    return row


def _max_steps(env: str) -> int:
    import gymnasium as gym

    import sb3_denfac  # noqa: F401

    return int(gym.spec(env_facts(env).gym_id).max_episode_steps)


def plan(cost_dir: Path = COST_DIR, sweep_dir: Path = SWEEP_DIR) -> pd.DataFrame:
    """Estimates from the runs in ``cost_dir``, checked against the finished runs in ``sweep_dir``; writes
    ``sweep_plan.csv`` and ``sweep_plan.md`` in ``cost_dir``."""
    episodes, runs = fa.load(cost_dir)
    metas = {(r["algo"], r["env"]): r for r in store.read_runs(cost_dir) if r["seed"] == 0}
    rows = []
    for (algo, env), group in episodes.groupby(["algo", "env"]):
        rows.append(extrapolate(group, algo, env, suites.budget(env).episodes, metas[algo, env]["hyperparams"]))
    costs = pd.DataFrame(rows)
    # Where the short run never half-filled D, its cost per |D| is not measured: take the largest one of the same row
    # measured with D at least half full (conservative).
    for i, r in costs.iterrows():
        if r["algo"] in REPLAY_ALGOS and r["d_fill"] < 0.5:
            ref = costs[(costs["algo"] == r["algo"]) & (costs["d_fill"] >= 0.5)]
            if not ref.empty:
                j = ref["per_d"].idxmax()
                costs.loc[i, "per_d"] = ref.loc[j, "per_d"]
                costs.loc[i, "model"] = f"{r['model']}, cost per |D| from {ref.loc[j, 'env']}"
                costs.loc[i, "estimate"] = (
                    r["per_step"] * r["budget"] * _max_steps(r["env"]) + ref.loc[j, "per_d"] * r["memory_sum"]
                )
    costs.to_csv(cost_dir / suites.SWEEP_PLAN.name, index=False)
    lines = [
        "# Sweep plan: measured CPU cost per run and the whole sweep",
        "",
        __doc__.split("\n\n", 1)[1].split("Usage")[0].strip(),
        "",
    ]
    est = costs.pivot(index="algo", columns="env", values="estimate")
    est = est.reindex(index=[a for a in ALGOS if a in est.index], columns=[e for e in suites.ENVS if e in est.columns])
    lines += [
        "Estimated CPU seconds per full run (budget of each env):",
        "",
        est.round(0).reset_index().to_markdown(index=False),
        "",
    ]
    show = costs[
        ["algo", "env", "measured_episodes", "measured_steps", "measured_cpu", "mean_length", "model", "per_step", "per_d"]
    ]
    lines += ["Measurements (one seed):", "", show.to_markdown(index=False, floatfmt=".4g"), ""]
    lookup = {(r.algo, r.env): r.estimate for r in costs.itertuples()}
    _, finished = fa.load(sweep_dir)
    if not finished.empty:
        finished["estimate"] = [lookup.get((a, e), np.nan) for a, e in zip(finished["algo"], finished["env"], strict=True)]
        ratio = finished["cpu_time"] / finished["estimate"]
        lines += [f"Check against the {len(finished)} sweep runs finished so far: measured / estimated CPU seconds, median "
                  f"{ratio.median():.2f} (range {ratio.min():.2f}-{ratio.max():.2f}). The machine was shared (load average "
                  "5-8 on 2 cores), which slows a process's CPU seconds too.", ""]  # fmt: skip
    for suite in suites.SUITES.values():
        if suite.study != "sweep":
            continue
        done = set(zip(finished["algo"], finished["env"], finished["seed"], strict=True))
        cells = suite.cells()
        estimate = {c: lookup.get(c[:2], np.nan) for c in cells}
        unmeasured = sorted({f"{a} on {e}" for (a, e, _), v in estimate.items() if not np.isfinite(v)})
        total = np.nansum(list(estimate.values()))
        left = np.nansum([v for c, v in estimate.items() if c not in done])
        per_algo = {a: np.nansum([v for c, v in estimate.items() if c[0] == a]) / 3600 for a in suite.algos}
        lines += [f"Suite `{suite.name}`: {len(cells)} runs, about {total / 3600:.1f} CPU hours "
                  f"({total / 3600 / SESSION_CORE_HOURS:.1f} sessions on one core at {SESSION_CORE_HOURS} core hours each); "
                  f"still to run: {left / 3600:.1f} CPU hours. Per algorithm (CPU hours): "
                  + ", ".join(f"{a} {h:.2f}" for a, h in per_algo.items()) + "."
                  + (f" Not measured (left out of the sums): {', '.join(unmeasured)}." if unmeasured else ""), ""]  # fmt: skip
    (cost_dir / "sweep_plan.md").write_text("\n".join(lines))
    return costs


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    rows = [a for a, row in ALGOS.items() if row.family != "ablation"]
    parser.add_argument("--algos", nargs="+", default=rows)
    parser.add_argument("--envs", nargs="+", default=list(suites.ENVS))
    parser.add_argument("--plan-only", action="store_true")
    parser.add_argument("--results", default=str(COST_DIR), help="folder of the cost runs and the plan")
    parser.add_argument("--sweep", default=str(SWEEP_DIR), help="the sweep's results, to check the estimates against")
    args = parser.parse_args(argv)
    cost_dir = Path(args.results)
    if not args.plan_only:
        measure(args.algos, args.envs, cost_dir)
    print(plan(cost_dir, Path(args.sweep)).to_string())
    print((cost_dir / "sweep_plan.md").read_text())


if __name__ == "__main__":
    main()
