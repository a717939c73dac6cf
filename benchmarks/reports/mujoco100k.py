"""The report of the field's data-efficiency benchmark (suite ``mujoco100k``): Gymnasium MuJoCo at 100k env steps.

Reads the study's runs file (``results/mujoco100k/runs.jsonl.gz``) and writes next to it ``mujoco100k.md`` and
``mujoco100k.png``. Per (row, env), over seeds:

- **final**: the mean return of the evaluation at the budget (10 deterministic episodes), the field's figure;
- **best**: the best evaluation of the run, and **final / best** (does a run hold what it finds?);
- **mean of evaluations**: the area under the evaluation curve per evaluation (the evaluations every 10k steps and the
  final one, averaged: how early the return came, not only where it ended);
- **CPU s**: training CPU seconds per run (evaluations left out), one torch thread.

The published figures (``configs/frontier_100k.csv``: the authors' per-seed results on the v4 envs, read once, with
their source) are the reference: in the table, the last one logged at or before 100k steps; in the figure, their curves.

    python -m benchmarks.reports.mujoco100k [--results benchmarks/results/mujoco100k]
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.reports.frontier import (
    FRONTIER_METHODS,
    frontier,
    frontier_at_budget,
    published,
    published_mean,
    reference_table,
)
from benchmarks.reports.tables import env_order, provenance, provenance_line
from benchmarks.runner import store
from benchmarks.runner.algos import ALGOS
from benchmarks.runner.suites import MUJOCO100K_ENVS

#: the suite's results folder (the report's default)
RESULTS = Path(__file__).resolve().parents[1] / "results" / "mujoco100k"


def load(results_dir: str | Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(evaluations, runs) of the study's finished runs with a budget of env steps.

    evaluations: algo, env, seed, timesteps, score (mean of the evaluation's episodes); runs: one row per run with
    final, best, final_over_best, mean_eval, cpu_time, episodes, gradient_steps, timesteps."""
    evals, runs = [], []
    for record in store.read_runs(results_dir):
        if not record.get("timesteps_requested") or not record.get("evaluations"):  # read_runs: finished runs only
            continue
        key = {k: record[k] for k in ("algo", "env", "seed")}
        scores = [(e["timesteps"], float(np.mean(e["scores"]))) for e in record["evaluations"]]
        evals += [{**key, "timesteps": t, "score": s} for t, s in scores]
        values = np.array([s for _, s in scores])
        final, best = values[-1], values.max()
        runs.append(
            {
                **key,
                "final": final,
                "best": best,
                "final_over_best": final / best if best > 0 else float("nan"),
                "mean_eval": values.mean(),
                "cpu_time": record["cpu_time"],
                "episodes": record["n_episodes"],
                "gradient_steps": record.get("gradient_steps"),
                "timesteps": record["timesteps"],
                **provenance(record),
            }
        )
    evals, runs = pd.DataFrame(evals), pd.DataFrame(runs)
    if not runs.empty:
        reached = steps_to_level(evals).set_index(["algo", "env", "seed"])["steps"]
        runs["to_sac_level"] = [reached.get(key, np.nan) for key in zip(runs["algo"], runs["env"], runs["seed"], strict=True)]
    return evals, runs


def _envs(frame: pd.DataFrame) -> list[str]:
    """The envs of ``frame``: the suite's in its order, then any other."""
    return env_order(frame["env"], MUJOCO100K_ENVS)


def _label(algo: str) -> str:
    return ALGOS[algo].label if algo in ALGOS else algo


def _median(values: pd.Series) -> float:
    """The median of the values that are not NaN (final / best is NaN where the best return is not positive)."""
    values = values.dropna()
    return float(values.median()) if len(values) else float("nan")


def _per_seed_steps(values: pd.Series) -> str:
    return ", ".join("-" if np.isnan(v) else f"{v / 1000:.0f}k" for v in values)


def _per_seed(values: pd.Series, digits: int = 0) -> str:
    return ", ".join(f"{v:.{digits}f}" for v in values)


