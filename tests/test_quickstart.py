"""The README's main job (sb3_denfac.quickstart) end to end on a tiny budget."""

import numpy as np
import pytest
from stable_baselines3.common.monitor import load_results

from sb3_denfac import DENFAC
from sb3_denfac.quickstart import main


def test_quickstart_writes_model_logs_and_plot(tmp_path, capsys):
    summary = main(["--env", "sb3_denfac/ContinuousCartPole-v0", "--episodes", "3", "--log-dir", str(tmp_path)])
    run_dir = tmp_path / "denfac_sb3_denfac-ContinuousCartPole-v0_seed0"
    assert summary["episodes"] == 3
    monitor = load_results(str(run_dir))
    assert len(monitor) == 3 and np.all(monitor["paper_performance"] <= 0)
    assert summary["best_training_performance"] == monitor["paper_performance"].max()
    assert (run_dir / "learning_curve.png").stat().st_size > 1000
    assert list((run_dir / "tensorboard").rglob("events.out.tfevents.*"))
    model = DENFAC.load(run_dir / "model.zip")
    assert model.num_timesteps == monitor["l"].sum()
    out = capsys.readouterr().out
    assert str(run_dir / "learning_curve.png") in out
    # The policy of the best episode is kept, and the output says why it matters.
    best = DENFAC.load(run_dir / "best_model.zip")
    best_episode = summary["best_episode"]
    assert monitor["paper_performance"].iloc[best_episode - 1] == summary["best_training_performance"]
    assert best.num_timesteps == monitor["l"].iloc[:best_episode].sum()  # saved at the end of that episode
    assert "best_model.zip" in out and "not monotone" in out
    assert np.isfinite(summary["best_model_deterministic_performance"])


def test_quickstart_on_an_env_outside_the_paper(tmp_path):
    """Envs without info["paper_performance"]: the episode return is plotted and reported."""
    summary = main(["--env", "Pendulum-v1", "--episodes", "2", "--log-dir", str(tmp_path)])
    run_dir = tmp_path / "denfac_Pendulum-v1_seed0"
    monitor = load_results(str(run_dir))
    assert summary["episodes"] == 2 and summary["best_training_performance"] == monitor["r"].max()
    assert (run_dir / "learning_curve.png").stat().st_size > 1000
    assert (run_dir / "best_model.zip").is_file() and np.isfinite(summary["final_deterministic_performance"])


@pytest.mark.parametrize(("env_id", "close"), [("NoSuchEnv-v0", None), ("Pendulm-v1", "Pendulum-v1")])
def test_quickstart_unknown_env_id(tmp_path, capsys, env_id, close):
    """One line naming the id (and the registered ids close to it), a non-zero exit code, and nothing written."""
    with pytest.raises(SystemExit) as exit_info:
        main(["--env", env_id, "--log-dir", str(tmp_path / "runs")])
    assert exit_info.value.code != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and repr(env_id) in err
    assert close is None or close in err
    assert not (tmp_path / "runs").exists()


def test_quickstart_plot_labels_equal_or_close_replays_apart(tmp_path):
    """The final and the best policy's replays: one label "final = best" where they print the same value, labels moved
    apart where they are close, left alone where they are far apart."""
    from sb3_denfac.quickstart import plot_learning_curve, replay_labels

    same = replay_labels([("final", 500.0, "tab:red"), ("best", 500.0, "tab:purple")], 400.0)
    assert same == [("final = best 500", 500.0, "tab:purple", 0.0)]
    close = replay_labels([("final", 250.0, "tab:red"), ("best", 256.0, "tab:purple")], 400.0)
    assert [(text, offset) for text, _, _, offset in close] == [("final 250", -5.0), ("best 256", 5.0)]
    far = replay_labels([("final", 100.0, "tab:red"), ("best", 400.0, "tab:purple")], 400.0)
    assert [offset for *_, offset in far] == [0.0, 0.0]
    replays = {"final policy, deterministic (model.zip)": 500.0, "best episode's policy (best_model.zip, episode 2)": 500.0}
    plot_learning_curve(np.array([500.0, 300.0, 450.0]), "env", "denfac", True, tmp_path / "curve.png", replays=replays)
    assert (tmp_path / "curve.png").stat().st_size > 1000
