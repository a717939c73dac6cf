"""Analysis of the Figure 3 data-efficiency sweep: best-so-far curves, tables, IQM with bootstrap intervals.

Reads the per-run files written by ``benchmarks/figure3.py`` (``runs/<algo>/<env>/seed_<k>.csv`` + ``.json``) and writes,
next to them: ``episodes.csv`` (all episodes, tidy), ``runs.csv`` (one line per run), ``figure3.png`` (one panel per
env, median and quartiles of the best registered performance per episode, as in the paper's Figure 3) and
``figure3.md`` (tables).

Usage: ``python benchmarks/figure3_analysis.py --results benchmarks/results/figure3``
"""

from __future__ import annotations

import argparse
import csv
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

EPISODE_FIELDS = ("algo", "env", "seed", "episode", "performance", "best_so_far", "return", "length", "timesteps", "wall_time")


@dataclass(frozen=True)
class EnvSpec:
    """What the benchmark needs to know about an environment.

    :param name: short name used on the command line and in file names.
    :param gym_id: Gymnasium id.
    :param lower_is_better: direction of the per-episode measure (Acrobot: steps to the goal).
    :param threshold: "solved" level for the episodes-to-threshold table (``best < threshold`` when lower is better,
        ``best >= threshold`` otherwise); ``None``: no threshold.
    :param score_range: (worst, best) reference scores for normalisation to [0, 1] in the aggregate (IQM);
        ``None``: min-max over all runs of the sweep on that env.
    :param gamma: the paper's discount factor, used only when ``sb3_denfac/hyperparams/<algo>.yml`` has no entry.
    :param label: panel title.
    """

    name: str
    gym_id: str
    lower_is_better: bool = False
    threshold: float | None = None
    score_range: tuple[float, float] | None = None
    gamma: float | None = None
    label: str = ""
    notes: str = field(default="", compare=False)


# Thresholds and normalisation references of the paper's three tasks (see docs/benchmark.md).
ENV_SPECS: dict[str, EnvSpec] = {
    "acrobot": EnvSpec(
        "acrobot",
        "sb3_denfac/ContinuousAcrobot-v0",
        lower_is_better=True,
        threshold=500.0,
        score_range=(500.0, 0.0),
        gamma=0.9,
        label="Acrobot (steps to goal, lower is better)",
        notes="threshold: the goal is reached at all (< 500 steps); score (500 - steps) / 500",
    ),
    "cartpole": EnvSpec(
        "cartpole",
        "sb3_denfac/ContinuousCartPole-v0",
        threshold=-500.0,
        score_range=(-1000.0, 0.0),
        gamma=0.99,
        label="CartPole (return, higher is better)",
        notes="threshold: -500, i.e. the pole stays up for the 500 steps; score (return + 1000) / 1000",
    ),
    "halfcheetah": EnvSpec(
        "halfcheetah",
        "sb3_denfac/HalfCheetahPaper-v0",
        threshold=50.0,
        score_range=None,
        gamma=0.99,
        label="Half-Cheetah (return, higher is better)",
        notes="threshold: return >= 50, i.e. runs forward (the initial near-zero policy stands still at |return| < 2); "
        "score: min-max over the sweep",
    ),
}


def env_spec(name_or_id: str) -> EnvSpec:
    """The spec of a short name or Gymnasium id; an unknown id gets a generic "higher is better" spec."""
    if name_or_id in ENV_SPECS:
        return ENV_SPECS[name_or_id]
    for spec in ENV_SPECS.values():
        if spec.gym_id == name_or_id:
            return spec
    return EnvSpec(name_or_id, name_or_id, label=name_or_id)


def running_best(performance: Sequence[float] | np.ndarray, lower_is_better: bool) -> np.ndarray:
    """Best registered performance since the first episode (NaN episodes are skipped)."""
    perf = np.asarray(performance, dtype=np.float64)
    if perf.size == 0:
        return perf
    fill = np.inf if lower_is_better else -np.inf
    best = (np.minimum if lower_is_better else np.maximum).accumulate(np.where(np.isnan(perf), fill, perf))
    return np.where(np.isinf(best), np.nan, best)


def reached(values: np.ndarray, spec: EnvSpec) -> np.ndarray:
    assert spec.threshold is not None
    return values < spec.threshold if spec.lower_is_better else values >= spec.threshold


