"""Aggregates and verdicts with rliable: IQM with stratified bootstrap intervals, probability of improvement, verdict rules.

Scores are oriented so that higher is better (a lower-is-better measure is negated for rank statistics and normalised
with its reference range for the IQM). All intervals are 95% percentile intervals of rliable's stratified bootstrap
(runs resampled within each env), ``REPS`` resamples, fixed random state.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator

import numpy as np
import pandas as pd

from sb3_denfac.envs.facts import env_facts

REPS = 2000
EQUAL_MARGIN = (0.25, 0.75)  # "about equal": the whole interval of P(A > B) within this band
MEASURES = {"final_best": "best-so-far at the budget (the paper's measure)", "last10": "mean of the last 10 episodes"}


def median_reached(values) -> float:
    """The median of a measure some runs never reached (None or NaN: "not within the budget"), counting those as past
    every other: NaN when the middle run (either middle run, for an even count) did not reach it."""
    array = np.array([np.inf if v is None or v != v else float(v) for v in values], dtype=float)
    middle = float(np.median(array)) if len(array) else np.nan
    return middle if np.isfinite(middle) else np.nan


@contextlib.contextmanager
def _seeded() -> Iterator[np.random.RandomState]:
    """A fixed random state for one rliable call. rliable 1.2's stratified bootstraps draw their indices from numpy's
    *global* generator and ignore ``random_state``: the global one is seeded too, and restored afterwards. The
    FutureWarning that arch (rliable's bootstrap) gives for that legacy argument, once per call, is silenced here."""
    state = np.random.get_state()
    np.random.seed(0)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "random_state is deprecated", FutureWarning, r"arch\.")
            yield np.random.RandomState(0)  # rliable's API takes the legacy RandomState
    finally:
        np.random.set_state(state)


def oriented(runs: pd.DataFrame, measure: str, lower_is_better: bool | None = None) -> pd.Series:
    """The measure with higher = better: negated on lower-is-better envs, or everywhere if ``lower_is_better`` (a
    measure whose direction is the same on every env, e.g. CPU seconds; None: the env's)."""
    if lower_is_better is not None:
        return runs[measure] * (-1.0 if lower_is_better else 1.0)
    sign = runs["env"].map(lambda e: -1.0 if env_facts(e).lower_is_better else 1.0)
    return runs[measure] * sign


def normalised(runs: pd.DataFrame, measure: str) -> pd.Series:
    """Score in [0, 1] per env: the env's ``score_range`` reference, else min-max over the runs given (on that env)."""
    out = pd.Series(np.nan, index=runs.index)
    for env, group in runs.groupby("env"):
        ref = env_facts(env).score_range
        worst, best = ref if ref is not None else (group[measure].min(), group[measure].max())
        if env_facts(env).lower_is_better and ref is None:
            worst, best = best, worst
        span = (best - worst) or 1.0
        out.loc[group.index] = (group[measure] - worst) / span
    return out


def score_matrix(runs: pd.DataFrame, algo: str, envs: list[str], values: pd.Series) -> np.ndarray:
    """(seeds, envs) matrix of ``values`` for ``algo`` over the seeds it has on every env of ``envs``."""
    mine = runs[runs["algo"] == algo]
    seeds = set.intersection(*(set(mine.loc[mine["env"] == e, "seed"]) for e in envs)) if envs else set()
    if not seeds:
        return np.empty((0, len(envs)))
    table = values[mine.index].groupby([mine["seed"], mine["env"]]).first().unstack("env")
    return table.loc[sorted(seeds), envs].to_numpy(dtype=np.float64)


def iqm_table(runs: pd.DataFrame, envs: list[str], measure: str) -> pd.DataFrame:
    """IQM of the normalised measure over (seed, env) per algorithm, with its interval; seeds common to ``envs``."""
    values = normalised(runs, measure)
    scores = {a: score_matrix(runs, a, envs, values) for a in runs["algo"].unique()}
    scores = {a: s for a, s in scores.items() if s.shape[0] >= 2}
    if not scores:
        return pd.DataFrame(columns=["algo", "runs", "iqm", "low", "high"])
    from rliable import library as rly
    from rliable import metrics

    with _seeded() as random_state:
        point, interval = rly.get_interval_estimates(
            scores, lambda x: np.array([metrics.aggregate_iqm(x)]), reps=REPS, random_state=random_state
        )
    rows = [
        {"algo": a, "runs": scores[a].size, "iqm": float(point[a][0]), "low": interval[a][0, 0], "high": interval[a][1, 0]}
        for a in scores
    ]
    return pd.DataFrame(rows)


def probability_of_improvement(
    runs: pd.DataFrame, a: str, b: str, envs: list[str], measure: str, lower_is_better: bool | None = None
) -> tuple[float, float, float, int, int]:
    """P(a > b) on ``measure`` (oriented by ``oriented(runs, measure, lower_is_better)``) averaged over ``envs``
    (rliable), its interval, and the run counts of a and b."""
    from rliable import library as rly
    from rliable import metrics

    values = oriented(runs, measure, lower_is_better)
    x, y = score_matrix(runs, a, envs, values), score_matrix(runs, b, envs, values)
    if x.shape[0] < 2 or y.shape[0] < 2:
        return np.nan, np.nan, np.nan, x.shape[0], y.shape[0]
    with _seeded() as random_state:
        point, interval = rly.get_interval_estimates(
            {"p": (x, y)}, metrics.probability_of_improvement, reps=REPS, random_state=random_state
        )
    return float(point["p"]), float(interval["p"][0, 0]), float(interval["p"][1, 0]), x.shape[0], y.shape[0]


def verdict(kind: str, low: float, high: float) -> str:
    """held / refuted / inconclusive from the interval of P(a > b).

    ``better``: held if low > 0.5, refuted if high < 0.5. ``equal``: refuted if the interval excludes 0.5, held if it
    lies within ``EQUAL_MARGIN``. Otherwise (or without an interval) inconclusive.
    """
    if not np.isfinite(low) or not np.isfinite(high):
        return "inconclusive (too few runs)"
    if kind == "better":
        return "held" if low > 0.5 else "refuted" if high < 0.5 else "inconclusive"
    if low > 0.5 or high < 0.5:
        return "refuted"
    return "held" if EQUAL_MARGIN[0] <= low and high <= EQUAL_MARGIN[1] else "inconclusive"


def combine(verdicts: list[str]) -> str:
    """A claim made of several comparisons: refuted if one is, held if all are, otherwise inconclusive."""
    if any(v == "refuted" for v in verdicts):
        return "refuted"
    if verdicts and all(v == "held" for v in verdicts):
        return "held"
    return "inconclusive"


def goal_fraction(reached: int, n: int) -> tuple[float, float]:
    """Clopper-Pearson 95% interval of the fraction of runs that reached the goal."""
    from scipy.stats import binomtest

    if n == 0:
        return np.nan, np.nan
    ci = binomtest(reached, n).proportion_ci(0.95)
    return float(ci.low), float(ci.high)
