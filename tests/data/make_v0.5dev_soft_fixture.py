"""Writes ``denfac_soft_v0.5dev_pendulum.zip`` and its expected outputs: a DENFAC with the soft actor as the 0.5
development builds had it (``DENFAC(..., ent_coef="auto_0.5")``, before the soft actor became ``SoftDENFAC``).

Run on the 0.5 development code (commit 535dd21): ``python tests/data/make_v0.5dev_soft_fixture.py``."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np

from sb3_denfac import DENFAC

HERE = Path(__file__).parent

if __name__ == "__main__":
    env = gym.make("Pendulum-v1", max_episode_steps=50)
    model = DENFAC("MlpPolicy", env, ent_coef="auto_0.5", target_entropy=-0.5, bootstrap_bounds=True, critic_steps=5, seed=0)
    model.learn(200)
    model.save(HERE / "denfac_soft_v0.5dev_pendulum.zip")
    obs = np.stack([env.observation_space.sample() for _ in range(4)]).astype(np.float32)
    expected = dict(
        obs=obs.tolist(),
        actions=model.predict(obs, deterministic=True)[0].tolist(),
        keys=sorted(model.policy.state_dict()),
        log_ent_coef=model.policy.log_ent_coef.item(),
    )
    (HERE / "soft_v0.5dev_pendulum_expected.json").write_text(json.dumps(expected, indent=1) + "\n")
