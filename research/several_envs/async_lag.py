"""Is the asynchronous update's cost on Reacher its one-update lag? DENFAC's updates run in place (no thread), but the
episodes are played by the actor from before the last update (``Stale``, a subclass overriding the documented
``train`` and ``_explore`` hooks), against DENFAC as it is; Reacher-v5, seeds 0-1, the deterministic return
of 5 episodes after every 4 training episodes.

    python -m research.several_envs.async_lag
"""

from __future__ import annotations

import copy

import numpy as np
import torch as th
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy

from sb3_denfac import DENFAC
from sb3_denfac.common.truncated_normal import clamp_mean, sample_truncated_normal


class Stale(DENFAC):
    """Episodes played by the actor from before the last update (what async_update plays while its update runs)."""

    stale: th.nn.Module | None = None
    previous: th.nn.Module | None = None

    def train(self, gradient_steps: int, batch_size: int | None = None) -> None:
        self.stale, self.previous = self.previous, copy.deepcopy(self.policy.actor)
        super().train(gradient_steps, batch_size)

    def _explore(self, observation):  # type: ignore[override]
        actor = self.stale or self.policy.actor
        actor.set_training_mode(False)
        obs, _ = self.policy.obs_to_tensor(observation)
        with th.no_grad():
            mean = actor(obs).cpu().numpy().reshape((-1, *self.action_space.shape)).astype(np.float32)
        return sample_truncated_normal(mean, self.sigma, -1.0, 1.0), clamp_mean(mean, -1.0, 1.0, self.sigma)


def main() -> None:
    for cls in (DENFAC, Stale):
        for seed in (0, 1):
            model = cls("MlpPolicy", make_vec_env("Reacher-v5", n_envs=1, seed=seed), seed=seed)
            returns = []
            for _ in range(4):
                model.learn(200, reset_num_timesteps=False)
                mean, _ = evaluate_policy(model, make_vec_env("Reacher-v5", n_envs=1, seed=9), 5)
                returns.append(round(float(mean), 1))
            print(cls.__name__, seed, returns, flush=True)


if __name__ == "__main__":
    main()
