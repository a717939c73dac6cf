"""The benchmark's rows: an algorithm of the zoo and where its settings are.

A *row* is a zoo algorithm plus a YAML file (``denfac`` and ``denfac_default`` are the same class with different
files), or another row with overrides, or a row of a row file. The hyperparameters of a row on an env:
``benchmarks.runner.hyperparams``. The suites that run them, and the per-env budgets: ``benchmarks.runner.suites``.

The ablation's rows (``abl:<name>``) are data, ``configs/ablation.yml``: this module reads their names,
``benchmarks.runner.hyperparams`` their settings (through ``benchmarks.runner.rows``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from benchmarks.runner import rows as row_files

_BENCHMARKS = Path(__file__).resolve().parents[1]
PACKAGE_HYPERPARAMS_DIR = _BENCHMARKS.parent / "hyperparams"  # the package's zoo YAML files (sb3_denfac.hyperparams)
BENCHMARK_CONFIGS_DIR = _BENCHMARKS / "configs"  # YAML of benchmark-only rows (e.g. denfac_default)
ABLATION_ROWS = BENCHMARK_CONFIGS_DIR / "ablation.yml"  # the ablation's rows and suite, as data


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


#: Peers from packages outside the RL Zoo's registry: zoo name -> (module, class, the pip package that provides it).
#: They are optional (``pip install -e ".[frontier]"``): :func:`register_external` adds one to the zoo on first use.
EXTERNAL_ZOO_ALGOS: dict[str, tuple[str, str, str]] = {"sbx_crossq": ("sbx", "CrossQ", "sbx-rl")}

#: One thread for JAX's CPU work, as the runner gives torch one (``torch.set_num_threads(1)``): the CPU seconds of a
#: JAX peer are then comparable to the others'. Set before JAX is first imported; an ``XLA_FLAGS`` already set is kept.
JAX_ONE_THREAD = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def register_external(zoo_algo: str) -> None:
    """Register the peer ``zoo_algo`` of :data:`EXTERNAL_ZOO_ALGOS` with the RL Zoo (nothing for any other name); an
    ImportError names the package to install if it is missing."""
    if zoo_algo not in EXTERNAL_ZOO_ALGOS:
        return
    import importlib
    import os

    import rl_zoo3

    module_name, class_name, package = EXTERNAL_ZOO_ALGOS[zoo_algo]
    os.environ.setdefault("XLA_FLAGS", JAX_ONE_THREAD)
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise ImportError(
            f"The row's algorithm {zoo_algo!r} is {package}'s {class_name}: pip install {package} "
            '(or the frontier extra: pip install -e ".[frontier]")'
        ) from error
    rl_zoo3.ALGOS.setdefault(zoo_algo, getattr(module, class_name))


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
        # the data-efficient preset: SoftDENFAC("MlpPolicy", env, **presets.DATA_EFFICIENT) (configs/)
        Algo("denfac_data_efficient", "soft_denfac", "SoftDENFAC (data-efficient preset)", "paper"),
        # the compute dial's data-efficient end on DENFAC's own networks: rho 4 within (10, None), bootstrap bounds
        # (presets.DENFAC_DATA_EFFICIENT, the data-efficient preset up to 0.5, whose runs were recorded under
        # denfac_data_efficient; configs/)
        Algo("denfac_rho4", "denfac", "DENFAC (dial at rho 4)", "paper"),
        # the dial's middle point: rho 4's at half its compute
        Algo(
            "denfac_rho2",
            "denfac",
            "DENFAC (dial at rho 2)",
            "paper",
            base="denfac_rho4",
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
        # the same with SAC's width of critic (256-256) on mini-batches of 128 (a joint pass of 256 rows): the screen's
        # `soft_crossq_w256_b128` (research/frontier_critics: the 64-wide critic loses Ant-v5's stand, 256 holds it)
        Algo(
            "soft_crossq_wide",
            "soft_denfac",
            "SoftDENFAC (rho 2, CrossQ's critic 256-256, batch 128)",
            "paper",
            base="soft_crossq",
            overrides=(
                ("policy_kwargs", {"batch_renorm": True, "net_arch": {"pi": [64, 64], "qf": [256, 256]}}),
                ("batch_size", 128),
            ),
        ),
        # the same at rho 1, CrossQ's and SAC's update-to-data ratio: SAC's critic rows per env step (one joint pass of
        # 256 rows per env step), at or below SB3 SAC's CPU (research/frontier_critics)
        Algo(
            "soft_crossq_wide_rho1",
            "soft_denfac",
            "SoftDENFAC (rho 1, CrossQ's critic 256-256, batch 128)",
            "paper",
            base="soft_crossq_wide",
            overrides=(("update_to_data_ratio", 1.0),),
        ),
        # the data-efficient preset (the wide pair at rho 1.5; its runs before it became the preset were recorded as
        # soft_crossq_wide_rho15) without Algorithm 1's floor of 10 fitted iterations after each episode (range
        # (1, None)): rho critic steps per env step and no more; the floor adds 16-27% of the critic steps on
        # Hopper-v5 and Walker2d-v5 (research/frontier_critics)
        Algo(
            "soft_crossq_wide_rho15_nofloor",
            "soft_denfac",
            "SoftDENFAC (the preset without the floor)",
            "paper",
            base="denfac_data_efficient",
            overrides=(("n_fitted_iterations", (1, None)),),
        ),
        # the preset with CrossQ's Adam (beta1 0.5 for the actor and the critic, sb3-contrib's and sbx's CrossQ
        # default): a shorter memory of past gradients while the batch renormalisation's statistics drift; the probe of
        # what holds the gait the preset finds on Hopper-v5 and loses (final / best 0.23-0.94 there)
        Algo(
            "soft_crossq_wide_rho15_beta05",
            "soft_denfac",
            "SoftDENFAC (the preset with Adam beta1 0.5)",
            "paper",
            base="denfac_data_efficient",
            overrides=(
                (
                    "policy_kwargs",
                    {
                        "batch_renorm": True,
                        "net_arch": {"pi": [64, 64], "qf": [256, 256]},
                        "optimizer_kwargs": {"betas": (0.5, 0.999)},
                    },
                ),
            ),
        ),
        # the preset with TD7's policy checkpoints (one assessment episode): the actor of the best training episode so
        # far plays the evaluations; training is the preset's, so each cell pairs with the preset's cell of its seed
        Algo(
            "soft_crossq_wide_rho15_checkpoints",
            "soft_denfac",
            "SoftDENFAC (the preset with policy checkpoints)",
            "paper",
            base="denfac_data_efficient",
            overrides=(("checkpoint_episodes", 1),),
        ),
        # the same judged on the minimum of three whole episodes (TD7's longer assessment, for envs whose episodes start
        # from random states); the updates of an assessment's episodes wait for its end, so training differs
        Algo(
            "soft_crossq_wide_rho15_checkpoints3",
            "soft_denfac",
            "SoftDENFAC (the preset with policy checkpoints over three episodes)",
            "paper",
            base="denfac_data_efficient",
            overrides=(("checkpoint_episodes", 3),),
        ),
        # the same with DENFAC's proximal anchor on the soft actor's mean (lambda 5: an update moves it about 0.1), the
        # screen's `soft_crossq_prox5` (research/frontier_critics: the soft actor's wide first actions fail Ant)
        Algo(
            "soft_crossq_anchor",
            "soft_denfac",
            "SoftDENFAC (rho 2, CrossQ's critic, anchor 5)",
            "paper",
            base="denfac_rho2",
            overrides=(*CROSSQ_CRITIC, ("actor_proximal", 5.0)),
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
        # the frontier peer at a cost this machine can run: sbx's CrossQ (JAX) with its own defaults (a 1024-1024
        # batch-renormalised critic, "slightly smaller [than the paper's 2048] for faster computation", Adam beta1 0.5,
        # actor delay 3, step size 1e-3, batch renorm in the actor too) and the RL Zoo's 5k random warm-up steps
        # (configs/crossq_sbx.yml); about 110 ms per env step on one core here, ~3 CPU hours per 100k-step run
        Algo("crossq_sbx", "sbx_crossq", "sbx CrossQ (1024-wide critic)", "peer"),
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


def _ablation_rows() -> dict[str, Algo]:
    """The ablation's rows ``abl:<name>``, as ``configs/ablation.yml`` states them (its suite: ``suites.SUITES``)."""
    content = yaml.safe_load(ABLATION_ROWS.read_text())
    return {
        f"abl:{name}": Algo(
            f"abl:{name}", row_files.algorithm(content["rows"], name), name, "ablation", rows_file=ABLATION_ROWS, row=name
        )
        for name in content["rows"]
    }


ABLATION_ALGOS = _ablation_rows()
ALGOS.update(ABLATION_ALGOS)
