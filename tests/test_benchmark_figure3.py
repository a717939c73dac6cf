"""Figure 3 benchmark: the episode-performance callback, suites, peer settings, verdict rules, and a tiny sweep end to end
(records, rliable aggregates, verdicts, plots, resume)."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import figure3  # benchmarks/ is on the path: pyproject.toml, [tool.pytest.ini_options] pythonpath
import figure3_stats as st
import figure3_suites as suites
import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3 import TD3
from stable_baselines3.common.env_util import make_vec_env

from sb3_denfac.common.callbacks import EpisodePerformanceCallback
from sb3_denfac.envs.facts import env_facts


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


def test_env_facts_and_budgets():
    acrobot, cartpole = env_facts("acrobot"), env_facts("sb3_denfac/ContinuousCartPole-v0")
    assert (acrobot.gamma, acrobot.lower_is_better, cartpole.gamma) == (0.9, True, 0.99)
    assert acrobot.reached(320.0) and not acrobot.reached(500.0) and not acrobot.reached(float("nan"))
    assert cartpole.reached(-500.0) and not cartpole.reached(-501.0)
    assert env_facts("Pendulum-v1").gamma is None and env_facts("MountainCarContinuous-v0").measure == "episode return"
    assert {e: suites.BUDGETS[e].episodes for e in suites.GENERALISATION_ENVS} == {
        "acrobot": 100, "cartpole": 100, "halfcheetah": 100, "pendulum": 40, "invertedpendulum": 100
    }  # fmt: skip
    assert gym.spec("sb3_denfac/ContinuousAcrobot75-v0").max_episode_steps == 75


def test_suites_and_cells():
    figure3_cells = figure3.select_cells("figure3")
    assert len(figure3_cells) == len(set(figure3_cells)) == 5 * 6 * 10 + 4 * 6 * 5
    for algo in ("denfac", "denfac_default", "nfac", "cacla", "cmaes"):
        assert suites.SUITES["figure3"].seeds(algo) == tuple(range(10))
    generalisation = figure3.select_cells("generalisation")
    assert {a for a, _, _ in generalisation} == {"denfac_default", "denfac", "sac", "crossq"}
    assert len(generalisation) == 4 * 5 * 5 and set(generalisation) <= set(figure3_cells)  # shared runs
    assert [c[2] for c in figure3_cells] == sorted(c[2] for c in figure3_cells)  # seed by seed
    assert figure3.select_cells("generalisation", envs=["pendulum"], seeds=[0]) == [
        ("denfac", "pendulum", 0), ("denfac_default", "pendulum", 0), ("sac", "pendulum", 0), ("crossq", "pendulum", 0)
    ]  # fmt: skip
    with pytest.raises(ValueError, match="unknown --suite"):
        figure3.select_cells("nope")
    with pytest.raises(ValueError, match="unknown --algos"):
        figure3.select_cells(None, ["nope"], ["cartpole"], [0])
    assert figure3.parse_episodes(["60", "halfcheetah=20"])["halfcheetah"] == 20
    assert figure3.parse_episodes(["60"])["pendulum"] == 60 and figure3.parse_episodes(None) is None


def test_hyperparams_lookup(tmp_path):
    (tmp_path / "td3.yml").write_text("sb3_denfac/ContinuousCartPole-v0:\n  learning_starts: 7\ndefault:\n  tau: 0.5\n")
    assert suites.load_hyperparams("td3", "cartpole", [tmp_path])[0] == {"learning_starts": 7, "gamma": 0.99}
    params, source = suites.load_hyperparams("td3", "acrobot", [tmp_path])
    assert params == {"tau": 0.5, "gamma": 0.9} and source == "td3.yml[default] + the env's gamma 0.9"
    assert suites.load_hyperparams("td3", "pendulum", [tmp_path])[0] == {"tau": 0.5}  # Pendulum prescribes no gamma
    # DENFAC (default): the library's defaults, plus only the env's prescribed gamma
    assert suites.load_hyperparams("denfac_default", "acrobot")[0] == {"policy": "MlpPolicy", "gamma": 0.9}
    assert suites.load_hyperparams("denfac_default", "invertedpendulum")[0] == {"policy": "MlpPolicy"}
    # the Acrobot variant takes the Acrobot entries (the paper's Figure 5 settings)
    assert suites.load_hyperparams("denfac", "acrobot75")[0] == suites.load_hyperparams("denfac", "acrobot")[0]
    with pytest.raises(FileNotFoundError):
        suites.load_hyperparams("nope", "cartpole")


@pytest.mark.parametrize("algo", ["td3", "sac", "crossq", "ddpg"])
def test_peers_train_within_the_first_episode(algo):
    """learning_starts is at most one (full-length) episode on every benchmark env; DDPG keeps its 8 updates per step."""
    for env in suites.ENVS:
        params, _ = suites.load_hyperparams(algo, env)
        length = gym.spec(env_facts(env).gym_id).max_episode_steps
        assert params.get("learning_starts", 100) <= length, (algo, env)
        if algo == "ddpg":
            assert params["gradient_steps"] == 8


def test_verdict_rules():
    assert st.verdict("better", 0.55, 0.9) == "held" and st.verdict("better", 0.1, 0.45) == "refuted"
    assert st.verdict("better", 0.4, 0.8) == "inconclusive"
    assert st.verdict("equal", 0.3, 0.7) == "held" and st.verdict("equal", 0.2, 0.7) == "inconclusive"
    assert st.verdict("equal", 0.51, 0.7) == "refuted" and st.verdict("better", np.nan, np.nan).startswith("inconclusive")
    assert st.combine(["held", "held"]) == "held" and st.combine(["held", "refuted"]) == "refuted"
    assert st.combine(["held", "inconclusive"]) == "inconclusive"


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def test_tiny_sweep_end_to_end_and_resume(tmp_path, monkeypatch):
    """DENFAC, CMA-ES and TD3 on CartPole for 3 episodes, 2 seeds, with rliable aggregates and verdicts; a SAC whose
    warm-up outlasts the budget is run too and must be left out of every table."""
    monkeypatch.setattr(st, "REPS", 200)
    (tmp_path / "hp").mkdir()
    (tmp_path / "hp" / "sac.yml").write_text("default:\n  learning_starts: 100000\n")
    (tmp_path / "hp" / "td3.yml").write_text("default:\n  learning_starts: 10\n  policy_kwargs:\n    net_arch: [16]\n")
    kwargs = dict(results_dir=tmp_path / "out", hyperparams_dirs=[tmp_path / "hp"], workers=2, verbose=0)
    status = figure3.sweep(["denfac", "cmaes", "td3", "sac"], ["cartpole"], [0, 1], 3, **kwargs)
    assert len(status["done"]) == 8 and not status["failed"] and not status["skipped"]
    out = tmp_path / "out"

    episodes = _rows(out / "episodes.csv")
    assert len(episodes) == 4 * 2 * 3
    for row in episodes:  # CartPole's paper measure is the episode return
        assert float(row["performance"]) == pytest.approx(float(row["return"]), abs=1e-3)
        assert float(row["cpu_time"]) > 0
    meta = json.loads((out / "runs" / "td3" / "cartpole" / "seed_1.json").read_text())
    assert meta["episodes"] == 3 and meta["cpu_time"] > 0 and meta["hyperparams_source"].startswith("td3.yml[default]")
    assert meta["git"]["commit"] and meta["machine"]["torch_threads"] == 1 and len(meta["load_average"]["start"]) == 3
    # evaluated at the last episode (before the 10th), from CartPole's random start: a zero action cannot score 0 there
    assert [e["episode"] for e in meta["evaluations"]] == [3] and meta["eval_kwargs"] == {"random_start": True}
    assert len(meta["evaluations"][0]["scores"]) == suites.BUDGETS["cartpole"].eval_episodes == 5
    runs = {(r["algo"], r["seed"]): r for r in _rows(out / "runs.csv")}
    assert runs[("sac", "0")]["trained"] == "False" and runs[("td3", "0")]["trained"] == "True"

    report = (out / "figure3.md").read_text()
    assert "Runs left out because their model never trained" in report
    tables = report.split("## cartpole")[1]
    assert "SB3 TD3" in tables and "SB3 SAC" not in tables.split("## Aggregates")[0]
    assert "IQM of the normalised best-so-far" in report and "Probability that DENFAC (faithful) beats" in report
    assert "| DENFAC (faithful) more data-efficient than SB3 TD3 | cartpole |" in report
    assert "SB3 SAC" not in report.split("## Verdicts")[1]
    for png in ("figure3.png", "figure3_compute.png", "figure3_profile.png", "all_runs.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG", png
    zoo = np.load(out / "zoo" / "td3" / "sb3_denfac-ContinuousCartPole-v0_0" / "evaluations.npz")
    assert zoo["results"].shape == (3, 1) and np.all(np.diff(zoo["timesteps"]) > 0)

    # Resume: finished runs are skipped; a run without its final .json (interrupted) is redone.
    (out / "runs" / "td3" / "cartpole" / "seed_0.json").unlink()
    status = figure3.sweep(["denfac", "cmaes", "td3", "sac"], ["cartpole"], [0, 1], 3, **{**kwargs, "workers": 0})
    assert [(t["algo"], t["seed"]) for t in status["done"]] == [("td3", 0)]
    assert len(status["skipped"]) == 7


def test_ray_missing_gives_clear_error(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(SystemExit, match="pip install"):
        figure3.sweep(["td3"], ["cartpole"], [0], 1, results_dir=tmp_path, ray_address="auto", verbose=0)


def test_ray_sweep(tmp_path):
    pytest.importorskip("ray")
    status = figure3.sweep(["td3"], ["cartpole"], [0], 2, results_dir=tmp_path, ray_address="local", verbose=0)
    assert len(status["done"]) == 1 and (tmp_path / "runs" / "td3" / "cartpole" / "seed_0.json").exists()


def test_cost_extrapolation_recovers_the_cost_models():
    """Synthetic per-episode CPU times: the step model and the replay model (cost growing with |D|) are recovered."""
    import figure3_cost as cost
    import pandas as pd

    lengths = np.array([500, 120, 300, 500, 40, 500, 250, 500, 500, 80, 500, 500, 360, 500])
    steps = np.cumsum(lengths)
    memory = np.minimum(6000, np.concatenate([[0], steps[:-1]]))
    per_episode_cpu = 1e-3 * lengths + 2e-5 * memory + 0.05  # a * steps + b * |D| + c
    episodes = pd.DataFrame(
        {"episode": np.arange(1, 15), "cpu_time": np.cumsum(per_episode_cpu), "timesteps": steps, "length": lengths}
    )
    row = cost.extrapolate(episodes, "denfac", "acrobot", 100, {"buffer_size": "6000"})
    assert (row["per_step"], row["per_d"], row["per_episode"]) == pytest.approx((1e-3, 2e-5, 0.05), rel=1e-6)
    full = np.minimum(6000, np.arange(100) * 500).sum()
    assert row["estimate"] == pytest.approx(1e-3 * 100 * 500 + 2e-5 * full + 0.05 * 100, rel=1e-6)

    online = episodes.assign(cpu_time=np.maximum(0, steps - 100) * 0.01)  # 10 ms per step after a 100-step warm-up
    row = cost.extrapolate(online, "sac", "acrobot", 100, {"learning_starts": "100"})
    assert row["model"] == "step" and row["estimate"] == pytest.approx(0.01 * 100 * 500, rel=1e-6)


def test_missing_cells_cost_the_seeds_left_from_measured_runs():
    import figure3_analysis
    import pandas as pd

    suite = suites.Suite("t", ("pendulum", "cartpole"), ((("sac",), (0, 1, 2)),), "test")
    runs = pd.DataFrame(dict(algo=["sac", "sac"], env=["pendulum"] * 2, seed=[0, 1], cpu_time=[3600.0, 7200.0]))
    row = figure3_analysis.missing_cells(suite, runs).iloc[0]
    assert row["pendulum"] == "2/3, 1.50 h"  # one seed left at the median of the measured runs
    planned = 3 * suites.estimated_cost("sac", "cartpole") / 3600
    assert row["cartpole"] == f"0/3, <={planned:.2f} h"  # no run yet: the plan's upper bound
    assert float(row["CPU hours left"]) == pytest.approx(1.5 + planned, abs=0.01)
