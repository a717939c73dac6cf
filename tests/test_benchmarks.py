"""The benchmark package: the episode-performance callback, suites, peer settings, verdict rules, the compact runs file,
and a tiny sweep end to end (records, rliable aggregates, verdicts, plots, resume). Smoke tests of the other entry
points: tests/test_benchmark_entry_points.py."""

from __future__ import annotations

import csv
import gzip
import importlib.util
import re
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from gymnasium import spaces
from stable_baselines3 import TD3
from stable_baselines3.common.env_util import make_vec_env

from benchmarks import run as runner
from benchmarks.reports import stats as st
from benchmarks.reports import verdicts
from benchmarks.runner import store, suites
from benchmarks.runner import sweep as sweeps
from benchmarks.runner.algos import ABLATION_ROWS, ALGOS
from benchmarks.runner.hyperparams import denfac_critic_steps_per_episode, load_hyperparams
from sb3_denfac.common.callbacks import EpisodePerformanceCallback
from sb3_denfac.envs.facts import env_facts
from sb3_denfac.zoo.config import OPTIONAL_ENV_PACKAGES, register_optional_env


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
    # rtol 1e-7: the scripted episodes' rewards summed in float64 (no network involved)
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
    figure3_cells = sweeps.select_cells("figure3")
    assert len(figure3_cells) == len(set(figure3_cells)) == 6 * 6 * 10 + 6 * 6 * 5
    for algo in ("denfac", "denfac_default", "nfac", "cacla", "cmaes"):
        assert suites.SUITES["figure3"].seeds(algo) == tuple(range(10))
    generalisation = sweeps.select_cells("generalisation")
    assert {a for a, _, _ in generalisation} == {"denfac_default", "denfac", "sac", "crossq", "sac_matched", "td3_matched"}
    assert len(generalisation) == 6 * 5 * 5 and set(generalisation) <= set(figure3_cells)  # shared runs
    assert [c[2] for c in figure3_cells] == sorted(c[2] for c in figure3_cells)  # seed by seed
    assert sweeps.select_cells("generalisation", envs=["pendulum"], seeds=[0]) == [
        ("denfac", "pendulum", 0), ("denfac_default", "pendulum", 0), ("sac", "pendulum", 0), ("crossq", "pendulum", 0),
        ("sac_matched", "pendulum", 0), ("td3_matched", "pendulum", 0),
    ]  # fmt: skip
    with pytest.raises(ValueError, match="unknown --suite"):
        sweeps.select_cells("nope")
    with pytest.raises(ValueError, match="unknown --algos"):
        sweeps.select_cells(None, ["nope"], ["cartpole"], [0])
    # a request the suite does not hold is named, not answered with "0 runs to do"
    with pytest.raises(ValueError, match=r"--envs \['Walker2d-v5'\] not in suite 'ablation'.*leave out --suite"):
        sweeps.select_cells("ablation", ["abl:default05"], ["hopper", "Walker2d-v5"])
    with pytest.raises(ValueError, match=r"--algos \['sac'\] not in suite 'diagnosis'"):
        sweeps.select_cells("diagnosis", ["sac"])
    with pytest.raises(ValueError, match=r"--seeds \[3\] not in suite 'diagnosis'"):
        sweeps.select_cells("diagnosis", seeds=[3])
    diagnosis = sweeps.select_cells("diagnosis")  # both ways: SAC's ingredients into DENFAC, DENFAC's into SAC
    assert len(diagnosis) == 8 * 4 * 3 and {"abl:default05", "sac_matched_frozen"} <= {a for a, _, _ in diagnosis}
    frozen = load_hyperparams("sac_matched_frozen", "hopper")[0]
    assert (frozen["tau"], frozen["target_update_interval"], frozen["gradient_steps"]) == (1.0, 50, 500)
    matched = sweeps.select_cells("matched")
    assert {e for _, e, _ in matched} >= {"hopper", "reacher"} and len(matched) == 10 * 7 * 5
    ablation = suites.SUITES["ablation"]
    assert ablation.study == "ablation" and ablation.diagnostics_every > 0
    # a user's runs go to runs/<study>/ under the current directory, never into the committed benchmarks/results/
    assert sweeps.default_results_dir("ablation") == Path.cwd() / "runs" / "ablation"
    assert sweeps.default_results_dir(None) == Path.cwd() / "runs" / "sweep"
    assert sweeps.COMMITTED_RESULTS not in sweeps.default_results_dir("matched").parents
    assert "abl:faithful" in ablation.algos and not any("proto" in a for a in ablation.algos)
    assert suites.budget("halfcheetah", None, ablation).episodes == 30 and suites.budget("halfcheetah").episodes == 100
    assert sweeps.parse_episodes(["60", "halfcheetah=20"])["halfcheetah"] == 20
    assert sweeps.parse_episodes(["60"])["pendulum"] == 60 and sweeps.parse_episodes(None) is None


