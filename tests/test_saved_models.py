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
from stable_baselines3.common.save_util import load_from_zip_file

from sb3_denfac import CACLA, CMAES, DDPG, DENFAC, NFAC

DATA = Path(__file__).parent / "data"
ALGOS = {"denfac": DENFAC, "ddpg": DDPG, "nfac": NFAC, "cacla": CACLA, "cmaes": CMAES}
EXPECTED = json.loads((DATA / "v0.2_pendulum_expected.json").read_text())


@pytest.mark.parametrize("name", list(ALGOS))
def test_v0_2_model_loads_predicts_and_trains(name: str) -> None:
    model = ALGOS[name].load(DATA / f"{name}_v0.2_pendulum.zip", device="cpu")
    assert sorted(model.policy.state_dict().keys()) == EXPECTED[name]["keys"]
    obs = np.asarray(EXPECTED["obs"], dtype=np.float32)
    # rtol 1e-5: one forward pass on another CPU's float32 kernels than the fixture's (an ulp or so), not a trained value
    np.testing.assert_allclose(model.predict(obs, deterministic=True)[0], np.asarray(EXPECTED[name]["actions"]), rtol=1e-5)
    model.set_env(gym.make("Pendulum-v1", max_episode_steps=50))
    model.learn(100, reset_num_timesteps=False)
    assert all(th.isfinite(p).all() for p in model.policy.parameters())


#: (actor, critic) rates the fixtures were saved with; DDPG's ``learning_rate`` then meant the critic's (it still does
#: when ``critic_learning_rate`` is None, the new meaning: the rate of each network without its own).
RATES = {"denfac": (1e-3, 1e-3), "ddpg": (2e-3, 1e-3), "nfac": (1e-3, 2e-3), "cacla": (1e-3, 2e-3)}


@pytest.mark.parametrize("name", list(RATES))
def test_v0_2_optimizer_state_and_rates_are_restored(name: str) -> None:
    """The saved Adam state (whatever name 0.2 gave it) lands in ``policy.actor.optimizer`` / ``policy.critic.optimizer``,
    and each network keeps its learning rate."""
    path = DATA / f"{name}_v0.2_pendulum.zip"
    _, saved, _ = load_from_zip_file(path, device="cpu", load_data=False)
    model = ALGOS[name].load(path, device="cpu")
    for net, rate in zip(("actor", "critic"), RATES[name], strict=True):
        saved_state = next(saved[key] for key in (f"{net}.optimizer", f"policy.{net}_optimizer") if key in saved)
        state = getattr(model.policy, net).optimizer.state_dict()
        assert [float(s["step"]) for s in state["state"].values()] == [float(s["step"]) for s in saved_state["state"].values()]
        for index, moments in saved_state["state"].items():  # float32 defaults (1.3e-6): stored moments, read back
            th.testing.assert_close(state["state"][index]["exp_avg"], moments["exp_avg"])
        assert getattr(model, f"{net}_lr_schedule")(0.5) == pytest.approx(rate)
    assert any(saved[key]["state"] for key in saved if key != "policy"), "the fixture has no Adam state to compare"


def test_v0_2_denfac_keeps_the_plain_actor_update() -> None:
    """0.2 saved no ``actor_proximal`` (the option was off by default then) and 0.2/0.3 no ``n_critics``: the model
    loads with the proximal actor off and one critic, not with today's defaults, and a model saved now keeps the
    values it was built with."""
    model = DENFAC.load(DATA / "denfac_v0.2_pendulum.zip", device="cpu")
    assert model.actor_proximal == 0.0 and DENFAC("MlpPolicy", "Pendulum-v1").actor_proximal == 1.0
    assert model.critic.n_critics == 1 and DENFAC("MlpPolicy", "Pendulum-v1").critic.n_critics == 2
    assert model.update_to_data_ratio is None and model.gradient_steps == -1  # 0.2 saved gradient_steps=1


def test_policy_defaults_are_saved_and_missing_keys_mean_an_older_file(tmp_path) -> None:
    """DENFACPolicy's defaults are the library's (no overlay) and a model records them in ``policy_kwargs``, so a file
    says which networks it has; a file without those keys (as 0.1 wrote, and 0.2/0.3 without n_critics) gets the
    networks of the version that wrote it (sb3_denfac.common.compat)."""
    from sb3_denfac.common.compat import DENFAC_POLICY_KWARGS_OF_OLD_FILES
    from sb3_denfac.denfac.policies import DEFAULT_NET_ARCH

    env = gym.make("Pendulum-v1", max_episode_steps=50)
    model = DENFAC("MlpPolicy", env, seed=0)
    recorded = {key: model.policy_kwargs[key] for key in DENFAC_POLICY_KWARGS_OF_OLD_FILES}
    assert recorded == {"net_arch": DEFAULT_NET_ARCH, "batch_norm": False, "init": "default", "n_critics": 2}
    model.save(tmp_path / "now.zip")
    loaded = DENFAC.load(tmp_path / "now.zip", device="cpu")
    assert loaded.critic.n_critics == 2 and {k: loaded.policy_kwargs[k] for k in recorded} == recorded

    paper_nets = dict(net_arch=dict(pi=[20], qf=[50, 7]), batch_norm=True, init="paper", n_critics=1)
    old = DENFAC("MlpPolicy", env, seed=0, policy_kwargs=paper_nets)
    for key in DENFAC_POLICY_KWARGS_OF_OLD_FILES:  # what a file of 0.1 saved: none of these keys
        del old.policy_kwargs[key]
    old.save(tmp_path / "old.zip")
    loaded = DENFAC.load(tmp_path / "old.zip", device="cpu")  # the paper's networks, or the state dict would not fit
    assert {k: loaded.policy_kwargs[k] for k in paper_nets} == paper_nets
    obs = np.asarray(EXPECTED["obs"], dtype=np.float32)
    # exact: the same parameters, saved and read back, through the same kernels in one process
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], old.predict(obs, deterministic=True)[0])
