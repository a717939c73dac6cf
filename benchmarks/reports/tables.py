"""The tables of a study's reports, from its runs (``benchmarks.reports.analysis.load``): per env (:func:`env_table`), the
settings each row was given (:func:`settings_table`), the cells a suite still misses (:func:`missing_cells`), and the
``matched`` suite's answer to the user (:func:`answer_table`). ``benchmarks.reports.analysis`` writes them into the reports.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from benchmarks.runner import suites
from benchmarks.runner.algos import ALGOS
from benchmarks.runner.suites import SUITES, Suite, estimated_cost
from sb3_denfac.envs.facts import env_facts

#: The rows of the user's answer (suite ``matched``): DENFAC's default (its soft actor, the data-efficient preset, DENFAC
#: at rho 4) against SAC at each schedule.
ANSWER_ALGOS = (
    "denfac_default",
    "denfac_default04",
    "denfac_soft",
    "denfac_soft_min",
    "denfac_data_efficient",
    "denfac_rho4",
    "sac",
    "sac_matched",
    "td3_matched",
)
#: Its levels where the env's threshold says little about "learnt the task": Half-Cheetah's 50 is "runs forward at
#: all", Hopper's 3800 (Gymnasium's) is out of reach in 100 episodes; its 1000 is "survives about the whole episode"
#: (standing still for 1000 steps earns 1000 of survival bonus), so its cells also give the return beyond that bonus.
ANSWER_LEVELS = {"halfcheetah": 1000.0, "hopper": 1000.0}
#: The second level of an env that pays a survival bonus: one episode earning this much beyond the bonus, i.e. moving,
#: not only standing (Hopper-v5 pays its forward velocity per step of dt = 0.008 s: 100 is about 0.8 m forward).
BEYOND_BONUS_LEVEL = 100.0


def beyond_survival(returns: pd.Series, lengths: pd.Series, survival_bonus: float | None) -> pd.Series:
    """The part of each episode's return earned beyond the env's survival bonus (``EnvFacts.survival_bonus`` per
    step): return - bonus x length; NaN where the env pays no such bonus."""
    if survival_bonus is None:
        return pd.Series(np.nan, index=returns.index)
    return returns.astype(float) - survival_bonus * lengths.astype(float)


def row_order(algos) -> list[str]:
    known = list(ALGOS)
    return sorted(set(algos), key=lambda a: (known.index(a) if a in known else len(known), a))


def env_order(envs, known: Sequence[str] | None = None) -> list[str]:
    """``envs`` without repeats: those of ``known`` (default: the figure3 suite's) in its order, then any other sorted."""
    known = list(SUITES["figure3"].envs if known is None else known)
    return sorted(set(envs), key=lambda e: (known.index(e) if e in known else len(known), e))


def provenance(record: dict[str, Any]) -> dict[str, Any]:
    """Where a run ran: its machine ("cpu (n cores)"), commit (7 characters) and load average at its end (the highest of
    the 1, 5 and 15 minutes'), for a report's header (:func:`provenance_line`)."""
    machine = {"cpu_model": "?", "nproc": "?", **(record.get("machine") or {})}
    return {
        "machine": "{cpu_model} ({nproc} cores)".format_map(machine),
        "commit": ((record.get("git") or {}).get("commit") or "")[:7],
        "load": max((record.get("load_average") or {}).get("end") or [float("nan")]),
    }


def provenance_line(runs: pd.DataFrame) -> str:
    """The report header's line on the machines, commits and load of ``runs`` (columns of :func:`provenance`)."""
    return (
        f"Machines: {', '.join(sorted(set(runs['machine'])))}; commits: {', '.join(sorted(set(runs['commit'])))}; load "
        f"average at the runs' ends {runs['load'].min():.1f}-{runs['load'].max():.1f} (CPU seconds are inflated on a busy "
        "machine: compare them within a table, as ratios).\n"
    )


def _quartiles(values: pd.Series, digits: int = 1) -> str:
    values = values.dropna()
    if values.empty:
        return "–"
    q1, med, q3 = values.quantile([0.25, 0.5, 0.75])
    return f"{med:.{digits}f} [{q1:.{digits}f}, {q3:.{digits}f}]"


def env_table(runs: pd.DataFrame, env: str) -> pd.DataFrame:
    """One row per algorithm: runs, seeds, and median [Q1, Q3] of each measure, threshold reached, CPU cost."""
    facts = env_facts(env)
    rows = []
    for algo in row_order(runs.loc[runs["env"] == env, "algo"]):
        r = runs[(runs["env"] == env) & (runs["algo"] == algo)]
        reached = r["episodes_to_threshold"].notna()
        rows.append(
            {
                "algo": ALGOS[algo].label if algo in ALGOS else algo,
                "runs (seeds)": f"{len(r)} ({_seed_list(r['seed'])})",
                "best so far": _quartiles(r["final_best"]),
                "last-10 mean": _quartiles(r["last10"]),
                "deterministic eval (last)": _quartiles(r["final_eval"]),
                "threshold: episodes (reached/runs)": (
                    f"{r.loc[reached, 'episodes_to_threshold'].median():.0f} ({reached.sum()}/{len(r)})"
                    if reached.any()
                    else f"– (0/{len(r)})"
                )
                if facts.threshold is not None
                else "",
                "fall-back fraction": _quartiles(r["fall_back"], 2) if facts.threshold is not None else "",
                **(
                    {"last-10 beyond the survival bonus": _quartiles(r["last10_beyond_survival"])}
                    if facts.survival_bonus is not None
                    else {}
                ),
                "CPU s per run": _quartiles(r["cpu_time"], 0),
                "CPU s per episode": _quartiles(r["cpu_per_episode"], 2),
            }
        )
    return pd.DataFrame(rows)


def first_reaches(episodes: pd.DataFrame, r: pd.DataFrame, column: str, level: float, lower_is_better: bool) -> pd.DataFrame:
    """The first episode (its row of ``episodes``: episode, timesteps, cumulative cpu_time, ...) whose cumulative best
    of ``column`` reaches ``level``, for each run of ``r`` (one algo and env) that reached it."""
    firsts = []
    for seed in r["seed"]:
        e = episodes[(episodes["algo"] == r["algo"].iloc[0]) & (episodes["env"] == r["env"].iloc[0])]
        e = e[e["seed"] == seed]
        best = e[column].cummin() if lower_is_better else e[column].cummax()
        reached = e[best < level] if lower_is_better else e[best >= level]
        if len(reached):
            firsts.append(reached.iloc[0])
    return pd.DataFrame(firsts)


def _first_reach(episodes: pd.DataFrame, r: pd.DataFrame, column: str, level: float, lower_is_better: bool) -> str:
    """Medians of the episodes, env steps and CPU seconds at the first episode whose cumulative best of ``column``
    reaches ``level``, over the runs ``r`` that reached it (reached/runs)."""
    hit = first_reaches(episodes, r, column, level, lower_is_better)
    if not len(hit):
        return f"never (0/{len(r)})"
    return (
        f"{hit['episode'].median():.0f} ep, {hit['timesteps'].median():.0f} steps, "
        f"{hit['cpu_time'].median():.0f} CPU s ({len(hit)}/{len(r)})"
    )


def answer_table(episodes: pd.DataFrame, runs: pd.DataFrame, algos: Sequence[str] = ANSWER_ALGOS) -> pd.DataFrame:
    """Per env, per algorithm: medians over the runs that reached :data:`ANSWER_LEVELS` (else the env's threshold) of
    the episodes, env steps and CPU seconds to first reach it (reached/runs), and over all runs the fall-back fraction
    after the threshold, the last-10 mean (of the exploring episodes) and the last deterministic evaluation (of the
    final policy, ``run_one``'s ``eval_episodes``). An env that pays a survival bonus gets a second row: the first episode
    earning :data:`BEYOND_BONUS_LEVEL` beyond it, and the last-10 mean beyond it."""
    rows = []
    for env in env_order(runs["env"]):
        facts = env_facts(env)
        level = ANSWER_LEVELS.get(env, facts.threshold)
        if level is None:
            continue
        op = "<" if facts.lower_is_better else ">="
        row = {"env": env, "level": f"{op} {level:g}"}
        moving = {"env": env, "level": f"beyond the survival bonus >= {BEYOND_BONUS_LEVEL:g}"}
        if facts.survival_bonus is not None:
            with_beyond = episodes.assign(
                beyond=beyond_survival(episodes["return"], episodes["length"], facts.survival_bonus)
                if {"return", "length"} <= set(episodes)
                else np.nan
            )
        for algo in algos:
            r = runs[(runs["env"] == env) & (runs["algo"] == algo)]
            if r.empty:
                row[ALGOS[algo].label] = moving[ALGOS[algo].label] = "–"
                continue
            reach = _first_reach(episodes, r, "best_so_far", level, facts.lower_is_better)
            fall_back = f"{r['fall_back'].median():.2f}" if r["fall_back"].notna().any() else "–"
            cell = f"{reach}; fall-back {fall_back}; last-10 {r['last10'].median():.4g}"
            if facts.survival_bonus is not None:
                beyond = r["last10_beyond_survival"].median()
                cell += f" ({beyond:.4g} beyond the survival bonus)"
                moving_reach = _first_reach(with_beyond, r, "beyond", BEYOND_BONUS_LEVEL, False)
                moving[ALGOS[algo].label] = f"{moving_reach}; last-10 {beyond:.4g}"
            if r["final_eval"].notna().any():
                cell += f"; final eval {r['final_eval'].median():.4g}"
            row[ALGOS[algo].label] = cell
        rows.append(row)
        if facts.survival_bonus is not None:
            rows.append(moving)
    return pd.DataFrame(rows)


def _seed_list(seeds: pd.Series) -> str:
    s = sorted(int(x) for x in seeds)
    return f"{s[0]}-{s[-1]}" if s == list(range(s[0], s[-1] + 1)) and len(s) > 2 else ",".join(map(str, s))


def settings_table(runs: pd.DataFrame) -> pd.DataFrame:
    """What each algorithm was given on each env: the YAML entry the runs were built from."""
    table = runs.groupby(["algo", "env"])["hyperparams_source"].agg(lambda s: "; ".join(sorted(set(s)))).unstack("env")
    table = table.reindex(index=row_order(table.index), columns=env_order(table.columns)).fillna("–")
    table.index = [ALGOS[a].label if a in ALGOS else a for a in table.index]
    return table.rename_axis("algo").reset_index()


def markdown(df: pd.DataFrame) -> str:
    return df.to_markdown(index=False) if not df.empty else "(no runs)"


def _of_budget(suite: Suite, run: Any) -> bool:
    """Whether ``run`` (a row of the runs frame) was made for its env's budget in ``suite`` (True where the frame does
    not record the budget)."""
    episodes, timesteps = getattr(run, "episodes_requested", None), getattr(run, "timesteps_requested", None)
    if episodes is None and timesteps is None:
        return True
    budget = suites.budget(run.env, None, suite)
    if budget.timesteps is not None:
        return timesteps is not None and not pd.isna(timesteps) and int(timesteps) == budget.timesteps
    return (timesteps is None or pd.isna(timesteps)) and int(episodes) == budget.episodes


def missing_cells(suite: Suite, runs: pd.DataFrame) -> pd.DataFrame:
    """Finished/wanted seeds per (algo, env) of the suite where incomplete, with the CPU hours still needed: the median
    CPU seconds of the cell's finished runs times the seeds left, or where it has none, the plan's estimate
    (``benchmarks.studies.cost``, full-length episodes: an upper bound where episodes end early), marked <=. A cell with
    neither is marked "cost not measured" and counted apart in the total.

    Only runs made for the cell's budget in the suite count (where ``runs`` says, ``analysis.BUDGET_FIELDS``): a
    3-episode smoke run of a 40-episode cell is neither one of its seeds nor a measure of its cost."""
    runs = runs[[_of_budget(suite, run) for run in runs.itertuples()]] if not runs.empty else runs
    done = set(zip(runs["algo"], runs["env"], runs["seed"], strict=True))
    measured = runs.groupby(["algo", "env"])["cpu_time"].median().to_dict() if not runs.empty else {}
    rows = {}
    for algo in suite.algos:
        want = suite.seeds(algo)
        row, hours, unmeasured = {}, 0.0, 0
        for env in suite.envs:
            left = sum((algo, env, s) not in done for s in want)
            row[env] = f"{len(want) - left}/{len(want)}"
            if not left:
                continue
            cost = left * measured.get((algo, env), estimated_cost(algo, env)) / 3600
            if np.isfinite(cost):
                hours += cost
                row[env] += f", {'' if (algo, env) in measured else '<='}{cost:.2f} h"
            else:
                unmeasured += 1
                row[env] += ", cost not measured"
        if hours or unmeasured:
            total = f"{hours:.2f}" + (f" + {unmeasured} cells not measured" if unmeasured else "")
            rows[ALGOS[algo].label] = {**row, "CPU hours left": total}
    return pd.DataFrame.from_dict(rows, orient="index").rename_axis("algo").reset_index() if rows else pd.DataFrame()
