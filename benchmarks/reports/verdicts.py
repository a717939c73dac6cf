"""The verdict table: one row per claim of the paper's section 4, and DENFAC against TD3, SAC and CrossQ.

Each claim is decided on each measure of ``benchmarks.reports.stats.MEASURES`` by the rules of
``benchmarks.reports.stats.verdict`` and ``benchmarks.reports.stats.combine`` from rliable's probability of
improvement P(A > B) on one env and its 95% interval.
"""

from __future__ import annotations

import pandas as pd

from benchmarks.reports import stats as st
from benchmarks.runner.algos import ALGOS
from sb3_denfac.envs.facts import env_facts

PAPER_ENVS = ["acrobot", "cartpole", "halfcheetah", "acrobot75"]  # acrobot75: the authors' episode length
PEERS = ["td3", "sac", "crossq"]


def _label(algo: str) -> str:
    return ALGOS[algo].label if algo in ALGOS else algo


def _compare(
    runs: pd.DataFrame,
    a: str,
    b: str,
    env: str,
    measure: str,
    kind: str,
    lower_is_better: bool | None = None,
    relation: str = ">",
) -> tuple[str, str]:
    """The verdict of "a ``kind`` b" on one env and its text, P(a ``relation`` b) = p [low, high]."""
    p, low, high, na, nb = st.probability_of_improvement(runs, a, b, [env], measure, lower_is_better)
    text = (
        f"P({_label(a)} {relation} {_label(b)}) = {p:.2f} [{low:.2f}, {high:.2f}], n = {na} vs {nb}"
        if na >= 2 and nb >= 2
        else (f"n = {na} vs {nb} runs")
    )
    return st.verdict(kind, low, high), text


#: Fewest runs of an algorithm on an env for a comparison: rliable's interval needs two.
MIN_RUNS = 2


def _missing_text(missing: dict[str, int]) -> str:
    """The text naming the algorithms with fewer than :data:`MIN_RUNS` runs, e.g. "no runs of A, B; 1 run of C"."""
    parts = []
    for n in sorted(set(missing.values())):
        labels = ", ".join(_label(a) for a, k in missing.items() if k == n)
        parts.append(f"no runs of {labels}" if n == 0 else f"{n} run{'s' * (n > 1)} of {labels}")
    return "; ".join(parts)


def _decide(results: list[tuple[str, str]], missing: dict[str, int]) -> tuple[str, str]:
    """The verdict and intervals of a claim from its comparisons' ``results``; ``missing``: algorithms of the claim
    with fewer than :data:`MIN_RUNS` runs on the env (and their counts), whose comparisons are left out (the others'
    verdict is then given "so far", unless one refutes it)."""
    verdict = st.combine([v for v, _ in results]) if len(results) > 1 else results[0][0] if results else ""
    if missing and verdict != "refuted":
        text = _missing_text(missing)
        verdict = f"{verdict} so far; {text}" if results else f"pending: {text}"
    return verdict, "; ".join(t for _, t in results)


def _claim(runs: pd.DataFrame, claim: str, env: str, parts: list[tuple[str, str, str]], missing: dict[str, int]) -> dict:
    """One claim on one env from its comparisons ``parts``, on each measure of ``st.MEASURES``."""
    row = {"claim": claim, "env": env}
    for measure in st.MEASURES:
        results = [_compare(runs, a, b, env, measure, kind) for a, b, kind in parts]
        row[f"verdict ({measure})"], row[f"interval ({measure})"] = _decide(results, missing)
    return row


def _cpu_claim(runs: pd.DataFrame, claim: str, env: str, parts: list[tuple[str, str, str]], missing: dict[str, int]) -> dict:
    """A claim on computation: "A better than B" = A's CPU seconds per environment step lower than B's (per step, not
    per run: where episodes end at a goal, a run that learns less takes more steps)."""
    runs = runs.assign(cpu_per_step=runs["cpu_time"] / runs["timesteps"])
    results = [
        _compare(runs, a, b, env, "cpu_per_step", kind, lower_is_better=True, relation="cheaper than") for a, b, kind in parts
    ]
    return _first_measure_row(claim, env, *_decide(results, missing), "(CPU per step only)")


def _first_measure_row(claim: str, env: str, verdict: str, text: str, elsewhere: str) -> dict[str, str]:
    """A claim decided on one measure only: its verdict and text in the columns of the first of ``st.MEASURES``
    (the best-so-far), ``elsewhere`` in the other verdict columns."""
    first = next(iter(st.MEASURES))
    row = {"claim": claim, "env": env}
    for measure in st.MEASURES:
        row[f"verdict ({measure})"] = verdict if measure == first else elsewhere
        row[f"interval ({measure})"] = text if measure == first else ""
    return row


