"""Several envs whose episodes end at the same step: one update per episode, back to back (DENFAC's choice), or one
update with their summed budget of fitted iterations?

    python -m research.several_envs.joint_updates [--seeds 0 1 2 3 4] [--n-envs 4] [--episodes 40]

Pendulum-v1's episodes all last 200 steps, so with 4 envs every update time has 4 finished episodes. DENFAC's
default (K = 10 fitted iterations per episode, with one env as the reference) either runs 4 updates of K back to
back (``DENFAC``) or one update of 4 K (``Joint``: a subclass whose ``_run_updates``, the documented hook, sums the
budget). Same fitted iterations, same critic and actor steps; the difference is that each update starts a new
updater (the proximal actor's anchor pi_old, the fast updater's flat copies) and draws its own targets' noise.
Episodes to the level (-200) from the ``benchmarks.studies.slow_env`` machinery (no delay); results: ``joint_updates.json``
and the README beside this file.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from stable_baselines3.common.env_util import make_vec_env

from benchmarks.studies.slow_env import reached, train
from sb3_denfac import DENFAC


class Joint(DENFAC):
    """DENFAC with one update per step at which episodes ended, of their summed fitted iterations."""

    def _run_updates(self, iterations: list[int], reset: bool = False) -> None:
        super()._run_updates([sum(iterations)], reset)


class JointK(DENFAC):
    """DENFAC with one update per step at which episodes ended, K_e from their summed length (K without
    ``update_to_data_ratio``): the actor moves one update per batch of new data (async_fix.py's ``sync_joint``)."""

    def _finished_episodes(self, gradient_steps: int) -> list[int]:
        lengths = super()._finished_episodes(gradient_steps)
        return [sum(lengths)] if lengths else lengths


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    parser.add_argument("--n-envs", type=int, default=4)
    parser.add_argument("--episodes", type=int, default=40)
    args = parser.parse_args(argv)
    out = Path(__file__).with_name("joint_updates.json")
    results = json.loads(out.read_text()) if out.exists() else {}
    for seed in args.seeds:
        variants = (
            ("one_env", DENFAC, 1),
            ("back_to_back", DENFAC, args.n_envs),
            ("joint", Joint, args.n_envs),
            ("joint_k", JointK, args.n_envs),
        )
        for name, cls, n_envs in variants:
            key = f"{name}/n{n_envs}/seed{seed}"
            if key in results:
                continue
            model = cls("MlpPolicy", make_vec_env("Pendulum-v1", n_envs=n_envs, seed=seed), seed=seed)
            run = train(model, "Pendulum-v1", seed, args.episodes)
            hit = reached({"env": "Pendulum-v1", **run})
            results[key] = dict(
                episodes_to_level=hit and hit["episodes"],
                final_eval=run["evaluations"][-1]["mean"],
                updates=model._n_updates,
                cpu=run["cpu"],
                evaluations=[(e["episodes"], round(e["mean"], 1)) for e in run["evaluations"]],
            )
            out.write_text(json.dumps(results, indent=1))
            print(key, results[key]["episodes_to_level"], round(results[key]["final_eval"]), flush=True)


if __name__ == "__main__":
    main()
