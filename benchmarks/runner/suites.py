"""What the benchmark runs: algorithms (rows), per-env budgets and suites.

An *algorithm* here is a benchmark row: a zoo algorithm plus a YAML file (``denfac`` and ``denfac_default`` are the
same class with different files). A *suite* is a set of (algorithm, env, seed) cells; suites share their runs, so a
cell that two suites contain is trained once. The hyperparameters of a row on an env: ``benchmarks.runner.hyperparams``.

The ablation's rows (``abl:<name>``) and its suite are data, ``configs/ablation.yml``: this module reads their names and
budgets, ``benchmarks.runner.hyperparams`` their settings (through ``benchmarks.runner.rows``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from benchmarks.runner import rows as row_files

_BENCHMARKS = Path(__file__).resolve().parents[1]
PACKAGE_HYPERPARAMS_DIR = _BENCHMARKS.parent / "hyperparams"  # the package's zoo YAML files (sb3_denfac.hyperparams)
BENCHMARK_CONFIGS_DIR = _BENCHMARKS / "configs"  # YAML of benchmark-only rows (e.g. denfac_default)
ABLATION_ROWS = BENCHMARK_CONFIGS_DIR / "ablation.yml"  # the ablation's rows and suite, as data
# estimated CPU seconds per run, written by benchmarks.studies.cost
SWEEP_PLAN = _BENCHMARKS / "results" / "cost" / "sweep_plan.csv"


@dataclass(frozen=True)
class Algo:
    """A benchmark row: ``zoo_algo`` with the settings of ``<name>.yml`` (the zoo's lookup), or of another row
    (``base``) with ``overrides`` on top, or of the row ``row`` of the row file ``rows_file`` (the ablation's,
    :mod:`benchmarks.runner.rows`); ``label`` for tables. ``benchmarks.runner.hyperparams.load_hyperparams`` resolves them."""

    name: str
    zoo_algo: str
    label: str
    family: str  # "paper" (the paper's Figure 3 algorithms), "peer" (what users pick today), "ablation"
    base: str | None = None
    overrides: tuple[tuple[str, Any], ...] = ()
    rows_file: Path | None = None
    row: str | None = None


#: DENFAC's schedule for an SB3 off-policy peer: train at every episode end, as many critic steps as the default DENFAC
#: (``"denfac"``: ``benchmarks.runner.hyperparams.denfac_critic_steps_per_episode``).
MATCHED_SCHEDULE = (("train_freq", (1, "episode")), ("gradient_steps", "denfac"))
#: CrossQ's critic in the fitted iterations: batch renorm, each critic step bootstrapping from itself.
CROSSQ_CRITIC = (("frozen_targets", False), ("policy_kwargs", {"batch_renorm": True}))
#: A high update-to-data ratio, as DroQ and REDQ use (20 gradient steps per environment step).
HIGH_UTD = (("train_freq", 1), ("gradient_steps", 20))

ALGOS: dict[str, Algo] = {
    a.name: a
    for a in (
        Algo("denfac", "denfac", "DENFAC (faithful)", "paper"),
        Algo("denfac_default", "denfac", "DENFAC (default)", "paper"),
        # 0.4's default (the two critics' minimum, deterministic next actions): the sweep's "DENFAC (default)" runs
        # made before 0.5 changed the default, kept under this name
        Algo(
            "denfac_default04",
            "denfac",
            "DENFAC (0.4 default)",
            "paper",
            base="denfac_default",
            overrides=(("critic_target", "min"), ("target_policy_noise", 0.0)),
        ),  # fmt: skip
        # The soft actor (SoftDENFAC, zoo name soft_denfac; the 0.5 development builds' DENFAC(ent_coef="auto")): SAC's
        # squashed Gaussian actor and soft targets inside the fitted iterations, with the targets' bootstrap value
        # bounded (bootstrap_bounds; research/ablation/journal.md, 23-24)
        Algo(
            "denfac_soft",
            "soft_denfac",
            "DENFAC, soft actor",
            "paper",
            base="denfac_default",
            overrides=(("ent_coef", "auto"), ("bootstrap_bounds", True)),
        ),  # fmt: skip
        # the soft actor with the critics' minimum in its targets and 20 fitted iterations of 25 critic and 12 actor
        # steps (the same steps per episode, targets refreshed twice as often; research/ablation/journal.md, 25)
        Algo(
            "denfac_soft_min",
            "soft_denfac",
            "DENFAC, soft actor, min targets, K = 20",
            "paper",
            base="denfac_soft",
            overrides=(
                ("critic_target", "min"),
                ("n_fitted_iterations", 20),
                ("critic_steps", 25),
                ("actor_steps", 12),
            ),
        ),  # fmt: skip
        # the compute dial's data-efficient end (sb3_denfac.denfac.presets.DATA_EFFICIENT; configs/)
        Algo("denfac_data_efficient", "denfac", "DENFAC (data-efficient preset)", "paper"),
        # the dial's middle point: the preset at half its compute (presets.data_efficient(update_to_data_ratio=2))
        Algo(
            "denfac_rho2",
            "denfac",
            "DENFAC (dial at rho 2)",
            "paper",
            base="denfac_data_efficient",
            overrides=(("update_to_data_ratio", 2.0),),
        ),  # fmt: skip
        # the preset's candidate (research/frontier_critics): rho 2 with CrossQ's critic (batch renorm, no frozen copy)
        Algo(
            "denfac_crossq",
            "denfac",
            "DENFAC (rho 2, CrossQ's critic)",
            "paper",
            base="denfac_rho2",
            overrides=CROSSQ_CRITIC,
        ),
        # the same with SAC's actor (SoftDENFAC): the screen's `soft_crossq` (research/frontier_critics)
        Algo(
            "soft_crossq",
            "soft_denfac",
            "SoftDENFAC (rho 2, CrossQ's critic)",
            "paper",
            base="denfac_rho2",
            overrides=CROSSQ_CRITIC,
        ),
        # the package's zoo entry of a goal-conditioned env (hyperparams/denfac.yml: MultiInputPolicy, HerReplayBuffer,
        # gamma 0.95, the compute dial), for the robotics suite; the peers' rows read their files' entries of the env
        Algo("denfac_her", "denfac", "DENFAC + HER (zoo entry)", "paper", base="denfac"),
        # the same with SAC's actor (hyperparams/soft_denfac.yml: presets.GOALS' values, SoftDENFAC's bounds)
        Algo("soft_denfac_her", "soft_denfac", "SoftDENFAC + HER (zoo entry)", "paper", base="soft_denfac"),
        Algo("nfac", "nfac", "NFAC+", "paper"),
        Algo("cacla", "cacla", "CACLA+", "paper"),
        Algo("cmaes", "cmaes", "CMA-ES", "paper"),
        Algo("ddpg", "ddpg", "DDPG (paper's)", "paper"),
        Algo("td3", "td3", "SB3 TD3", "peer"),
        Algo("sac", "sac", "SB3 SAC", "peer"),
        Algo("crossq", "crossq", "sb3-contrib CrossQ", "peer"),
        # the RL Zoo's MuJoCo settings (its `HalfCheetah-v3: &mujoco-defaults` entry: 10k random warm-up steps, then
        # SB3's defaults, one gradient step per env step), for the field's 100k-step budget; the `sac` row keeps the
        # short warm-up of the episode budgets
        Algo(
            "sac_zoo", "sac", "SB3 SAC (RL Zoo MuJoCo settings)", "peer", base="sac", overrides=(("learning_starts", 10_000),)
        ),
        # the frontier peer at the field's budget: sb3-contrib's CrossQ with the RL Zoo's MuJoCo settings (its
        # `HalfCheetah-v4: &mujoco-defaults` entry: 5k random warm-up steps, step size 1e-3, actor delay 3, a 256-256
        # actor and a 2048-2048 batch-renormalised critic, one gradient step per env step); about 260 ms per env step
        # on one core of this project's machine, so a 100k-step run is ~7 CPU hours (checkpointed: --checkpoint-every)
        Algo(
            "crossq_zoo",
            "crossq",
            "sb3-contrib CrossQ (RL Zoo MuJoCo settings)",
            "peer",
            base="crossq",
            overrides=(
                ("learning_starts", 5_000),
                ("learning_rate", 1e-3),
                ("policy_delay", 3),
                ("policy_kwargs", {"net_arch": {"pi": [256, 256], "qf": [2048, 2048]}}),
            ),
        ),
        Algo("sac_matched", "sac", "SB3 SAC on DENFAC's schedule", "peer", base="sac", overrides=MATCHED_SCHEDULE),
        Algo("td3_matched", "td3", "SB3 TD3 on DENFAC's schedule", "peer", base="td3", overrides=MATCHED_SCHEDULE),
        Algo("sac_utd20", "sac", "SB3 SAC, 20 steps per env step", "peer", base="sac", overrides=HIGH_UTD),
        # DENFAC's ingredients taken into SAC on DENFAC's schedule (the diagnosis; TD3 is SAC without its entropy term
        # and stochastic actor): DENFAC's width, and targets frozen for 50 critic steps as in one fitted iteration
        Algo(
            "sac_matched_64",
            "sac",
            "SAC on DENFAC's schedule, 64-64",
            "peer",
            base="sac_matched",
            overrides=(("policy_kwargs", {"net_arch": [64, 64]}),),
        ),  # fmt: skip
        Algo(
            "sac_matched_frozen",
            "sac",
            "SAC on DENFAC's schedule, targets frozen 50 steps",
            "peer",
            base="sac_matched",
            overrides=(("tau", 1.0), ("target_update_interval", 50)),
        ),  # fmt: skip
    )
}


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
                        "denfac",
                        "sac",
                        "sac_matched",
                        "td3_matched",
                    ),
                    _FIVE,
                ),
            ),  # fmt: skip
            "the default DENFAC (and its soft-actor option and data-efficient preset) against SB3's SAC and TD3 given "
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
                (("denfac_default", "denfac_rho2", "denfac_data_efficient", "denfac_crossq", "soft_crossq"), _FIVE),
                (("sac_zoo",), (0, 1)),
                (("crossq_zoo",), (0,)),
            ),
            "the field's data-efficiency benchmark: Gymnasium MuJoCo at 100k env steps, 10 deterministic evaluation "
            "episodes every 10k steps; DENFAC's compute dial at three points (the default, rho 2, the data-efficient "
            "preset's rho 4) against SB3 SAC with the RL Zoo's MuJoCo settings, with the published 100k-step figures "
            "as reference lines",
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


def _ablation() -> tuple[dict[str, Algo], Suite]:
    """The ablation's rows ``abl:<name>`` and its suite (study ``ablation``), as ``configs/ablation.yml`` states them."""
    content = yaml.safe_load(ABLATION_ROWS.read_text())
    study = content["suite"]
    rows = {
        f"abl:{name}": Algo(
            f"abl:{name}", row_files.algorithm(content["rows"], name), name, "ablation", rows_file=ABLATION_ROWS, row=name
        )
        for name in content["rows"]
    }
    budgets = tuple((env, Budget(**budget)) for env, budget in study["budgets"].items())
    suite = Suite(
        "ablation",
        tuple(env for env, _ in budgets),
        ((tuple(rows), tuple(study["seeds"])),),
        " ".join(study["description"].split()),
        study="ablation",
        budgets=budgets,
        diagnostics_every=study["diagnostics_every"],
    )
    return rows, suite


ABLATION_ALGOS, _ABLATION_SUITE = _ablation()
ALGOS.update(ABLATION_ALGOS)
SUITES[_ABLATION_SUITE.name] = _ABLATION_SUITE