def _cacla_goal(runs: pd.DataFrame, env: str) -> dict[str, str] | None:
    cacla = runs[(runs["algo"] == "cacla") & (runs["env"] == env)]
    if cacla.empty:
        return None
    n, reached = len(cacla), int(cacla["final_best"].map(env_facts(env).reached).sum())
    low, high = st.goal_fraction(reached, n)
    budget = int(cacla["episodes"].min())
    v = (
        "refuted"
        if reached
        else f"held within {budget} episodes (the paper: 750)"
        if n >= 2
        else "inconclusive (too few runs)"
    )
    text = f"{reached}/{n} runs reached the goal within {budget} episodes; fraction 95% CI [{low:.2f}, {high:.2f}]"
    return _first_measure_row("CACLA+ cannot reach the Acrobot goal", env, v, text, "(best-so-far only)")


def verdict_table(runs: pd.DataFrame) -> pd.DataFrame:
    """All claims that the runs can speak to: the paper's claims on its envs as soon as one of their comparisons has
    runs (naming the algorithms still without runs), DENFAC against each peer on every env where both have runs."""
    counts = runs.groupby(["algo", "env"]).size().to_dict()
    rows = []

    def add(claim: str, env: str, parts: list[tuple[str, str, str]], partial: bool = False, decide=_claim) -> None:
        """The claim's row if its algorithms all have at least :data:`MIN_RUNS` runs on ``env``; with ``partial``,
        also if some of them do, from the comparisons between those, naming the algorithms with fewer (left out if
        none has enough)."""
        algos = list(dict.fromkeys(a for part in parts for a in part[:2]))
        missing = {a: counts.get((a, env), 0) for a in algos if counts.get((a, env), 0) < MIN_RUNS}
        if missing and (not partial or len(missing) == len(algos)):
            return
        ready = [(a, b, kind) for a, b, kind in parts if a not in missing and b not in missing]
        rows.append(decide(runs, claim, env, ready, missing))

    for env in PAPER_ENVS:
        add("DENFAC more data-efficient than DDPG", env, [("denfac", "ddpg", "better")], partial=True)
        add("DENFAC about equal to NFAC+", env, [("denfac", "nfac", "equal")], partial=True)
        add(
            "CMA-ES strong: better than the online DDPG and CACLA+",
            env,
            [("cmaes", "ddpg", "better"), ("cmaes", "cacla", "better")],
            partial=True,
        )
        others = [(x, "cacla", "better") for x in ("denfac", "nfac", "ddpg", "cmaes")]
        add("CACLA+ the least data-efficient", env, others, partial=True)
        faster = [("cacla", x, "better") for x in ("denfac", "nfac", "ddpg", "cmaes")]
        add("CACLA+ the fastest in computation", env, faster, partial=True, decide=_cpu_claim)
    for env in ("acrobot", "acrobot75"):
        goal = _cacla_goal(runs, env)
        if goal is not None:
            rows.append(goal)
    envs = list(dict.fromkeys(runs["env"]))
    for denfac in ("denfac", "denfac_default", "denfac_default04"):  # 0.4's default until 0.5's has its runs
        for peer in PEERS:
            for env in envs:
                add(f"{_label(denfac)} more data-efficient than {_label(peer)}", env, [(denfac, peer, "better")])
    return pd.DataFrame(rows)


RULES = f"""Rules. For two algorithms A and B on one env, P(A > B) is rliable's probability of improvement (the
Mann-Whitney probability that a run of A beats a run of B, ties counting half) on the measure named in the column, with
its 95% stratified-bootstrap interval [low, high] ({st.REPS} resamples). "A more data-efficient than B": **held** if
low > 0.5, **refuted** if high < 0.5, otherwise **inconclusive**. "A about equal to B": **refuted** if the interval
excludes 0.5, **held** if it lies within [{st.EQUAL_MARGIN[0]}, {st.EQUAL_MARGIN[1]}], otherwise inconclusive. A claim
made of several comparisons is refuted if one of them is, held if all are, otherwise inconclusive; where some of a
paper claim's algorithms have fewer than {MIN_RUNS} runs on an env (too few for an interval), it is decided on the
comparisons between those that have them and marked "so far", naming the others' run counts (a refutation by one of
them stands), "pending" where none of its comparisons has them; DENFAC against a peer needs {MIN_RUNS} runs of each. Measures:
{"; ".join(f"`{k}` = {v}" for k, v in st.MEASURES.items())} (of the exploring policy). The CACLA+ goal claim counts
runs whose best-so-far reached the goal, with a Clopper-Pearson interval; "CACLA+ the fastest in computation" compares
the CPU seconds per environment step (lower is better; P(A cheaper than B))."""
