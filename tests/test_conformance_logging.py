"""SB3 plugin contract, part 2: TensorBoard and custom loggers, callbacks (counts, checkpoints, evaluation, early stop),
progress bar (after SB3's tests/test_tensorboard.py, test_logger.py, test_callbacks.py). The tiny variants and
helpers: fixtures of ``conftest.py``."""

from __future__ import annotations

import pathlib

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.callbacks import (
    BaseCallback,
    CallbackList,
    CheckpointCallback,
    EvalCallback,
    StopTrainingOnMaxEpisodes,
)
from stable_baselines3.common.callbacks import ProgressBarCallback as SB3ProgressBarCallback
from stable_baselines3.common.logger import KVWriter, Logger

import sb3_denfac  # noqa: F401  (registers the paper envs)
from sb3_denfac.common.logging_keys import RENAMED, TRAIN_KEYS, WITH_AN_OPTION, WRITTEN_BY

REPO = pathlib.Path(__file__).resolve().parents[1]
#: The algorithm (zoo name, the key of ``WRITTEN_BY``) of each tiny variant of conftest.py.
ALGORITHM_OF = {"denfac_plain": "denfac", "ddpg_ig": "ddpg"}

# ----- logging, callbacks, progress bar (SB3 tests/test_tensorboard.py, test_callbacks.py) -----------------------------


@pytest.mark.algorithms("all")
def test_tensorboard(tmp_path: pathlib.Path, name: str, episode_steps, make_model) -> None:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    model = make_model(name, tensorboard_log=str(tmp_path))
    model.learn(3 * episode_steps, log_interval=1)
    class_name = type(model).__name__
    run_dirs = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert [p.name for p in run_dirs] == [f"{class_name}_1"], "tb_log_name must default to the class name"
    event_files = list(run_dirs[0].glob("events.out.tfevents.*"))
    assert event_files
    accumulator = EventAccumulator(str(run_dirs[0]))
    accumulator.Reload()
    tags = accumulator.Tags()["scalars"]
    assert any(tag.startswith("train/") for tag in tags), tags
    assert "time/fps" in tags, tags
    assert any(tag.startswith("rollout/") for tag in tags), tags

    model.learn(episode_steps, reset_num_timesteps=False, log_interval=1)  # continues the same run
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{class_name}_1"]


class KeyCollector(KVWriter):
    """An SB3 logger output that keeps the name of every key written to it (whatever the formats it is excluded from)."""

    def __init__(self) -> None:
        self.keys: set[str] = set()

    def write(self, key_values: dict, key_excluded: dict, step: int = 0) -> None:
        self.keys |= set(key_values)

    def close(self) -> None:
        pass


@pytest.mark.algorithms("all")
def test_train_keys_are_the_documented_ones(name: str, episode_steps, make_env, make_model) -> None:
    """Each algorithm writes exactly the ``train/`` keys that sb3_denfac.common.logging_keys (and the table of
    docs/conventions.md) gives it: no undocumented key, none of the documented ones missing, no name of 0.4."""
    collector = KeyCollector()
    # Rewards shifted to > 0: NFAC and CACLA write train/actor_loss only when their actor moved (a TD error > 0), which
    # a critic starting near 0 never sees on Pendulum's negative rewards in a few episodes.
    env = gym.wrappers.TransformReward(make_env(), lambda reward: reward + 20.0)
    model = make_model(name, env=env, seed=0)
    model.set_logger(Logger(folder=None, output_formats=[collector]))
    model.learn(6 * episode_steps, log_interval=1)
    written = {key for key in collector.keys if key.startswith("train/")}
    assert written == set(WRITTEN_BY[ALGORITHM_OF.get(name, name)])
    assert not written & set(RENAMED)


def test_logging_keys_table_is_the_module() -> None:
    """docs/conventions.md's logging-keys table has one row per key of TRAIN_KEYS, with its meaning and the algorithms
    that write it (WRITTEN_BY; WITH_AN_OPTION: "(x)"), in the module's order."""
    columns = ["denfac", "soft_denfac", "ddpg", "nfac", "cacla", "cmaes"]
    assert set(WRITTEN_BY) == set(columns)
    assert all(key in TRAIN_KEYS for keys in WRITTEN_BY.values() for key in keys)
    assert all(key in TRAIN_KEYS and set(algos) <= set(columns) for key, (_, algos) in WITH_AN_OPTION.items())
    rows = [line for line in (REPO / "docs" / "conventions.md").read_text().splitlines() if line.startswith("| `train/")]
    table = {}
    for row in rows:
        key, meaning, *marks = (cell.strip() for cell in row.strip().strip("|").split(" | "))
        table[key.strip("`")] = (meaning, marks)
    table = {key: value for key, value in table.items() if key not in RENAMED}  # the renaming table's rows
    assert list(table) == list(TRAIN_KEYS)
    for key, (meaning, marks) in table.items():
        assert meaning == TRAIN_KEYS[key], key
        with_option = WITH_AN_OPTION.get(key, ("", ()))[1]
        assert marks == ["x" if key in WRITTEN_BY[algo] else "(x)" if algo in with_option else "-" for algo in columns], key


@pytest.mark.algorithms("all")
def test_custom_logger(tmp_path: pathlib.Path, name: str, episode_steps, make_model) -> None:
    """A logger set with ``set_logger`` is kept by ``learn`` and receives the train/ keys (SB3 tests/test_logger.py)."""
    from stable_baselines3.common.logger import configure

    model = make_model(name)
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(3 * episode_steps, log_interval=1)
    header = (tmp_path / "progress.csv").read_text().splitlines()[0].split(",")
    assert any(key.startswith("train/") for key in header), header


