"""What the gait the preset finds is worth if it is kept: the actor of the best training episode so far (TD7's policy
checkpoints, Fujimoto et al. 2023, "For SALE", with one assessment episode), evaluated beside the last actor.

DENFAC's policy changes only at episode ends, so each training episode is a rollout of one actor. At the end of every
training episode, before the update that follows it, this probe copies the actor's weights if the episode's return
(its exploring actions included) is at least the best so far. Training is untouched: the copy is only evaluated. At
every evaluation point (``research.mujoco100k.probe``: the first episode end past every 10k steps, and at the budget)
both are evaluated deterministically, the last actor on the probe's evaluation env (the suite's figure) and the copy
on a second one seeded 20_000 + seed, 10 episodes each. One run so gives both curves, paired by construction.

    python -m research.frontier_critics.checkpoint_probe --rows-file research/frontier_critics/rows.yml \\
        --rows soft_wide15 --envs Hopper-v5 --seeds 0
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.monitor import Monitor

from research.mujoco100k.probe import StepEvaluations, main

HERE = Path(__file__).parent


class CheckpointEvaluations(StepEvaluations):
    """:class:`StepEvaluations` plus the best training episode's actor, evaluated at the same points."""

    def __init__(self, env: gym.Env, every: int, episodes: int) -> None:
        super().__init__(env, every, episodes)
        self.best_return = -np.inf
        self.checkpoint: dict[str, th.Tensor] | None = None
        self.checkpoint_episode = 0
        self.checkpoint_env: gym.Env | None = None
        self.checkpoints: list[dict[str, Any]] = []  # the evaluations of the copy, in ``evaluations``' order

    def record(self) -> dict[str, Any]:
        return {"checkpoint_evaluations": self.checkpoints}

    def _on_training_start(self) -> None:
        spec = self.env.unwrapped.spec
        assert spec is not None
        self.checkpoint_env = Monitor(gym.make(spec.id))
        self.checkpoint_env.reset(seed=20_000 + int(self.model.seed or 0))

    def _on_step(self) -> bool:
        super()._on_step()
        for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
            if done and "episode" in info and info["episode"]["r"] >= self.best_return:
                # the episode's actor: the update that follows it has not run yet
                self.best_return = float(info["episode"]["r"])
                self.checkpoint = copy.deepcopy(self.model.policy.actor.state_dict())
                self.checkpoint_episode = self.n_episodes
        return True

    def evaluate(self) -> None:
        super().evaluate()
        if self.checkpoint is None:
            self.checkpoints.append({"timesteps": int(self.model.num_timesteps), "mean": None})
            return
        actor = self.model.policy.actor
        last = copy.deepcopy(actor.state_dict())
        actor.load_state_dict(self.checkpoint)
        assert self.checkpoint_env is not None
        mean = self.mean_return(self.checkpoint_env)
        actor.load_state_dict(last)
        self.checkpoints.append(
            {
                "timesteps": int(self.model.num_timesteps),
                "mean": mean,
                "episode": self.checkpoint_episode,
                "training_return": self.best_return,
            }
        )


if __name__ == "__main__":
    main(
        evaluations=CheckpointEvaluations,
        out=HERE / "checkpoint.jsonl",
        description=__doc__.split("\n\n")[0],
    )
