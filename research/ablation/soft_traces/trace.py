"""Trace of one ablation configuration's updates (``journal.md``, section 25): per episode, its return and length,
and after the update that follows it alpha (``train/ent_coef``), the mean target (``train/q_target_mean``), the share
of bootstrap values outside the bounds (``train/bootstrap_clip_fraction``), the critic's loss, and the soft actor's
standard deviation (before tanh) over the states of D: median and 90th percentile.

A separate run from the benchmark's (plain ``Monitor`` env, no evaluations), so it does not reproduce a sweep run's
trajectory; it shows what the values and the policy do over one run.

Usage: ``python -m research.ablation.soft_traces.trace soft+min+K20 acrobot 0 100 out.jsonl``
(row of ``benchmarks/configs/ablation.yml``, short env name or Gymnasium id, seed, episodes, output file).
"""

import json
import sys

import gymnasium as gym
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor

import sb3_denfac.envs  # noqa: F401  (the paper's env ids)
from benchmarks.runner.algos import ALGOS
from benchmarks.runner.hyperparams import load_hyperparams
from sb3_denfac.envs.facts import env_facts
from sb3_denfac.soft_denfac import SoftDENFACPolicy
from sb3_denfac.zoo import algorithm_class

LOGGED = ("train/q_target_mean", "train/bootstrap_clip_fraction", "train/ent_coef", "train/critic_loss")


class Trace(BaseCallback):
    """One row per episode; the update that follows it is read when the next rollout starts (before any log dump)."""

    def __init__(self, episodes: int):
        super().__init__()
        self.episodes, self.rows, self.ret = episodes, [], 0.0

    def _on_step(self) -> bool:
        self.ret += float(self.locals["rewards"][0])
        if self.locals["dones"][0]:
            length = self.locals["infos"][0].get("episode", {}).get("l")
            self.rows.append(dict(ep=len(self.rows) + 1, ret=self.ret, len=length))
            self.ret = 0.0
        return len(self.rows) < self.episodes

    def _on_rollout_start(self) -> None:
        values = self.model.logger.name_to_value
        if not self.rows or "train/q_target_mean" not in values:
            return
        row = self.rows[-1]
        row.update({key.split("/")[1]: float(values[key]) for key in LOGGED if key in values})
        policy = self.model.policy
        if isinstance(policy, SoftDENFACPolicy):
            buffer = self.model.replay_buffer
            with th.no_grad():
                _, log_std, _ = policy.actor.get_action_dist_params(th.as_tensor(buffer.observations[: buffer.size(), 0]))
            std = log_std.exp()
            row.update(std_median=float(std.median()), std_p90=float(std.quantile(0.9)))


def main(config: str, env_name: str, seed: int, episodes: int, out: str) -> None:
    th.set_num_threads(1)
    kwargs, _ = load_hyperparams(f"abl:{config}", env_name)  # the benchmark row's, with the env's gamma
    kwargs.pop("policy")
    algo = algorithm_class(ALGOS[f"abl:{config}"].zoo_algo)  # DENFAC, or SoftDENFAC for the soft rows
    model = algo("MlpPolicy", Monitor(gym.make(env_facts(env_name).gym_id)), seed=seed, **kwargs)
    trace = Trace(episodes)
    model.learn(10**8, callback=trace)
    with open(out, "w") as f:
        f.writelines(json.dumps(row) + "\n" for row in trace.rows)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5])
