"""Prototype, not in the library (ablation README, section 22): the proximal coefficient set by whether the actor's
moves of two successive updates agree.

Section 21 found that at the actor's own actions the two critics' dQ/da agree little more often than chance on most
envs: eq. (5) drives pi(s) to the critic's maximum, and the proximal step, normalised to unit mean gradient norm, then
moves the actor by up to ~1/(2 lambda) per update along the fit's noise. Within one update an optimum and a flat
critic look alike; across updates they do not: where the task keeps paying for progress, the critic's maximum moves
with the data and the actor's successive moves point the same way; at a balance they are a random walk. Here, with
P a probe of 1024 states drawn from D before update t, and d_t(s) = pi after update t minus pi before it
(d_{t-1} on the same states, from a copy of the actor kept from before update t-1),

    c_t = 1/|P| sum_{s in P} cos(d_t(s), d_{t-1}(s))          (1: the same direction, 0: unrelated, -1: back)

and the next update uses lambda_{t+1} = LAMBDA / max(c_t, FLOOR) (FLOOR 0.1: at most 10x the default's lambda, i.e. a
tenth of its step; LAMBDA = the model's ``actor_proximal``, 1). Everything else is the default's. Runs
``benchmarks.run`` in this process with the patch (use ``--workers 0 --checkpoint-every 0``: the actor kept from before
the last update is not in the checkpoints); ``displacement_step/`` holds its runs and, per run, c_t every update
(``displacement_step/steps/<env>_<seed>.jsonl``).

Usage: ``python displacement_step.py --algos abl:default05 --envs cartpole --seeds 0 1 2 --workers 0
--checkpoint-every 0 --results benchmarks/results/ablation/prototypes/displacement_step``
"""

import copy
import json
import os
import sys
from pathlib import Path

import torch as th

from benchmarks import run
from sb3_denfac.denfac.denfac import DENFAC

FLOOR = float(os.environ.get("DS_FLOOR", "0.1"))
PROBE = 1024
STATS = Path(os.environ.get("DS_STATS", "benchmarks/results/ablation/prototypes/displacement_step/steps"))

_train = DENFAC.train


def _actions(model: DENFAC, obs: th.Tensor) -> th.Tensor:
    model.policy.actor.set_training_mode(False)
    with th.no_grad():
        return model.policy.actor(obs).clamp(-1.0, 1.0)


def train(self, gradient_steps, batch_size=None):
    state = self.__dict__.setdefault("_displacement", {"lambda": self.actor_proximal, "previous": None, "updates": 0})
    if self.replay_buffer.size() < 2:
        return _train(self, gradient_steps, batch_size)
    data = self.replay_buffer.all_samples(env=self._vec_normalize_env)
    probe = data.observations[th.randint(data.observations.shape[0], (PROBE,))]  # states of D before this update
    snapshot = copy.deepcopy(self.policy.actor)  # the actor before update t
    snapshot.optimizer = None
    before = _actions(self, probe)
    self.actor_proximal = state.get("next_lambda", state["lambda"])
    _train(self, gradient_steps, batch_size)
    moved = _actions(self, probe) - before  # d_t
    record = {"update": state["updates"] + 1, "timesteps": self.num_timesteps, "lambda": self.actor_proximal}
    record["step"] = float(moved.norm(dim=1).mean())
    if state["previous"] is not None:
        earlier = state["previous"]
        earlier.set_training_mode(False)
        with th.no_grad():
            previous_move = before - earlier(probe).clamp(-1.0, 1.0)  # d_{t-1} on the same states
        c = float(th.nn.functional.cosine_similarity(moved, previous_move, dim=1, eps=1e-12).mean())
        state["next_lambda"] = state["lambda"] / max(c, FLOOR)
        record["c"] = c
    state["previous"] = snapshot
    state["updates"] += 1
    STATS.mkdir(parents=True, exist_ok=True)
    env_id = self.env.envs[0].spec.id.split("/")[-1]
    with open(STATS / f"{env_id}_{self.seed}.jsonl", "a") as f:
        f.write(json.dumps(record) + "\n")


if __name__ == "__main__":
    DENFAC.train = train
    sys.exit(run.main(sys.argv[1:]))
