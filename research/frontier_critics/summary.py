"""The screen's table: per (row, env), each seed's final and best evaluation, final / best, the mean of the
evaluations and the CPU seconds, with the ``mujoco100k`` suite's ``denfac_rho2`` runs of the same seeds as baseline.

    python -m research.frontier_critics.summary
"""

from __future__ import annotations

import gzip
import json
import statistics
from pathlib import Path

import pandas as pd

HERE = Path(__file__).parent
SUITE = HERE.parents[1] / "benchmarks" / "results" / "mujoco100k" / "runs.jsonl.gz"
ENVS = ("Hopper-v5", "Walker2d-v5")


def _line(row: str, env: str, seed: int, scores: list[float], cpu: float) -> dict:
    return {
        "row": row,
        "env": env,
        "seed": seed,
        "final": round(scores[-1]),
        "best": round(max(scores)),
        "final / best": round(scores[-1] / max(scores), 2) if max(scores) > 0 else None,
        "mean of evaluations": round(sum(scores) / len(scores)),
        "CPU s": round(cpu),
    }


def runs(seeds: tuple[int, ...] = (0, 1)) -> pd.DataFrame:
    lines = []
    for path in sorted(HERE.glob("runs_*.jsonl")):
        for text in path.read_text().splitlines():
            r = json.loads(text)
            lines.append(_line(r["row"], r["env"], r["seed"], [e["mean"] for e in r["evaluations"]], r["cpu_time"]))
    with gzip.open(SUITE, "rt") as f:
        for text in f:
            r = json.loads(text)
            if r["algo"] == "denfac_rho2" and r["env"] in ENVS and r["seed"] in seeds:
                scores = [statistics.mean(e["scores"]) for e in r["evaluations"]]
                lines.append(_line("rho2 (suite)", r["env"], r["seed"], scores, r["cpu_time"]))
    return pd.DataFrame(lines).sort_values(["env", "row", "seed"])


def table() -> pd.DataFrame:
    """Per (env, row): the medians over seeds (with 2 seeds, their mean) and the seeds' finals."""
    frame = runs()
    grouped = frame.groupby(["env", "row"])
    out = grouped[["final", "best", "mean of evaluations", "CPU s"]].median().round()
    out["final / best"] = grouped["final / best"].median().round(2)
    out["finals"] = grouped["final"].apply(lambda s: ", ".join(str(v) for v in s))
    return out.reset_index()


if __name__ == "__main__":
    print(runs().to_markdown(index=False))
    print()
    print(table().to_markdown(index=False))
