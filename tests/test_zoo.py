"""RL Zoo integration (sb3_denfac.zoo): training from the YAML files, Optuna studies on SQLite, config validation."""

from __future__ import annotations

import argparse
import importlib.util
import os
import sqlite3
import subprocess
import sys
import time
from contextlib import closing
from pathlib import Path

import gymnasium as gym
import numpy as np
import optuna
import pytest
import torch as th
import yaml
from rl_zoo3.exp_manager import ExperimentManager
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from sb3_denfac import zoo
from sb3_denfac.zoo import cli
from sb3_denfac.zoo import samplers as zoo_samplers

ENV = "sb3_denfac/ContinuousCartPole-v0"  # the cheapest of the paper's envs
ENV_FOLDER = ENV.replace("/", "-")
REPO = Path(__file__).resolve().parents[1]

# Tiny-run overrides (-params) that only shrink the per-episode work; everything else comes from the YAML entry.
CHEAP_PARAMS = {
    "denfac": ["n_fitted_iterations:2", "actor_steps:3", "critic_steps:3"],
    "soft_denfac": ["n_fitted_iterations:2", "actor_steps:3", "critic_steps:3"],
    "ddpg": ["gradient_steps:1"],
    "nfac": ["n_fitted_iterations:2", "actor_steps:3", "critic_steps:3"],
    "cacla": ["n_steps:100"],
    "cmaes": ["population_size:4"],
    "td3": ["learning_starts:100"],
}
OPTIMIZE_ALGO = "cmaes"  # the cheapest trials (no gradient steps)


@pytest.fixture(scope="module", autouse=True)
def registered() -> None:
    zoo.register()


def _scalar_tags(tb_dir: Path) -> set[str]:
    tags: set[str] = set()
    for event_file in tb_dir.rglob("events.out.tfevents.*"):
        accumulator = EventAccumulator(str(event_file))
        accumulator.Reload()
        tags |= set(accumulator.Tags()["scalars"])
    return tags


@pytest.mark.parametrize("algo", list(CHEAP_PARAMS))
def test_zoo_trains_from_yaml(algo: str, tmp_path: Path) -> None:
    logs, tb = tmp_path / "logs", tmp_path / "tb"
    argv = ["train", "--algo", algo, "--env", ENV, "-n", "300", "-f", str(logs), "-tb", str(tb), "--seed", "0"]
    argv += ["--eval-freq", "-1", "--verbose", "0"]
    if CHEAP_PARAMS[algo]:
        argv += ["-params", *CHEAP_PARAMS[algo]]
    zoo.main(argv)

    run_dir = logs / algo / f"{ENV_FOLDER}_1"
    model_path = run_dir / f"{ENV_FOLDER}.zip"
    assert model_path.is_file()
    # The zoo recorded the hyperparameters it read from this package's YAML file.
    assert "n_timesteps" in (run_dir / ENV_FOLDER / "config.yml").read_text()
    # Monitor records the paper's per-episode measure next to the return (monitor_kwargs of the YAML entry).
    assert (run_dir / "0.monitor.csv").read_text().splitlines()[1] == "r,l,t,paper_performance"
    model = zoo.algorithm_class(algo).load(model_path, env=gym.make(ENV), device="cpu")
    assert model.num_timesteps >= 300
    tags = _scalar_tags(tb / ENV_FOLDER)
    assert any(tag.startswith("train/") for tag in tags), tags  # the algorithm's internals
    assert any(tag.startswith("rollout/") for tag in tags), tags  # return curves


@pytest.mark.parametrize("explicit", [None, "2"])
def test_train_uses_one_torch_thread_unless_told(explicit: str | None, tmp_path: Path) -> None:
    """The command line defaults to one torch thread (several collapse on a loaded machine); --num-threads wins."""
    argv = ["train", "--algo", "cmaes", "--env", ENV, "-n", "100", "-f", str(tmp_path), "--eval-freq", "-1"]
    argv += ["--verbose", "0", "-params", *CHEAP_PARAMS["cmaes"]]
    if explicit is not None:
        argv += ["--num-threads", explicit]
    th.set_num_threads(3)  # neither the default nor the explicit value
    try:
        zoo.main(argv)
        assert th.get_num_threads() == (1 if explicit is None else int(explicit))
    finally:
        th.set_num_threads(1)
    assert zoo.prepare_train_args(argv[1:]).count("--num-threads") == 1


