"""The hyperparameters of a benchmark row on an env (``load_hyperparams``), and where they come from.

A row (``benchmarks.runner.algos.ALGOS``) states its settings in one of three ways: a zoo-style YAML file ``<row>.yml`` (the
package's ``hyperparams/`` or ``benchmarks/configs/``), another row with overrides on top, or a row of a row file (the
ablation's ``benchmarks/configs/ablation.yml``, :mod:`benchmarks.runner.rows`).
"""

from __future__ import annotations

import functools
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import yaml

from benchmarks.runner import rows as row_files
from benchmarks.runner.algos import ALGOS, BENCHMARK_CONFIGS_DIR, PACKAGE_HYPERPARAMS_DIR, Algo, register_external
from benchmarks.runner.suites import HYPERPARAMS_OF
from sb3_denfac.envs.facts import env_facts


def denfac_critic_steps_per_episode() -> int:
    """Critic gradient steps the default DENFAC takes at every episode end: K fitted iterations x critic steps."""
    import inspect

    from sb3_denfac import DENFAC

    params = inspect.signature(DENFAC.__init__).parameters
    return int(params["n_fitted_iterations"].default) * int(params["critic_steps"].default)


def _paper_denfac() -> dict[str, Any]:
    from sb3_denfac.denfac.presets import paper

    return paper()


#: Rows whose package YAML states the paper's settings only for the paper's envs (its ``default`` entry is the
#: library's general default): on any other env they use this preset, so "DENFAC (faithful)" stays Algorithm 1.
PRESET_ELSEWHERE: dict[str, Any] = {"denfac": _paper_denfac}  # the one preset: presets.PAPER


def _takes_gamma(algo: str) -> bool:
    import inspect

    from sb3_denfac.zoo import algorithm_class

    zoo_algo = ALGOS[algo].zoo_algo if algo in ALGOS else algo
    register_external(zoo_algo)
    return "gamma" in inspect.signature(algorithm_class(zoo_algo).__init__).parameters


def load_hyperparams(algo: str, env: str, dirs: Iterable[str | Path] = ()) -> tuple[dict[str, Any], str]:
    """The hyperparameters of row ``algo`` on ``env`` and where they come from: (hyperparameters, source).

    - A row of a row file (the ablation's ``abl:<name>``) takes that row (:func:`row_file_hyperparams`).
    - A row with a ``base`` row takes that row's hyperparameters with its ``overrides`` on top (``gradient_steps``
      ``"denfac"``: :func:`denfac_critic_steps_per_episode`).
    - Any other row: zoo-style lookup of ``<algo>.yml`` in ``dirs``, then the package's folder, then
      ``benchmarks/configs``: the entry of the env's Gymnasium id (of its base env for a variant, ``HYPERPARAMS_OF``),
      else ``default``. Fails if no file or entry exists: every row states its settings.

    The env's prescribed gamma (``ENV_FACTS``) is added when the result sets none and the algorithm has one."""
    row = ALGOS.get(algo)
    if row is not None and row.rows_file is not None:
        hyperparams, source = row_file_hyperparams(row, env)
        hyperparams = {"policy": "MlpPolicy", **hyperparams}
    elif row is not None and row.base is not None:
        hyperparams, source = load_hyperparams(row.base, env, dirs)
        overrides = {k: (denfac_critic_steps_per_episode() if v == "denfac" else v) for k, v in row.overrides}
        hyperparams = {**hyperparams, **overrides}
        source += " + " + ", ".join(f"{k}={v}" for k, v in overrides.items())
        return hyperparams, source
    else:
        hyperparams, source = yaml_hyperparams(algo, env, dirs)
    env_fact = env_facts(env)
    if "gamma" not in hyperparams and env_fact.gamma is not None and _takes_gamma(algo):
        hyperparams["gamma"] = env_fact.gamma
        source += f" + the env's gamma {env_fact.gamma}"
    return hyperparams, source


def yaml_hyperparams(algo: str, env: str, dirs: Iterable[str | Path] = ()) -> tuple[dict[str, Any], str]:
    """The zoo-style entry of ``<algo>.yml`` for ``env`` (:func:`load_hyperparams`'s third case) and its source."""
    from sb3_denfac.zoo import load_config_file, select_entry

    dirs = list(dirs)
    entry_id = env_facts(HYPERPARAMS_OF.get(env, env)).gym_id
    for folder in [*map(Path, dirs), PACKAGE_HYPERPARAMS_DIR, BENCHMARK_CONFIGS_DIR]:
        path = folder / f"{algo}.yml"
        if path.is_file():
            break
    else:
        raise FileNotFoundError(
            f"no {algo}.yml in {[str(d) for d in dirs]}, {PACKAGE_HYPERPARAMS_DIR} or {BENCHMARK_CONFIGS_DIR}"
        )
    config = load_config_file(path)
    if algo in PRESET_ELSEWHERE and entry_id not in config:
        return {"policy": "MlpPolicy", **PRESET_ELSEWHERE[algo]()}, f"sb3_denfac.denfac.presets.PAPER (no {path.name} entry)"
    key = entry_id if entry_id in config else "default"
    return select_entry(config, entry_id, path), f"{path.name}[{key}]"


@functools.cache
def _row_file(path: Path) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """A row file's content and its rows as written (its ``rows`` section, or the whole file)."""
    content = yaml.safe_load(path.read_text())
    return content, row_files.read_rows(path, "rows" if "rows" in content else None)


def _get(mapping: dict[str, Any], path: list[str]) -> Any:
    for key in path:
        if not isinstance(mapping, dict) or key not in mapping:
            return None
        mapping = mapping[key]
    return mapping


def row_file_hyperparams(row: Algo, env: str) -> tuple[dict[str, Any], str]:
    """The constructor arguments of ``row.row`` in ``row.rows_file`` on ``env``, and their source.

    The file's ``figure5`` rule (the ablation's): a row over ``figure5.over`` (the paper's DENFAC) takes, on an env
    with an entry in ``hyperparams/denfac.yml`` (the paper's envs), that entry's values of ``figure5.keys`` (dotted
    paths, e.g. ``policy_kwargs.net_arch``) wherever it kept the ``over`` row's value."""
    from sb3_denfac.denfac.presets import with_overrides

    assert row.rows_file is not None and row.row is not None
    content, rows = _row_file(row.rows_file)
    kwargs = row_files.resolve(rows, row.row)
    source = f"{row.rows_file.name}[{row.row}]"
    rule = content.get("figure5")
    if rule and rule["over"] in row_files.chain(rows, row.row):
        entry_id = env_facts(HYPERPARAMS_OF.get(env, env)).gym_id
        from sb3_denfac.zoo import load_config_file

        if entry_id in load_config_file(PACKAGE_HYPERPARAMS_DIR / "denfac.yml"):
            entry, entry_source = yaml_hyperparams("denfac", env)
            paper_row = row_files.resolve(rows, rule["over"])
            for key in rule["keys"]:
                path = key.split(".")
                value = _get(entry, path)
                if value is not None and _get(kwargs, path) == _get(paper_row, path):
                    for name in reversed(path):
                        value = {name: value}
                    kwargs = with_overrides(kwargs, value)
            source += f" + Figure 5 of {entry_source}"
    return kwargs, source
