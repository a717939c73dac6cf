"""Rows as data: named constructor settings in a YAML file, each over a base, as the RL Zoo's entries are.

A row is a mapping of constructor arguments with three keys of its own:

- ``base: <row>``: start from that row of the same file (resolved first), the row's keys over it;
- ``preset: <name>``: start from a preset of :data:`sb3_denfac.zoo.config.PRESETS` (``preset: paper`` is
  :data:`sb3_denfac.denfac.presets.PAPER`);
- ``algo: <zoo name>``: the algorithm the arguments are for (:func:`algorithm`; default ``denfac``), inherited from
  the base.

The row's other keys override what it starts from through :func:`sb3_denfac.denfac.presets.with_overrides` (mappings
such as ``policy_kwargs`` and its ``net_arch`` merged key by key, anything else replaced). YAML has no tuples: a tuple
argument is written, and resolved, as a list.

Used by the benchmark's ablation rows (``benchmarks/configs/ablation.yml``) and by the studies in ``research/``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

STRUCTURE = ("base", "preset", "algo")  # a row's keys that are not constructor arguments


def read_rows(path: str | Path, section: str | None = None) -> dict[str, dict[str, Any]]:
    """The rows of ``path`` as written (bases and presets not resolved): the file's mapping, or its ``section``."""
    path = Path(path)
    content = yaml.safe_load(path.read_text()) or {}
    rows = content.get(section) if section is not None else content
    if not isinstance(rows, dict) or not all(isinstance(row, dict) or row is None for row in rows.values()):
        where = f"{path}" + (f", section {section!r}" if section is not None else "")
        raise ValueError(f"{where}: expected a mapping of rows, each a mapping of constructor arguments")
    return {str(name): dict(row or {}) for name, row in rows.items()}


def chain(rows: dict[str, dict[str, Any]], name: str) -> list[str]:
    """``name`` and its bases, nearest first (``["soft+min", "soft", "default05+bounds", ...]``)."""
    names: list[str] = []
    while name is not None:
        if name not in rows:
            known = f"{', '.join(list(rows)[:8])}..." if len(rows) > 8 else ", ".join(rows)
            raise KeyError(f"row {name!r} is not defined{f' (base of {names[-1]!r})' if names else ''}; rows: {known}")
        if name in names:
            raise ValueError(f"rows based on each other: {' -> '.join([*names, name])}")
        names.append(name)
        name = rows[name].get("base")
    return names


def algorithm(rows: dict[str, dict[str, Any]], name: str, default: str = "denfac") -> str:
    """The zoo name of the algorithm of row ``name``: its own ``algo``, else its nearest base's, else ``default``."""
    return next((rows[step]["algo"] for step in chain(rows, name) if "algo" in rows[step]), default)


def resolve(rows: dict[str, dict[str, Any]], name: str) -> dict[str, Any]:
    """The constructor arguments of row ``name``: its bases' and preset's, with its own keys over them."""
    from sb3_denfac.denfac.presets import with_overrides

    resolved: dict[str, Any] = {}
    for step in reversed(chain(rows, name)):
        row = rows[step]
        if "preset" in row:
            from sb3_denfac.zoo import expand_preset

            resolved = with_overrides(resolved, expand_preset({"preset": row["preset"]}, f" (row {step!r})"))
        resolved = with_overrides(resolved, {k: v for k, v in row.items() if k not in STRUCTURE})
    return resolved


def load_rows(path: str | Path, section: str | None = None) -> dict[str, dict[str, Any]]:
    """Every row of ``path`` (or of its ``section``) resolved (:func:`resolve`), in the file's order."""
    rows = read_rows(path, section)
    return {name: resolve(rows, name) for name in rows}
