"""The README's answer at a glance, from the committed runs of the study ``benchmarks/results/sweep/``.

Per env of the ``matched`` suite (and SAC at 20 gradient steps per env step of ``high_utd``, where it ran): the median
number of episodes until the best-so-far first reached the level (``tables.first_reaches``, as the matched report
counts them; the level is ``tables.ANSWER_LEVELS``, else the env's threshold), and the median CPU seconds per run.
A run that never reached the level counts as beyond the budget, so a median beyond it reads "not reached (k/n)".

Writes ``answer.md`` (the table) and ``answer.png`` (the figure) into the study's folder, and the table into the
README between ``<!-- answer:start -->`` and ``<!-- answer:end -->`` (``tests/test_readme.py`` keeps them equal).

Usage: ``python -m benchmarks.reports.readme`` (options: ``--results``, ``--out``, ``--readme``)
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.reports import analysis, plots, tables
from benchmarks.runner import suites
from benchmarks.runner.suites import SUITES
from sb3_denfac.envs.facts import env_facts

REPO = Path(__file__).resolve().parents[2]
SWEEP = REPO / "benchmarks" / "results" / "sweep"
README = REPO / "README.md"
START, END = "<!-- answer:start -->", "<!-- answer:end -->"
FIGURE = "answer.png"

#: The columns: (suite, row, header, the figure's colour and marker).
COLUMNS = (
    ("matched", "denfac_default", "DENFAC", "tab:blue", "o"),
    ("matched", "denfac_soft", "SoftDENFAC", "tab:cyan", "D"),
    ("matched", "denfac_rho4", "DENFAC at rho 4", "tab:green", "P"),
    ("matched", "sac", "SAC, 1 step per env step", "tab:orange", "s"),
    ("matched", "sac_matched", "SAC on DENFAC's schedule", "tab:red", "^"),
    ("high_utd", "sac_utd20", "SAC, 20 steps per env step", "tab:purple", "v"),
)
#: The panels: (key, env, the level in words, the figure's panel title). Hopper's second level is the return beyond
#: its survival bonus (1 per step: standing still for 1000 steps earns 1000).
PANELS = (
    ("pendulum", "pendulum", "Pendulum-v1: swung up and held (return ≥ -200)", "Pendulum-v1\nreturn ≥ -200"),
    ("invertedpendulum", "invertedpendulum", "InvertedPendulum-v5: balanced for all 1000 steps",
     "InvertedPendulum-v5\n1000 steps balanced"),
    ("hopper", "hopper", "Hopper-v5: survives a whole episode (return ≥ 1000)", "Hopper-v5\nreturn ≥ 1000 (survives)"),
    ("hopper_moving", "hopper", "Hopper-v5: hops forward (100 beyond the survival bonus)",
     "Hopper-v5\n100 beyond the bonus (hops)"),
    ("reacher", "reacher", "Reacher-v5: return ≥ -3.75 (Gymnasium's threshold)", "Reacher-v5\nreturn ≥ -3.75"),
    ("halfcheetah", "halfcheetah", "Half-Cheetah (paper's): return ≥ 1000", "Half-Cheetah (paper's)\nreturn ≥ 1000"),
    ("cartpole", "cartpole", "CartPole (paper's): pole kept up (return ≥ -500)", "CartPole (paper's)\nreturn ≥ -500"),
    ("acrobot", "acrobot", "Acrobot (paper's): goal reached", "Acrobot (paper's)\ngoal reached"),
)  # fmt: skip
_BEYOND = 1e9  # the episodes of a run that never reached the level: any quantile that weighs it lies past the budget


def measure(results_dir: str | Path = SWEEP) -> pd.DataFrame:
    """One row per (panel, column) that has runs: runs, runs that reached the level, quartiles of the episodes to it
    (past ``budget`` where they weigh a run that did not), median CPU seconds per run, the budget in episodes."""
    episodes, runs = analysis.load(results_dir)
    runs = runs[runs["trained"]]
    rows = []
    for key, env, _, _ in PANELS:
        facts = env_facts(env)
        if key == "hopper_moving":
            moving = episodes["env"] == env
            column, level, lower = "beyond", tables.BEYOND_BONUS_LEVEL, False
            data = episodes[moving].assign(
                beyond=tables.beyond_survival(
                    episodes.loc[moving, "return"], episodes.loc[moving, "length"], facts.survival_bonus
                )
            )
        else:
            data, column, lower = episodes, "best_so_far", facts.lower_is_better
            level = tables.ANSWER_LEVELS.get(env, facts.threshold)
        for suite_name, algo, *_ in COLUMNS:
            suite = SUITES[suite_name]
            if env not in suite.envs:
                continue
            r = runs[(runs["algo"] == algo) & (runs["env"] == env) & runs["seed"].isin(suite.seeds(algo))]
            r = r[[tables._of_budget(suite, run) for run in r.itertuples()]]  # a smoke run is no seed of the cell
            if r.empty:
                continue
            hits = tables.first_reaches(data, r, column, level, lower)
            values = np.full(len(r), _BEYOND)
            values[: len(hits)] = hits["episode"] if len(hits) else []
            q1, median, q3 = np.quantile(values, [0.25, 0.5, 0.75])
            budget = suites.budget(env, None, suite).episodes
            rows.append(
                {"panel": key, "algo": algo, "runs": len(r), "reached": len(hits), "q1": q1, "median": median, "q3": q3,
                 "cpu": float(r["cpu_time"].median()), "budget": budget}
            )  # fmt: skip
    return pd.DataFrame(rows)


def _cell(row: pd.Series | None) -> str:
    if row is None:
        return "–"
    if row["median"] > row["budget"]:
        return f"not reached ({row['reached']}/{row['runs']})"
    return f"{row['median']:.0f}"


def table(m: pd.DataFrame) -> str:
    """The answer as markdown: one row per panel, one median per cell, and the range of the median CPU per run."""
    found = {(row.panel, row.algo): row for _, row in m.iterrows()}
    header = ["env: level (episodes per run)", *(column[2] for column in COLUMNS)]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for key, env, words, _ in PANELS:
        budget = suites.budget(env).episodes
        cells = [_cell(found.get((key, algo))) for _, algo, *_ in COLUMNS]
        lines.append(f"| {words} ({budget}) | " + " | ".join(cells) + " |")
    cpu = []
    for _, algo, *_ in COLUMNS:
        mine = m.loc[m["algo"] == algo, "cpu"]
        cpu.append(f"{mine.min():,.0f}-{mine.max():,.0f} s" if len(mine) else "–")
    lines.append("| median CPU per run, range over the envs | " + " | ".join(cpu) + " |")
    return "\n".join(lines) + "\n"


def body(table_md: str, folder: str) -> str:
    """The figure, what a cell is, the table; links relative to the study's ``folder``."""
    return (
        f"![Episodes to the level against CPU per run, per env]({folder}{FIGURE})\n\n"
        "DENFAC's default, its soft actor and DENFAC at 4 critic steps per env step (`presets.DENFAC_DATA_EFFICIENT`) "
        "against SB3's SAC at "
        "three schedules, the same episodes: median episodes until the best-so-far first reached the "
        "level, 5 seeds per cell (a run that did not reach it counts as past the budget), one torch thread per run "
        f"([matched]({folder}matched.md), [high_utd]({folder}high_utd.md) reports):\n\n"
        f"{table_md}"
    )


