"""The README answers at a glance and stays true: its answer block is what ``python -m benchmarks.reports.readme`` writes from
the committed runs, it is short, it embeds a committed figure, its commands are CI's, and its relative links resolve."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from benchmarks.reports import readme

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> Path:
    """The entry point run end to end on the committed runs, into a folder of its own and a copy of the README."""
    out = tmp_path_factory.mktemp("answer")
    (out / "README.md").write_text(README.read_text())
    readme.main(["--out", str(out), "--readme", str(out / "README.md")])
    return out


def test_the_readme_answer_is_generated_from_the_committed_runs(generated):
    assert (generated / "README.md").read_text() == README.read_text(), "run `python -m benchmarks.reports.readme`"
    assert (generated / "answer.md").read_text() == (readme.SWEEP / "answer.md").read_text()
    assert (generated / "answer.png").stat().st_size > 10_000
    block = README.read_text().split(readme.START)[1].split(readme.END)[0]
    rows = [line for line in block.splitlines() if line.startswith("| ")]
    assert len(rows) == 1 + len(readme.PANELS) + 1  # header, one row per level, the CPU line
    for row in rows[1:-1]:  # one number per cell, or "not reached (k/n)", or "–" where the row was not run
        for cell in row.strip("|").split("|")[1:]:
            assert re.fullmatch(r" (\d+|not reached \(\d/\d\)|–) ", cell), row


def test_replace_block_refuses_a_readme_without_markers():
    assert readme.replace_block(f"a\n{readme.START}\nold\n{readme.END}\nb", "new") == "a\nnew\nb"
    with pytest.raises(ValueError, match="no <!-- answer:start -->"):
        readme.replace_block("no block here", "new")


def test_the_readme_is_short_and_embeds_a_committed_figure():
    text = README.read_text()
    assert len(text.splitlines()) <= 150
    figures = re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", text)
    assert figures == ["benchmarks/results/sweep/answer.png"]  # one figure, the generated one
    assert (REPO / figures[0]).is_file()


def test_the_readme_commands_are_the_ones_ci_runs():
    text = README.read_text()
    ci = (REPO / ".ci" / "run").read_text().split("verbatim ---\n")[1].splitlines()[0]
    assert f"```bash\n{ci}\n```" in text
    install = "python3 -m venv .venv && .venv/bin/pip install -q -c constraints-dev.txt -e ."
    quickstart = f"{install} && .venv/bin/python -m sb3_denfac.quickstart"
    assert f"```bash\n{quickstart}\n```" in text
    assert "from sb3_denfac import DENFAC, presets" in text


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: link text kept, lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _outside_code(text: str) -> list[str]:
    lines, fenced = [], False
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
        elif not fenced:
            lines.append(re.sub(r"`[^`]*`", "", line) if not line.startswith("#") else line)
    return lines


def anchors(path: Path) -> set[str]:
    """The anchors of a markdown file's headings (a repeated heading gets -1, -2, ...) and its explicit ids."""
    found: dict[str, int] = {}
    result = set()
    for line in _outside_code(path.read_text()):
        result |= set(re.findall(r"""id=["']([^"']+)["']""", line))
        if match := re.match(r"#{1,6} (.+)", line):
            slug = _slug(match.group(1))
            result.add(f"{slug}-{found[slug]}" if slug in found else slug)
            found[slug] = found.get(slug, 0) + 1
    return result


def broken_links(path: Path) -> list[str]:
    """The relative links of a markdown file whose file, or anchor in a markdown file, does not exist."""
    broken = []
    for line in _outside_code(path.read_text()):
        for target in LINK.findall(line):
            if re.match(r"[a-z]+:", target):  # https:, mailto:
                continue
            file, _, anchor = target.partition("#")
            resolved = (path.parent / file).resolve() if file else path
            if not resolved.exists():
                broken.append(target)
            elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved):
                broken.append(target)
    return broken


def test_every_relative_link_of_the_readme_resolves():
    assert _slug("The 0.5 default, and SAC on DENFAC's schedule (issue #23)") == (
        "the-05-default-and-sac-on-denfacs-schedule-issue-23"
    )
    assert _slug("The soft actor: `SoftDENFAC`") == "the-soft-actor-softdenfac"
    assert not broken_links(README)