def env_table(runs: pd.DataFrame, env: str) -> pd.DataFrame:
    """One line per row on ``env``: medians over seeds, with the per-seed finals."""
    lines = []
    for algo, r in runs[runs["env"] == env].groupby("algo", sort=False):
        r = r.sort_values("seed")
        lines.append(
            {
                "row": _label(algo),
                "seeds": len(r),
                "final, median (per seed)": f"{r['final'].median():.0f} ({_per_seed(r['final'])})",
                "best, median": f"{r['best'].median():.0f}",
                "final / best, median": f"{_median(r['final_over_best']):.2f}",
                "mean of evaluations, median": f"{r['mean_eval'].median():.0f}",
                "CPU s per run, median": f"{r['cpu_time'].median():.0f}",
                "episodes, median": f"{r['episodes'].median():.0f}",
                "env steps to the published SAC's 100k return, per seed": _per_seed_steps(r["to_sac_level"]),
            }
        )
    return pd.DataFrame(lines)


def targets(runs: pd.DataFrame, algo: str = "denfac_data_efficient", peer: str = "sac_zoo") -> list[str]:
    """The data-efficient preset's targets for ``algo`` (docs/denfac.md), each met or missed with its figures (medians
    over seeds): at least the published SAC and SB3 SAC here (``peer``), at least half the published CrossQ, final /
    best at least 0.8, and CPU per run at most ``peer``'s."""
    mine = runs[runs["algo"] == algo]
    if mine.empty:
        return [f"- no finished runs of `{algo}` yet"]
    ref = frontier_at_budget()
    theirs = runs[runs["algo"] == peer].groupby("env")
    peer_n, peer_final, peer_cpu = theirs.size(), theirs["final"].median(), theirs["cpu_time"].median()
    out = []
    for env in MUJOCO100K_ENVS:
        here = mine[mine["env"] == env]
        if here.empty:
            out.append(f"- {env}: no finished runs yet")
            continue
        final, n = here["final"].median(), len(here)
        sac, crossq = published_mean(ref, "SAC (UTD 1)", env), published_mean(ref, "CrossQ (UTD 1)", env)
        checks = [
            ("the published SAC", sac),
            (f"SB3 SAC here ({peer_n.get(env, 0)} seeds)", peer_final.get(env, float("nan"))),
            ("half the published CrossQ", crossq / 2),
        ]
        verdicts = [  # a shortfall under 1 with one decimal (it would round to 0)
            f"{name} {level:.0f} " + ("met" if final >= level else f"missed by {level - final:.{int(level - final < 1)}f}")
            for name, level in checks
            if not np.isnan(level)
        ]
        ratio = _median(here["final_over_best"])
        cpu, sac_cpu = here["cpu_time"].median(), peer_cpu.get(env, float("nan"))
        cpu_words = (
            "no SAC runs" if np.isnan(sac_cpu) else f"{cpu / sac_cpu:.2f}x SB3 SAC's ({'met' if cpu <= sac_cpu else 'missed'})"
        )
        out.append(
            f"- {env} ({n} seed{'s' if n != 1 else ''}): final {final:.0f}; "
            + "; ".join(verdicts)
            + f"; final / best {ratio:.2f} ({'met' if ratio >= 0.8 else 'missed'}); CPU {cpu:,.0f} s, {cpu_words}"
        )
    return out


def steps_to_level(evals: pd.DataFrame, budget: int = 100_000) -> pd.DataFrame:
    """Per run: the env steps of its first evaluation at or above the published SAC's return at ``budget`` steps on
    the env (the level), NaN if none reaches it."""
    ref = frontier_at_budget(budget)
    rows = []
    for (algo, env, seed), e in evals.groupby(["algo", "env", "seed"], sort=False):
        level = published_mean(ref, "SAC (UTD 1)", env)
        hit = e.loc[e["score"] >= level, "timesteps"]  # NaN level (not published): never reached
        rows.append({"algo": algo, "env": env, "seed": seed, "level": level, "steps": hit.min() if len(hit) else np.nan})
    return pd.DataFrame(rows)