def episodes_to_threshold(best: np.ndarray, spec: EnvSpec) -> float:
    """First episode (1-based) whose best-so-far reaches the threshold, NaN if never."""
    if spec.threshold is None or best.size == 0:
        return float("nan")
    hits = np.flatnonzero(reached(np.nan_to_num(best, nan=np.inf if spec.lower_is_better else -np.inf), spec))
    return float(hits[0] + 1) if hits.size else float("nan")


def interquartile_mean(x: np.ndarray) -> float:
    """Mean of the middle 50% (25% trimmed each side), as in rliable's IQM."""
    x = np.sort(np.asarray(x, dtype=np.float64).ravel())
    n = x.size
    if n == 0:
        return float("nan")
    cut = int(np.floor(0.25 * n))
    middle = x[cut : n - cut] if n - 2 * cut > 0 else x
    return float(middle.mean())


def stratified_bootstrap_iqm(
    scores_per_env: Iterable[np.ndarray], n_resamples: int = 2000, confidence: float = 0.95, seed: int = 0
) -> tuple[float, float, float]:
    """IQM over all (env, seed) scores with a percentile interval from a bootstrap that resamples seeds within each env."""
    groups = [np.asarray(g, dtype=np.float64) for g in scores_per_env if len(g) > 0]
    if not groups:
        return float("nan"), float("nan"), float("nan")
    point = interquartile_mean(np.concatenate(groups))
    rng = np.random.default_rng(seed)
    stats = np.empty(n_resamples)
    for i in range(n_resamples):
        stats[i] = interquartile_mean(np.concatenate([g[rng.integers(0, g.size, g.size)] for g in groups]))
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(stats, [alpha, 1.0 - alpha])
    return point, float(low), float(high)


# ----------------------------------------------------------------------------------------------------------------- loading


@dataclass
class Run:
    algo: str
    env: str
    seed: int
    meta: dict[str, Any]
    episodes: list[dict[str, Any]]

    def column(self, key: str) -> np.ndarray:
        return np.array([float(e[key]) for e in self.episodes], dtype=np.float64)

    def best(self) -> np.ndarray:
        """Best registered performance per episode (recomputed from the raw measures)."""
        return running_best(self.column("performance"), env_spec(self.env).lower_is_better)


def load_runs(results_dir: str | Path) -> list[Run]:
    """All finished runs (a run is finished when its ``.json`` exists; it is written after the ``.csv``)."""
    runs = []
    for meta_path in sorted(Path(results_dir, "runs").glob("*/*/seed_*.json")):
        meta = json.loads(meta_path.read_text())
        with meta_path.with_suffix(".csv").open(newline="") as f:
            episodes = list(csv.DictReader(f))
        runs.append(Run(meta["algo"], meta["env"], int(meta["seed"]), meta, episodes))
    return runs


def best_matrix(runs: list[Run], spec: EnvSpec, n_episodes: int | None = None) -> np.ndarray:
    """(n_runs, n_episodes) best-so-far matrix, NaN-padded where a run has fewer episodes."""
    curves = [r.best() for r in runs]
    width = n_episodes or max((c.size for c in curves), default=0)
    out = np.full((len(curves), width), np.nan)
    for i, c in enumerate(curves):
        out[i, : min(width, c.size)] = c[:width]
    return out


def _group(runs: list[Run]) -> dict[str, dict[str, list[Run]]]:
    grouped: dict[str, dict[str, list[Run]]] = {}
    for r in sorted(runs, key=lambda r: (r.env, r.algo, r.seed)):
        grouped.setdefault(r.env, {}).setdefault(r.algo, []).append(r)
    return grouped


def _env_order(envs: Iterable[str]) -> list[str]:
    known = list(ENV_SPECS)
    return sorted(envs, key=lambda e: (known.index(e) if e in known else len(known), e))


ALGO_ORDER = ["denfac", "nfac", "ddpg", "cacla", "cmaes", "td3", "sac", "crossq"]


def _algo_order(algos: Iterable[str]) -> list[str]:
    return sorted(algos, key=lambda a: (ALGO_ORDER.index(a) if a in ALGO_ORDER else len(ALGO_ORDER), a))


# ----------------------------------------------------------------------------------------------------------------- outputs


