"""Probe: SoftDENFAC's proximal anchor per fitted iteration instead of per update (pi_old = the actor at the start of
each fitted iteration), through the public seam ``updater_classes``. A study, not an option: it asks whether the
anchor's unit explains why the per-update anchor (``actor_proximal``) holds Ant-v5's start but freezes HalfCheetah-v5
(100 updates in 100k steps).

    python -m research.frontier_critics.iteration_anchor --row soft_crossq_prox5 --envs Ant-v5 HalfCheetah-v5 --steps 30000
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from benchmarks.rows import load_rows
from research.mujoco100k import probe
from sb3_denfac import SoftDENFAC
from sb3_denfac.denfac.update_paths import UpdaterClasses
from sb3_denfac.soft_denfac.updaters import SoftAutogradUpdater, SoftFastUpdater

HERE = Path(__file__).parent
ROWS = HERE / "rows.yml"


class IterationAnchor:
    """pi_old refreshed to the actor at the start of every fitted iteration's actor steps."""

    def fit_actor(self, obs, batches=None):
        if self.old_actor is not None:
            self.old_actor.load_state_dict(self.policy.actor.state_dict())
        return super().fit_actor(obs, batches)


class IterationAnchorAutograd(IterationAnchor, SoftAutogradUpdater):
    pass


class IterationAnchorFast(IterationAnchor, SoftFastUpdater):
    pass


class IterationAnchoredSoftDENFAC(SoftDENFAC):
    updater_classes = UpdaterClasses(plain=IterationAnchorAutograd, fast=IterationAnchorFast)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=["Ant-v5", "HalfCheetah-v5"])
    parser.add_argument("--row", default="soft_crossq_prox5", help="a SoftDENFAC row of rows.yml, anchored per iteration")
    parser.add_argument("--steps", type=int, default=30000)
    parser.add_argument("--out", type=Path, default=HERE / "iteration_anchor.jsonl")
    args = parser.parse_args()
    row = {**load_rows(ROWS)[args.row], "algo": "soft_denfac"}
    name = f"{args.row}_per_iteration"
    for env_id in args.envs:
        record = probe.run_one(name, row, env_id, 0, args.steps, 5000, 10, algorithm=IterationAnchoredSoftDENFAC)
        with args.out.open("a") as f:
            f.write(json.dumps(record) + "\n")
        print(env_id, round(record["cpu_time"]), [round(e["mean"]) for e in record["evaluations"]], flush=True)


if __name__ == "__main__":
    main()
