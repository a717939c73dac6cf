"""sb3-contrib's documentation convention for the package's six algorithms, on the tiny variants of ``conftest.py``."""

from __future__ import annotations

import inspect

import pytest


@pytest.mark.algorithms("all")
def test_class_documents_every_argument(name: str, algo_class) -> None:
    """sb3-contrib style: an ``MlpPolicy`` alias and a ``:param name:`` line for every constructor argument."""
    cls = algo_class(name)
    assert "MlpPolicy" in cls.policy_aliases
    parameters = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    missing = [p for p in parameters if f":param {p}:" not in (cls.__doc__ or "")]
    assert not missing, f"{cls.__name__} docstring lacks {missing}"


def test_package_version_is_the_distribution_version() -> None:
    """``sb3_denfac.__version__`` is the one place of the version: ``pyproject.toml`` reads it, the CHANGELOG's newest
    section is that version, and the installed distribution says it (saved models and bug reports quote it)."""
    import importlib.metadata
    import re
    from pathlib import Path

    import tomllib

    import sb3_denfac

    root = Path(__file__).resolve().parents[1]
    pyproject = tomllib.loads((root / "pyproject.toml").read_text())
    assert "version" not in pyproject["project"] and "version" in pyproject["project"]["dynamic"]
    assert pyproject["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "sb3_denfac.__version__"}
    newest = re.search(r"^## \[(\d+\.\d+\.\d+)\]", (root / "CHANGELOG.md").read_text(), re.MULTILINE)
    assert newest is not None and newest.group(1) == sb3_denfac.__version__
    assert importlib.metadata.version("sb3-denfac") == sb3_denfac.__version__
