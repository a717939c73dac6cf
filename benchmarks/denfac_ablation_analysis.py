"""Tables of the DENFAC ablation runs (``denfac_ablation.py``): per (config, env) medians and quartiles over seeds.

Writes ``runs.csv`` (one line per run), ``episodes.csv`` (one line per episode), ``diagnostics.csv`` and
``tables.md`` next to ``runs/``. Usage: ``python benchmarks/denfac_ablation_analysis.py``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

RESULTS = Path(__file__).resolve().parent / "results" / "denfac_ablation"
# return threshold per env for "episode of first return above"
THRESH = {"pendulum": -200.0, "halfcheetah": 50.0, "cartpole": -500.0, "invpendulum": 999.0, "acrobot": None}


def load(results: Path) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    runs, eps, diags = [], [], []
    for f in sorted((results / "runs").glob("*/*/seed_*.json")):
        r = json.loads(f.read_text())
        ret = np.asarray(r["returns"], dtype=float)
        perf = np.asarray(r["paper_performance"], dtype=float)
        env = r["env"]
        if env == "acrobot":  # steps to the goal (500 = not reached), lower is better
            score = -perf
            reached = np.flatnonzero(perf < 500)
        else:
            score = ret
            th_ = THRESH.get(env)
            reached = np.flatnonzero(ret >= th_) if th_ is not None else np.array([])
        best = np.maximum.accumulate(score)
        n = len(ret)
        first = int(reached[0]) + 1 if len(reached) else np.nan
        # stability: fraction of episodes after the first success falling below half the best (returns shifted by
        # the env's worst observed episode so that "half" is meaningful for negative returns)
        stab = np.nan
        if len(reached):
            lo = score.min()
            after = score[reached[0] + 1 :]
            if len(after):
                stab = float(np.mean((after - lo) < 0.5 * (best[-1] - lo)))
        row = dict(
            config=r["config"],
            env=env,
            seed=r["seed"],
            episodes=n,
            last10=float(score[-10:].mean()),
            best=float(best[-1]),
            first_above=first,
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
            for k in ("fit_r2", "q_mc_corr", "q_mc_bias", "q_std", "mc_std", "iw_mean", "td_mse", "target_var"):
                row[k] = d.get(k, np.nan)
            row["q_std/mc_std"] = d["q_std"] / d["mc_std"] if d.get("mc_std") else np.nan
        runs.append(row)
        for i in range(n):
            eps.append(dict(config=r["config"], env=env, seed=r["seed"], episode=i + 1, ret=ret[i], perf=perf[i], best=best[i]))
        for d in r["diagnostics"]:
            diags.append(dict(config=r["config"], env=env, seed=r["seed"], **d))
    return pd.DataFrame(runs), pd.DataFrame(eps), pd.DataFrame(diags)


def q(x: pd.Series) -> str:
    x = x.dropna()
    if len(x) == 0:
        return "–"
    return f"{x.median():.0f} [{x.quantile(0.25):.0f}, {x.quantile(0.75):.0f}]"


def table(runs: pd.DataFrame, env: str, configs: list[str] | None = None) -> str:
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
                "1st ep above thr (median; reached)": f"{fa.median():.0f} ({fa.notna().sum()}/{len(g)})" if fa.notna().any() else f"– (0/{len(g)})",
                "fit R2": f"{g['fit_r2'].median():.3f}" if "fit_r2" in g else "–",
                "corr(Q,MC)": f"{g['q_mc_corr'].median():.2f}" if "q_mc_corr" in g else "–",
                "std Q/MC": f"{g['q_std/mc_std'].median():.2f}" if "q_std/mc_std" in g else "–",
                "mean c": f"{g['iw_mean'].median():.2f}" if "iw_mean" in g else "–",
                "CPU s/ep": f"{g.cpu_per_ep.median():.2f}",
            }
        )
    return pd.DataFrame(rows).to_markdown(index=False) + "\n"


def main() -> int:
    results = Path(sys.argv[1]) if len(sys.argv) > 1 else RESULTS
    runs, eps, diags = load(results)
    runs.to_csv(results / "runs.csv", index=False)
    eps.to_csv(results / "episodes.csv", index=False)
    diags.to_csv(results / "diagnostics.csv", index=False)
    out = []
    for env in ["pendulum", "halfcheetah", "cartpole", "invpendulum", "acrobot"]:
        if (runs.env == env).any():
            out.append(f"## {env}\n\n" + table(runs, env))
    (results / "tables.md").write_text("\n".join(out))
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
