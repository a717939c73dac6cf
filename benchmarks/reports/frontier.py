"""The published 100k-step figures of the data-efficiency frontier (``benchmarks/configs/frontier_100k.csv``, each
with its file and commit): the curves, their value at a budget, and the reference table of the ``mujoco100k`` report."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

_BENCHMARKS = Path(__file__).resolve().parents[1]
FRONTIER_CSV = _BENCHMARKS / "configs" / "frontier_100k.csv"
#: The published methods drawn in the figure and listed in the table, in this order.
FRONTIER_METHODS = ("SAC (UTD 1)", "REDQ (UTD 20)", "DroQ (UTD 20)", "CrossQ (UTD 1)", "SimbaV2 (UTD 2)", "MR.Q")


@functools.cache
def _frontier_csv() -> pd.DataFrame:
    return pd.read_csv(FRONTIER_CSV, comment="#")


def frontier() -> pd.DataFrame:
    """The published curves: method, env, env_step, mean, std, n_seeds, source. ``env`` is the v5 id this suite runs;
    the published runs are on its v4 twin (the same task with minor model fixes)."""
    curves = _frontier_csv().copy()
    curves["env"] = curves["env"].str.replace("-v4", "-v5")
    return curves


def frontier_at_budget(budget: int = 100_000) -> pd.DataFrame:
    """Per (method, env): the last published evaluation at or before ``budget`` steps."""
    curves = frontier()
    curves = curves[curves["env_step"] <= budget].sort_values("env_step")
    return curves.groupby(["method", "env"], as_index=False).tail(1).reset_index(drop=True)


def published(ref: pd.DataFrame, method: str, env: str) -> pd.Series | None:
    """The row of ``ref`` (:func:`frontier_at_budget`) for ``method`` on ``env``, None if it was not published."""
    hit = ref[(ref["method"] == method) & (ref["env"] == env)]
    return None if hit.empty else hit.iloc[0]


def published_mean(ref: pd.DataFrame, method: str, env: str) -> float:
    row = published(ref, method, env)
    return float("nan") if row is None else float(row["mean"])


def reference_table(envs: Sequence[str]) -> pd.DataFrame:
    """The published figures at 100k steps on ``envs`` (v5 names; the published runs are on v4)."""
    ref = frontier_at_budget()
    lines = []
    for method in FRONTIER_METHODS:
        line = {"method": method}
        for env in envs:
            row = published(ref, method, env)
            line[env] = (
                "-"
                if row is None
                else f"{row['mean']:.0f} ± {row['std']:.0f} ({row['n_seeds']} seeds, at {row['env_step'] / 1000:.0f}k)"
            )
        lines.append(line)
    return pd.DataFrame(lines)
