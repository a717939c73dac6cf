"""Section 27's comparison of the default candidates (``journal.md``): the probability that each candidate's run beats
the 0.5 default's and the matched SAC's, averaged over the eight envs that all of them ran at 5 seeds (the matched
suite's seven and Walker2d-v5), on the best-so-far, the last-10 mean and the final deterministic evaluation
(``benchmarks.reports.stats.probability_of_improvement``: rliable's, with its 95% interval).

Runs: the sweep's rows (``benchmarks/results/sweep``) and the ablation's (``benchmarks/results/ablation`` and its
``walker2d/``); a cell in both is taken from the sweep. ``python -m research.ablation.default_choice``
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.reports import analysis
from benchmarks.reports import stats as st
from benchmarks.runner import store

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "results"
FOLDERS = (RESULTS / "sweep", RESULTS / "ablation", RESULTS / "ablation" / "walker2d")
#: the rows compared, by the name section 27 gives them (sweep rows and their ablation twins on Walker2d-v5)
NAMES = {
    "denfac_default": "0.5 default",
    "abl:default05": "0.5 default",
    "denfac_soft": "soft",
    "abl:soft": "soft",
    "abl:soft+K20": "soft + K = 20",
    "denfac_soft_min": "soft + min + K = 20",
    "abl:soft+min+K20": "soft + min + K = 20",
    "sac_matched": "SAC on DENFAC's schedule",
}
ENVS = ["pendulum", "invertedpendulum", "halfcheetah", "cartpole", "hopper", "reacher", "acrobot", "Walker2d-v5"]
SEEDS = range(5)
MEASURES = ("final_best", "last10", "final_eval")


def load_runs() -> pd.DataFrame:
    """The compared rows' runs on ``ENVS`` and ``SEEDS``, ``algo`` renamed by ``NAMES``, one run per cell."""
    records = [
        r
        for folder in FOLDERS
        for r in store.read_runs(folder)
        if r["algo"] in NAMES and r["env"] in ENVS and int(r["seed"]) in SEEDS
    ]
    runs = analysis.load_records(records)[1]
    runs = runs.assign(algo=runs["algo"].map(NAMES)).drop_duplicates(["algo", "env", "seed"])
    return runs.reset_index(drop=True)


def table(runs: pd.DataFrame, reference: str) -> pd.DataFrame:
    rows = []
    for candidate in dict.fromkeys(NAMES.values()):
        if candidate == reference:
            continue
        row = {"candidate": candidate}
        for measure in MEASURES:
            p, lo, hi, na, nb = st.probability_of_improvement(runs, candidate, reference, ENVS, measure)
            row[measure] = f"{p:.2f} [{lo:.2f}, {hi:.2f}] ({na} vs {nb})" if np.isfinite(p) else "–"
        rows.append(row)
    return pd.DataFrame(rows)


def main() -> None:
    runs = load_runs()
    for reference in ("0.5 default", "SAC on DENFAC's schedule"):
        print(f"P(candidate beats {reference}), averaged over {len(ENVS)} envs:")
        print(table(runs, reference).to_string(index=False), end="\n\n")


if __name__ == "__main__":
    sys.exit(main())