@pytest.mark.parametrize("algo", sorted(zoo.ALGORITHMS))
def test_enjoy_runs_a_trained_agent(algo: str, tmp_path: Path) -> None:
    """The zoo's enjoy script loads the saved agent without an env (SB3 ``load(path)``) and plays it."""
    logs = tmp_path / "logs"
    common = ["--algo", algo, "--env", ENV, "-f", str(logs), "--seed", "0", "--verbose", "0"]
    params = ["-params", *CHEAP_PARAMS[algo]] if CHEAP_PARAMS[algo] else []
    zoo.main(["train", *common, "-n", "100", "--eval-freq", "-1", *params])
    reward_log = tmp_path / "enjoy"
    zoo.main(["enjoy", *common, "-n", "600", "--no-render", "--deterministic", "--reward-log", str(reward_log)])
    # The Monitor of the enjoy run recorded at least one finished episode (CartPole episodes end within 500 steps).
    assert len((reward_log / "0.monitor.csv").read_text().splitlines()) >= 3


def _saved_zoo_agent(logs: Path, env_id: str) -> None:
    """A tiny CMA-ES agent saved where the zoo's enjoy / record_video scripts look for experiment 1."""
    from sb3_denfac import CMAES

    folder = logs / "cmaes" / f"{env_id.replace('/', '-')}_1"
    folder.mkdir(parents=True)
    CMAES("MlpPolicy", gym.make(env_id, max_episode_steps=10), population_size=2).save(folder / env_id.replace("/", "-"))


def test_enjoy_without_a_folder_reads_what_train_wrote(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without -f, enjoy looks where train writes by default (logs/), not in the zoo's rl-trained-agents (a Hugging
    Face download of agents the hub does not have); with nothing there it names the folder it looked in."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit, match=r"the log folder .logs. does not exist"):
        zoo.main(["enjoy", "--algo", "cmaes", "--env", ENV, "--no-render"])
    _saved_zoo_agent(tmp_path / "logs", ENV)
    zoo.main(["enjoy", "--algo", "cmaes", "--env", ENV, "-n", "20", "--no-render", "--deterministic"])
    assert cli.with_default_folder(["--algo", "td3", "--env", ENV]) == ["--algo", "td3", "--env", ENV]  # the zoo's own


@pytest.mark.parametrize("env_id", ["sb3_denfac/ContinuousAcrobot-v0", ENV])
def test_record_video_writes_an_mp4(tmp_path: Path, env_id: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """With the video extra, record_video renders a paper env headless and writes a small mp4."""
    pytest.importorskip("pygame", reason="the video extra (pygame, moviepy) is not installed")
    pytest.importorskip("moviepy", reason="the video extra (pygame, moviepy) is not installed")
    monkeypatch.delenv("DISPLAY", raising=False)
    logs, videos = tmp_path / "logs", tmp_path / "videos"
    _saved_zoo_agent(logs, env_id)
    zoo.main(["record_video", "--algo", "cmaes", "--env", env_id, "-f", str(logs), "-n", "12", "-o", str(videos)])
    (video,) = videos.glob("*.mp4")
    assert 1000 < video.stat().st_size < 1_000_000


def test_record_video_without_the_extra_names_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None if name == "pygame" else object())  # absent
    with pytest.raises(SystemExit, match=r"record_video needs pygame .*sb3-denfac\[video\]"):
        zoo.main(["record_video", "--algo", "cmaes", "--env", ENV, "-f", str(tmp_path)])


def _study(logs: Path, algo: str) -> optuna.Study:
    return optuna.load_study(study_name=f"{algo}-{ENV_FOLDER}", storage=f"sqlite:///{logs / 'optuna.db'}")


