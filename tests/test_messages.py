"""Errors name their real cause: the command line, the action space, the file or folder tried (issue 25)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch as th

from sb3_denfac import zoo
from sb3_denfac.quickstart import main as quickstart

ALGORITHMS = ["denfac", "ddpg", "nfac", "cacla", "cmaes"]


def _zoo_error(*argv: str) -> str:
    with pytest.raises(SystemExit) as excinfo:
        zoo.main(list(argv))
    return str(excinfo.value.code)


def test_bad_params_value_names_the_command_line(tmp_path: Path) -> None:
    message = _zoo_error(
        "train", "--algo", "denfac", "--env", "Pendulum-v1", "-f", str(tmp_path / "logs"), "-params", "gamma:2"
    )
    assert "-params gamma:2" in message and "gamma (discount factor)" in message
    assert not (tmp_path / "logs").exists()


def test_bad_yaml_value_still_names_the_file(tmp_path: Path) -> None:
    conf = tmp_path / "bad.yml"
    conf.write_text("Pendulum-v1:\n  n_timesteps: 1000\n  policy: 'MlpPolicy'\n  gamma: 3\n")
    message = _zoo_error(
        "train", "--algo", "denfac", "--env", "Pendulum-v1", "-f", str(tmp_path / "logs"), "--conf-file", str(conf),
        "-params", "sigma:0.2",
    )  # fmt: skip
    assert f"{conf}, entry 'Pendulum-v1'" in message and "-params" not in message


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_discrete_env_names_the_action_space_in_the_zoo(algo: str, tmp_path: Path) -> None:
    message = _zoo_error("train", "--algo", algo, "--env", "CartPole-v1", "-f", str(tmp_path / "logs"))
    assert "CartPole-v1 has the action space Discrete(2)" in message and "Box" in message
    assert "entry" not in message and not (tmp_path / "logs").exists()


def test_discrete_env_names_the_action_space_in_the_quickstart(tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit):
        quickstart(["--env", "CartPole-v1", "--log-dir", str(tmp_path / "runs")])
    err = capsys.readouterr().err
    assert "action space Discrete(2)" in err and "entry" not in err
    assert not (tmp_path / "runs").exists()


def test_unknown_env_lists_every_package_id(capsys, tmp_path: Path) -> None:
    with pytest.raises(SystemExit):
        quickstart(["--env", "sb3_denfac/NoSuch-v0", "--log-dir", str(tmp_path)])
    assert "sb3_denfac/ContinuousAcrobot75-v0" in capsys.readouterr().err


@pytest.mark.algorithms("all")
def test_load_of_a_missing_file_names_the_path(name: str, algo_class, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError) as excinfo:
        algo_class(name).load("does_not_exist.zip")
    message = str(excinfo.value)
    assert "'does_not_exist.zip'" in message and ".zip.zip" not in message and str(tmp_path) in message
    with pytest.raises(FileNotFoundError, match=r"'model' or 'model\.zip'"):
        algo_class(name).load("model")


def test_enjoy_with_a_missing_folder_names_it(tmp_path: Path) -> None:
    missing = tmp_path / "no_logs"
    message = _zoo_error("enjoy", "--algo", "denfac", "--env", "Pendulum-v1", "-f", str(missing))
    assert f"'{missing}' does not exist" in message
    (tmp_path / "logs" / "denfac" / "Pendulum-v1_1").mkdir(parents=True)
    message = _zoo_error("enjoy", "--algo", "ddpg", "--env", "Pendulum-v1", "-f", str(tmp_path / "logs"))
    assert f"'{tmp_path / 'logs' / 'ddpg'}' does not exist" in message and "denfac" in message
    message = _zoo_error("enjoy", "--algo", "denfac", "--env", "Pendulum-v1", "-f", str(tmp_path / "logs"), "--exp-id", "2")
    assert "Pendulum-v1_2" in message and "Pendulum-v1_1" in message


def test_enjoy_names_a_run_folder_without_a_model(tmp_path: Path) -> None:
    """A run folder without a model (a run stopped before it saved one; earlier versions' optimize made empty ones) is
    named with the runs that have one, instead of the zoo's traceback."""
    import gymnasium as gym

    from sb3_denfac import CMAES

    env_id, logs = "sb3_denfac/ContinuousCartPole-v0", tmp_path / "logs"
    name = env_id.replace("/", "-")
    (logs / "cmaes" / f"{name}_1").mkdir(parents=True)
    CMAES("MlpPolicy", gym.make(env_id, max_episode_steps=10), population_size=2).save(logs / "cmaes" / f"{name}_1" / name)
    (logs / "cmaes" / f"{name}_2" / name).mkdir(parents=True)  # what a refused optimize used to leave
    argv = ["enjoy", "--algo", "cmaes", "--env", env_id, "-f", str(logs), "-n", "5", "--no-render"]
    message = _zoo_error(*argv)
    assert f"the latest run '{logs / 'cmaes' / f'{name}_2'}' holds no model" in message
    assert "pass --exp-id 1" in message
    assert "--exp-id 1" in _zoo_error(*argv, "--exp-id", "2")
    assert "has one: train first" in _zoo_error(*argv, "--exp-id", "1", "--load-best")
    zoo.main([*argv, "--exp-id", "1", "--verbose", "0"])  # the suggested run plays


def test_preset_of_another_algorithm_is_refused_by_name() -> None:
    import gymnasium as gym

    from sb3_denfac import NFAC, SoftDENFAC, presets

    env = gym.make("Pendulum-v1")
    with pytest.raises(TypeError, match=r"presets\.PAPER is DENFAC's preset, and SoftDENFAC does not take") as error:
        SoftDENFAC("MlpPolicy", env, **presets.PAPER)
    for key in ("weighting", "sigma", "target_policy_noise"):
        assert repr(key) in str(error.value)
    assert "'learning_rate'" not in str(error.value)  # SoftDENFAC takes it
    with pytest.raises(TypeError, match=r"presets\.PAPER is DENFAC's preset, and NFAC does not take .*'buffer_size'"):
        NFAC("MlpPolicy", env, **presets.paper(sigma=0.1))
    with pytest.raises(TypeError, match="^SoftDENFAC does not take weighting: no importance weights"):  # no preset
        SoftDENFAC("MlpPolicy", env, weighting="retrace")
    SoftDENFAC("MlpPolicy", env, **presets.DATA_EFFICIENT)  # its own preset
    with pytest.raises(TypeError, match=r"presets\.DATA_EFFICIENT is SoftDENFAC's preset, and NFAC does not take"):
        NFAC("MlpPolicy", env, **presets.DATA_EFFICIENT)
    with pytest.raises(TypeError, match=r"presets\.DENFAC_DATA_EFFICIENT is DENFAC's preset, and NFAC does not take"):
        NFAC("MlpPolicy", env, **presets.DENFAC_DATA_EFFICIENT)


def test_quickstart_help_is_for_a_user(capsys) -> None:
    with pytest.raises(SystemExit):
        quickstart(["--help"])
    out = capsys.readouterr().out
    assert "README" not in out and "main job" not in out
    assert "(default: 50)" in out and "sb3_denfac/ContinuousAcrobot75-v0" in out
    for help_text in ("the algorithm", "continuous (Box) action space", "random seed", "run's folder", "progress bar"):
        assert help_text in out  # --algo, --env, --seed, --log-dir, --progress-bar


def test_ddpg_gradient_steps_zero_collects_without_training(make_env) -> None:
    from sb3_denfac import DDPG

    model = DDPG("MlpPolicy", make_env(), gradient_steps=0, learning_starts=10, batch_size=8, seed=0)
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(60)
    assert model.num_timesteps == 60 and model.replay_buffer.size() == 60
    assert model._n_updates == 0
    assert all(th.equal(a, b) for a, b in zip(before, model.policy.parameters(), strict=True))
    with pytest.raises(ValueError, match="gradient_steps"):
        DDPG("MlpPolicy", make_env(), gradient_steps=-2)
    assert np.isfinite(model.predict(make_env().reset(seed=0)[0], deterministic=True)[0]).all()


# ----- devices (no GPU needed: the device is faked where a check reads it) -----------------------------------------


def test_auto_takes_the_autograd_updater_off_the_cpu_and_fast_is_refused(make_model, monkeypatch) -> None:
    from sb3_denfac.denfac import update_paths, updaters
    from sb3_denfac.denfac.fast import FastUpdater

    model = make_model("denfac")
    settings = updaters.FitSettings.of(model)
    assert isinstance(update_paths.make_updater(model.policy, settings, "auto").updater, FastUpdater)
    cuda = th.device("cuda")
    parameters = model.policy.parameters

    class _OnCuda:  # a parameter that reports the CUDA device
        device = cuda

    monkeypatch.setattr(model.policy, "parameters", lambda: iter([_OnCuda(), *parameters()]))
    choice = update_paths.make_updater(model.policy, settings, "auto")
    assert isinstance(choice.updater, updaters.AutogradUpdater) and "'cuda'" in choice.fast_refused
    with pytest.raises(ValueError, match="verified on the CPU only.*'cuda'"):
        update_paths.make_updater(model.policy, settings, "fast")


@pytest.mark.algorithms("all")
def test_small_networks_on_cuda_through_auto_warn_once(name: str, make_model, monkeypatch) -> None:
    import warnings

    from sb3_denfac.common import device as device_module

    monkeypatch.setattr(device_module, "_warned", set())
    monkeypatch.setattr(device_module, "_is_cuda", lambda device: True)  # as if device="auto" had found CUDA
    with pytest.warns(UserWarning, match=r"running on the GPU because device='auto'.*device='cpu'"):
        make_model(name, device="auto")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        make_model(name, device="auto")  # once per algorithm
        device_module._warned.clear()
        make_model(name, device="cpu")  # an explicit device: the caller's choice


@pytest.mark.skipif(th.cuda.is_available(), reason="needs a machine without CUDA")
@pytest.mark.algorithms("all")
def test_cuda_asked_where_there_is_none_warns_and_runs_on_the_cpu(name: str, make_model, monkeypatch) -> None:
    """SB3 falls back to the CPU without a word when device="cuda" finds no CUDA; every algorithm here says so, once."""
    import warnings

    from sb3_denfac.common import device as device_module

    monkeypatch.setattr(device_module, "_warned", set())
    with pytest.warns(UserWarning, match=r"device='cuda' but CUDA is not available here.*runs on the CPU"):
        model = make_model(name, device="cuda")
    assert model.device.type == "cpu" and all(p.device.type == "cpu" for p in model.policy.parameters())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        make_model(name, device="cuda").learn(20)  # once per algorithm; it trains on


def test_small_network_warning_rules() -> None:
    from sb3_denfac.common.device import warn_about_device

    small, big = th.nn.Linear(4, 4), th.nn.Linear(1000, 1000)
    assert not warn_about_device("X1", "auto", th.device("cpu"), small)
    assert not warn_about_device("X1", "cuda", th.device("cuda"), small)
    assert not warn_about_device("X1", "auto", th.device("cuda"), big)
    with pytest.warns(UserWarning, match="X1 is running on the GPU"):
        assert warn_about_device("X1", "auto", th.device("cuda"), small)


def test_denfac_buffer_too_small_for_an_episode_of_each_env_names_n_envs() -> None:
    from stable_baselines3.common.env_util import make_vec_env

    from sb3_denfac import DENFAC

    # Pendulum's episodes last 200 steps; SB3 keeps buffer_size // n_envs steps of each env
    with pytest.raises(ValueError, match=r"buffer_size \(D=600\) // n_envs=4 .*max_episode_steps=200.*of each env"):
        DENFAC("MlpPolicy", make_vec_env("Pendulum-v1", n_envs=4), buffer_size=600)
    DENFAC("MlpPolicy", make_vec_env("Pendulum-v1", n_envs=4), buffer_size=800)
