"""A subclass that shares most of its parent's constructor arguments: it names its own, forwards the rest, and its
signature and docstring show them all (the parent's ``:param`` entries, once)."""

from __future__ import annotations

import inspect
import re
from collections.abc import Callable, Mapping
from typing import Any


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
    entry of every other constructor argument, in the signature's order. A constructor that forwards ``**kwargs`` to
    the parent's gets the signature of what it takes (:func:`forwarding_signature`, without the names in the class's
    ``PINNED``) first."""

    def decorate(cls: type) -> type:
        parameters = inspect.signature(cls.__init__).parameters.values()  # type: ignore[misc]
        if any(p.kind is p.VAR_KEYWORD for p in parameters):
            cls.__init__.__signature__ = forwarding_signature(cls, parent, getattr(cls, "PINNED", {}))  # type: ignore[misc]
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


def forwarding_signature(cls: type, parent: type, pinned: Mapping[str, str]) -> inspect.Signature:
    """The signature of ``cls.__init__(self, <its own arguments>, **kwargs)`` that forwards ``kwargs`` to
    ``parent.__init__``: the parent's arguments in the parent's order, ``cls``'s own ones (their defaults) in place,
    those ``pinned`` left out. Set as ``cls.__init__.__signature__``, it is what ``inspect.signature``, the docs and
    the zoo read."""
    own = {n: p for n, p in inspect.signature(cls.__init__).parameters.items() if p.kind is not p.VAR_KEYWORD}
    merged = [own.get(name, p) for name, p in inspect.signature(parent.__init__).parameters.items() if name not in pinned]
    extra = [p for name, p in own.items() if name not in {q.name for q in merged}]
    last = len(merged) - (merged[-1].name == "_init_setup_model")  # the private flag stays last
    merged = [*merged[:last], *extra, *merged[last:]]
    # what cls.__init__ takes: its own positional arguments by position, everything else by keyword
    positional = [p for p in merged if p.default is p.empty]
    keyword = [p.replace(kind=p.KEYWORD_ONLY) for p in merged if p.default is not p.empty]
    return inspect.Signature([*positional, *keyword])


def check_forwarded(cls: type, kwargs: Mapping[str, Any], pinned: Mapping[str, str]) -> None:
    """Refuse, with Python's ``TypeError`` naming ``cls``, a keyword that ``cls`` pins (and why) or that its signature
    (:func:`forwarding_signature`) does not hold."""
    parameters = inspect.signature(cls.__init__).parameters  # type: ignore[misc]
    for name in kwargs:
        if name in pinned:
            raise TypeError(f"{cls.__name__} does not take {name}: {pinned[name]}")
        if name not in parameters:
            raise TypeError(f"{cls.__name__}.__init__() got an unexpected keyword argument {name!r}")