def test_optimize_on_sqlite_resumes_the_study(tmp_path: Path) -> None:
    """The default study resumes; each trial trains with (and records) the entry's policy_kwargs around the sampled
    net_arch, and ``--trial-id`` rebuilds both from the same default study."""
    logs = tmp_path / "logs"
    entry = zoo.select_entry(zoo.load_config_file(zoo.default_config_path(OPTIMIZE_ALGO)), ENV)
    entry_policy_kwargs = {**entry["policy_kwargs"], "batch_norm": True}  # not the policy's default, not sampled
    conf = tmp_path / "conf.yml"
    conf.write_text(yaml.safe_dump({ENV: {**entry, "policy_kwargs": entry_policy_kwargs}}))
    argv = ["train", "--algo", OPTIMIZE_ALGO, "--env", ENV, "-n", "200", "-f", str(logs), "--conf-file", str(conf)]
    argv += ["--verbose", "0"]
    tune = ["-optimize", "--n-evaluations", "1", "--eval-episodes", "1", "--sampler", "random", "--pruner", "none"]
    tune += ["--no-optim-plots"]
    zoo.main([*argv, *tune, "--n-trials", "2", "--seed", "1"])
    first = _study(logs, OPTIMIZE_ALGO).trials
    assert len(first) == 2
    assert all(t.state == optuna.trial.TrialState.COMPLETE for t in first)
    assert all(t.user_attrs[zoo_samplers.ENTRY_POLICY_KWARGS] == entry_policy_kwargs for t in first)

    zoo.main([*argv, *tune, "--n-trials", "1", "--seed", "2"])
    trials = _study(logs, OPTIMIZE_ALGO).trials
    assert len(trials) == 3
    assert [t.params for t in trials[:2]] == [t.params for t in first]

    other_budget = [a if a != "200" else "150" for a in argv]  # -n 150: trials not comparable with the study's
    with pytest.raises(SystemExit, match=r"made with n_timesteps=200 \(3 finished trials\); this run asks for 150"):
        zoo.main([*other_budget, *tune, "--n-trials", "1", "--seed", "4"])
    assert len(_study(logs, OPTIMIZE_ALGO).trials) == 3

    zoo.main([*argv, "--trial-id", "1", "--eval-freq", "-1", "--seed", "3"])  # the zoo ignores --trial-id 0
    (model_path,) = (logs / OPTIMIZE_ALGO).glob(f"*/{ENV_FOLDER}.zip")
    policy_kwargs = zoo.algorithm_class(OPTIMIZE_ALGO).load(model_path, device="cpu").policy_kwargs
    assert policy_kwargs["batch_norm"] is True
    assert policy_kwargs["net_arch"] == zoo_samplers.ACTOR_ARCHS[trials[1].params["actor_arch"]]


def _completed_trial_count(db: Path) -> int:
    """Completed trials in an optuna SQLite file, read without writing: ``optuna.load_study`` would create missing
    tables and race the tuner that is creating them (``IntegrityError`` on ``alembic_version``)."""
    try:
        with closing(sqlite3.connect(f"{db.as_uri()}?mode=ro", uri=True, timeout=1.0)) as connection:
            return connection.execute("SELECT COUNT(*) FROM trials WHERE state = 'COMPLETE'").fetchone()[0]
    except sqlite3.Error:
        return 0  # no file or tables yet, or the tuner holds a write lock


