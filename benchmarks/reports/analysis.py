"""Analysis of a study's runs: tables (``benchmarks.reports.tables``), aggregates and verdicts (rliable), plots; one report per
suite.

Reads the study's compact runs file (``<results>/runs.jsonl.gz``, ``benchmarks.runner.store``) and writes next to it:
``runs.csv`` (one line per run, with its measures), and for every suite of the study with finished runs
``<suite>.md`` (tables, aggregates, verdicts), ``<suite>.png`` (curves), ``<suite>_compute.png`` (best-so-far against
CPU seconds) and ``<suite>_profile.png`` (performance profile); ``all_runs.md`` covers every finished run.

Usage: ``python -m benchmarks.reports.analysis --results benchmarks/results/sweep``
"""

from __future__ import annotations

import argparse
import ast
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.reports import plots, verdicts
from benchmarks.reports import stats as st
from benchmarks.reports.tables import (
    BEYOND_BONUS_LEVEL,
    answer_table,
    beyond_survival,
    env_order,
    env_table,
    markdown,
    missing_cells,
    row_order,
    settings_table,
)
from benchmarks.runner import store
from benchmarks.runner.algos import ALGOS
from benchmarks.runner.suites import ROBOTICS_ENVS, SUITES, Suite
from sb3_denfac.common.performance import fall_back_fraction
from sb3_denfac.envs.facts import env_facts

RUN_FIELDS = [
    *("algo", "env", "seed", "episodes", "timesteps", "cpu_time", "eval_cpu_time", "wall_time", "final_best", "last10"),
    *("final_eval", "episodes_to_threshold", "fall_back", "cpu_per_episode", "gradient_steps", "trained"),
    "last10_beyond_survival",
    *("hyperparams_source", "commit", "device"),
]
COMMITTED = Path(__file__).resolve().parents[1] / "results"  # the committed studies, benchmarks/results/<study>/
#: The budget a run was made for (not written to ``runs.csv``): a suite counts a cell's runs of its own budget only.
BUDGET_FIELDS = ["episodes_requested", "timesteps_requested"]


def _learning_starts(meta: dict) -> int:
    with_value = meta.get("hyperparams", {}).get("learning_starts")
    return int(ast.literal_eval(with_value)) if with_value is not None else 0


