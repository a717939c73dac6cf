"""Docstrings of a subclass that shares most of its parent's arguments: the parent's ``:param`` entries, once."""

from __future__ import annotations

import inspect
import re
from collections.abc import Callable


def param_entries(doc: str) -> dict[str, str]:
    """The ``:param name: ...`` entries of a docstring (with their indented continuation lines), by name."""
    entries: dict[str, str] = {}
    lines = inspect.cleandoc(doc).splitlines()
    for index, line in enumerate(lines):
        match = re.match(r":param (\w+):", line)
        if match is None:
            continue
        block = [line]
        for following in lines[index + 1 :]:
            if not following.startswith(" ") or not following.strip():
                break
            block.append(following)
        entries[match.group(1)] = "\n".join(block)
    return entries


def with_parent_params(parent: type) -> Callable[[type], type]:
    """Class decorator: the class's docstring gets, after its own text, its own ``:param`` entries and ``parent``'s
    entry of every other constructor argument, in the signature's order."""

    def decorate(cls: type) -> type:
        _document(cls, parent)
        return cls

    return decorate


def _document(cls: type, parent: type) -> None:
    own = param_entries(cls.__doc__ or "")
    inherited = param_entries(parent.__doc__ or "")
    names = [name for name in inspect.signature(cls.__init__).parameters if name != "self"]
    entries = [own.get(name) or inherited.get(name) for name in names]
    text = re.split(r"\n\s*:param ", inspect.cleandoc(cls.__doc__ or ""), maxsplit=1)[0].rstrip()
    cls.__doc__ = text + "\n\n" + "\n".join(entry for entry in entries if entry) + "\n"
