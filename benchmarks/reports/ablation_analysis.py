"""Tables of the DENFAC ablation (rows ``abl:<name>``, ``benchmarks/configs/ablation.yml``): per (config, env) medians
and quartiles over seeds.

Reads the study's runs file (``results/ablation/runs.jsonl.gz``) and writes ``runs.csv`` (one line per run) and
``tables.md`` next to it. Usage: ``python -m benchmarks.reports.ablation_analysis [RESULTS_DIR]``. What the study found:
``research/ablation/``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.runner import store
from benchmarks.runner.suites import SUITES
from sb3_denfac.common.performance import best_so_far, fall_back_fraction

RESULTS = Path(__file__).resolve().parents[1] / "results" / "ablation"
# the budget a config's rows are named after without "(N ep)": the suite's
DEFAULT_EPISODES = {env: budget.episodes for env, budget in SUITES["ablation"].budgets}
HELD_OUT = ("hopper", "reacher")  # envs not used to choose the 0.3 settings
TWIN = "default+proximal+n_critics2"  # the library's clipped double Q (n_critics=2) on 0.3's default
UTD = "default04+utd2.5"  # 0.4's default with update_to_data_ratio=2.5
# return threshold per env for "episode of first return above"
THRESH = {"pendulum": -200.0, "halfcheetah": 50.0, "cartpole": -500.0, "invertedpendulum": 999.0, "acrobot": None}


def load(results: Path, upto: int | None = None) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """Per-run metrics; with ``upto`` every run is cut to its first ``upto`` episodes (shorter runs dropped)."""
    runs, eps, diags = [], [], []
    for record in store.read_runs(results):
        episodes = record["episodes"]
        r = {
            "config": record["algo"].removeprefix("abl:"),
            "env": record["env"],
            "seed": record["seed"],
            "episodes": record["n_episodes"],
            "lengths": episodes["length"],
            "cpu_s": record["cpu_time"],
            "cpu_s_per_episode": record["cpu_time"] / max(record["n_episodes"], 1),
            "diagnostics": record.get("diagnostics") or [],
        }
        ret = np.asarray(episodes["return"], dtype=float)
        perf = np.asarray(episodes["performance"], dtype=float)
        if upto is not None:
            if len(ret) < upto:
                continue
            ret, perf = ret[:upto], perf[:upto]
            r["diagnostics"] = [d for d in r["diagnostics"] if d["episode"] <= upto]
        env = r["env"]
        if env == "acrobot":  # steps to the goal (500 = not reached), lower is better; score = -steps
            # the runner recorded returns (performance_key fallback); the goal gives reward +1 and ends the episode,
            # a timeout gives the max height (< 0.99), so steps to the goal = length where the return is 1
            lengths = np.asarray(r["lengths"][: len(ret)], dtype=float)
            perf = np.where(ret >= 0.999, lengths, 500.0)
            score = -perf
            hit = perf < 500
        else:
            score = ret
            th_ = THRESH.get(env)
            hit = ret >= th_ if th_ is not None else np.zeros(len(ret), bool)
        reached = np.flatnonzero(hit)
        best = best_so_far(score, lower_is_better=False)  # score: higher is better on every env (Acrobot: -steps)
        n = len(ret)
        first = int(reached[0]) + 1 if len(reached) else np.nan
        stab = fall_back_fraction(score, False, hit)  # halfway from the run's worst episode
        row = dict(
            config=r["config"]
            if r["episodes"] == DEFAULT_EPISODES.get(env, r["episodes"]) or upto
            else f"{r['config']} ({r['episodes']} ep)",
            env=env,
            seed=r["seed"],
            budget=r["episodes"],
            episodes=n,
            last10=float(score[-10:].mean()),
            best=float(best[-1]),
            first_above=first,
            hits=int(hit.sum()),
            cpu_s=r["cpu_s"],
            cpu_per_ep=r["cpu_s_per_episode"],
            fallback_frac=stab,
        )
        for k_ep in (10, 15, 20, 30, 40, 50, 100):
            if n >= k_ep:
                row[f"best@{k_ep}"] = float(best[k_ep - 1])
                row[f"last10@{k_ep}"] = float(score[max(0, k_ep - 10) : k_ep].mean())
        if r["diagnostics"]:
            d = r["diagnostics"][-1]
            for k in (
                "fit_r2",
                "q_mc_corr",
                "q_mc_bias",
                "q_std",
                "mc_std",
                "iw_mean",
                "td_mse",
                "target_var",
                "grad_sign_agreement",
                "grad_sign_agreement_data",
            ):
                row[k] = d.get(k, np.nan)
            row["q_std/mc_std"] = d["q_std"] / d["mc_std"] if d.get("mc_std") else np.nan
        runs.append(row)
        for i in range(n):
            eps.append(
                dict(config=r["config"], env=env, seed=r["seed"], episode=i + 1, ret=ret[i], perf=perf[i], best=best[i])
            )
        for d in r["diagnostics"]:
            diags.append(dict(config=r["config"], env=env, seed=r["seed"], **d))
    runs_df = pd.DataFrame(runs)
    if upto is not None and not runs_df.empty:  # one run per (config, env, seed): the one made for the shortest budget
        runs_df = runs_df.sort_values("budget").drop_duplicates(["config", "env", "seed"]).sort_index()
    return runs_df, pd.DataFrame(eps), pd.DataFrame(diags)


def q(x: pd.Series) -> str:
    x = x.dropna()
    if len(x) == 0:
        return "–"
    return f"{x.median():.0f} [{x.quantile(0.25):.0f}, {x.quantile(0.75):.0f}]"


def to_markdown(df: pd.DataFrame) -> str:
    """Markdown table without the optional ``tabulate`` dependency."""
    cols = list(df.columns)
    lines = ["| " + " | ".join(map(str, cols)) + " |", "|" + "---|" * len(cols)]
    for _, r in df.iterrows():
        lines.append("| " + " | ".join(str(r[c]) for c in cols) + " |")
    return "\n".join(lines)


def full_budget_options(runs: pd.DataFrame) -> list[str]:
    """Library default (0.2, ``default``) against the proximal actor (0.3's default), and the latter with 256-256
    networks or clipped double-Q (prototype ``cdq``, library :data:`TWIN`), and :data:`TWIN` with a data-proportional
    update (:data:`UTD`), at each env's full budget; :data:`HELD_OUT` envs check a choice, not its basis."""
    out = []
    full_budgets = {"pendulum": 40, "halfcheetah": 100, "cartpole": 100, "invertedpendulum": 100, "acrobot": 100}
    full_budgets |= dict.fromkeys(HELD_OUT, 100)
    for env, budget in full_budgets.items():
        suffix = "" if DEFAULT_EPISODES[env] == budget else f" ({budget} ep)"
        names = ("default", "default+proximal", "default+proximal+nets256", "default+proximal+cdq", TWIN, UTD)
        configs = [f"{name}{suffix}" for name in names]
        if ((runs.env == env) & runs.config.isin(configs)).any():
            held_out = (
                " (held out of the 0.3 settings; Reacher's Q diagnostics prompted the clipped double-Q probe, Hopper is"
                " held out of it)"
            )
            out.append(f"### {env}, {budget} episodes{held_out if env in HELD_OUT else ''}\n")
            out.append(table(runs, env, configs))
    return out


#: 0.5's candidates: one change each to 0.4's default (:data:`TWIN`; ``default04`` is the same configuration)
CANDIDATES = (
    *("default04+smooth", "default04+mean", "default04+mean+smooth", "default04+sigma0.3"),
    *("default04+nets256", "default04+lr3e-4", "default04-proximal"),
    # the 0.5 default (default05 = default04+mean+smooth) on the sparse Acrobot, one change at a time
    *("default05+gamma0.99", "default05-proximal", "default05+per-critic", "default05+sigma0.3"),
    *("faithful", "faithful+gamma0.99"),
    # Pendulum: SAC's settings in 0.5's default, and a uniform warm-up episode (section 14)
    *("default05", "default05+nets256", "default05+lr3e-4", "default05+warmup200"),
)


def candidates(runs: pd.DataFrame) -> list[str]:
    """0.4's default against each of :data:`CANDIDATES` at each env's full budget (Acrobot: 100 episodes)."""
    out = []
    for env in ("invertedpendulum", "hopper", "reacher", "acrobot", "pendulum", "cartpole", "halfcheetah"):
        suffix = f" ({100} ep)" if DEFAULT_EPISODES.get(env) not in (None, 100, 40) else ""
        configs = [f"{name}{suffix}" for name in (TWIN, *CANDIDATES)]
        if ((runs.env == env) & runs.config.isin(configs[1:])).any():
            out.append(f"### {env}\n")
            out.append(table(runs, env, configs))
    return out


def table(runs: pd.DataFrame, env: str, configs: list[str] | None = None) -> str:
    if runs.empty:
        return "(no runs)\n"
    df = runs[runs.env == env]
    if configs is not None:
        df = df[df.config.isin(configs)]
    if df.empty:
        return "(no runs)\n"
    rows = []
    order = configs if configs is not None else sorted(df.config.unique())
    for c in order:
        g = df[df.config == c]
        if g.empty:
            continue
        fa = g.first_above
        rows.append(
            {
                "config": c,
                "seeds": len(g),
                "last-10 mean": q(g.last10),
                "best-so-far": q(g.best),
                "1st ep above thr (median; reached)": f"{fa.median():.0f} ({fa.notna().sum()}/{len(g)})"
                if fa.notna().any()
                else f"– (0/{len(g)})",
                "fit R2": f"{g['fit_r2'].median():.3f}" if "fit_r2" in g else "–",
                "corr(Q,MC)": f"{g['q_mc_corr'].median():.2f}" if "q_mc_corr" in g else "–",
                "std Q/MC": f"{g['q_std/mc_std'].median():.2f}" if "q_std/mc_std" in g else "–",
                "mean c": f"{g['iw_mean'].median():.2f}" if "iw_mean" in g else "–",
                "fall-back frac": f"{g.fallback_frac.median():.2f}" if g.fallback_frac.notna().any() else "–",
                "eps above thr": f"{g.hits.median():.0f}" if "hits" in g else "–",
                "CPU s/ep": f"{g.cpu_per_ep.median():.2f}",
            }
        )
    return to_markdown(pd.DataFrame(rows)) + "\n"


def select(runs: pd.DataFrame, prefix: str, base: str) -> list[str]:
    if runs.empty:
        return [base]
    names = sorted(c for c in runs.config.unique() if c.startswith(prefix))
    return [base] + [c for c in names if c != base]


def write_tables(results: Path) -> Path:
    """Write the study's ``runs.csv`` and ``tables.md`` in ``results``; return the tables' path."""
    runs, eps, diags = load(results)
    runs.to_csv(results / "runs.csv", index=False)
    out = ["# Tables (generated by `python -m benchmarks.reports.ablation_analysis`)\n"]
    out.append("## Pendulum-v1, 40 episodes: from the good config back towards faithful (one factor reverted)\n")
    out.append(table(runs, "pendulum", ["faithful"] + select(runs, "good", "good")))
    out.append("## Pendulum-v1, 40 episodes: from faithful towards good (one factor changed)\n")
    out.append(table(runs, "pendulum", select(runs, "faithful", "faithful")))
    out.append("## HalfCheetahPaper-v0, 30 episodes: faithful, good and good minus one factor\n")
    out.append(table(runs, "halfcheetah", ["faithful"] + select(runs, "good", "good")))
    for env in ["cartpole", "invertedpendulum", "acrobot"]:
        if (runs.env == env).any():
            out.append(f"## {env}: generalisation of the good config\n")
            out.append(table(runs, env))
    out.append("## Prototypes, Pendulum-v1, 40 episodes (plain-autograd subclasses; 'good' = library fast path)\n")
    out.append(table(runs, "pendulum", ["good"] + select(runs, "proto", "proto-uniform")))
    r20, _, _ = load(results, upto=20)
    out.append("## Prototypes, HalfCheetahPaper-v0, every run cut to its first 20 episodes\n")
    out.append(table(r20, "halfcheetah", ["good"] + select(r20, "proto", "proto-uniform") + ["good+D3000"]))
    options = ["default", "default+per-critic", "default+per-both", "default+proximal"]  # library options (options.py)
    out.append("## Library options, Pendulum-v1, 40 episodes ('good' / 'proto-*': the same equations, earlier runs)\n")
    out.append(table(runs, "pendulum", [*options, "good", "proto-per-critic", "proto-proxg1"]))
    out.append("## Library options, HalfCheetahPaper-v0, every run cut to its first 20 episodes\n")
    out.append(table(r20, "halfcheetah", [*options, "good", "proto-per-critic", "proto-proxg1"]))
    out.append("## The proximal actor at full budgets (`default` = 0.2's default, `default+proximal` = 0.3's)\n")
    out.extend(full_budget_options(runs))
    out.append(
        "## 0.5 candidates: one change each to 0.4's default (`" + TWIN + "`), full budgets\n\n"
        "`eps above thr`: episodes at the threshold (Acrobot: episodes that reach the goal), median over seeds.\n"
    )
    out.extend(candidates(runs))
    (results / "tables.md").write_text("\n".join(out))
    return results / "tables.md"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    print(f"wrote {write_tables(Path(argv[0]) if argv else RESULTS)} (and runs.csv)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