def test_killed_optimisation_keeps_completed_trials(tmp_path: Path) -> None:
    """SIGKILL a tuning process after its first completed trial; rerunning the same command continues the study."""
    logs = tmp_path / "logs"
    argv = ["train", "--algo", OPTIMIZE_ALGO, "--env", ENV, "-n", "200", "-f", str(logs), "-optimize"]
    argv += ["--n-evaluations", "1", "--eval-episodes", "1", "--pruner", "none", "--no-optim-plots", "--verbose", "0"]
    process = subprocess.Popen(
        [sys.executable, "-m", "sb3_denfac.zoo", *argv, "--n-trials", "1000", "--seed", "1"],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and process.poll() is None:
            time.sleep(1.0)
            if _completed_trial_count(logs / "optuna.db"):
                break
    finally:
        process.kill()
        process.wait()
    # the tuner is dead: optuna can open the file now (and roll back a write the kill interrupted)
    completed = _study(logs, OPTIMIZE_ALGO).get_trials(states=(optuna.trial.TrialState.COMPLETE,))
    assert completed, "the tuning process completed no trial"

    zoo.main([*argv, "--n-trials", "1", "--seed", "2"])
    trials = _study(logs, OPTIMIZE_ALGO).get_trials(states=(optuna.trial.TrialState.COMPLETE,))
    before = {t.number for t in completed}
    assert before < {t.number for t in trials}
    assert len(trials) >= len(completed) + 1


def test_optimize_makes_no_run_folder(tmp_path: Path) -> None:
    """A tuning run keeps its trials in the study: it leaves no empty ``<env>_<n>`` run folder (which ``enjoy`` would
    take for the latest run), neither when its trials ran nor when it is refused before them."""
    logs = tmp_path / "logs"
    argv = ["optimize", "--algo", OPTIMIZE_ALGO, "--env", ENV, "-f", str(logs), "--n-evaluations", "1"]
    argv += ["--eval-episodes", "1", "--sampler", "random", "--pruner", "none", "--no-optim-plots", "--verbose", "0"]
    argv += ["--n-trials", "1", "-params", *CHEAP_PARAMS[OPTIMIZE_ALGO]]
    zoo.main([*argv, "-n", "200", "--seed", "1"])
    assert len(_study(logs, OPTIMIZE_ALGO).trials) == 1
    with pytest.raises(SystemExit, match=r"made with n_timesteps=200"):  # refused: another budget
        zoo.main([*argv, "-n", "150", "--seed", "2"])
    assert sorted(p.name for p in (logs / OPTIMIZE_ALGO).glob(f"{ENV_FOLDER}_*")) == []


def _save_tiny_denfac(folder: Path, env_id: str, policy: str = "MlpPolicy") -> None:
    """A tiny DENFAC saved where the zoo's enjoy script looks for experiment 1 of ``env_id``."""
    from sb3_denfac import DENFAC

    name = env_id.replace("/", "-")
    (folder / "denfac" / f"{name}_1").mkdir(parents=True)
    model = DENFAC(policy, gym.make(env_id), buffer_size=1000, policy_kwargs=dict(net_arch=dict(pi=[4], qf=[4])))
    model.save(folder / "denfac" / f"{name}_1" / name)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the display is DISPLAY / WAYLAND_DISPLAY on Linux")
def test_enjoy_without_a_display_plays_without_rendering(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    _save_tiny_denfac(tmp_path / "logs", ENV)
    zoo.main(["enjoy", "--algo", "denfac", "--env", ENV, "-f", str(tmp_path / "logs"), "-n", "5", "--verbose", "0"])
    assert "no display (DISPLAY is not set): playing without rendering" in capsys.readouterr().err
    assert cli.without_display(["--algo", "denfac", "--no-render"]) == ["--algo", "denfac", "--no-render"]
    monkeypatch.setenv("DISPLAY", ":0")
    assert cli.without_display(["--algo", "denfac"]) == ["--algo", "denfac"]  # a display: the zoo renders


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the display is DISPLAY / WAYLAND_DISPLAY on Linux")
def test_enjoy_on_pybullet_without_a_display_does_not_hang(tmp_path: Path) -> None:
    """panda-gym renders with PyBullet's GUI, which waits on the X server forever without one."""
    pytest.importorskip("panda_gym", reason="the robotics extra (panda-gym) is not installed")
    import panda_gym  # noqa: F401  (registers PandaReach-v3)

    _save_tiny_denfac(tmp_path / "logs", "PandaReach-v3", "MultiInputPolicy")
    environ = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    result = subprocess.run(
        [sys.executable, "-m", "sb3_denfac.zoo", "enjoy", "--algo", "denfac", "--env", "PandaReach-v3", "-n", "10"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"},
        timeout=120,  # it hung until killed: fail instead
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert "no display" in result.stderr


@pytest.mark.parametrize("algo", sorted(zoo_samplers.SAMPLERS))
def test_sampled_hyperparameters_fit_the_constructor(algo: str) -> None:
    """Every sampler's output, merged into the YAML entry as the zoo does, passes validation and builds a model; it
    keeps the entry's other policy_kwargs (read from the trial); converter + the same merge == sampler."""
    entry = zoo.select_entry(zoo.load_config_file(zoo.default_config_path(algo)), ENV)
    kept = {"init": "paper"} if algo == "soft_denfac" else {"batch_norm": True}  # SAC's actor has no batch norm
    entry_policy_kwargs = {**kept, **entry.get("policy_kwargs", {})}  # a key besides net_arch, to be kept
    entry["policy_kwargs"] = entry_policy_kwargs
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=0))
    for _ in range(5):
        trial = study.ask()
        trial.set_user_attr(zoo_samplers.ENTRY_POLICY_KWARGS, entry_policy_kwargs)
        sampled = zoo_samplers.SAMPLERS[algo](trial, 1, 1, {})
        assert "train_freq" not in sampled
        converted = zoo_samplers.CONVERTERS[algo](trial.params)
        tuned = set(converted["policy_kwargs"])  # net_arch, and DENFAC's n_critics
        assert {k: v for k, v in sampled["policy_kwargs"].items() if k not in tuned} == {
            k: v for k, v in entry_policy_kwargs.items() if k not in tuned
        }
        assert zoo_samplers.with_entry_policy_kwargs(converted, entry_policy_kwargs) == sampled
        merged = {**entry, **sampled}
        zoo.validate_entry(algo, merged, env_id=ENV)
        zoo.make_model(algo, ENV, merged, device="cpu").get_env().close()  # the values are usable too


def test_denfac_sampler_tunes_the_stability_options() -> None:
    """The DENFAC sampler offers both values of n_critics, the plain ascent (lambda 0) besides proximal actors, both
    critic targets (with two critics: one has nothing to combine) with and without smoothing, with and without
    bootstrap bounds, and the model the zoo builds from a trial has what was sampled, with no ignored setting."""
    import warnings

    entry = zoo.select_entry(zoo.load_config_file(zoo.default_config_path("denfac")), ENV)
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=0))
    seen: set[tuple[int, bool]] = set()
    targets: set[tuple[str, bool]] = set()
    bounds: set[bool] = set()
    for _ in range(24):
        trial = study.ask()
        trial.set_user_attr(zoo_samplers.ENTRY_POLICY_KWARGS, entry["policy_kwargs"])
        sampled = zoo_samplers.sample_denfac_params(trial, 1, 1, {})
        with warnings.catch_warnings():
            warnings.filterwarnings("error", message=".* ignores ")
            model = zoo.make_model("denfac", ENV, {**entry, **sampled}, device="cpu")
        assert len(model.critic.q_networks) == trial.params["n_critics"]
        assert model.actor_proximal == trial.params["actor_proximal"]
        assert ("critic_target" in trial.params) == (trial.params["n_critics"] == 2)
        assert model.critic_target == trial.params.get("critic_target", "mean")
        assert model.target_policy_noise == trial.params["target_policy_noise"]
        assert model.bootstrap_bounds == trial.params["bootstrap_bounds"]
        bounds.add(model.bootstrap_bounds)
        seen.add((trial.params["n_critics"], trial.params["actor_proximal"] > 0))
        if trial.params["n_critics"] == 2:
            targets.add((trial.params["critic_target"], trial.params["target_policy_noise"] > 0))
        model.get_env().close()
    assert seen == {(1, False), (1, True), (2, False), (2, True)}
    assert targets == {("mean", False), ("mean", True), ("min", False), ("min", True)}
    assert bounds == {False, True}


