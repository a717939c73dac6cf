"""Figure 3 benchmark: the episode-performance callback, a tiny sweep end to end (records, analysis, plot, resume)."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3 import TD3
from stable_baselines3.common.env_util import make_vec_env

from sb3_denfac.common.callbacks import EpisodePerformanceCallback

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import figure3  # noqa: E402
import figure3_analysis as fa  # noqa: E402


class ScriptedEpisodesEnv(gym.Env):
    """Episode k (1-based) lasts 2 + k % 3 steps, gives reward 1 per step and reports paper_performance = 100 - 7 * k % 40."""

    observation_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, with_key: bool = True):
        self.with_key = with_key
        self.episode = 0
        self.t = 0

    @staticmethod
    def expected(k: int) -> tuple[int, float]:
        return 2 + k % 3, float(100 - (7 * k) % 40)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.episode += 1
        self.t = 0
        return np.zeros(2, np.float32), {}

    def step(self, action):
        self.t += 1
        length, performance = self.expected(self.episode)
        done = self.t >= length
        info = {"paper_performance": performance} if (done and self.with_key) else {}
        return np.zeros(2, np.float32), 1.0, done, False, info


def _no_training_td3(env) -> TD3:
    return TD3("MlpPolicy", env, learning_starts=10**6, policy_kwargs={"net_arch": [4]}, seed=0, device="cpu")


@pytest.mark.parametrize("lower_is_better", [False, True])
def test_callback_records_paper_performance_and_stops(lower_is_better):
    env = make_vec_env(ScriptedEpisodesEnv, n_envs=1, seed=0)
    callback = EpisodePerformanceCallback(max_episodes=7, lower_is_better=lower_is_better)
    model = _no_training_td3(env).learn(10_000, callback=callback)

    expected = [ScriptedEpisodesEnv.expected(k) for k in range(1, 8)]
    assert callback.n_episodes == 7  # stopped by the episode budget, far below the step budget
    assert model.num_timesteps == sum(length for length, _ in expected)
    np.testing.assert_allclose(callback.performances(), [p for _, p in expected])
    running = np.minimum.accumulate if lower_is_better else np.maximum.accumulate
    np.testing.assert_allclose([r["best_so_far"] for r in callback.records], running([p for _, p in expected]))
    assert [r["length"] for r in callback.records] == [length for length, _ in expected]
    assert [r["return"] for r in callback.records] == [float(length) for length, _ in expected]  # from Monitor
    assert [r["timesteps"] for r in callback.records] == list(np.cumsum([length for length, _ in expected]))
    walls = [r["wall_time"] for r in callback.records]
    assert walls == sorted(walls) and walls[0] >= 0
    assert callback.best_so_far == callback.records[-1]["best_so_far"]


def test_callback_without_key_and_with_two_envs():
    env = make_vec_env(lambda: ScriptedEpisodesEnv(with_key=False), n_envs=2, seed=0)
    callback = EpisodePerformanceCallback(max_episodes=4, fallback_to_return=True)
    _no_training_td3(env).learn(10_000, callback=callback)
    assert callback.n_episodes >= 4
    assert [r["episode"] for r in callback.records] == list(range(1, callback.n_episodes + 1))
    # Without the key the measure falls back to the episode return (= its length here).
    assert [r["performance"] for r in callback.records] == [float(r["length"]) for r in callback.records]

    nan_callback = EpisodePerformanceCallback(max_episodes=2, fallback_to_return=False)
    _no_training_td3(make_vec_env(lambda: ScriptedEpisodesEnv(with_key=False), n_envs=1)).learn(1000, callback=nan_callback)
    assert np.isnan(nan_callback.performances()).all()
    with pytest.raises(ValueError, match="max_episodes"):
        EpisodePerformanceCallback(max_episodes=0)


def test_analysis_helpers():
    np.testing.assert_allclose(fa.running_best([3.0, np.nan, 1.0, 2.0], lower_is_better=True), [3.0, 3.0, 1.0, 1.0])
    np.testing.assert_allclose(fa.running_best([np.nan, -5.0, -7.0, -1.0], lower_is_better=False), [np.nan, -5, -5, -1])
    acrobot, cartpole = fa.ENV_SPECS["acrobot"], fa.ENV_SPECS["cartpole"]
    assert fa.episodes_to_threshold(np.array([500.0, 500.0, 320.0]), acrobot) == 3.0  # goal first reached at episode 3
    assert np.isnan(fa.episodes_to_threshold(np.array([500.0, 500.0]), acrobot))
    assert fa.episodes_to_threshold(np.array([-900.0, -500.0]), cartpole) == 2.0
    assert fa.interquartile_mean(np.array([0.0, 1.0, 2.0, 3.0, 100.0, -100.0, 1.5, 2.5])) == pytest.approx(1.75)
    point, low, high = fa.stratified_bootstrap_iqm([np.array([0.1, 0.2, 0.3]), np.array([0.5, 0.6, 0.9])], n_resamples=200)
    assert low <= point <= high and 0.1 <= low and high <= 0.9
    assert figure3.parse_episodes(["60", "halfcheetah=20"], ["acrobot", "halfcheetah"]) == {"acrobot": 60, "halfcheetah": 20}
    with pytest.raises(ValueError, match="no budget"):
        figure3.parse_episodes(["halfcheetah=20"], ["acrobot"])


def test_hyperparams_lookup(tmp_path):
    (tmp_path / "td3.yml").write_text("sb3_denfac/ContinuousCartPole-v0:\n  learning_starts: 7\ndefault:\n  tau: 0.5\n")
    assert figure3.load_hyperparams("td3", "cartpole", tmp_path)[0] == {"learning_starts": 7}
    assert figure3.load_hyperparams("td3", "acrobot", tmp_path)[0] == {"tau": 0.5}
    params, source = figure3.load_hyperparams("sac", "acrobot", tmp_path)
    assert params == {"gamma": 0.9} and "fallback" in source
    with pytest.raises(ValueError, match="unknown --algos"):
        figure3.sweep(["nope"], ["cartpole"], [0], 1, results_dir=tmp_path)


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def test_tiny_sweep_end_to_end_and_resume(tmp_path):
    # TD3 and SAC with the package's CartPole YAML entries (learning_starts 1000: a few short random episodes, cheap).
    kwargs = dict(results_dir=tmp_path, workers=2, verbose=0)
    status = figure3.sweep(["td3", "sac"], ["cartpole"], [0, 1], 3, **kwargs)
    assert len(status["done"]) == 4 and not status["failed"] and not status["skipped"]

    episodes = _rows(tmp_path / "episodes.csv")
    assert len(episodes) == 2 * 2 * 3
    assert {(r["algo"], r["seed"]) for r in episodes} == {("td3", "0"), ("td3", "1"), ("sac", "0"), ("sac", "1")}
    for row in episodes:  # CartPole's paper measure is the episode return
        assert float(row["performance"]) == pytest.approx(float(row["return"]), abs=1e-3)
        assert float(row["performance"]) <= 0.0
    meta = json.loads((tmp_path / "runs" / "td3" / "cartpole" / "seed_1.json").read_text())
    assert meta["episodes"] == 3 and meta["wall_time"] > 0 and "td3.yml" in meta["hyperparams_source"]
    assert (tmp_path / "figure3.png").read_bytes()[:4] == b"\x89PNG"
    report = (tmp_path / "figure3.md").read_text()
    assert "| td3 | 2 |" in report and "| sac | 2 |" in report and "IQM" in report
    zoo = np.load(tmp_path / "zoo" / "sac" / "sb3_denfac-ContinuousCartPole-v0_0" / "evaluations.npz")
    assert zoo["results"].shape == (3, 1) and np.all(np.diff(zoo["timesteps"]) > 0)

    # Resume: finished runs are skipped; a run without its final .json (interrupted) is redone.
    (tmp_path / "runs" / "sac" / "cartpole" / "seed_0.json").unlink()
    status = figure3.sweep(["td3", "sac"], ["cartpole"], [0, 1], 3, **{**kwargs, "workers": 0})
    assert [(t["algo"], t["seed"]) for t in status["done"]] == [("sac", 0)]
    assert len(status["skipped"]) == 3


def test_ray_missing_gives_clear_error(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(SystemExit, match="pip install"):
        figure3.sweep(["td3"], ["cartpole"], [0], 1, results_dir=tmp_path, ray_address="auto", verbose=0)


def test_ray_sweep(tmp_path):
    pytest.importorskip("ray")
    status = figure3.sweep(["td3"], ["cartpole"], [0], 2, results_dir=tmp_path, ray_address="local", verbose=0)
    assert len(status["done"]) == 1 and (tmp_path / "runs" / "td3" / "cartpole" / "seed_0.json").exists()
