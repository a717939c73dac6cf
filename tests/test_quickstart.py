"""The README's main job (sb3_denfac.quickstart) end to end on a tiny budget."""

import numpy as np
from stable_baselines3.common.monitor import load_results

from sb3_denfac import DENFAC
from sb3_denfac.quickstart import best_so_far, main


def test_best_so_far_follows_the_direction_of_the_measure():
    values = np.array([500.0, 320.0, 410.0, 150.0])
    np.testing.assert_array_equal(best_so_far(values, lower_is_better=True), [500, 320, 320, 150])
    np.testing.assert_array_equal(best_so_far(-values, lower_is_better=False), [-500, -320, -320, -150])


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
    assert str(run_dir / "learning_curve.png") in capsys.readouterr().out