def test_soft_denfac_sampler_offers_only_its_own_settings() -> None:
    """SoftDENFAC's sampler tunes the fitted iterations and alpha's start, none of the deterministic actor's settings
    (which its constructor does not take), and the model the zoo builds from a trial has what was sampled."""
    entry = zoo.select_entry(zoo.load_config_file(zoo.default_config_path("soft_denfac")), ENV)
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=0))
    starts: set[str] = set()
    for _ in range(16):
        trial = study.ask()
        sampled = zoo_samplers.sample_soft_denfac_params(trial, 1, 1, {})
        assert not {"sigma", "inverting_gradients", "actor_proximal", "target_policy_noise", "weighting"} & set(sampled)
        model = zoo.make_model("soft_denfac", ENV, {**entry, **sampled}, device="cpu")
        assert model.ent_coef == trial.params["ent_coef"]
        assert model.critic_target == trial.params.get("critic_target", "mean")
        starts.add(model.ent_coef)
        model.get_env().close()
    assert starts == {"auto", "auto_0.1", "auto_0.01"}


@pytest.mark.parametrize("path", sorted(zoo.HYPERPARAMS_DIR.glob("*.yml")), ids=lambda p: p.stem)
def test_every_yaml_entry_validates(path: Path) -> None:
    config = zoo.validate_config_file(path, path.stem)
    for env_id in zoo.PACKAGE_ENV_IDS:
        assert env_id in config, f"{path.name} has no entry for {env_id}"


