"""Cost of the default DENFAC's end-of-episode update with one critic against two (``policy_kwargs`` ``n_critics``).

For each env, a default DENFAC (two critics) is trained for ``--episodes`` episodes; its replay buffer is then given to
fresh default models with ``n_critics`` 1 and 2 (fast updater, the default's), and one update of each is timed, the two
interleaved in every repeat, with one torch thread: the ratio is what the second critic costs per update, measured side
by side on the same real data. Results: ``results/update_cost/update_cost_critics.{json,md}`` (commit, machine, load, medians).

Usage: ``python -m benchmarks.studies.update_cost_critics [--repeats 7] [--episodes 20] [--envs Pendulum-v1 ...]``
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th

from benchmarks.runner.task import git_state, machine_info
from benchmarks.studies.update_cost import RESULTS
from sb3_denfac import DENFAC


def timed_update(model: DENFAC) -> float:
    start = time.process_time()
    model._update()
    return time.process_time() - start


def measure(env_id: str, episodes: int, repeats: int, folder: Path) -> dict:
    env = gym.make(env_id)
    steps = episodes * env.spec.max_episode_steps  # type: ignore[union-attr]
    trained = DENFAC("MlpPolicy", env, seed=0, device="cpu").learn(steps)  # ends early episodes too: steps is a bound
    buffer_path = folder / f"{env_id.replace('/', '-')}_buffer.pkl"
    trained.save_replay_buffer(buffer_path)
    models = {}
    for n_critics in (1, 2):
        model = DENFAC("MlpPolicy", gym.make(env_id), seed=1, device="cpu", policy_kwargs=dict(n_critics=n_critics))
        model.load_replay_buffer(buffer_path)
        model._setup_learn(1)  # the logger the update writes to
        models[n_critics] = model
    times: dict[int, list[float]] = {1: [], 2: []}
    for _ in range(repeats):
        for n_critics, model in models.items():
            times[n_critics].append(timed_update(model))
    one, two = (float(np.median(times[n])) for n in (1, 2))
    return dict(
        env=env_id, transitions=int(trained.replay_buffer.size()), one_critic_s=one, two_critics_s=two, ratio=two / one
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--envs", nargs="+", default=["Pendulum-v1", "InvertedPendulum-v5", "sb3_denfac/HalfCheetahPaper-v0"])
    parser.add_argument("--output", default=str(RESULTS / "update_cost_critics"))
    args = parser.parse_args(argv)
    th.set_num_threads(1)
    meta = dict(git=git_state(), machine=machine_info(), load_average_start=os.getloadavg())
    meta |= dict(repeats=args.repeats, episodes=args.episodes)
    with tempfile.TemporaryDirectory() as folder:
        rows = [measure(env_id, args.episodes, args.repeats, Path(folder)) for env_id in args.envs]
    meta["load_average_end"] = os.getloadavg()
    Path(args.output + ".json").write_text(json.dumps(dict(meta=meta, rows=rows), indent=2))
    lines = [
        "# One end-of-episode update of the default DENFAC: one critic against two (`update_cost_critics.py`)\n",
        f"Commit {meta['git'].get('commit', 'unknown')[:7]}, {meta['machine']['cpu_model']}, {meta['machine']['nproc']} "
        f"cores, load average {meta['load_average_start'][0]:.1f} at the start and "
        f"{meta['load_average_end'][0]:.1f} at the end, one torch thread, fast updater, buffer of a default (two-critic) "
        f"run after {args.episodes} episodes, median CPU s over {args.repeats} interleaved repeats.\n",
        "| env | transitions in D | one critic (s) | two critics (s) | ratio |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['env']} | {r['transitions']} | {r['one_critic_s']:.3f} | {r['two_critics_s']:.3f} | {r['ratio']:.2f} |"
        )
    Path(args.output + ".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
