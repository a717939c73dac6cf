"""The probes' table: one line per run of ``runs*.jsonl`` (final and best evaluation, their mean, CPU, episodes).

python -m research.mujoco100k.summary
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

HERE = Path(__file__).parent


def table() -> pd.DataFrame:
    rows = []
    for path in sorted(HERE.glob("runs*.jsonl")):
        for line in path.read_text().splitlines():
            r = json.loads(line)
            scores = [e["mean"] for e in r["evaluations"]]
            rows.append(
                {
                    "row": r["row"],
                    "env": r["env"],
                    "seed": r["seed"],
                    "final": round(scores[-1]),
                    "best": round(max(scores)),
                    "mean of evaluations": round(sum(scores) / len(scores)),
                    "CPU s": round(r["cpu_time"]),
                    "episodes": r["episodes"],
                }
            )
    return pd.DataFrame(rows).sort_values(["env", "row", "seed"])


if __name__ == "__main__":
    print(table().to_markdown(index=False))