@pytest.mark.parametrize("path", sorted(zoo.HYPERPARAMS_DIR.glob("*.yml")), ids=lambda p: p.stem)
def test_every_yaml_entry_builds_a_model(path: Path, tmp_path: Path) -> None:
    """The zoo's own ExperimentManager (with this package's preset expansion) turns every entry into a model (values,
    not only keys, are usable)."""
    for env_id in zoo.PACKAGE_ENV_IDS:
        args = argparse.Namespace(conf_file=str(path))
        manager = zoo.CheckedExperimentManager(
            args, path.stem, env_id, str(tmp_path), eval_freq=-1, config=str(path), seed=0, verbose=0
        )
        model, _ = manager.setup_experiment()
        assert isinstance(model, zoo.algorithm_class(path.stem))
        model.get_env().close()


@pytest.mark.parametrize("algo", ["denfac", "td3"])  # td3: the zoo's noise_type / noise_std too
def test_make_model_builds_what_the_zoo_builds(algo: str, tmp_path: Path) -> None:
    """make_model (quickstart, Figure 3 benchmark) and the zoo's own setup_experiment give the same model from an entry."""
    config = str(zoo.default_config_path(algo))
    manager = zoo.CheckedExperimentManager(
        argparse.Namespace(conf_file=config), algo, ENV, str(tmp_path), eval_freq=-1, config=config, seed=3
    )
    manager.device, manager.verbose = "cpu", 0
    zoo_model, _ = manager.setup_experiment()
    ours = zoo.make_model(algo, ENV, zoo.load_hyperparams(algo, ENV), seed=3, device="cpu")
    assert type(ours) is type(zoo_model) and ours.policy_kwargs == zoo_model.policy_kwargs
    assert (ours.gamma, ours.buffer_size, ours.batch_size) == (zoo_model.gamma, zoo_model.buffer_size, zoo_model.batch_size)
    assert type(ours.action_noise) is type(zoo_model.action_noise)
    if algo == "td3":
        np.testing.assert_array_equal(ours.action_noise._sigma, zoo_model.action_noise._sigma)
    for (key, value), other in zip(ours.policy.state_dict().items(), zoo_model.policy.state_dict().values(), strict=True):
        assert th.equal(value, other), key
    zoo_model.get_env().close()
    ours.get_env().close()


def test_make_model_names_a_missing_zoo_step(monkeypatch: pytest.MonkeyPatch) -> None:
    """make_model uses two private ExperimentManager steps: an rl_zoo3 without one gets an error naming it."""
    entry = zoo.load_hyperparams("cmaes", ENV)
    monkeypatch.delattr(ExperimentManager, "_preprocess_action_noise")
    with pytest.raises(zoo.ZooConfigError, match=r"rl_zoo3 .* ExperimentManager\._preprocess_action_noise"):
        zoo.make_model("cmaes", ENV, entry)


def test_paper_figure5_values() -> None:
    denfac = zoo.load_config_file(zoo.default_config_path("denfac"))
    acrobot, cartpole = (zoo.select_entry(denfac, env) for env in ("sb3_denfac/ContinuousAcrobot-v0", ENV))
    assert (acrobot["buffer_size"], acrobot["reset_critic"], acrobot["inverting_gradients"], acrobot["gamma"]) == (
        6000,
        True,
        False,
        0.9,
    )
    assert (cartpole["buffer_size"], cartpole["reset_critic"], cartpole["inverting_gradients"]) == (3000, False, True)
    assert (cartpole["n_fitted_iterations"], cartpole["actor_steps"], cartpole["actor_learning_rate"]) == (10, 25, 0.1)
    ddpg = zoo.load_config_file(zoo.default_config_path("ddpg"))["sb3_denfac/ContinuousCartPole-v0"]
    assert (ddpg["batch_size"], ddpg["tau"], ddpg["gradient_steps"]) == (64, 0.1, 8)


