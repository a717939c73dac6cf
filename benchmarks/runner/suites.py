"""What the benchmark runs: per-env budgets and suites.

A *suite* is a set of (algorithm, env, seed) cells, an algorithm being a benchmark row (``benchmarks.runner.algos``);
suites share their runs, so a cell that two suites contain is trained once. The hyperparameters of a row on an env:
``benchmarks.runner.hyperparams``.

The ablation's suite is data, ``configs/ablation.yml``: this module reads its budgets, seeds and description,
``benchmarks.runner.algos`` the ablation's rows (``abl:<name>``), ``benchmarks.runner.hyperparams`` their settings
(through ``benchmarks.runner.rows``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from benchmarks.runner.algos import ABLATION_ALGOS, ABLATION_ROWS, ALGOS

_BENCHMARKS = Path(__file__).resolve().parents[1]
# estimated CPU seconds per run, written by benchmarks.studies.cost
SWEEP_PLAN = _BENCHMARKS / "results" / "cost" / "sweep_plan.csv"


@dataclass(frozen=True)
class Budget:
    """Episodes per run, and a deterministic evaluation of ``eval_episodes`` episodes every ``eval_every`` episodes on
    the env made with ``eval_kwargs``.

    With ``timesteps`` (the field's budgets, e.g. 100k env steps on MuJoCo) a run lasts that many env steps instead,
    ``episodes`` is 0 (no episode count), and ``eval_every`` counts env steps: the policy is evaluated at the first
    episode end at or after every multiple, and once more at the budget."""

    episodes: int
    eval_every: int = 10
    eval_episodes: int = 1  # 1 where the start state is deterministic (the evaluation is then deterministic too)
    eval_kwargs: tuple[tuple[str, Any], ...] = ()
    timesteps: int | None = None

    @staticmethod
    def steps(timesteps: int, eval_every: int, eval_episodes: int) -> Budget:
        """A budget of ``timesteps`` env steps, evaluated every ``eval_every`` steps."""
        return Budget(0, eval_every, eval_episodes, (), timesteps)


BUDGETS: dict[str, Budget] = {
    "acrobot": Budget(100, 10, 1),
    # From CartPole's rest start a zero action balances forever (a near-zero initial actor would score a perfect 0): the
    # evaluation starts from gymnasium's random state instead (uniform in +-0.05), as the authors tested from them.
    "cartpole": Budget(100, 10, 5, (("random_start", True),)),
    "halfcheetah": Budget(100, 10, 3),
    "pendulum": Budget(40, 10, 5),
    "invertedpendulum": Budget(100, 10, 5),
    "acrobot75": Budget(100, 10, 1),
    "hopper": Budget(100, 10, 3),
    "reacher": Budget(100, 10, 5),
}
ENVS = list(BUDGETS)
FIGURE3_ENVS = ("acrobot", "cartpole", "halfcheetah", "pendulum", "invertedpendulum", "acrobot75")
GENERALISATION_ENVS = ("acrobot", "cartpole", "halfcheetah", "pendulum", "invertedpendulum")
#: The matched-schedule comparison: the generalisation envs and two held-out MuJoCo tasks.
MATCHED_ENVS = (*GENERALISATION_ENVS, "hopper", "reacher")
#: The field's data-efficiency benchmark: Gymnasium MuJoCo at 100k env steps, 10 deterministic evaluation episodes
#: every 10k steps (docs/benchmark.md, "The field's budget").
MUJOCO100K_ENVS = ("HalfCheetah-v5", "Hopper-v5", "Walker2d-v5", "Ant-v5")
MUJOCO100K_BUDGET = Budget.steps(100_000, 10_000, 10)
#: Goal-conditioned arm tasks (panda-gym, the robotics extra), measured by the share of goals reached: a deterministic
#: evaluation of 20 episodes (goals) every 5 episodes on Reach, every 20 on Push (docs/benchmark.md, "Goal-conditioned").
ROBOTICS_ENVS = ("PandaReach-v3", "PandaPush-v3")
ROBOTICS_BUDGETS = (("PandaReach-v3", Budget(100, 5, 20)), ("PandaPush-v3", Budget(200, 20, 20)))
# A variant env takes the YAML entries of the env it varies (the YAML files are keyed by the paper's env ids).
HYPERPARAMS_OF = {"acrobot75": "acrobot"}


@dataclass(frozen=True)
class Suite:
    """Cells ``(algo, env, seed)``: every env of ``envs`` for each ``(algos, seeds)`` group.

    Suites of one ``study`` share one results folder (``results/<study>/``) and so their runs: a cell two of them
    contain is trained once. ``budgets`` overrides the env budgets; ``diagnostics_every`` > 0 records DENFAC's
    critic-fit diagnostics every that many episodes."""

    name: str
    envs: tuple[str, ...]
    groups: tuple[tuple[tuple[str, ...], tuple[int, ...]], ...]
    description: str
    study: str = "sweep"
    budgets: tuple[tuple[str, Budget], ...] = ()
    diagnostics_every: int = 0

    @property
    def algos(self) -> list[str]:
        return [a for algos, _ in self.groups for a in algos]

    def seeds(self, algo: str) -> tuple[int, ...]:
        return next(seeds for algos, seeds in self.groups if algo in algos)

    def cells(self) -> list[tuple[str, str, int]]:
        """All cells, seed by seed (a sweep stopped early has every (algo, env) at its first seeds)."""
        cells = [(a, e, s) for algos, seeds in self.groups for a in algos for e in self.envs for s in seeds]
        return sorted(cells, key=lambda c: (c[2], self.envs.index(c[1]), list(ALGOS).index(c[0])))


_PAPER = ("denfac", "denfac_default", "nfac", "cacla", "cmaes")
_MATCHED = ("sac_matched", "td3_matched")  # SB3's SAC and TD3 on DENFAC's schedule
_THREE, _FIVE, _TEN = tuple(range(3)), tuple(range(5)), tuple(range(10))
SUITES: dict[str, Suite] = {
    s.name: s
    for s in (
        Suite(
            "figure3",
            FIGURE3_ENVS,
            ((_PAPER, _TEN), (("ddpg", "td3", "sac", "crossq", *_MATCHED), _FIVE), (("denfac_default04",), _TEN)),
            "the paper's Figure 3 comparison plus SB3 TD3/SAC (at one step per env step and on DENFAC's schedule) and "
            "sb3-contrib CrossQ, on the paper's three envs, two held-out Gymnasium envs, and the Acrobot with the "
            "authors' 75-decision episodes",
        ),
        Suite(
            "generalisation",
            GENERALISATION_ENVS,
            ((("denfac_default", "denfac", "sac", "crossq", *_MATCHED), _FIVE),),
            "DENFAC's default and faithful configurations against SAC (at one step per env step and on DENFAC's "
            "schedule), TD3 on DENFAC's schedule and CrossQ, library defaults, five envs",
        ),
        Suite(
            "matched",
            MATCHED_ENVS,
            (
                (
                    (
                        "denfac_default",
                        "denfac_default04",
                        "denfac_soft",
                        "denfac_soft_min",
                        "denfac_data_efficient",
                        "denfac_rho4",
                        "denfac",
                        "sac",
                        "sac_matched",
                        "td3_matched",
                    ),
                    _FIVE,
                ),
            ),  # fmt: skip
            "the default DENFAC (its soft-actor option, the data-efficient preset and DENFAC at rho 4) against SB3's SAC "
            "and TD3 given "
            "DENFAC's schedule (train at every episode end, as many critic steps as DENFAC's default) and SAC at one step "
            "per env step; equal episodes, gradient steps and CPU reported",
        ),
        Suite(
            "diagnosis",
            ("invertedpendulum", "hopper", "reacher", "pendulum"),  # Pendulum: the matched SAC learns it sooner
            (
                (("sac_matched", "td3_matched", "sac_matched_64", "sac_matched_frozen"), _THREE),
                (
                    tuple(f"abl:{c}" for c in ("default05", "default05+nets256", "default05+lr3e-4", "default05-proximal")),
                    _THREE,
                ),
            ),  # fmt: skip
            "why SAC on DENFAC's schedule holds what DENFAC finds and loses: one ingredient at a time, both ways (SAC's "
            "into DENFAC's default, DENFAC's into SAC), with DENFAC's critic-fit diagnostics",
            diagnostics_every=10,
        ),
        Suite(
            "high_utd",
            ("pendulum", "reacher"),
            ((("sac_utd20",), _FIVE),),
            "SB3 SAC at 20 gradient steps per env step (DroQ's and REDQ's ratio, without their regularisers), on the "
            "envs where its cost fits",
        ),
        Suite(
            "mujoco100k",
            MUJOCO100K_ENVS,
            (
                (
                    (
                        "denfac_default",
                        "denfac_rho2",
                        "denfac_rho4",
                        "denfac_data_efficient",
                        "denfac_crossq",
                        "soft_crossq",
                        "soft_crossq_wide",
                        "soft_crossq_wide_rho1",
                        "soft_crossq_wide_rho15_nofloor",
                        "soft_crossq_wide_rho15_beta05",
                        "soft_crossq_wide_rho15_checkpoints",
                        "soft_crossq_wide_rho15_checkpoints3",
                        "soft_crossq_anchor",
                    ),
                    _FIVE,
                ),
                (("sac_zoo",), (0, 1)),
                (("crossq_zoo", "crossq_sbx"), (0,)),
            ),
            "the field's data-efficiency benchmark: Gymnasium MuJoCo at 100k env steps, 10 deterministic evaluation "
            "episodes every 10k steps; DENFAC's compute dial at three points (the default, rho 2, rho 4), the frontier's "
            "critics inside the fitted iterations and the data-efficient preset (SoftDENFAC with CrossQ's critic) "
            "against SB3 SAC with the RL Zoo's MuJoCo settings and the frontier's CrossQ, with the published 100k-step "
            "figures as reference lines",
            study="mujoco100k",
            budgets=tuple((env, MUJOCO100K_BUDGET) for env in MUJOCO100K_ENVS),
        ),
        Suite(
            "robotics",
            ROBOTICS_ENVS,
            ((("denfac_her", "soft_denfac_her", "sac", "td3", *_MATCHED), _FIVE),),
            "goal-conditioned arm tasks with hindsight goals (HerReplayBuffer): DENFAC's and SoftDENFAC's zoo entries "
            "against SB3's SAC and "
            "TD3 with the zoo's HER settings, at one gradient step per env step and on DENFAC's schedule; success rate "
            "against episodes, episodes to 90% success, CPU per run",
            study="robotics",
            budgets=ROBOTICS_BUDGETS,
        ),
        Suite(
            "denfac_cartpole",
            ("cartpole",),
            ((("denfac",), _FIVE),),
            "DENFAC with the paper's CartPole settings, 5 seeds x 100 episodes (formerly benchmarks/denfac_cartpole.py)",
        ),
    )
}


def budget(env: str, episodes: int | None = None, suite: Suite | None = None) -> Budget:
    """The env's budget in ``suite`` (else ``BUDGETS``); ``episodes`` overrides its episode count; unknown envs: 100
    episodes, 1 evaluation episode."""
    base = dict(suite.budgets).get(env) if suite is not None else None
    base = base or BUDGETS.get(env, Budget(100))
    if episodes is not None and base.timesteps is not None:
        raise ValueError(f"--episodes: {env}'s budget in this suite is {base.timesteps} env steps, not episodes")
    return base if episodes is None else Budget(episodes, base.eval_every, base.eval_episodes, base.eval_kwargs)


@functools.cache
def _cost_table() -> dict[tuple[str, str], float]:
    import csv

    if not SWEEP_PLAN.exists():
        return {}
    with SWEEP_PLAN.open(newline="") as f:
        return {(r["algo"], r["env"]): float(r["estimate"]) for r in csv.DictReader(f)}


def estimated_cost(algo: str, env: str) -> float:
    """Estimated CPU seconds of one full run (``results/sweep_plan.csv``); NaN if not measured."""
    return _cost_table().get((algo, env), float("nan"))


def _ablation() -> Suite:
    """The ablation's suite (study ``ablation``) of its rows ``abl:<name>``, as ``configs/ablation.yml`` states it."""
    study = yaml.safe_load(ABLATION_ROWS.read_text())["suite"]
    budgets = tuple((env, Budget(**budget)) for env, budget in study["budgets"].items())
    return Suite(
        "ablation",
        tuple(env for env, _ in budgets),
        ((tuple(ABLATION_ALGOS), tuple(study["seeds"])),),
        " ".join(study["description"].split()),
        study="ablation",
        budgets=budgets,
        diagnostics_every=study["diagnostics_every"],
    )


_ABLATION_SUITE = _ablation()
SUITES[_ABLATION_SUITE.name] = _ABLATION_SUITE
