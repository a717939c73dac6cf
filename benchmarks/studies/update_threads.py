"""One fast DENFAC update at 1 and 2 torch threads, interleaved, on a real (trained) Acrobot buffer.

Run it with the other core busy and idle to see whether two threads help or collapse on a shared 2-core machine.
Writes ``benchmarks/results/update_cost/update_threads.json`` (appends one record per run: load average, times, medians).

Usage: ``python -m benchmarks.studies.update_threads [--repeats 5] [--episodes 10]``
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import torch as th

from benchmarks.runner.task import git_state
from benchmarks.studies.update_cost import RESULTS, load_denfac, make_buffers


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--episodes", type=int, default=10, help="training episodes before the trained buffer")
    parser.add_argument("--output", default=str(RESULTS / "update_threads.json"), help="JSON file to append to")
    args = parser.parse_args(argv)
    th.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        path = make_buffers("acrobot", Path(tmp), args.episodes)["trained"]
        models = {threads: load_denfac(path, "fast") for threads in (1, 2)}
        load_start = os.getloadavg()
        times: dict[int, list[float]] = {1: [], 2: []}
        for _ in range(args.repeats):
            for threads, model in models.items():
                th.set_num_threads(threads)
                start = time.perf_counter()
                model._update()
                times[threads].append(time.perf_counter() - start)
    record = dict(
        commit=git_state().get("commit", "unknown")[:10],
        load_average_start=load_start,
        load_average_end=os.getloadavg(),
        times_s=times,
        median_s={threads: float(np.median(t)) for threads, t in times.items()},
    )
    out = Path(args.output)
    records = json.loads(out.read_text()) if out.is_file() else []
    out.write_text(json.dumps([*records, record], indent=1))
    print(json.dumps(record))


if __name__ == "__main__":
    main()