class CountingCallback(BaseCallback):
    def __init__(self) -> None:
        super().__init__()
        self.calls = dict(training_start=0, rollout_start=0, step=0, rollout_end=0, training_end=0)

    def _on_training_start(self) -> None:
        self.calls["training_start"] += 1

    def _on_rollout_start(self) -> None:
        self.calls["rollout_start"] += 1

    def _on_step(self) -> bool:
        self.calls["step"] += 1
        return True

    def _on_rollout_end(self) -> None:
        self.calls["rollout_end"] += 1

    def _on_training_end(self) -> None:
        self.calls["training_end"] += 1


@pytest.mark.algorithms("all")
def test_callbacks(
    tmp_path: pathlib.Path, name: str, episode_steps, off_policy_names, algo_class, make_env, make_model
) -> None:
    model = make_model(name)
    counting = CountingCallback()
    checkpoint = CheckpointCallback(
        save_freq=2 * episode_steps,
        save_path=str(tmp_path / "checkpoints"),
        save_replay_buffer=name in off_policy_names,
    )
    evaluation = EvalCallback(
        make_env(),
        eval_freq=2 * episode_steps,
        n_eval_episodes=1,
        log_path=str(tmp_path / "eval"),
        best_model_save_path=str(tmp_path / "best"),
        warn=False,
    )
    model.learn(4 * episode_steps, callback=CallbackList([counting, checkpoint, evaluation]))

    assert counting.calls["step"] == model.num_timesteps == 4 * episode_steps
    assert counting.calls["training_start"] == counting.calls["training_end"] == 1
    assert counting.calls["rollout_start"] >= 1 and counting.calls["rollout_end"] >= 1
    for steps in (2 * episode_steps, 4 * episode_steps):
        assert (tmp_path / "checkpoints" / f"rl_model_{steps}_steps.zip").exists()
    if name in off_policy_names:
        assert (tmp_path / "checkpoints" / f"rl_model_replay_buffer_{2 * episode_steps}_steps.pkl").exists()
    loaded = algo_class(name).load(tmp_path / "checkpoints" / f"rl_model_{2 * episode_steps}_steps.zip")
    assert loaded.num_timesteps == 2 * episode_steps
    evaluations = np.load(tmp_path / "eval" / "evaluations.npz")
    np.testing.assert_array_equal(evaluations["timesteps"], [2 * episode_steps, 4 * episode_steps])
    assert (tmp_path / "best" / "best_model.zip").exists()


class StopAfter(BaseCallback):
    def __init__(self, n_calls: int) -> None:
        super().__init__()
        self.limit = n_calls

    def _on_step(self) -> bool:
        return self.n_calls < self.limit


@pytest.mark.algorithms("all")
def test_callback_stops_training(name: str, episode_steps, make_model) -> None:
    model = make_model(name)
    model.learn(10 * episode_steps, callback=StopAfter(episode_steps + 5))
    assert model.num_timesteps == episode_steps + 5


@pytest.mark.algorithms("all")
def test_stop_on_max_episodes(name: str, episode_steps, make_model) -> None:
    """SB3's StopTrainingOnMaxEpisodes reads ``locals["dones"]``: every training loop must expose it."""
    model = make_model(name)
    model.learn(10 * episode_steps, callback=StopTrainingOnMaxEpisodes(max_episodes=2))
    assert model.num_timesteps == 2 * episode_steps


@pytest.mark.filterwarnings("error::tqdm.TqdmExperimentalWarning")
@pytest.mark.algorithms("all")
def test_progress_bar(name: str, monkeypatch: pytest.MonkeyPatch, episode_steps, make_model) -> None:
    """SB3's progress bar, without tqdm's "rich is experimental" warning: the bar is created and counts every step."""
    from sb3_denfac.common.callbacks import ProgressBarCallback

    bars: list[tuple[float, float]] = []
    close = SB3ProgressBarCallback._on_training_end

    def record_then_close(self) -> None:
        bars.append((self.pbar.n, self.pbar.total))
        close(self)

    monkeypatch.setattr(SB3ProgressBarCallback, "_on_training_end", record_then_close)
    model = make_model(name)
    model.learn(2 * episode_steps, progress_bar=True)
    assert model.num_timesteps == 2 * episode_steps
    assert bars == [(2 * episode_steps, 2 * episode_steps)]
    assert issubclass(ProgressBarCallback, SB3ProgressBarCallback)


def test_progress_bar_counts_episodes_when_budgeted_in_episodes(episode_steps, make_model) -> None:
    """Episodes that end early (CartPole failures) still fill a bar budgeted in episodes."""
    from sb3_denfac.common.callbacks import ProgressBarCallback

    horizon = 5 * episode_steps
    env = gym.make("sb3_denfac/ContinuousCartPole-v0", max_episode_steps=horizon, random_start=True)
    model = make_model("denfac", env=env, buffer_size=4 * horizon, seed=0)
    bar = ProgressBarCallback(max_episodes=3)
    model.learn(3 * horizon, callback=[StopTrainingOnMaxEpisodes(max_episodes=3), bar])
    assert model.num_timesteps < 3 * horizon, "the test needs episodes that end early"
    assert bar.pbar.n == bar.pbar.total == 3
