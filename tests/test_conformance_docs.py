"""sb3-contrib's documentation convention for the package's five algorithms, on the tiny variants of ``conftest.py``."""

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
    """``sb3_denfac.__version__`` is the version ``pyproject.toml`` builds (saved models and bug reports quote it)."""
    from pathlib import Path

    import tomllib

    import sb3_denfac

    pyproject = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    assert sb3_denfac.__version__ == pyproject["project"]["version"]
