"""Sphinx configuration of the documentation site: the Markdown pages of docs/ (myst-parser) and the API reference of
docs/api/ (autodoc on the docstrings' ``:param name:`` field lists, which Sphinx reads natively).

Build with ``.venv/bin/sphinx-build -b html docs docs/_build/html`` (the ``docs`` extra); tests/test_docs_site.py
builds it with warnings as errors."""

from __future__ import annotations

import inspect
import os
import sys
from pathlib import Path
from typing import Any

from docutils import nodes
from sphinx import addnodes
from sphinx.application import Sphinx
from sphinx.transforms import SphinxTransform
from sphinx.util.typing import stringify_annotation

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # the package from this checkout, installed or not

import sb3_denfac  # noqa: E402

project = "sb3-denfac"
author = "sb3-denfac contributors"
copyright = "sb3-denfac contributors"
release = version = sb3_denfac.__version__

extensions = ["myst_parser", "sphinx.ext.autodoc"]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]

# GitHub's anchors (docs/page.md#a-heading) for headings down to ####, as the pages link them.
myst_heading_anchors = 4

autodoc_member_order = "bysource"
autodoc_typehints = "description"  # the signature's types beside each ``:param:`` entry
autodoc_typehints_description_target = "documented"
autodoc_default_options = {"show-inheritance": True}

html_theme = "sphinx_rtd_theme"
html_title = f"sb3-denfac {release}"
html_show_sourcelink = False


class OutOfTreeLinks(SphinxTransform):
    """The pages' links to files of the repository outside docs/ (``../benchmarks/results/sweep/matched.md``,
    ``../research/ablation/README.md``, the README's ``CHANGELOG.md``), which read as links on GitHub, become download
    links, as myst-parser makes of the links to other existing files (``.png``, ``.json``): the site carries a copy of
    the file. A link whose file does not exist is left to myst-parser, whose warning fails the ``-W`` build. (Anchors
    into those files are checked by tests/test_docs_site.py, with the README's link checker.)"""

    default_priority = 5  # while reading, before the download files are collected

    def apply(self, **kwargs: object) -> None:
        srcdir = Path(self.env.srcdir).resolve()
        docdir = (srcdir / self.env.docname).parent
        for node in list(self.document.findall(addnodes.pending_xref)):
            if node.get("reftype") != "myst":
                continue
            if node.get("refdomain") == "doc":  # an existing .md file, as a document name outside the source folder
                if node["reftarget"] in self.env.found_docs:
                    continue
                target = Path(self.env.srcdir, node["reftarget"] + ".md")  # myst names it by its path less the suffix
            elif node.get("refdomain") is None and node.source:  # from an included file (the README), relative to it
                path = node["reftarget"].partition("#")[0]
                if not path or ":" in path:
                    continue
                target = Path(node.source).parent / path
            else:
                continue
            target = target.resolve()
            if not target.is_file() or target.is_relative_to(srcdir) or not target.is_relative_to(ROOT):
                continue
            link = addnodes.download_reference(
                refdomain=None, reftype="myst", refdoc=self.env.docname, refexplicit=True,
                reftarget=os.path.relpath(target, docdir),
            )  # fmt: skip
            link.source, link.line = node.source, node.line
            link += node.children or [nodes.literal(text=str(target.relative_to(ROOT)))]
            node.replace_self(link)


def constructor_signature(
    app: Sphinx, what: str, name: str, obj: Any, options: Any, signature: str | None, return_annotation: str | None
) -> tuple[str, None] | None:
    """A class's signature and parameter types as Python reads them from its constructor. autodoc would show
    ``(*args, **kwargs)`` (``InputChecksMixin.__new__``) and take each parameter's type from the class attribute of
    the same name (``env: VecEnv | None`` of SB3's ``BaseAlgorithm``, not the constructor's ``GymEnv | str``)."""
    if what != "class":
        return None
    try:
        parameters = inspect.signature(obj).parameters.values()
    except (TypeError, ValueError):
        return None
    recorded = getattr(getattr(app.env, "current_document", None), "autodoc_annotations", None)  # Sphinx >= 9
    if recorded is None:  # before: autodoc's temp_data
        recorded = app.env.temp_data.setdefault("annotations", {})
    types = recorded.setdefault(name, {})
    types.clear()  # the ones recorded from the class's attributes
    for p in parameters:
        if p.annotation is not p.empty:
            types[p.name] = p.annotation if isinstance(p.annotation, str) else stringify_annotation(p.annotation)
    bare = inspect.Signature([p.replace(annotation=p.empty) for p in parameters])
    return str(bare), None


def setup(app: Sphinx) -> dict[str, bool]:
    app.add_transform(OutOfTreeLinks)
    app.connect("autodoc-process-signature", constructor_signature, priority=600)  # after autodoc's own recording
    return {"parallel_read_safe": True, "parallel_write_safe": True}