def test_hyperparams_lookup(tmp_path):
    (tmp_path / "td3.yml").write_text("sb3_denfac/ContinuousCartPole-v0:\n  learning_starts: 7\ndefault:\n  tau: 0.5\n")
    assert load_hyperparams("td3", "cartpole", [tmp_path])[0] == {"learning_starts": 7, "gamma": 0.99}
    params, source = load_hyperparams("td3", "acrobot", [tmp_path])
    assert params == {"tau": 0.5, "gamma": 0.9} and source == "td3.yml[default] + the env's gamma 0.9"
    assert load_hyperparams("td3", "pendulum", [tmp_path])[0] == {"tau": 0.5}  # Pendulum prescribes no gamma
    # DENFAC (default): the library's defaults, plus only the env's prescribed gamma
    assert load_hyperparams("denfac_default", "acrobot")[0] == {"policy": "MlpPolicy", "gamma": 0.9}
    assert load_hyperparams("denfac_default", "invertedpendulum")[0] == {"policy": "MlpPolicy"}
    # the Acrobot variant takes the Acrobot entries (the paper's Figure 5 settings)
    assert load_hyperparams("denfac", "acrobot75")[0] == load_hyperparams("denfac", "acrobot")[0]
    with pytest.raises(FileNotFoundError):
        load_hyperparams("nope", "cartpole")


def test_ablation_configurations_take_the_papers_settings_from_one_place():
    """The faithful ablation rows are presets.PAPER plus the env's Figure 5 values of hyperparams/denfac.yml."""
    from sb3_denfac.denfac.presets import PAPER, paper

    yaml = load_hyperparams("denfac", "acrobot")[0]
    yaml_cartpole = load_hyperparams("denfac", "cartpole")[0]
    faithful = load_hyperparams("abl:faithful", "acrobot")[0]
    for key in ("buffer_size", "reset_critic", "inverting_gradients", "gamma"):
        assert faithful[key] == yaml[key], key
    assert faithful["policy_kwargs"]["net_arch"] == yaml["policy_kwargs"]["net_arch"]
    assert faithful["learning_rate"] == PAPER["learning_rate"] and faithful["weighting"] == "retrace"
    on_pendulum = load_hyperparams("abl:faithful", "pendulum")[0]
    assert on_pendulum == {"policy": "MlpPolicy", **paper(buffer_size=6000)} and on_pendulum["buffer_size"] == 6000
    # a factor moved away from the paper is not put back by the env's values
    assert load_hyperparams("abl:faithful+nets", "acrobot")[0]["policy_kwargs"]["net_arch"] == {
        "pi": [64, 64], "qf": [64, 64]
    }  # fmt: skip
    assert load_hyperparams("abl:faithful+D", "acrobot")[0]["buffer_size"] == 100_000
    assert load_hyperparams("abl:faithful+lr", "cartpole")[0]["buffer_size"] == yaml_cartpole["buffer_size"] == 3000
    assert load_hyperparams("abl:good+vecnorm", "pendulum")[0]["normalize"] is True


def test_row_files_resolve_bases_and_presets(tmp_path):
    """A row file's rows start from their ``base`` row or ``preset``, their own keys merged over it (policy_kwargs and
    net_arch key by key); a missing base or a loop of bases is named."""
    from benchmarks.runner.rows import chain, load_rows, read_rows, resolve
    from sb3_denfac.denfac.presets import PAPER, with_overrides

    path = tmp_path / "rows.yml"
    path.write_text(
        "rows:\n"
        "  paper: {preset: paper, buffer_size: 6000}\n"
        "  wide: {base: paper, policy_kwargs: {net_arch: {pi: [64]}}, adam_betas: [0.9, 0.999]}\n"
        "  plain: {learning_rate: 0.001}\n"
        "  orphan: {base: nope}\n"
        "  loop: {base: loop2}\n"
        "  loop2: {base: loop}\n"
    )
    rows = read_rows(path, "rows")
    assert chain(rows, "wide") == ["wide", "paper"] and resolve(rows, "plain") == {"learning_rate": 0.001}
    wide = resolve(rows, "wide")
    assert wide == with_overrides(
        PAPER, {"buffer_size": 6000, "policy_kwargs": {"net_arch": {"pi": [64]}}, "adam_betas": [0.9, 0.999]}
    )
    assert wide["policy_kwargs"]["net_arch"]["qf"] == PAPER["policy_kwargs"]["net_arch"]["qf"]  # merged, not replaced
    with pytest.raises(KeyError, match="row 'nope' is not defined"):
        resolve(rows, "orphan")
    with pytest.raises(ValueError, match="based on each other"):
        resolve(rows, "loop")
    path.write_text("a: {gamma: 0.9}\nb: {base: a, sigma: 0.2}\n")  # a file of rows alone (research/mujoco100k/rows.yml)
    assert load_rows(path) == {"a": {"gamma": 0.9}, "b": {"gamma": 0.9, "sigma": 0.2}}