#: the preset with policy checkpoints over one episode and over three (their targets follow the preset's)
CHECKPOINT_ROWS = ("soft_crossq_wide_rho15_checkpoints", "soft_crossq_wide_rho15_checkpoints3")
#: Colours: the rows run here bold, the published curves thin and dashed.
ROW_COLOURS = {
    "denfac_default": "black",
    "denfac_rho2": "tab:orange",
    "denfac_crossq": "darkviolet",
    "soft_crossq": "darkgreen",
    "soft_crossq_wide": "limegreen",
    "soft_crossq_wide_rho1": "mediumseagreen",
    "soft_crossq_wide_rho15_nofloor": "darkcyan",
    "soft_crossq_wide_rho15_beta05": "steelblue",
    "soft_crossq_wide_rho15_checkpoints": "darkred",
    "soft_crossq_wide_rho15_checkpoints3": "salmon",
    "soft_crossq_anchor": "olive",
    "denfac_data_efficient": "tab:red",
    "sac_zoo": "tab:blue",
    "crossq_zoo": "tab:purple",
    "crossq_sbx": "magenta",
}
OTHER_COLOURS = ("tab:green", "gold", "teal", "tab:brown")
FRONTIER_COLOURS = ("tab:cyan", "tab:olive", "tab:purple", "tab:brown", "tab:pink", "tab:gray")


def _colours(algos) -> dict[str, str]:
    """One colour per row, the same in every figure: the suite's rows their own, any other the next free one."""
    others = iter(OTHER_COLOURS * 4)
    return {algo: ROW_COLOURS.get(algo) or next(others) for algo in dict.fromkeys(algos)}


def _legend_entries(axes) -> tuple[list, list[str]]:
    """The handles and labels of all panels, each label once, in order of appearance."""
    entries: dict[str, object] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    return list(entries.values()), list(entries)


def plot_cost(evals: pd.DataFrame, runs: pd.DataFrame, path: Path) -> None:
    """Per env: the final evaluation at the budget (median over seeds, the seeds as small dots) against CPU seconds per
    run (median), one point per row; the published SAC's and REDQ's 100k-step returns as horizontal lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, NullFormatter

    envs = _envs(runs)
    ref = frontier_at_budget()
    colours = _colours(runs["algo"])
    fig, axes = plt.subplots(1, len(envs), figsize=(3.6 * len(envs), 3.3), squeeze=False)
    for ax, env in zip(axes[0], envs, strict=True):
        for method, colour in (("SAC (UTD 1)", "tab:cyan"), ("REDQ (UTD 20)", "tab:olive")):
            row = published(ref, method, env)
            if row is not None:
                ax.axhline(row["mean"], ls="--", lw=1, color=colour, label=f"{method}, published at 100k (v4)")
        for algo, r in runs[runs["env"] == env].groupby("algo", sort=False):
            cpu = r["cpu_time"].median()
            ax.scatter(r["cpu_time"], r["final"], s=10, color=colours[algo], alpha=0.5)
            ax.scatter([cpu], [r["final"].median()], s=60, color=colours[algo], label=_label(algo), zorder=3)
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(env)
        ax.set_xlabel("CPU s per run (log)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("final evaluation at 100k steps")
    handles, names = _legend_entries(axes[0])
    fig.legend(handles, names, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.16, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _row_labels(runs: pd.DataFrame, envs: list[str]) -> dict[str, str]:
    """Each row's legend: its label, seeds and median CPU s per run on each env."""
    labels = {}
    for algo, r in runs.groupby("algo", sort=False):
        cpu = " / ".join(
            f"{r.loc[r['env'] == env, 'cpu_time'].median():.0f}" if (r["env"] == env).any() else "-" for env in envs
        )
        labels[algo] = f"{_label(algo)} ({r['seed'].nunique()} seeds; CPU s per run: {cpu})"
    return labels