def test_preset_is_expanded_with_the_entry_over_it() -> None:
    """``preset: paper`` starts from presets.PAPER; the entry's keys win, policy_kwargs (and net_arch) merge key by key;
    the paper entries of denfac.yml spell only their per-env values and no constructor ever sees ``preset``."""
    from sb3_denfac.denfac.presets import PAPER

    config = {ENV: {"preset": "paper", "gamma": 0.5, "buffer_size": 6000, "policy_kwargs": {"net_arch": {"pi": [5]}}}}
    entry = zoo.select_entry(config, ENV)
    assert "preset" not in entry and config[ENV]["preset"] == "paper"  # the file's mapping is left as read
    assert (entry["gamma"], entry["buffer_size"], entry["reset_actor"], entry["batch_size"]) == (0.5, 6000, True, None)
    assert entry["policy_kwargs"] == {**PAPER["policy_kwargs"], "net_arch": {"pi": [5], "qf": [50, 7]}}
    assert PAPER["policy_kwargs"]["net_arch"] == {"pi": [20], "qf": [50, 7]}  # the preset itself is not modified
    denfac = zoo.load_config_file(zoo.default_config_path("denfac"))
    for env_id in zoo.PACKAGE_ENV_IDS:
        assert denfac[env_id]["preset"] == "paper"
        assert not {"batch_size", "reset_actor", "weighting", "adam_betas", "actor_proximal"} & set(denfac[env_id])
        assert "preset" not in zoo.load_hyperparams("denfac", env_id)
    with pytest.raises(zoo.ZooConfigError, match="Unknown preset 'papr'"):
        zoo.select_entry({ENV: {"preset": "papr"}}, ENV)
    with pytest.raises(zoo.ZooConfigError, match="preset 'paper' .* denfac's arguments, not nfac's"):
        zoo.select_entry(config, ENV, algo="nfac")
    with pytest.raises(zoo.ZooConfigError, match="policy_kwargs as a YAML mapping"):
        zoo.select_entry({ENV: {"preset": "paper", "policy_kwargs": "dict(n_critics=2)"}}, ENV)


def test_preset_from_the_command_line(tmp_path: Path) -> None:
    """``-params "preset:'paper'"`` on an entry without a preset trains the paper's DENFAC, the entry's keys kept."""
    logs = tmp_path / "logs"
    argv = ["train", "--algo", "denfac", "--env", "Pendulum-v1", "-f", str(logs), "-n", "400", "--eval-freq", "-1"]
    zoo.main([*argv, "-params", "preset:'paper'", "n_fitted_iterations:1", "critic_steps:2", "actor_steps:2"])
    (model_path,) = logs.rglob("Pendulum-v1.zip")
    model = zoo.algorithm_class("denfac").load(model_path, device="cpu")
    assert (model.batch_size, model.reset_actor, model.actor_proximal, model.n_fitted_iterations) == (None, True, 0.0, 1)
    assert model.critic.n_critics == 1 and model.policy_kwargs["init"] == "paper"


# ---------------------------------------------------------------------------------------------------------------------
# Bad configurations fail before training, with the culprit named
# ---------------------------------------------------------------------------------------------------------------------


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.yml"
    path.write_text(text)
    return path


def _train_error(tmp_path: Path, conf: Path, *extra: str, algo: str = "denfac") -> str:
    logs = tmp_path / "logs"
    with pytest.raises(SystemExit) as excinfo:
        zoo.main(["train", "--algo", algo, "--env", ENV, "-f", str(logs), "--conf-file", str(conf), *extra])
    assert not logs.exists(), "the error must come before the zoo creates anything"
    return str(excinfo.value.code)


GOOD_ENTRY = f"""{ENV}:
  n_timesteps: 1000
  policy: 'MlpPolicy'
"""