def test_ablation_rows_are_the_yaml_rows():
    """The suite ``ablation`` is configs/ablation.yml: its rows in the file's order, its budgets and seeds."""
    import yaml

    content = yaml.safe_load(ABLATION_ROWS.read_text())
    ablation = suites.SUITES["ablation"]
    assert ablation.algos == [f"abl:{name}" for name in content["rows"]] and len(ablation.algos) == 79
    assert dict(ablation.budgets)["pendulum"] == suites.Budget(40, 10, 0) and ablation.seeds("abl:soft") == (0, 1, 2)
    params, source = load_hyperparams("abl:soft+min+K20", "acrobot")
    assert source == "ablation.yml[soft+min+K20] + the env's gamma 0.9"
    assert (params["critic_target"], params["n_fitted_iterations"], params["gamma"]) == ("min", 20, 0.9)
    # the soft actor's rows are SoftDENFAC's (algo: soft_denfac, inherited from the row `soft`), with its arguments only
    assert ALGOS["abl:soft+min+K20"].zoo_algo == "soft_denfac" and ALGOS["abl:default05"].zoo_algo == "denfac"
    from sb3_denfac.zoo import make_model

    model = make_model("soft_denfac", "Pendulum-v1", params)
    assert (model.ent_coef, model.bootstrap_bounds, model.critic_target, model.critic_steps) == ("auto", True, "min", 25)
    assert load_hyperparams("abl:faithful", "acrobot")[1].startswith("ablation.yml[faithful] + Figure 5 of denfac.yml[")


def test_ablation_rows_keep_their_meaning_when_the_library_default_changes():
    """The rows named after an earlier default (0.2's ``good``, 0.4's ``default04``) pin the settings a later default
    changed, so that a rerun is the configuration of their recorded runs; ``default05`` is 0.5's (today's) default."""
    from sb3_denfac.denfac import DENFAC

    def settings(row):
        model = DENFAC(env="Pendulum-v1", **load_hyperparams(row, "pendulum")[0])
        return model.critic_target, model.target_policy_noise, model.actor_proximal, model.policy_kwargs["n_critics"]

    assert settings("abl:good") == ("min", 0.0, 0.0, 1)
    assert settings("abl:default04") == ("min", 0.0, 1.0, 2)
    assert settings("abl:default04+smooth") == ("min", 0.2, 1.0, 2)
    assert settings("abl:default04+mean") == ("mean", 0.0, 1.0, 2)
    default = DENFAC("MlpPolicy", "Pendulum-v1")
    assert settings("abl:default05") == (default.critic_target, default.target_policy_noise, default.actor_proximal, 2)


@pytest.mark.parametrize("algo", ["td3", "sac", "crossq", "ddpg", "sac_matched", "td3_matched", "sac_utd20"])
def test_peers_train_within_the_first_episode(algo):
    """learning_starts is at most one (full-length) episode on every env of every suite the peer is in; DDPG keeps its
    8 updates per step."""
    envs = {e for suite in suites.SUITES.values() if algo in suite.algos for e in suite.envs}
    assert envs
    for env in envs:
        gym_id = env_facts(env).gym_id
        if gym_id in OPTIONAL_ENV_PACKAGES and importlib.util.find_spec(OPTIONAL_ENV_PACKAGES[gym_id][0]) is None:
            continue  # an optional package's env (the robotics extra), not installed here
        register_optional_env(gym_id)
        params, _ = load_hyperparams(algo, env)
        length = gym.spec(gym_id).max_episode_steps
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