def load(results_dir: str | Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(episodes, runs) of the finished runs of the study's runs file: per (algo, env, seed), its longest budget."""
    return load_records(store.read_runs(results_dir))


def load_records(records: Iterable[dict]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """:func:`load` of run records already read (e.g. some rows of a runs file, ``store.read_runs``)."""
    episode_frames, run_rows = [], []
    longest: dict[tuple, dict] = {}
    for record in records:
        cell = store.cell_of(record)[:3]
        if cell not in longest or record["episodes_requested"] > longest[cell]["episodes_requested"]:
            longest[cell] = record
    for meta in longest.values():
        eps = pd.DataFrame(meta["episodes"])
        eps = eps.astype({c: float for c in ("performance", "best_so_far", "cpu_time") if c in eps})
        eps.insert(0, "seed", int(meta["seed"]))
        eps.insert(0, "env", meta["env"])
        eps.insert(0, "algo", meta["algo"])
        episode_frames.append(eps)
        facts = env_facts(meta["env"])
        machine = meta.get("machine") or {}
        hits = eps.loc[eps["best_so_far"].map(facts.reached), "episode"]
        evaluations = meta.get("evaluations") or []
        run_rows.append(
            {
                **{k: meta.get(k) for k in ("algo", "env", "seed", "timesteps", "cpu_time", "eval_cpu_time", "wall_time")},
                "gradient_steps": meta.get("gradient_steps"),
                "episodes": len(eps),
                "final_best": float(eps["best_so_far"].iloc[-1]) if len(eps) else np.nan,
                "last10": float(eps["performance"].tail(10).mean()),
                "last10_beyond_survival": float(
                    beyond_survival(eps["return"], eps["length"], facts.survival_bonus).tail(10).mean()
                )
                if {"return", "length"} <= set(eps)
                else np.nan,
                "final_eval": float(np.mean(evaluations[-1]["scores"])) if evaluations else np.nan,
                "episodes_to_threshold": float(hits.iloc[0]) if len(hits) else np.nan,
                "fall_back": fall_back_fraction(
                    eps["performance"],
                    facts.lower_is_better,
                    eps["performance"].map(facts.reached),
                    facts.score_range[0] if facts.score_range else None,
                ),
                "cpu_per_episode": float(meta.get("cpu_time", np.nan)) / max(len(eps), 1),
                # A run trained if its model updated at all: more steps than the warm-up, and a second episode.
                "trained": bool(meta.get("timesteps", 0) > _learning_starts(meta) and len(eps) >= 2),
                "hyperparams_source": meta.get("hyperparams_source", ""),
                "commit": (meta.get("git") or {}).get("commit", "")[:10],
                "device": machine.get("gpu") or machine.get("device", "cpu"),
                **{field: meta.get(field) for field in BUDGET_FIELDS},
            }
        )
    episodes = pd.concat(episode_frames, ignore_index=True) if episode_frames else pd.DataFrame()
    return episodes, pd.DataFrame(run_rows, columns=RUN_FIELDS + BUDGET_FIELDS)


def _worst(facts) -> str:
    return f"{facts.score_range[0]:g}" if facts.score_range else "the run's worst episode"


def report(title: str, episodes: pd.DataFrame, runs: pd.DataFrame, out: Path, stem: str, suite: Suite | None = None) -> str:
    """The markdown of one report; writes its three plots ``<stem>.png``, ``<stem>_compute.png``, ``<stem>_profile.png``."""
    lines = [f"# {title}", ""]
    if suite is not None:
        missing = missing_cells(suite, runs)
        lines += [f"Suite `{suite.name}`: {suite.description}.", ""]
        lines += (
            [
                "Cells not complete (finished/wanted seeds, CPU hours to finish: from the cell's finished runs, "
                "or <= the plan's full-length estimate where it has none):",
                "",
                markdown(missing),
                "",
            ]
            if not missing.empty
            else ["Every cell is complete.", ""]
        )
    excluded = runs[~runs["trained"]]
    if not excluded.empty:
        lines += ["Runs left out because their model never trained (budget within the warm-up):", "",
                  markdown(excluded[["algo", "env", "seed", "timesteps", "hyperparams_source"]]), ""]  # fmt: skip
    runs = runs[runs["trained"]]
    if runs.empty:
        return "\n".join([*lines, "No finished run has trained yet.", ""])
    episodes = episodes.merge(runs[["algo", "env", "seed"]], on=["algo", "env", "seed"])
    envs, algos = env_order(runs["env"]), row_order(runs["algo"])
    commits = sorted(set(runs["commit"]))
    lines += [f"Runs: {len(runs)}; code commits: {', '.join(commits) or 'unknown'} (per run in `runs.csv`).", ""]
    on_gpu = runs[runs["device"] != "cpu"]
    if not on_gpu.empty:  # their CPU seconds are not comparable with the others'
        cells = []
        for (algo, env, device), group in on_gpu.groupby(["algo", "env", "device"]):
            seeds = f"seed{'s' * (len(group) > 1)} {', '.join(map(str, sorted(group['seed'])))}"
            cells.append(f"{ALGOS[algo].label if algo in ALGOS else algo} {env} {seeds} ({device})")
        lines += [f"Trained on a GPU (their CPU seconds leave out the GPU's work): {'; '.join(cells)}.", ""]
    plots.curves(episodes, envs, algos, out / f"{stem}.png")
    plots.compute_tradeoff(episodes, envs, algos, out / f"{stem}_compute.png")
    lines += [f"![curves]({stem}.png)", "", f"![compute]({stem}_compute.png)", ""]
    lines += ["## What each algorithm was given (YAML entry per env)", "", markdown(settings_table(runs)), ""]
    for env in envs:
        facts = env_facts(env)
        direction = "lower is better" if facts.lower_is_better else "higher is better"
        budget = int(runs.loc[runs["env"] == env, "episodes"].max())
        lines += [f"## {env} (`{facts.gym_id}`, {facts.measure}, {direction}; {budget} episodes)", ""]
        if facts.threshold is not None:
            op = "<" if facts.lower_is_better else ">="
            lines += [f"Threshold: best so far {op} {facts.threshold:g} ({facts.threshold_meaning}). Fall-back fraction: "
                      "of the episodes after the first that reached it, the share below half the best so far (halfway "
                      f"from {_worst(facts)}).", ""]  # fmt: skip
        if facts.survival_bonus is not None:
            lines += [f"Every step pays a survival bonus of {facts.survival_bonus:g}: standing still for the whole "
                      "episode earns its length in return. \"Beyond the survival bonus\" = return - bonus x length, the "
                      "part earned by the task itself (moving forward, less the control cost).", ""]  # fmt: skip
        lines += [markdown(env_table(runs, env)), ""]
    if suite is not None and suite.name == "matched":
        lines += ["## The user's answer: to the threshold, and after it", "",
                  "Medians over the runs that reached the level (the env's threshold, or `tables.ANSWER_LEVELS`) of "
                  "the episodes, env steps and CPU seconds (cumulative, at the end of that episode) it took (reached/"
                  "runs); over all runs, the fall-back fraction after the threshold, the last-10 mean of the exploring "
                  "episodes and the final eval, the deterministic policy's return after the last episode (mean of the "
                  "suite's evaluation episodes). Where the env pays a survival bonus, also the last-10 mean beyond it, "
                  "and a second row: the first episode "
                  f"earning {BEYOND_BONUS_LEVEL:g} beyond the bonus, i.e. moving, not only standing.", "",
                  markdown(answer_table(episodes, runs)), ""]  # fmt: skip
    lines += aggregates(runs, envs, out, stem)
    if suite is None or suite.name == "figure3":
        table = verdicts.verdict_table(runs)
        if not table.empty:
            lines += ["## Verdicts", "", verdicts.RULES, "", markdown(table), ""]
    return "\n".join(lines)


def aggregates(runs: pd.DataFrame, envs: list[str], out: Path, stem: str) -> list[str]:
    """IQM (normalised, over envs) per measure, probability of improvement of DENFAC over each algorithm, profile."""
    lines = ["## Aggregates over envs (rliable)", ""]
    notes = [f"{e}: {env_facts(e).score_range}" if env_facts(e).score_range else f"{e}: min-max over these runs" for e in envs]
    lines += ["Normalisation (worst, best) per env: " + "; ".join(notes) + ". Each algorithm's IQM uses the seeds it has on "
              "every env listed; 95% stratified-bootstrap intervals.", ""]  # fmt: skip
    for measure, meaning in st.MEASURES.items():
        iqm = st.iqm_table(runs, envs, measure)
        if iqm.empty:
            continue
        iqm = iqm.set_index("algo").loc[row_order(iqm["algo"])].reset_index()
        iqm["algo"] = [ALGOS[a].label if a in ALGOS else a for a in iqm["algo"]]
        iqm["IQM [95% CI]"] = [
            f"{p:.3f} [{lo:.3f}, {hi:.3f}]" for p, lo, hi in zip(iqm["iqm"], iqm["low"], iqm["high"], strict=True)
        ]
        lines += [f"IQM of the normalised {meaning}:", "", markdown(iqm[["algo", "runs", "IQM [95% CI]"]]), ""]
    # every DENFAC configuration of the study (DENFAC's or SoftDENFAC's class; the ablation's rows aside) against each
    # other row
    mine = [a for a in row_order(runs["algo"]) if a in ALGOS and ALGOS[a].family != "ablation"]
    for denfac in [a for a in mine if ALGOS[a].zoo_algo in ("denfac", "soft_denfac")]:
        rows = []
        for other in row_order(runs["algo"]):
            if other == denfac:
                continue
            row = {"other": ALGOS[other].label if other in ALGOS else other}
            for measure in st.MEASURES:
                shared = [e for e in envs if {denfac, other} <= set(runs.loc[runs["env"] == e, "algo"])]
                p, lo, hi, na, nb = st.probability_of_improvement(runs, denfac, other, shared, measure)
                row[f"P(improvement), {measure}"] = (
                    f"{p:.2f} [{lo:.2f}, {hi:.2f}] ({na} vs {nb} seeds)" if np.isfinite(p) else "–"
                )
            rows.append(row)
        lines += [f"Probability that {ALGOS[denfac].label} beats each algorithm, averaged over the envs both ran:", "",
                  markdown(pd.DataFrame(rows)), ""]  # fmt: skip
    values = st.normalised(runs, "final_best")
    scores = {a: st.score_matrix(runs, a, envs, values) for a in row_order(runs["algo"])}
    plots.performance_profile(
        scores, out / f"{stem}_profile.png", "Performance profile: normalised best-so-far at the budget", st.REPS
    )
    lines += [f"![performance profile]({stem}_profile.png)", ""]
    return lines


def analyse(results_dir: str | Path, suites: Sequence[str] | None = None) -> list[Path]:
    """Write runs.csv and the reports of the study's suites in ``results_dir``; return the reports written.

    With ``suites``, only those suites' reports are rewritten (``all_runs.md`` too only if named, as ``all_runs``).
    A study of env-step budgets gets its one report (``mujoco100k.md``), the goal-conditioned one ``robotics.md``."""
    chosen = None if suites is None else set(suites)
    if chosen is not None:
        known = {name for name, suite in SUITES.items() if suite.study != "ablation"} | {"all_runs"}
        if unknown := sorted(chosen - known):
            raise ValueError(f"unknown suite(s) {unknown}: this study's reports are {sorted(known)}")
    out = Path(results_dir)
    records = store.read_runs(out)
    if any(record.get("timesteps_requested") for record in records):  # budgets of env steps
        from benchmarks.reports import mujoco100k  # (imports nothing of this module)

        mujoco100k.report(out)
        return [out / "mujoco100k.md"]
    if records and all(record["env"] in ROBOTICS_ENVS for record in records):  # the goal-conditioned study
        from benchmarks.reports import robotics  # (imports nothing of this module)

        robotics.report(out)
        return [out / "robotics.md"]
    episodes, runs = load_records(records)
    if runs.empty:
        raise FileNotFoundError(f"no finished runs in {store.runs_path(out)}")
    runs.to_csv(out / "runs.csv", index=False, columns=RUN_FIELDS)
    written = []
    for suite in SUITES.values():
        if suite.study == "ablation":  # its tables: benchmarks.reports.ablation_analysis
            continue
        if chosen is not None and suite.name not in chosen:
            continue
        cells = {(a, e, s) for a, e, s in suite.cells()}
        mine = runs[[c in cells for c in zip(runs["algo"], runs["env"], runs["seed"], strict=True)]]
        if not mine.empty:
            text = report(f"Benchmark suite `{suite.name}`", episodes, mine, out, suite.name, suite)
            (out / f"{suite.name}.md").write_text(text)
            written.append(out / f"{suite.name}.md")
    if chosen is None or "all_runs" in chosen:
        (out / "all_runs.md").write_text(report("All finished runs", episodes, runs, out, "all_runs"))
        written.append(out / "all_runs.md")
    return written


def report_of_run(results_dir: str | Path, suite: str | None) -> list[Path]:
    """The report of one run of the runner (``python -m benchmarks.run``), written to ``results_dir``: its suite's
    alone (the ablation's ``tables.md``), or ``all_runs.md`` for cells outside a suite; the other suites' reports
    are left as they are (:func:`analyse`, ``python -m benchmarks.reports.analysis``, rewrites them all)."""
    if suite is not None and SUITES[suite].study == "ablation":
        from benchmarks.reports import ablation_analysis  # (imports nothing of this module)

        return [ablation_analysis.write_tables(Path(results_dir))]
    return analyse(results_dir, [suite or "all_runs"])


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--results", default=str(COMMITTED / "sweep"), help="the study's folder")
    parser.add_argument(
        "--suites", nargs="+", default=None, help="rewrite only these suites' reports ('all_runs' for all_runs.md)"
    )
    args = parser.parse_args(argv)
    try:
        written = analyse(args.results, args.suites)
    except ValueError as error:
        parser.error(str(error))
    print(f"wrote {', '.join(str(path) for path in written)} (and runs.csv)")


if __name__ == "__main__":
    main()
