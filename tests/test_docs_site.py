"""The documentation site (docs/, Sphinx with myst-parser: ``.venv/bin/sphinx-build -b html docs docs/_build/html``)
builds with warnings as errors, so a broken link, anchor or docstring fails, and its API reference lists every
algorithm, every policy class and DENFAC's presets."""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import io
import os
import posixpath
import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_readme import broken_links  # the README's link checker: files and GitHub anchors

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"
ALGORITHMS = ("DENFAC", "SoftDENFAC", "NFAC", "CACLA", "DDPG", "CMAES")
POLICY_MODULES = [f"sb3_denfac.{package}.policies" for package in ("denfac", "soft_denfac", "nfac", "cacla", "ddpg", "cmaes")]


def _require_docs_extra() -> None:
    missing = [name for name in ("sphinx", "myst_parser", "sphinx_rtd_theme") if importlib.util.find_spec(name) is None]
    if missing:
        message = f'{", ".join(missing)} missing: pip install -c constraints-dev.txt -e ".[docs]"'
        if os.environ.get("CI") == "true":  # CI installs the docs extra: a missing one is a broken install there
            pytest.fail(message)
        pytest.skip(message)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> tuple[subprocess.CompletedProcess, list[str], Path]:
    """The site built once as the docs say, with -W: the run, its warnings and the HTML folder."""
    _require_docs_extra()
    out = tmp_path_factory.mktemp("site")
    warnings_file = out / "warnings.txt"
    command = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-N", "-q", "-b", "html", "-w", str(warnings_file)]
    run = subprocess.run([*command, str(DOCS), str(out / "html")], cwd=REPO, capture_output=True, text=True, timeout=300)
    text = warnings_file.read_text() if warnings_file.exists() else ""
    warnings = [line for line in text.splitlines() if re.search(r"\b(WARNING|ERROR|SEVERE|CRITICAL):", line)]
    return run, warnings, out / "html"


def test_the_site_builds_with_warnings_as_errors_and_lists_the_api(site):
    """One test of the one build (under ``pytest -n 2`` each worker would build it for its own tests)."""
    run, warnings, html = site
    _check_warnings(run, warnings)
    pages = {p.stem for p in DOCS.glob("*.md")}
    assert {p.stem for p in html.glob("*.html")} >= pages | {"genindex", "search"}
    _check_api_reference(_objects(html))


def _check_warnings(run: subprocess.CompletedProcess, warnings: list[str]) -> None:
    assert not warnings, "\n".join(warnings)  # a broken link, anchor or docstring
    assert run.returncode == 0, run.stderr[-3000:]


def _objects(html: Path) -> dict[str, str]:
    """Every object of the site's inventory (objects.inv) by name, with its page."""
    from sphinx.util.inventory import InventoryFile

    content = (html / "objects.inv").read_bytes()
    if hasattr(InventoryFile, "loads"):  # Sphinx >= 8.2
        data = InventoryFile.loads(content, uri="").data
    else:
        data = InventoryFile.load(io.BytesIO(content), "", posixpath.join)
    return {
        name: entry.uri if hasattr(entry, "uri") else entry[2]  # Sphinx >= 9: an item with attributes; before: a tuple
        for role, objects in data.items()
        if role.startswith("py:")
        for name, entry in objects.items()
    }


def _check_api_reference(objects: dict[str, str]) -> None:
    """Every algorithm, every public class of the policies modules and their aliases, the presets, the callbacks."""
    expected = [f"sb3_denfac.{name}" for name in ALGORITHMS]
    for module_name in POLICY_MODULES:  # every public class a policies module defines, and its aliases
        module = importlib.import_module(module_name)
        for name, value in vars(module).items():
            defined_here = inspect.isclass(value) and value.__module__ == module_name
            if (defined_here and not name.startswith("_")) or name in ("MlpPolicy", "MultiInputPolicy"):
                expected.append(f"{module_name}.{name}")
    presets = "sb3_denfac.denfac.presets"
    names = ("PAPER", "DATA_EFFICIENT", "DENFAC_DATA_EFFICIENT", "OWNERS", "data_efficient", "paper", "with_overrides")
    expected += [f"{presets}.{name}" for name in names]
    expected += [f"sb3_denfac.common.callbacks.{name}" for name in ("EpisodePerformanceCallback", "UpdateStatsCallback")]
    missing = [name for name in expected if name not in objects]
    assert not missing, f"not in the API reference: {missing}"
    assert len([name for name in expected if ".policies." in name]) >= 15
    assert objects["sb3_denfac.DENFAC"].startswith("api/denfac.html")
    assert objects[f"{presets}.PAPER"].startswith("api/presets.html")


@pytest.mark.parametrize("page", sorted(p.name for p in DOCS.glob("*.md")))
def test_every_relative_link_of_the_docs_resolves(page):
    """Also the links out of docs/ (``../research/...``), which the site turns into downloads without their anchor:
    each file exists, and each anchor is a heading of its page."""
    assert not broken_links(DOCS / page)
