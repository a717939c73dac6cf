"""Writes ``denfac_soft_v0.5dev_pendulum.zip`` and its expected outputs: a DENFAC with the soft actor as the 0.5
development builds had it (``DENFAC(..., ent_coef="auto_0.5")``, before the soft actor became ``SoftDENFAC``).

Run on the 0.5 development code (commit 535dd21): ``python tests/data/make_v0.5dev_soft_fixture.py [DIR]`` (default:
this folder), e.g. from ``git archive 535dd21 | tar -x -C /tmp/v05`` as ``PYTHONPATH=/tmp/v05 python
tests/data/make_v0.5dev_soft_fixture.py /tmp/out``.

Besides the saved model (200 steps) and its predictions, the JSON holds what that build computed in one update, where
the float kernels of another CPU change results by rounding only (the test compares them with a float32 tolerance):
``first_update``, a model built with the same arguments after its first 50-step episode and update; ``update_after_load``,
the saved model loaded, seeded with 1 and trained one more 50-step episode and update. (After the 200 steps themselves,
other CPUs' kernels give an alpha and actions that differ from these by up to 20%: the file's values are compared after
a load, not after a rerun.)

The zip committed here was written by the first version of this script (on an AMD EPYC). The keys ``first_update``
and ``update_after_load`` were added by this version, run on commit 535dd21 on an AMD EPYC (AVX-512, PyTorch 2.13.0
native kernels) into another folder: its zip held the same parameters and Adam states, bit for bit, as the committed
one, which was kept."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th

from sb3_denfac import DENFAC

HERE = Path(__file__).parent
KWARGS = dict(ent_coef="auto_0.5", target_entropy=-0.5, bootstrap_bounds=True, critic_steps=5, seed=0)


def outputs(model: DENFAC, obs: np.ndarray) -> dict:
    return dict(log_ent_coef=model.policy.log_ent_coef.item(), actions=model.predict(obs, deterministic=True)[0].tolist())


if __name__ == "__main__":
    th.set_num_threads(1)
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE
    env = gym.make("Pendulum-v1", max_episode_steps=50)
    model = DENFAC("MlpPolicy", env, **KWARGS)
    model.learn(200)
    model.save(out / "denfac_soft_v0.5dev_pendulum.zip")
    # the observations the first version drew (unseeded), kept: the committed actions are at these
    previous = HERE / "soft_v0.5dev_pendulum_expected.json"
    if previous.exists():
        obs = np.asarray(json.loads(previous.read_text())["obs"], dtype=np.float32)
    else:
        obs = np.stack([env.observation_space.sample() for _ in range(4)]).astype(np.float32)
    expected = dict(
        obs=obs.tolist(),
        actions=model.predict(obs, deterministic=True)[0].tolist(),
        keys=sorted(model.policy.state_dict()),
        log_ent_coef=model.policy.log_ent_coef.item(),
    )
    first = DENFAC("MlpPolicy", gym.make("Pendulum-v1", max_episode_steps=50), **KWARGS).learn(50)
    expected["first_update"] = outputs(first, obs)
    loaded = DENFAC.load(out / "denfac_soft_v0.5dev_pendulum.zip", device="cpu")
    loaded.set_env(gym.make("Pendulum-v1", max_episode_steps=50))
    loaded.set_random_seed(1)
    loaded.learn(50, reset_num_timesteps=False)
    expected["update_after_load"] = outputs(loaded, obs)
    (out / "soft_v0.5dev_pendulum_expected.json").write_text(json.dumps(expected, indent=1) + "\n")
