"""Short seeded runs of DENFAC and SoftDENFAC through the episodic collection loop, reduced to what that loop decides:
which transitions enter D and when an update runs on how much of it.

``python tests/data/episodic_runs.py`` writes ``episodic_runs_expected.json`` (0.5.0's loop, saved before the episodic
base class replaced the collection mixins); ``tests/test_episodic.py`` reruns each case and compares. Each run records:

- ``updates``: per update, in order, (K_e, |D|) (full-batch steps: the last iteration's targets cover all of D), and
  the env steps at which the update was read (by the callback at the next rollout start or at the end);
- ``first_episode``: D's rows of the first 20 steps (observations, actions, behaviour means), collected by the freshly
  initialised actor;
- ``first_update``: the first update's mean target and the policy's parameters after it.

Counts are exact on any CPU (the episodes' lengths are time limits). Float values are compared with a tolerance
(the test states it): the same operations in the same order, but other CPU kernels round their last bits otherwise.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_denfac import DENFAC, SoftDENFAC
from sb3_denfac.common.callbacks import UpdateStatsCallback

EXPECTED = Path(__file__).with_name("episodic_runs_expected.json")

#: small networks and full-batch steps; K_e from each episode's length (about 1 critic step per env step)
SMALL: dict[str, Any] = dict(
    batch_size=None,
    critic_steps=5,
    actor_steps=5,
    update_to_data_ratio=1.0,
    n_fitted_iterations=(1, None),
    policy_kwargs=dict(net_arch=[16, 16]),
    seed=3,
)


def _pendulum(length: int) -> gym.Env:
    return gym.make("Pendulum-v1", max_episode_steps=length)


#: name: (algorithm, episode lengths of the envs, learn's budget, extra arguments). The budgets end inside episodes.
CASES: dict[str, tuple[type, tuple[int, ...], int, dict[str, Any]]] = {
    "denfac_one_env": (DENFAC, (60,), 150, {}),
    "denfac_two_envs": (DENFAC, (40, 70), 260, {}),
    "denfac_warm_up": (DENFAC, (40, 70), 200, dict(learning_starts=90)),
    "soft_denfac_two_envs": (SoftDENFAC, (40, 70), 260, {}),
    # the learner thread draws torch's numbers while DENFAC's exploration draws numpy's: the updates' values are
    # reproducible; which policy plays the steps after an episode end depends on the thread's timing, so only the
    # first update's values and the updates' (K_e, |D|) are compared
    "denfac_async": (DENFAC, (40, 70), 260, dict(async_update=True)),
}


def run(name: str) -> dict[str, Any]:
    algo, lengths, budget, extra = CASES[name]
    env = DummyVecEnv([lambda n=n: _pendulum(n) for n in lengths])
    model = algo("MlpPolicy", env, **SMALL, **extra)
    updates: list[list[int]] = []
    first: dict[str, Any] = {}

    def on_update(stats: Any) -> None:
        updates.append([int(stats.fitted_iterations), int(len(stats.q_targets)), int(model.num_timesteps)])
        if not first:
            first["q_target_mean"] = float(stats.q_targets.mean())
            first["parameters"] = {k: v.tolist() for k, v in model.policy.state_dict().items() if v.is_floating_point()}

    model.learn(budget, callback=UpdateStatsCallback(on_update))
    data = model.replay_buffer
    rows = slice(0, 20)
    first_episode = {
        "observations": data.observations[rows].tolist(),
        "actions": data.actions[rows].tolist(),
        "behaviour_means": data.behaviour_means[rows].tolist(),
    }
    return {
        "updates": updates,
        "num_timesteps": int(model.num_timesteps),
        "first_episode": first_episode,
        "first_update": first,
    }


if __name__ == "__main__":
    EXPECTED.write_text(json.dumps({name: run(name) for name in CASES}))
    print(f"wrote {EXPECTED}")