def test_paper_claims_with_missing_algorithms(monkeypatch):
    """A claim of the paper stays in the verdict table while some of its algorithms have no runs on an env: decided on
    the comparisons that have runs and marked "so far", refuted by any of them, "pending" where none has runs."""
    monkeypatch.setattr(st, "REPS", 200)
    level = {"denfac": -300.0, "nfac": -100.0, "cmaes": -900.0, "cacla": -800.0}  # CartPole returns: higher is better
    runs = pd.DataFrame(
        [
            {"algo": a, "env": "cartpole", "seed": s, "final_best": v + 10 * s, "last10": v - 10 * s, "cpu_time": 1.0}
            for a, v in level.items()
            for s in range(5)
        ]
    )
    runs["timesteps"] = 500
    table = verdicts.verdict_table(runs).set_index("claim")
    ddpg = "no runs of DDPG (paper's)"
    assert table.loc["DENFAC more data-efficient than DDPG", "verdict (final_best)"] == f"pending: {ddpg}"
    assert table.loc["DENFAC about equal to NFAC+", "verdict (final_best)"] == "refuted"  # nothing missing
    # CMA-ES is below CACLA+: refuted whatever DDPG would add
    assert table.loc["CACLA+ the least data-efficient", "verdict (last10)"] == "refuted"
    assert table.loc["CMA-ES strong: better than the online DDPG and CACLA+", "verdict (last10)"] == "refuted"
    runs.loc[runs["algo"] == "cmaes", ["final_best", "last10"]] += 400.0  # now above CACLA+
    table = verdicts.verdict_table(runs).set_index("claim")
    assert table.loc["CACLA+ the least data-efficient", "verdict (last10)"] == f"held so far; {ddpg}"
    assert "P(CMA-ES > CACLA+)" in table.loc["CACLA+ the least data-efficient", "interval (last10)"]
    # the computation claim compares CPU seconds per environment step, lower is better
    runs["cpu_time"] = runs["algo"].map({"denfac": 60.0, "nfac": 40.0, "cmaes": 5.0, "cacla": 20.0}) + runs["seed"]
    fastest = verdicts.verdict_table(runs).set_index("claim").loc["CACLA+ the fastest in computation"]
    assert fastest["verdict (final_best)"] == "refuted" and fastest["verdict (last10)"] == "(CPU per step only)"
    assert "P(CACLA+ cheaper than CMA-ES) = 0.00" in fastest["interval (final_best)"]
    runs.loc[runs["algo"] == "cmaes", "timesteps"] = 50  # CMA-ES: the same CPU over a tenth of the steps
    fastest = verdicts.verdict_table(runs).set_index("claim").loc["CACLA+ the fastest in computation"]
    assert fastest["verdict (final_best)"] == f"held so far; {ddpg}"
    # one run is too few for an interval: that algorithm counts as missing, with its count (adding a first run does
    # not turn "held so far" into "inconclusive")
    table = verdicts.verdict_table(runs[(runs["algo"] != "nfac") | (runs["seed"] == 0)]).set_index("claim")
    assert table.loc["DENFAC about equal to NFAC+", "verdict (final_best)"] == "pending: 1 run of NFAC+"
    least = table.loc["CACLA+ the least data-efficient"]
    assert least["verdict (last10)"] == f"held so far; {ddpg}; 1 run of NFAC+"
    assert "NFAC+" not in least["interval (last10)"] and "P(CMA-ES > CACLA+)" in least["interval (last10)"]
    assert set(table["env"]) == {"cartpole"}  # no row where no algorithm has runs
    # a peer comparison needs two runs of each
    peers = pd.concat([runs, runs[runs["algo"] == "denfac"].assign(algo="sac").head(1)])
    assert not verdicts.verdict_table(peers)["claim"].str.contains("SAC").any()
    peers = pd.concat([runs, runs[runs["algo"] == "denfac"].assign(algo="sac").head(2)])
    assert verdicts.verdict_table(peers)["claim"].str.contains("SAC").any()


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
    out = tmp_path / "out"
    kwargs = dict(results_dir=out, hyperparams_dirs=[tmp_path / "hp"], workers=2, verbose=0, zoo_logs=tmp_path / "zoo")
    status = runner.run(["denfac", "cmaes", "td3", "sac"], ["cartpole"], [0, 1], 3, **kwargs)
    assert len(status["done"]) == 8 and not status["failed"] and not status["skipped"]

    records = {(r["algo"], r["seed"]): r for r in store.read_runs(out)}
    assert len(records) == 8 and not [p for p in out.iterdir() if p.is_dir()]  # no per-run files: one runs file
    assert {p.name for p in out.iterdir()} >= {
        "all_runs.md", "all_runs.png", "all_runs_compute.png", "all_runs_profile.png", "runs.csv", "runs.jsonl.gz",
        "sweeps.jsonl",
    }  # fmt: skip
    assert not list(out.glob("figure3*"))  # cells outside a suite: the report of all runs, no suite's
    for record in records.values():  # CartPole's paper measure is the episode return
        eps = record["episodes"]
        assert len(eps["episode"]) == 3 and all(c > 0 for c in eps["cpu_time"])
        # atol 1e-3: the same return, stored rounded to 3 decimals
        np.testing.assert_allclose(eps["performance"], eps["return"], atol=1e-3)
    meta = records[("td3", 1)]
    assert meta["n_episodes"] == 3 and meta["cpu_time"] > 0 and meta["hyperparams_source"].startswith("td3.yml[default]")
    assert meta["git"]["commit"] and meta["machine"]["torch_threads"] == 1 and len(meta["load_average"]["start"]) == 3
    # TD3 takes one gradient step per env step after its 10-step warm-up, but none after the last step (the episode
    # budget stops training first)
    assert meta["gradient_steps"] == meta["timesteps"] - 10 - 1
    assert records[("cmaes", 0)]["gradient_steps"] is None  # no Q critic
    # evaluated at the last episode (before the 10th), from CartPole's random start: a zero action cannot score 0 there
    assert [e["episode"] for e in meta["evaluations"]] == [3] and meta["eval_kwargs"] == {"random_start": True}
    assert len(meta["evaluations"][0]["scores"]) == suites.BUDGETS["cartpole"].eval_episodes == 5
    runs = {(r["algo"], r["seed"]): r for r in _rows(out / "runs.csv")}
    assert runs[("sac", "0")]["trained"] == "False" and runs[("td3", "0")]["trained"] == "True"

    report = (out / "all_runs.md").read_text()
    assert "Runs left out because their model never trained" in report
    tables = report.split("## cartpole")[1]
    assert "SB3 TD3" in tables and "SB3 SAC" not in tables.split("## Aggregates")[0]
    assert "IQM of the normalised best-so-far" in report and "Probability that DENFAC (faithful) beats" in report
    assert re.search(r"\| DENFAC \(faithful\) more data-efficient than SB3 TD3 +\| cartpole +\|", report)
    assert re.search(r"\| DENFAC more data-efficient than DDPG +\| cartpole +\| pending: no runs of DDPG", report)
    assert "SB3 SAC" not in report.split("## Verdicts")[1]
    for png in ("all_runs.png", "all_runs_compute.png", "all_runs_profile.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG", png
    zoo = np.load(tmp_path / "zoo" / "td3" / "sb3_denfac-ContinuousCartPole-v0_0" / "evaluations.npz")
    assert zoo["results"].shape == (3, 1) and np.all(np.diff(zoo["timesteps"]) > 0)

    # Resume after a kill in the middle of an append: the truncated last record is dropped and its run redone.
    path = store.runs_path(out)
    last = store.read_records(out)
    *_, final = last
    path.write_bytes(path.read_bytes()[:-25])
    assert len(store.read_runs(out)) == 7
    status = runner.run(["denfac", "cmaes", "td3", "sac"], ["cartpole"], [0, 1], 3, **{**kwargs, "workers": 0})
    assert [(t["algo"], t["seed"]) for t in status["done"]] == [(final["algo"], final["seed"])]
    assert len(status["skipped"]) == 7 and len(store.read_runs(out)) == 8
    # Another budget is another run: the 3-episode runs do not stand for 2-episode ones.
    assert sweeps.select_cells(None, ["td3"], ["cartpole"], [0]) == [("td3", "cartpole", 0)]
    status = runner.run(["td3"], ["cartpole"], [0], 2, **{**kwargs, "workers": 0, "analysis": False})
    assert len(status["done"]) == 1 and len(store.read_runs(out)) == 9


def test_store_keeps_first_record_and_skips_a_corrupt_tail(tmp_path):
    record = {"algo": "a", "env": "e", "seed": 0, "episodes_requested": 2, "status": "done", "x": 1}
    store.append_record(tmp_path, record)
    store.append_record(tmp_path, {**record, "x": 2})  # the same cell again: the first one wins
    store.append_record(tmp_path, {**record, "seed": 1, "status": "failed", "error": "boom"})
    assert [r["x"] for r in store.read_runs(tmp_path)] == [1]
    assert store.finished_cells(tmp_path) == {("a", "e", 0, 2, None)}
    size = store.runs_path(tmp_path).stat().st_size
    with store.runs_path(tmp_path).open("ab") as f:
        f.write(b"not gzip at all")
    assert len(list(store.read_records(tmp_path))) == 3
    assert store.repair(tmp_path) == len(b"not gzip at all") and store.runs_path(tmp_path).stat().st_size == size
    assert store.repair(tmp_path) == 0
    store.write_records(tmp_path, list(store.read_records(tmp_path)))  # compaction: one gzip member, same records
    assert len(list(store.read_records(tmp_path))) == 3 and gzip.decompress(store.runs_path(tmp_path).read_bytes())


def test_matched_schedule_peers_take_denfacs_gradient_steps(tmp_path):
    """SAC on DENFAC's schedule trains at episode ends with as many critic steps as the default DENFAC: on the same
    budget both record the same number of gradient steps; SAC at 20 steps per env step records 20 per step."""
    params, source = load_hyperparams("sac_matched", "pendulum")
    assert params["train_freq"] == (1, "episode") and params["gradient_steps"] == denfac_critic_steps_per_episode()
    assert source.startswith("sac.yml[Pendulum-v1]") and "gradient_steps=500" in source
    assert load_hyperparams("td3_matched", "acrobot")[0]["gamma"] == 0.9  # the base row's env gamma is kept
    for row in ("sac_matched", "td3_matched", "sac_utd20"):  # everything else is the base row's
        base = load_hyperparams(ALGOS[row].base, "cartpole")[0]
        mine = load_hyperparams(row, "cartpole")[0]
        assert {k: v for k, v in mine.items() if k not in ("train_freq", "gradient_steps")} == {
            k: v for k, v in base.items() if k not in ("train_freq", "gradient_steps")
        }
    assert load_hyperparams("sac_utd20", "pendulum")[0]["gradient_steps"] == 20
    status = sweeps.sweep(["denfac_default", "sac_matched"], ["pendulum"], [0], 3, results_dir=tmp_path, workers=0,
                          verbose=0)  # fmt: skip
    assert len(status["done"]) == 2
    steps = {r["algo"]: r["gradient_steps"] for r in store.read_runs(tmp_path)}
    # two updates (after episodes 1 and 2; the budget stops training at the end of the third)
    assert steps == {"denfac_default": 1000, "sac_matched": 1000}


def test_ray_missing_gives_clear_error(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(SystemExit, match="pip install"):
        sweeps.sweep(["td3"], ["cartpole"], [0], 1, results_dir=tmp_path, ray_address="auto", verbose=0)


def test_ray_sweep(tmp_path):
    pytest.importorskip("ray")
    status = sweeps.sweep(["td3"], ["cartpole"], [0], 2, results_dir=tmp_path, ray_address="local", verbose=0)
    assert len(status["done"]) == 1 and store.finished_cells(tmp_path) == {("td3", "cartpole", 0, 2, None)}


def test_cost_extrapolation_recovers_the_cost_models():
    """Synthetic per-episode CPU times: the step model and the replay model (cost growing with |D|) are recovered."""
    import pandas as pd

    from benchmarks.studies import cost

    lengths = np.array([500, 120, 300, 500, 40, 500, 250, 500, 500, 80, 500, 500, 360, 500])
    steps = np.cumsum(lengths)
    memory = np.minimum(6000, np.concatenate([[0], steps[:-1]]))
    per_episode_cpu = 1e-3 * lengths + 2e-5 * memory + 0.05  # a * steps + b * |D| + c
    episodes = pd.DataFrame(
        {"episode": np.arange(1, 15), "cpu_time": np.cumsum(per_episode_cpu), "timesteps": steps, "length": lengths}
    )
    row = cost.extrapolate(episodes, "denfac", "acrobot", 100, {"buffer_size": "6000"})
    # rel 1e-6: a float64 least-squares fit of exactly linear data recovers its coefficients to rounding
    assert (row["per_step"], row["per_d"], row["per_episode"]) == pytest.approx((1e-3, 2e-5, 0.05), rel=1e-6)
    full = np.minimum(6000, np.arange(100) * 500).sum()
    assert row["estimate"] == pytest.approx(1e-3 * 100 * 500 + 2e-5 * full + 0.05 * 100, rel=1e-6)

    online = episodes.assign(cpu_time=np.maximum(0, steps - 100) * 0.01)  # 10 ms per step after a 100-step warm-up
    row = cost.extrapolate(online, "sac", "acrobot", 100, {"learning_starts": "100"})
    assert row["model"] == "step" and row["estimate"] == pytest.approx(0.01 * 100 * 500, rel=1e-6)


def test_missing_cells_cost_the_seeds_left_from_measured_runs():
    import pandas as pd

    from benchmarks.reports import tables

    suite = suites.Suite("t", ("pendulum", "cartpole"), ((("sac",), (0, 1, 2)),), "test")
    runs = pd.DataFrame(dict(algo=["sac", "sac"], env=["pendulum"] * 2, seed=[0, 1], cpu_time=[3600.0, 7200.0]))
    row = tables.missing_cells(suite, runs).iloc[0]
    assert row["pendulum"] == "2/3, 1.50 h"  # one seed left at the median of the measured runs
    planned = 3 * suites.estimated_cost("sac", "cartpole") / 3600
    assert row["cartpole"] == f"0/3, <={planned:.2f} h"  # no run yet: the plan's upper bound
    # abs 0.01: the table prints hours with 2 decimals
    assert float(row["CPU hours left"]) == pytest.approx(1.5 + planned, abs=0.01)
    unplanned = suites.Suite("u", ("pendulum", "no-such-env"), ((("sac",), (0, 1, 2)),), "test")
    row = tables.missing_cells(unplanned, runs).iloc[0]
    assert row["no-such-env"] == "0/3, cost not measured"  # neither a run nor the plan's estimate: said, not NaN
    assert row["CPU hours left"] == "1.50 + 1 cells not measured"
    # a smoke run (3 episodes of Pendulum's 40) is neither one of the cell's seeds nor a measure of its cost
    smoke = runs.assign(episodes_requested=[40, 3], timesteps_requested=[None, None])
    assert tables.missing_cells(suite, smoke).iloc[0]["pendulum"] == "1/3, 2.00 h"
    steps = suites.Suite(
        "s", ("Hopper-v5",), ((("sac",), (0, 1)),), "test", budgets=(("Hopper-v5", suites.Budget.steps(100, 10, 1)),)
    )
    of_steps = runs.assign(env="Hopper-v5", episodes_requested=[0, 0], timesteps_requested=[100, 50])
    assert tables.missing_cells(steps, of_steps).iloc[0]["Hopper-v5"] == "1/2, 1.00 h"


def test_bootstrap_intervals_are_reproducible_and_leave_numpys_generator_alone(monkeypatch):
    """rliable 1.2 draws bootstrap indices from numpy's global generator: the same runs give the same intervals."""
    import pandas as pd

    monkeypatch.setattr(st, "REPS", 100)
    rng = np.random.default_rng(1)
    runs = pd.DataFrame(
        [(a, e, s, rng.uniform(-1500, 0)) for a in ("x", "y") for e in ("pendulum",) for s in range(6)],
        columns=["algo", "env", "seed", "final_best"],
    )
    np.random.seed(123)
    before = np.random.get_state()[1].copy()
    first, second = st.iqm_table(runs, ["pendulum"], "final_best"), st.iqm_table(runs, ["pendulum"], "final_best")
    assert first.equals(second)
    assert st.probability_of_improvement(runs, "x", "y", ["pendulum"], "final_best") == st.probability_of_improvement(
        runs, "x", "y", ["pendulum"], "final_best"
    )
    assert (np.random.get_state()[1] == before).all()


def test_answer_table_reports_data_and_cpu_to_the_level():
    """Episodes, env steps and CPU seconds at the first episode whose best-so-far reaches the level, per algorithm."""
    import pandas as pd

    from benchmarks.reports import tables

    rows = []
    for seed, returns in enumerate(([500.0, 1000.0, 1000.0], [200.0, 300.0, 400.0])):
        for i, ret in enumerate(returns):
            best = max(returns[: i + 1])
            rows.append(dict(algo="sac_matched", env="invertedpendulum", seed=seed, episode=i + 1, performance=ret,
                             best_so_far=best, timesteps=100 * (i + 1), cpu_time=10.0 * (i + 1)))  # fmt: skip
    episodes = pd.DataFrame(rows)
    runs = pd.DataFrame([dict(algo="sac_matched", env="invertedpendulum", seed=s, fall_back=0.0, last10=v, final_eval=e)
                         for s, v, e in ((0, 833.3, 1000.0), (1, 300.0, 500.0))])  # fmt: skip
    table = tables.answer_table(episodes, runs, algos=("sac_matched", "denfac_default"))
    row = table.set_index("env").loc["invertedpendulum"]
    assert row["level"] == ">= 1000"
    assert row[ALGOS["sac_matched"].label].startswith("2 ep, 200 steps, 20 CPU s (1/2); fall-back 0.00")
    assert row[ALGOS["sac_matched"].label].endswith("last-10 566.6; final eval 750")  # the deterministic policy's
    assert row[ALGOS["denfac_default"].label] == "–"


def test_survival_bonus_separates_standing_from_moving(tmp_path):
    """On an env that pays a survival bonus (Hopper), a run that stands still for the whole episode and one that moves
    forward and falls can have the same return; the reports give the part beyond the bonus, which tells them apart."""
    from benchmarks.reports import analysis, tables
    from benchmarks.runner import store

    def record(algo, returns, lengths):
        n, clock = len(returns), [float(i) for i in range(1, len(returns) + 1)]
        best, steps = np.maximum.accumulate(returns).tolist(), np.cumsum(lengths).tolist()
        episodes = {"episode": list(range(1, n + 1)), "performance": returns, "best_so_far": best, "return": returns,
                    "length": lengths, "timesteps": steps, "cpu_time": clock, "wall_time": clock}  # fmt: skip
        return {"algo": algo, "env": "hopper", "seed": 0, "episodes_requested": n, "status": "done",
                "timesteps": int(sum(lengths)), "cpu_time": float(n), "episodes": episodes}  # fmt: skip

    standing = record("denfac_default", [1000.0] * 12, [1000] * 12)  # the healthy reward only
    hopping = record("sac_matched", [300.0] * 2 + [1000.0] * 10, [100] * 2 + [400] * 10)  # 600 beyond the bonus
    store.write_records(tmp_path, [standing, hopping])
    episodes, runs = analysis.load(tmp_path)
    beyond = runs.set_index("algo")["last10_beyond_survival"]
    assert beyond["denfac_default"] == 0.0 and beyond["sac_matched"] == 600.0
    assert runs.set_index("algo")["last10"].nunique() == 1  # the return alone cannot tell them apart
    table = tables.env_table(runs, "hopper").set_index("algo")
    assert table.loc[ALGOS["sac_matched"].label, "last-10 beyond the survival bonus"].startswith("600.0")
    assert "last-10 beyond the survival bonus" not in tables.env_table(runs.assign(env="reacher"), "reacher")
    answer = tables.answer_table(episodes, runs, algos=("denfac_default", "sac_matched")).set_index("level")
    assert list(answer["env"]) == ["hopper", "hopper"]  # the return's level, then the one beyond the bonus
    cell = answer.loc[">= 1000"]
    assert cell[ALGOS["denfac_default"].label].endswith("last-10 1000 (0 beyond the survival bonus)")
    moving = answer.loc["beyond the survival bonus >= 100"]
    assert moving[ALGOS["denfac_default"].label] == "never (0/1); last-10 0"  # stood for every episode
    # both reach a return of 1000 at episode 1 or 3; only the hopping run earns 100 beyond the bonus, at episode 1
    assert cell[ALGOS["sac_matched"].label].startswith("3 ep, 600 steps, 3 CPU s (1/1)")
    assert moving[ALGOS["sac_matched"].label] == "1 ep, 100 steps, 1 CPU s (1/1); last-10 600"


def test_bootstrap_intervals_print_no_warning_per_call(monkeypatch):
    """arch (under rliable) warns about the legacy ``random_state`` on every bootstrap; a report makes hundreds."""
    import warnings

    import pandas as pd

    monkeypatch.setattr(st, "REPS", 50)
    runs = pd.DataFrame([(a, "pendulum", s, -100.0 * s - (a == "y")) for a in "xy" for s in range(4)],
                        columns=["algo", "env", "seed", "final_best"])  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        st.iqm_table(runs, ["pendulum"], "final_best")
        st.probability_of_improvement(runs, "x", "y", ["pendulum"], "final_best")


def test_reports_name_the_runs_trained_on_a_gpu(tmp_path):
    """A run's CPU seconds leave out a GPU's work: the report says which runs trained on one (old records: the CPU)."""
    from benchmarks.reports import analysis
    from benchmarks.runner import store

    def record(seed, machine):
        n = 3
        episodes = {"episode": [1, 2, 3], "performance": [-900.0, -500.0, -300.0], "best_so_far": [-900.0, -500.0, -300.0],
                    "return": [-900.0, -500.0, -300.0], "length": [200] * n, "timesteps": [200, 400, 600],
                    "cpu_time": [1.0, 2.0, 3.0], "wall_time": [1.0, 2.0, 3.0]}  # fmt: skip
        return {"algo": "crossq", "env": "pendulum", "seed": seed, "episodes_requested": n, "status": "done",
                "timesteps": 600, "cpu_time": 3.0, "episodes": episodes, **machine}  # fmt: skip

    gpu = {"machine": {"device": "cuda", "gpu": "NVIDIA H200"}}
    store.write_records(tmp_path, [record(0, {}), record(1, gpu), record(2, gpu), record(3, {"machine": {"device": "cpu"}})])
    episodes, runs = analysis.load(tmp_path)
    assert list(runs.sort_values("seed")["device"]) == ["cpu", "NVIDIA H200", "NVIDIA H200", "cpu"]
    text = analysis.report("t", episodes, runs, tmp_path, "t")
    assert "Trained on a GPU (their CPU seconds leave out the GPU's work): sb3-contrib CrossQ pendulum seeds 1, 2" in text
    assert "(NVIDIA H200)" in text
    one = analysis.report("t", episodes, runs[runs["seed"] != 2], tmp_path, "t")
    assert "sb3-contrib CrossQ pendulum seed 1 (NVIDIA H200)" in one
    assert "Trained on a GPU" not in analysis.report("t", episodes, runs[runs["device"] == "cpu"], tmp_path, "t")