def write_tidy(runs: list[Run], results_dir: Path) -> None:
    with (results_dir / "episodes.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=EPISODE_FIELDS, extrasaction="ignore")
        writer.writeheader()
        for r in sorted(runs, key=lambda r: (r.env, r.algo, r.seed)):
            for e in r.episodes:
                writer.writerow({**e, "algo": r.algo, "env": r.env, "seed": r.seed})
    run_fields = ["algo", "env", "seed", "episodes", "timesteps", "wall_time", "cpu_time", "final_best", "hyperparams_source"]
    with (results_dir / "runs.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=run_fields)
        writer.writeheader()
        for r in sorted(runs, key=lambda r: (r.env, r.algo, r.seed)):
            best = r.best()
            writer.writerow(
                {
                    "algo": r.algo,
                    "env": r.env,
                    "seed": r.seed,
                    "episodes": len(r.episodes),
                    "timesteps": r.meta.get("timesteps"),
                    "wall_time": round(float(r.meta.get("wall_time", float("nan"))), 2),
                    "cpu_time": round(float(r.meta.get("cpu_time", float("nan"))), 2),
                    "hyperparams_source": r.meta.get("hyperparams_source", ""),
                    "final_best": best[-1] if best.size else "",
                }
            )


def plot_figure3(runs: list[Run], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grouped = _group(runs)
    envs = _env_order(grouped)
    fig, axes = plt.subplots(1, max(1, len(envs)), figsize=(5.2 * max(1, len(envs)), 4.2), squeeze=False)
    colors = plt.get_cmap("tab10")
    all_algos = _algo_order({a for e in grouped.values() for a in e})
    for ax, env in zip(axes[0], envs, strict=False):
        spec = env_spec(env)
        for algo in _algo_order(grouped[env]):
            best = best_matrix(grouped[env][algo], spec)
            x = np.arange(1, best.shape[1] + 1)
            with np.errstate(all="ignore"):
                q1, med, q3 = np.nanpercentile(best, [25, 50, 75], axis=0)
            color = colors((ALGO_ORDER + all_algos).index(algo) % 10)  # one fixed colour per algorithm
            label = f"{algo.upper()} (n={best.shape[0]})"
            ax.plot(x, med, color=color, label=label, lw=2.2 if algo == "denfac" else 1.3, drawstyle="steps-post")
            ax.fill_between(x, q1, q3, color=color, alpha=0.15, lw=0, step="post")
        if spec.threshold is not None:
            ax.axhline(spec.threshold, color="grey", ls=":", lw=1)
        ax.set_title(spec.label or env)
        ax.set_xlabel("episode")
        ax.set_ylabel("best registered performance")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Median and quartiles of the best registered performance (paper's Figure 3 layout)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _fmt(x: float, digits: int = 1) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def normalised_final_scores(runs: list[Run]) -> dict[str, dict[str, np.ndarray]]:
    """{algo: {env: normalised final best-so-far per seed}}, with each env's ``score_range`` or sweep min-max."""
    grouped = _group(runs)
    out: dict[str, dict[str, np.ndarray]] = {}
    for env, by_algo in grouped.items():
        spec = env_spec(env)
        finals = {a: np.array([r.best()[-1] for r in rs]) for a, rs in by_algo.items()}
        if spec.score_range is not None:
            worst, best = spec.score_range
        else:
            pooled = np.concatenate(list(finals.values()))
            pooled = pooled[np.isfinite(pooled)]
            worst, best = (pooled.max(), pooled.min()) if spec.lower_is_better else (pooled.min(), pooled.max())
        span = best - worst if best != worst else 1.0
        for algo, vals in finals.items():
            out.setdefault(algo, {})[env] = (vals - worst) / span
    return out


def summary_table(runs: list[Run]) -> list[str]:
    """One line per algorithm: per env, median final best-so-far [Q1, Q3] and runs reaching the threshold."""
    grouped = _group(runs)
    envs = _env_order(grouped)
    header = ["algo"] + [f"{env}: final best, median [Q1, Q3] (reached/runs)" for env in envs]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for algo in _algo_order({a for by_algo in grouped.values() for a in by_algo}):
        cells = [algo]
        for env in envs:
            rs = grouped[env].get(algo, [])
            finals = np.array([r.best()[-1] for r in rs]) if rs else np.array([])
            finals = finals[np.isfinite(finals)]
            if not finals.size:
                cells.append("–")
                continue
            q1, med, q3 = np.percentile(finals, [25, 50, 75])
            spec = env_spec(env)
            hit = int(reached(finals, spec).sum()) if spec.threshold is not None else 0
            cells.append(f"{_fmt(med)} [{_fmt(q1)}, {_fmt(q3)}] ({hit}/{len(rs)})")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def markdown_report(runs: list[Run], checkpoints: Sequence[int] = (10, 20, 50, 100)) -> str:
    grouped = _group(runs)
    lines = ["# Figure 3 benchmark: best registered performance", "", "## Summary", ""]
    lines += summary_table(runs) + [""]
    for env in _env_order(grouped):
        spec = env_spec(env)
        by_algo = grouped[env]
        n_max = max(len(r.episodes) for rs in by_algo.values() for r in rs)
        cps = [c for c in checkpoints if c < n_max] + [n_max]
        direction = "lower is better" if spec.lower_is_better else "higher is better"
        lines += [f"## {env} (`{spec.gym_id}`, {direction})", ""]
        if spec.threshold is not None:
            op = "<" if spec.lower_is_better else ">="
            lines += [f"Threshold: best-so-far {op} {spec.threshold:g}. {spec.notes}", ""]
        header = ["algo", "runs"] + [f"median best @ep {c} [Q1, Q3]" for c in cps]
        header += ["episodes to threshold (median; reached/runs)", "wall s per run (median)", "CPU s per run (median)"]
        lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for algo in _algo_order(by_algo):
            rs = by_algo[algo]
            best = best_matrix(rs, spec, n_max)
            cells = [algo, str(len(rs))]
            for c in cps:
                col = best[:, c - 1]
                col = col[np.isfinite(col)]
                if col.size:
                    q1, med, q3 = np.percentile(col, [25, 50, 75])
                    cells.append(f"{_fmt(med)} [{_fmt(q1)}, {_fmt(q3)}]")
                else:
                    cells.append("–")
            ett = np.array([episodes_to_threshold(r.best(), spec) for r in rs])
            hit = np.isfinite(ett)
            cells.append(f"{_fmt(np.median(ett[hit]) if hit.any() else np.nan, 0)} ({hit.sum()}/{len(rs)})")
            for key in ("wall_time", "cpu_time"):
                cells.append(_fmt(np.median([float(r.meta.get(key, np.nan)) for r in rs])))
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    # Aggregate: IQM over normalised final best-so-far, stratified bootstrap over seeds within envs.
    scores = normalised_final_scores(runs)
    lines += [
        "## Aggregate: IQM of normalised final best-so-far",
        "",
        "Scores per env: Acrobot (500 - steps) / 500, CartPole (return + 1000) / 1000, other envs min-max over all runs of "
        "the sweep (1 = best run). IQM over all (env, seed) scores; 95% percentile interval from 2000 bootstrap resamples "
        "of the seeds within each env. Only algorithms run on the same set of envs are comparable.",
        "",
        "| algo | envs | runs | IQM | 95% CI |",
        "|---|---|---|---|---|",
    ]
    for algo in _algo_order(scores):
        by_env = scores[algo]
        point, low, high = stratified_bootstrap_iqm(by_env.values())
        n = sum(v.size for v in by_env.values())
        envs = ", ".join(_env_order(by_env))
        lines.append(f"| {algo} | {envs} | {n} | {_fmt(point, 3)} | [{_fmt(low, 3)}, {_fmt(high, 3)}] |")
    lines.append("")
    return "\n".join(lines)


def analyse(results_dir: str | Path) -> str:
    """Write episodes.csv, runs.csv, figure3.png and figure3.md in ``results_dir``; return the markdown."""
    results_dir = Path(results_dir)
    runs = load_runs(results_dir)
    if not runs:
        raise FileNotFoundError(f"no finished runs under {results_dir / 'runs'}")
    write_tidy(runs, results_dir)
    plot_figure3(runs, results_dir / "figure3.png")
    report = markdown_report(runs)
    (results_dir / "figure3.md").write_text(report)
    return report


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--results", default=str(Path(__file__).parent / "results" / "figure3"), help="results folder")
    args = parser.parse_args(argv)
    print(analyse(args.results))


if __name__ == "__main__":
    main()