def plot(evals: pd.DataFrame, runs: pd.DataFrame, path: Path) -> None:
    """Per env: each row's evaluation curve (median over seeds, interquartile band; CPU per run in the legend) and the
    published curves (dashed, labelled with their env version and seed count)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    envs = _envs(evals)
    curves = frontier()
    labels = _row_labels(runs, envs)
    colours = _colours(labels)
    fig, axes = plt.subplots(1, len(envs), figsize=(4.2 * len(envs), 3.6), squeeze=False)
    for ax, env in zip(axes[0], envs, strict=True):
        for method, colour in zip(FRONTIER_METHODS, FRONTIER_COLOURS, strict=True):
            c = curves[(curves["method"] == method) & (curves["env"] == env)].sort_values("env_step")
            if not c.empty:
                label = f"{method}, published (v4, {c['n_seeds'].max()} seeds)"
                ax.plot(c["env_step"] / 1000, c["mean"], ls="--", lw=1, alpha=0.8, color=colour, label=label)
        for algo, e in evals[evals["env"] == env].groupby("algo", sort=False):
            grid = np.arange(10_000, 100_001, 10_000)
            # each seed's evaluations (at the first episode end past each 10k steps) interpolated onto the 10k grid
            per_seed = [np.interp(grid, s["timesteps"], s["score"]) for _, s in e.groupby("seed") if len(s) > 1]
            if not per_seed:
                continue
            values = np.array(per_seed)
            ax.plot(grid / 1000, np.median(values, axis=0), lw=2.2, color=colours[algo], label=labels[algo])
            lo, hi = np.percentile(values, [25, 75], axis=0)
            ax.fill_between(grid / 1000, lo, hi, color=colours[algo], alpha=0.15)
        ax.set_title(env)
        ax.set_xlabel("env steps (thousands)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("evaluation return (10 episodes)")
    handles, names = _legend_entries(axes[0])
    mine = [i for i, n in enumerate(names) if n in labels.values()]
    order = mine + [i for i in range(len(names)) if i not in mine]
    fig.legend([handles[i] for i in order], [names[i] for i in order], loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.04 + 0.045 * ((len(names) + 1) // 2), 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(results_dir: str | Path) -> str:
    """Write ``mujoco100k.md`` (and ``.png``) in ``results_dir``; return the markdown."""
    out = Path(results_dir)
    evals, runs = load(out)
    if runs.empty:
        raise FileNotFoundError(f"no finished runs with a budget of env steps in {store.runs_path(out)}")
    envs = _envs(runs)
    parts = [
        "# Benchmark suite `mujoco100k`: Gymnasium MuJoCo at 100k env steps\n",
        "Generated by `python -m benchmarks.reports.mujoco100k` from `runs.jsonl.gz`. Medians over seeds; final = the mean "
        "return of 10 deterministic episodes at the budget; one torch thread per run. Methods: "
        "[docs/benchmark.md](../../../docs/benchmark.md).\n",
        provenance_line(runs),
    ]
    for env in envs:
        parts += [f"## {env}\n", env_table(runs, env).to_markdown(index=False), ""]
    parts += [
        "## Published at 100k steps (reference)\n",
        "The authors' runs on the v4 envs (the same tasks with minor model fixes), read from their per-seed results "
        "(`benchmarks/configs/frontier_100k.csv`, with the file and commit of each): mean ± standard deviation across "
        "seeds of the last evaluation logged at or before 100k steps.\n",
        reference_table(MUJOCO100K_ENVS).to_markdown(index=False),
        "",
        "## Targets of the data-efficient preset\n",
        "Medians over seeds at 100k env steps: at least the published SAC and SB3 SAC here, at least half the "
        "published CrossQ, final / best at least 0.8, CPU per run at most SB3 SAC's here.\n",
        *targets(runs),
        "",
        "The same for the preset with policy checkpoints over one episode (the same training unless a run resumed) "
        "and over three: the evaluations play the kept actor.",
        *[line for algo in CHECKPOINT_ROWS for line in (f"\n`{algo}`:\n", *targets(runs, algo))],
        "",
        "![evaluation curves](mujoco100k.png)",
        "",
        "The return bought per CPU second: final evaluation against CPU per run (large dots: medians; small: seeds):",
        "",
        "![final evaluation against CPU](mujoco100k_cost.png)",
        "",
    ]
    text = "\n".join(parts)
    (out / "mujoco100k.md").write_text(text)
    plot(evals, runs, out / "mujoco100k.png")
    plot_cost(evals, runs, out / "mujoco100k_cost.png")
    return text


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--results", default=str(RESULTS), help="the study's folder")
    args = parser.parse_args(argv)
    report(args.results)
    print(f"wrote {Path(args.results) / 'mujoco100k.md'}")


if __name__ == "__main__":
    main()
