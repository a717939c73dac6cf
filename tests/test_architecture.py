"""docs/architecture.md is true to the code: every file of its layout exists, every module, class, function, method or
attribute it names in backticks is defined, and DENFAC's and SoftDENFAC's bases override each SB3 method once."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import stable_baselines3
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

from sb3_denfac import DENFAC, SoftDENFAC
from sb3_denfac.common.callbacks import ProgressBarHost, ProgressBarMixin
from sb3_denfac.common.checks import InputChecksHost, InputChecksMixin
from sb3_denfac.common.learning_rates import ActorCriticRatesMixin, RatesHost

ROOT = Path(__file__).parents[1]
PAGE = (ROOT / "docs" / "architecture.md").read_text()
NAME_COLUMN = 31  # the layout's descriptions start there; a line indented as far continues one
SOURCES = [ROOT / "sb3_denfac", ROOT / "benchmarks", ROOT / "research", Path(stable_baselines3.__file__).parent]


def _layout() -> list[str]:
    block = PAGE.split("## Layout", 1)[1].split("```", 2)[1]
    paths, stack = [], []  # stack: (indent, folder)
    for line in block.splitlines()[1:]:
        indent = len(line) - len(line.lstrip())
        if indent >= NAME_COLUMN or not line.strip():
            continue  # a description's continuation
        names = re.split(r"\s{2,}", line.strip())[0]  # the names, then two spaces or more, then the description
        while stack and stack[-1][0] >= indent:
            stack.pop()
        folder = "/".join(f for _, f in stack)
        for name in names.split():
            if "<" in name:
                continue
            path = f"{folder}/{name}" if folder else name
            if name.endswith("/"):
                stack.append((indent, name.rstrip("/")))
                folder = "/".join(f for _, f in stack)
            paths.append(path.rstrip("/"))
    return paths


@pytest.mark.parametrize("path", _layout())
def test_every_file_of_the_layout_exists(path: str) -> None:
    assert list(ROOT.glob(path)), f"docs/architecture.md names {path}, which does not exist"


def _definitions() -> str:
    return "\n".join(p.read_text() for source in SOURCES for p in source.rglob("*.py"))


DEFINED = _definitions()


def _named() -> list[str]:
    tokens = set(re.findall(r"`([^`\s]+)`", PAGE.split("## Layout", 1)[1].split("```", 2)[2]))
    return sorted(t for t in tokens if re.fullmatch(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*(\(\))?|[\w/]+\.py", t))


@pytest.mark.parametrize("name", _named())
def test_every_name_in_backticks_is_defined(name: str) -> None:
    if name.endswith(".py"):
        assert (ROOT / "sb3_denfac" / name).exists() or (ROOT / name).exists(), name
        return
    last = name.removesuffix("()").split(".")[-1]
    pattern = rf"(def|class) {last}\b|^\s*(self\.)?{last}\s*[:=]|^\s*{last},?$|\b{last}: "
    assert re.search(pattern, DEFINED, re.MULTILINE), f"docs/architecture.md names {name}: not defined in the code"


@pytest.mark.parametrize("algorithm", [DENFAC, SoftDENFAC])
def test_below_denfac_each_sb3_method_is_overridden_once(algorithm: type) -> None:
    """The episodic base and at most three mixins; each SB3 method overridden at most once below DENFAC, at most 10
    in all, as the page's table lists them."""
    mro = algorithm.__mro__
    below = mro[mro.index(DENFAC) + 1 : mro.index(OffPolicyAlgorithm)]
    assert len(below) <= 4, below
    sb3 = {name for base in OffPolicyAlgorithm.__mro__ for name in vars(base) if not name.startswith("__")}
    overrides = [name for cls in below for name in vars(cls) if name in sb3 and name != "_abc_impl"]
    assert len(overrides) == len(set(overrides)) and len(overrides) <= 10, overrides
    table = PAGE.split("Below DENFAC, each SB3 method is overridden once:", 1)[1].split("\n\n", 2)[1]
    listed = re.findall(r"^\| `(\w+)` \|", table, re.MULTILINE)
    assert sorted(listed) == sorted(overrides)


@pytest.mark.parametrize("name", ["denfac", "soft_denfac", "nfac", "cacla", "ddpg", "cmaes"])
def test_every_algorithm_provides_what_its_mixins_need(name: str, make_model) -> None:
    """Each generic mixin states what it needs from its host as a Protocol; every algorithm that uses it provides it."""
    model = make_model(name).learn(1)  # SB3 sets the logger up in learn
    hosts = {InputChecksMixin: InputChecksHost, ProgressBarMixin: ProgressBarHost, ActorCriticRatesMixin: RatesHost}
    used = [host for mixin, host in hosts.items() if isinstance(model, mixin)]
    assert used, type(model).__mro__
    for host in used:
        assert isinstance(model, host), host.__name__
