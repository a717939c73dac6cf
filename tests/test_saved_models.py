"""Models saved by sb3-denfac 0.2 (before the optimizers moved to ``policy.actor.optimizer`` and the actors were merged
into one class) still load, with the same state-dict keys, predict as when they were saved, and train on.

The files in tests/data/ were written by ``tests/data/make_v0.2_fixtures.py`` run on the 0.2 code (commit dedb04a)."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th

from sb3_denfac import CACLA, CMAES, DDPG, DENFAC, NFAC

DATA = Path(__file__).parent / "data"
ALGOS = {"denfac": DENFAC, "ddpg": DDPG, "nfac": NFAC, "cacla": CACLA, "cmaes": CMAES}
EXPECTED = json.loads((DATA / "v0.2_pendulum_expected.json").read_text())


@pytest.mark.parametrize("name", list(ALGOS))
def test_v0_2_model_loads_predicts_and_trains(name: str) -> None:
    model = ALGOS[name].load(DATA / f"{name}_v0.2_pendulum.zip", device="cpu")
    assert sorted(model.policy.state_dict().keys()) == EXPECTED[name]["keys"]
    obs = np.asarray(EXPECTED["obs"], dtype=np.float32)
    np.testing.assert_allclose(model.predict(obs, deterministic=True)[0], np.asarray(EXPECTED[name]["actions"]), rtol=1e-5)
    model.set_env(gym.make("Pendulum-v1", max_episode_steps=50))
    model.learn(100, reset_num_timesteps=False)
    assert all(th.isfinite(p).all() for p in model.policy.parameters())


#: (actor, critic) rates the fixtures were saved with; DDPG's ``learning_rate`` then meant the critic's (it still does
#: when ``critic_learning_rate`` is None, the new meaning: the rate of each network without its own).
RATES = {"denfac": (1e-3, 1e-3), "ddpg": (2e-3, 1e-3), "nfac": (1e-3, 2e-3), "cacla": (1e-3, 2e-3)}


@pytest.mark.parametrize("name", list(RATES))
def test_v0_2_optimizer_state_and_rates_are_restored(name: str) -> None:
    """The saved Adam state (step counts) lands in ``policy.actor.optimizer`` / ``policy.critic.optimizer``, and each
    network keeps its learning rate."""
    model = ALGOS[name].load(DATA / f"{name}_v0.2_pendulum.zip", device="cpu")
    for net, rate in zip(("actor", "critic"), RATES[name], strict=True):
        optimizer = getattr(model.policy, net).optimizer
        assert optimizer.state, f"{name}: no Adam state restored in policy.{net}.optimizer"
        assert all(float(state["step"]) > 0 for state in optimizer.state.values())
        assert getattr(model, f"{net}_lr_schedule")(0.5) == pytest.approx(rate)