def block(table_md: str) -> str:
    """The README's generated block: :func:`body` between the markers."""
    return f"{START}\n{body(table_md, 'benchmarks/results/sweep/')}{END}"


def replace_block(text: str, new_block: str) -> str:
    """``text`` with its block between :data:`START` and :data:`END` (both included) replaced by ``new_block``."""
    start, end = text.find(START), text.find(END)
    if start < 0 or end < start:
        raise ValueError(f"the README has no {START} ... {END} block")
    return text[:start] + new_block + text[end + len(END) :]


def figure(m: pd.DataFrame, path: Path) -> None:
    """Per panel: median episodes to the level (interquartile range as error bars) against median CPU seconds per run
    (log scale), one marker per column; hollow and at the budget where most runs did not reach the level."""
    plt = plots._plt()
    from matplotlib.ticker import FuncFormatter, NullFormatter

    fig, axes = plt.subplots(2, 4, figsize=(10, 6.2), sharex=True)
    for ax, (key, env, _, title) in zip(axes.flat, PANELS, strict=True):
        budget = suites.budget(env).episodes
        for _, algo, header, color, marker in COLUMNS:
            row = m[(m["panel"] == key) & (m["algo"] == algo)]
            if row.empty:
                continue
            row = row.iloc[0]
            y = min(row["median"], budget)
            low, high = y - min(row["q1"], budget), min(row["q3"], budget) - y
            ax.errorbar(row["cpu"], y, yerr=[[low], [high]], fmt=marker, color=color, ms=7, capsize=2, lw=1, mew=1.5,
                        mfc="white" if row["median"] > row["budget"] else color, label=header)  # fmt: skip
        ax.axhline(budget, color="grey", ls=":", lw=1)
        ax.set_xscale("log")
        ax.set_xlim(15, 3500)
        ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_ylim(0, budget * 1.08)
        ax.set_title(title, fontsize=8.5)
        ax.tick_params(labelsize=7.5)
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("episodes to the level", fontsize=8)
    for ax in axes[1]:
        ax.set_xlabel("CPU s per run (log)", fontsize=8)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8.5, frameon=False)
    fig.suptitle("Median and quartiles over 5 seeds; hollow at the budget (dotted): most runs did not reach the level",
                 fontsize=9)  # fmt: skip
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--results", default=str(SWEEP), help="the study's folder, with its runs.jsonl.gz")
    parser.add_argument("--out", default=None, help="where answer.md and answer.png go (default: --results)")
    parser.add_argument("--readme", default=str(README), help="the README whose answer block is replaced")
    args = parser.parse_args(argv)
    out = Path(args.out or args.results)
    out.mkdir(parents=True, exist_ok=True)
    m = measure(args.results)
    table_md = table(m)
    (out / "answer.md").write_text(f"# The README's answer (`python -m benchmarks.reports.readme`)\n\n{body(table_md, '')}")
    figure(m, out / FIGURE)
    readme = Path(args.readme)
    readme.write_text(replace_block(readme.read_text(), block(table_md)))
    print(table_md + f"\nwrote {out / 'answer.md'}, {out / FIGURE} and the answer block of {readme}")


if __name__ == "__main__":
    main()
