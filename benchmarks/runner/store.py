"""The compact runs file of a study: ``<results>/runs.jsonl.gz``, one JSON record per finished (or failed) run.

Each run is appended as its own gzip member, flushed and fsynced, by the one process that drives the sweep (workers
and Ray tasks return their result to it). A sweep killed while appending leaves at most a truncated last member,
which :func:`read_records` skips and :func:`repair` cuts off before the next sweep appends (the run is then simply
redone), so the file is always readable and a rerun resumes.
Git stores the growing file as a delta of its previous version (members are only appended).

A record is a flat dict: ``algo``, ``env``, ``seed``, ``status`` (``"done"`` or ``"failed"``), the run's metadata
(``task.run_one``), ``episodes`` (per-episode columns: ``{"episode": [...], "return": [...], ...}``), optional
``diagnostics`` (a list of dicts) and ``log`` (what the run printed), or ``error`` for a failed run.
"""

from __future__ import annotations

import gzip
import json
import os
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

RUNS_FILE = "runs.jsonl.gz"
#: algo, env, seed, episodes asked for, env steps asked for (None: an episode budget); another budget is another run
Cell = tuple[str, str, int, int, int | None]


def runs_path(results_dir: str | Path) -> Path:
    return Path(results_dir) / RUNS_FILE


def _line(record: dict[str, Any]) -> str:
    """One record as one JSON line (the format both writers share)."""
    return json.dumps(record, separators=(",", ":"), allow_nan=True) + "\n"


def append_record(results_dir: str | Path, record: dict[str, Any]) -> None:
    """Append one run (its own gzip member) and make it durable before returning."""
    path = runs_path(results_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = gzip.compress(_line(record).encode(), compresslevel=9, mtime=0)
    with path.open("ab") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def _members(raw: bytes) -> Iterator[tuple[bytes, int]]:
    """(decompressed text, end offset) of each complete gzip member, up to the first truncated or corrupt one."""
    offset = 0
    while offset < len(raw):
        decomp = zlib.decompressobj(wbits=31)  # one gzip member
        try:
            text = decomp.decompress(raw[offset:])
        except zlib.error:
            return
        if not decomp.eof:  # truncated member
            return
        offset = len(raw) - len(decomp.unused_data)
        yield text, offset


def read_records(results_dir: str | Path) -> Iterator[dict[str, Any]]:
    """Every complete record in file order; a truncated or corrupt tail (a killed append) is skipped."""
    path = runs_path(results_dir)
    if path.exists():
        yield from _file_records(path)


def _file_records(path: Path) -> Iterator[dict[str, Any]]:
    """The complete records of one runs file, whatever its name."""
    for text, _ in _members(path.read_bytes()):
        for line in text.decode().splitlines():
            yield json.loads(line)


def repair(results_dir: str | Path) -> int:
    """Cut a truncated or corrupt tail off the runs file (before appending to it); return the bytes removed."""
    path = runs_path(results_dir)
    if not path.exists():
        return 0
    raw = path.read_bytes()
    end = max((offset for _, offset in _members(raw)), default=0)
    if end < len(raw):
        with path.open("r+b") as f:
            f.truncate(end)
    return len(raw) - end


def read_runs(results_dir: str | Path) -> list[dict[str, Any]]:
    """The finished runs (``status == "done"``), one per cell (algo, env, seed, budget): the first one written wins."""
    runs: dict[Cell, dict[str, Any]] = {}
    for record in read_records(results_dir):
        if record.get("status") == "done":
            runs.setdefault(cell_of(record), record)
    return list(runs.values())


def finished_cells(results_dir: str | Path) -> set[Cell]:
    return {cell_of(r) for r in read_runs(results_dir)}


def cell_of(record: dict[str, Any]) -> Cell:
    steps = record.get("timesteps_requested")
    return record["algo"], record["env"], int(record["seed"]), int(record["episodes_requested"]), steps and int(steps)


def write_records(results_dir: str | Path, records: list[dict[str, Any]]) -> None:
    """Replace the runs file by ``records`` (conversion, compaction); written aside, then renamed into place."""
    path = runs_path(results_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    text = "".join(_line(record) for record in records)
    tmp.write_bytes(gzip.compress(text.encode(), compresslevel=9, mtime=0))  # one member: compresses best
    os.replace(tmp, path)


def merge(results_dir: str | Path, sources: list[str | Path]) -> list[Cell]:
    """Append to ``results_dir`` the finished runs of other runs files (a sweep run on another machine, with its own
    ``--results``) whose cells it does not hold yet; return those cells. A source is a runs file or a results folder."""
    repair(results_dir)
    held = finished_cells(results_dir)
    added: list[Cell] = []
    for source in sources:
        source = Path(source)
        if not source.exists():
            raise FileNotFoundError(f"no runs file at {source}")
        for record in _file_records(runs_path(source) if source.is_dir() else source):
            if record.get("status") == "done" and cell_of(record) not in held:
                append_record(results_dir, record)
                held.add(cell_of(record))
                added.append(cell_of(record))
    return added


def main(argv: list[str] | None = None) -> None:
    import argparse

    parser = argparse.ArgumentParser(description="Merge the finished runs of runs files into a study's results folder.")
    parser.add_argument("sources", nargs="+", help="runs files (any name) or results folders")
    parser.add_argument("--into", required=True, help="the study's results folder (e.g. benchmarks/results/sweep)")
    args = parser.parse_args(argv)
    try:
        added = merge(args.into, args.sources)
    except FileNotFoundError as error:
        parser.error(str(error))
    for algo, env, seed, episodes, timesteps in added:
        print(f"added {algo} {env} seed {seed} ({f'{timesteps} steps' if timesteps else f'{episodes} episodes'})")
    print(f"{len(added)} runs added to {runs_path(args.into)}")


if __name__ == "__main__":
    main()
