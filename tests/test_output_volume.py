"""Logger output at the zoo's verbosity: the train/ table every 4 episodes, as SB3's off-policy algorithms (issue 25)."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
from stable_baselines3 import TD3
from stable_baselines3.common.logger import configure

EPISODES = 8  # of 20 steps (conftest's make_env)


def _dumps(model, tmp_path: Path, steps: int) -> int:
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(steps)
    with open(tmp_path / "progress.csv") as handle:
        return len(list(csv.DictReader(handle)))


@pytest.mark.parametrize("name", ["denfac", "nfac", "ddpg"])
def test_episodic_algorithms_log_every_four_episodes_as_td3(name: str, make_model, make_env, episode_steps, tmp_path) -> None:
    steps = EPISODES * episode_steps
    reference = _dumps(TD3("MlpPolicy", make_env(), learning_starts=10, seed=0), tmp_path / "td3", steps)
    assert reference == EPISODES // 4
    assert _dumps(make_model(name, seed=0), tmp_path / name, steps) == reference


def test_cacla_logs_every_rollout_as_sb3_on_policy(make_model, episode_steps, tmp_path) -> None:
    model = make_model("cacla", seed=0, n_steps=2 * episode_steps)  # n_steps is CACLA's logging period (PPO's rollout)
    assert _dumps(model, tmp_path, EPISODES * episode_steps) == EPISODES // 2


def test_log_interval_one_still_logs_every_update(make_model, episode_steps, tmp_path) -> None:
    model = make_model("denfac", seed=0)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(EPISODES * episode_steps, log_interval=1)
    with open(tmp_path / "progress.csv") as handle:
        rows = list(csv.DictReader(handle))
    # SB3 dumps at an episode's end before the update that follows it: the first row has no train/ keys yet
    assert len(rows) == EPISODES and all(row["train/n_updates"] for row in rows[1:])