def test_unknown_key_names_key_and_algorithm(tmp_path: Path) -> None:
    message = _train_error(tmp_path, _write(tmp_path, GOOD_ENTRY + "  n_fitted_iteration: 3\n"))
    assert "n_fitted_iteration" in message and "denfac" in message and "n_fitted_iterations" in message


def test_monitor_info_keywords_must_be_a_tuple(tmp_path: Path) -> None:
    message = _train_error(tmp_path, _write(tmp_path, GOOD_ENTRY + "  monitor_kwargs: {info_keywords: [x]}\n"))
    assert "info_keywords" in message and "tuple" in message


def test_unknown_policy_name(tmp_path: Path) -> None:
    message = _train_error(tmp_path, _write(tmp_path, GOOD_ENTRY.replace("MlpPolicy", "MLPPolicy")))
    assert "MLPPolicy" in message and "MlpPolicy" in message


def test_unknown_policy_kwargs_key(tmp_path: Path) -> None:
    message = _train_error(tmp_path, _write(tmp_path, GOOD_ENTRY + "  policy_kwargs:\n    net_arc: [5]\n"))
    assert "net_arc" in message and "policy_kwargs" in message


def test_wrong_type_explains_yaml_float(tmp_path: Path) -> None:
    message = _train_error(tmp_path, _write(tmp_path, GOOD_ENTRY + "  critic_learning_rate: 1e-3\n"))
    assert "critic_learning_rate" in message and "!!float" in message
    message = _train_error(tmp_path, _write(tmp_path, GOOD_ENTRY + "  reset_critic: 'yes'\n"))
    assert "reset_critic" in message and "bool" in message


def test_wrong_type_from_command_line_override(tmp_path: Path) -> None:
    message = _train_error(tmp_path, _write(tmp_path, GOOD_ENTRY), "-params", "buffer_size:3000.5")
    assert "buffer_size" in message and "int" in message


def test_unknown_env_id_in_yaml_lists_known_ids(tmp_path: Path) -> None:
    text = GOOD_ENTRY + GOOD_ENTRY.replace(ENV, "sb3_denfac/ContinuousCartpole-v0")
    message = _train_error(tmp_path, _write(tmp_path, text))
    assert "sb3_denfac/ContinuousCartpole-v0" in message
    assert all(env_id in message for env_id in zoo.PACKAGE_ENV_IDS)


def test_unknown_env_on_command_line(tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as excinfo:
        zoo.main(["train", "--algo", "denfac", "--env", "sb3_denfac/NoSuchEnv-v0", "-f", str(tmp_path / "logs")])
    assert "sb3_denfac/NoSuchEnv-v0" in str(excinfo.value.code)
    assert zoo.PACKAGE_ENV_IDS[0] in str(excinfo.value.code)


def test_malformed_yaml_names_file_and_line(tmp_path: Path) -> None:
    conf = _write(tmp_path, GOOD_ENTRY + "  gamma: [0.9\n  sigma: 0.05\n")
    message = _train_error(tmp_path, conf)
    assert str(conf) in message and "line" in message


def test_cli_reports_config_errors_without_traceback(tmp_path: Path) -> None:
    conf = _write(tmp_path, GOOD_ENTRY + "  typo_key: 1\n")
    result = subprocess.run(
        [sys.executable, "-m", "sb3_denfac.zoo", "train", "--algo", "denfac", "--env", ENV, "--conf-file", str(conf)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"},
        timeout=120,
    )
    assert result.returncode != 0
    assert "typo_key" in result.stderr and "Traceback" not in result.stderr


def test_hyperparams_live_at_the_repository_root_and_every_package_ships() -> None:
    """One source for the YAML (hyperparams/, installed as sb3_denfac.hyperparams) and no package left out of the wheel
    (pyproject lists the packages explicitly because of that mapping)."""
    tomllib = pytest.importorskip("tomllib")
    assert zoo.HYPERPARAMS_DIR.resolve() == (REPO / "hyperparams").resolve()
    assert not (REPO / "sb3_denfac" / "hyperparams").exists()
    listed = set(tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(REPO).parts) for p in (REPO / "sb3_denfac").rglob("__init__.py")}
    assert found | {"sb3_denfac.hyperparams"} == listed
