"""Nothing lost on a kill: a DENFAC run with SB3's CheckpointCallback is SIGKILLed mid-way; a new process continues
from the last checkpoint (model, replay buffer with the behaviour means, step counters) and keeps learning."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.monitor import Monitor

from sb3_denfac import DENFAC

EPISODE = 50
SAVE_FREQ = 100  # steps: a checkpoint every second episode

CHILD = textwrap.dedent(
    f"""
    import os, sys
    import gymnasium as gym
    import numpy as np
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback
    from sb3_denfac import DENFAC

    folder = sys.argv[1]

    class RecordSaved(BaseCallback):
        # After CheckpointCallback (same frequency): what the checkpoint holds, written independently (atomically).
        def _on_step(self):
            if self.n_calls % {SAVE_FREQ} == 0:
                buffer = self.model.replay_buffer
                path = os.path.join(folder, f"state_{{self.num_timesteps}}.npz")
                np.savez(path + ".tmp.npz", pos=buffer.pos, full=buffer.full, observations=buffer.observations,
                         actions=buffer.actions, rewards=buffer.rewards, behaviour_means=buffer.behaviour_means,
                         n_updates=self.model._n_updates, episode_num=self.model._episode_num)
                os.replace(path + ".tmp.npz", path)
            return True

    model = DENFAC("MlpPolicy", gym.make("Pendulum-v1", max_episode_steps={EPISODE}), seed=0, n_fitted_iterations=2,
                   critic_steps=3, actor_steps=3, batch_size=32, policy_kwargs=dict(net_arch=dict(pi=[8], qf=[8])))
    checkpoints = CheckpointCallback({SAVE_FREQ}, folder, save_replay_buffer=True)
    model.learn(10_000_000, callback=CallbackList([checkpoints, RecordSaved()]))
    """
)


def _step_of(path: Path) -> int:
    return int(re.search(r"_(\d+)_steps", path.name).group(1))


@pytest.mark.timeout(120)
def test_sigkill_then_resume_from_the_last_checkpoint(tmp_path: Path) -> None:
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    child = subprocess.Popen([sys.executable, str(script), str(tmp_path)], env=env, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 90
        while len(list(tmp_path.glob("state_*.npz"))) < 3:  # three checkpoints written: kill during the run
            assert child.poll() is None, child.stderr.read().decode()
            assert time.monotonic() < deadline, "the child wrote no checkpoints in time"
            time.sleep(0.2)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
        child.stderr.close()
    assert child.returncode == -signal.SIGKILL

    # The newest checkpoint whose model, buffer and record are complete (one being written at the kill is skipped).
    steps = sorted({_step_of(p) for p in tmp_path.glob("rl_model_*_steps.zip")}, reverse=True)
    complete = [
        s
        for s in steps
        if (tmp_path / f"rl_model_replay_buffer_{s}_steps.pkl").is_file() and (tmp_path / f"state_{s}.npz").is_file()
    ]
    assert len(complete) >= 2
    step = complete[0]
    saved = np.load(tmp_path / f"state_{step}.npz")

    model = DENFAC.load(
        tmp_path / f"rl_model_{step}_steps.zip", env=Monitor(gym.make("Pendulum-v1", max_episode_steps=EPISODE))
    )
    model.load_replay_buffer(tmp_path / f"rl_model_replay_buffer_{step}_steps.pkl")
    buffer = model.replay_buffer
    assert model.num_timesteps == step and model._n_updates == int(saved["n_updates"]) > 0
    assert model._episode_num == int(saved["episode_num"])
    assert buffer.pos == int(saved["pos"]) and buffer.full == bool(saved["full"])
    # exact: stored arrays, saved and read back
    for name in ("observations", "actions", "rewards", "behaviour_means"):
        np.testing.assert_array_equal(getattr(buffer, name), saved[name], err_msg=name)
    assert np.isfinite(buffer.behaviour_means[: buffer.pos]).all() and np.abs(buffer.behaviour_means[: buffer.pos]).sum() > 0

    more = 2 * EPISODE
    model.learn(more, reset_num_timesteps=False)
    assert model.num_timesteps == step + more
    assert buffer.pos == int(saved["pos"]) + more  # the new transitions follow the saved ones
    np.testing.assert_array_equal(buffer.observations[: int(saved["pos"])], saved["observations"][: int(saved["pos"])])
    assert model._n_updates == int(saved["n_updates"]) + 2  # one update per new episode
    assert model._episode_num == int(saved["episode_num"]) + 2
    assert len(model.get_env().get_attr("episode_returns")[0]) == 2  # the continued run's episodes are recorded


@pytest.mark.timeout(300)
@pytest.mark.parametrize("algo", ["denfac_default", "td3"])
def test_benchmark_run_killed_mid_way_resumes_from_its_checkpoint(tmp_path: Path, algo: str) -> None:
    """A benchmark run SIGKILLed with its sweep goes on, on the rerun, from its last checkpoint (episode records,
    model, replay buffer, step and update counters) instead of from the start; its whole record matches an
    uninterrupted run's counts."""
    from benchmarks import run as runner
    from benchmarks.runner import store

    episodes = 8
    args = ["--algos", algo, "--envs", "pendulum", "--seeds", "0", "--episodes", str(episodes), "--workers", "0"]
    args += ["--no-analysis", "--checkpoint-every", "0.001"]  # a checkpoint after every episode's update
    killed, whole = tmp_path / "killed", tmp_path / "whole"
    progress = tmp_path / "progress" / f"{algo}_pendulum_0.json"
    env = {**os.environ, "BENCHMARK_PROGRESS_DIR": str(progress.parent), "OMP_NUM_THREADS": "1"}
    progress.parent.mkdir()
    repo = Path(__file__).resolve().parent.parent
    child = subprocess.Popen(
        [sys.executable, "-m", "benchmarks.run", *args, "--results", str(killed)], cwd=repo, env=env,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 240
        while not (progress.exists() and '"episodes": 4' in progress.read_text()):
            assert child.poll() is None, child.stderr.read().decode()
            assert time.monotonic() < deadline, "the run never reached its 4th episode"
            time.sleep(0.05)
    finally:
        os.killpg(child.pid, signal.SIGKILL)
        child.wait()
    (folder,) = (killed / "checkpoints").iterdir()
    from benchmarks.runner.checkpoints import load_checkpoint

    saved = load_checkpoint(folder)
    assert saved is not None and 3 <= len(saved["records"]) < episodes
    assert not store.read_runs(killed)  # the run had not finished
    from benchmarks.runner.algos import ALGOS
    from benchmarks.runner.checkpoints import resume_model
    from benchmarks.runner.hyperparams import load_hyperparams
    from sb3_denfac.zoo import make_model

    fresh = make_model(ALGOS[algo].zoo_algo, "Pendulum-v1", load_hyperparams(algo, "pendulum")[0])
    model = resume_model(fresh, folder, saved, "cpu")  # what the rerun trains on: the killed run's model and data
    steps_then = saved["records"][-1]["timesteps"]
    assert model.num_timesteps == model.replay_buffer.size() == steps_then and model._n_updates > 0

    # the same checkpoint, made (it says) with other settings: ignored, the run starts afresh
    import pickle
    import shutil

    other = tmp_path / "other"
    shutil.copytree(killed / "checkpoints", other / "checkpoints")
    state_file = other / "checkpoints" / folder.name / "state.pkl"
    state_file.write_bytes(pickle.dumps({**saved, "hyperparams": {"learning_rate": "0.5"}}))
    assert runner.main([*args, "--results", str(other)]) == 0
    assert "resumed" not in store.read_runs(other)[0] and "other settings" in store.read_runs(other)[0]["log"]

    assert runner.main([*args, "--results", str(killed)]) == 0
    assert runner.main([*args, "--results", str(whole), "--checkpoint-every", "0"]) == 0
    (resumed,), (uninterrupted,) = store.read_runs(killed), store.read_runs(whole)
    (where,) = resumed["resumed"]
    assert where["episodes"] == len(saved["records"]) and where["timesteps"] == saved["records"][-1]["timesteps"]
    assert where["device"] == "cpu" and where["host"]
    assert "resumed" not in uninterrupted and not (whole / "checkpoints").exists()
    assert not folder.exists()  # the finished run's record replaced its checkpoint
    for field in ("n_episodes", "timesteps", "gradient_steps"):
        assert resumed[field] == uninterrupted[field], field
    n = len(saved["records"])
    assert resumed["episodes"]["return"][:n] == [r["return"] for r in saved["records"]]  # the first process's episodes
    assert resumed["episodes"]["timesteps"] == uninterrupted["episodes"]["timesteps"] == [200 * (i + 1) for i in range(8)]
    for clock in ("cpu_time", "wall_time"):  # counted on across the two processes
        times = resumed["episodes"][clock]
        assert all(b > a for a, b in zip(times, times[1:], strict=False)) and resumed[clock] > saved[clock], clock
    assert resumed["checkpoint_cpu_time"] > 0 and "checkpoint_cpu_time" in uninterrupted
    assert [e["episode"] for e in resumed["evaluations"]] == [8]


@pytest.mark.timeout(300)
@pytest.mark.parametrize("algo", ["denfac", "nfac", "cacla", "cmaes", "ddpg", "sac", "crossq"])
def test_every_benchmark_row_saves_and_resumes_its_run(tmp_path: Path, algo: str) -> None:
    """Each algorithm of the sweep checkpoints after an episode's update and trains on from the checkpoint."""
    from stable_baselines3.common.callbacks import CallbackList

    from benchmarks.runner.algos import ALGOS
    from benchmarks.runner.checkpoints import RunCheckpoint, load_checkpoint, resume_model
    from benchmarks.runner.hyperparams import load_hyperparams
    from sb3_denfac.common.callbacks import EpisodePerformanceCallback
    from sb3_denfac.zoo import make_model

    hyperparams = {**load_hyperparams(algo, "pendulum")[0], "learning_starts": 50}
    if algo not in ("denfac", "ddpg", "sac", "crossq"):
        hyperparams.pop("learning_starts")
    build = lambda: make_model(ALGOS[algo].zoo_algo, "Pendulum-v1", hyperparams, seed=0)  # noqa: E731
    model, performance = build(), EpisodePerformanceCallback(max_episodes=2)
    checkpoint = RunCheckpoint(tmp_path, 0.0, lambda: {"episodes": performance.n_episodes})
    model.learn(10_000, callback=CallbackList([performance, checkpoint]))
    saved = load_checkpoint(tmp_path)
    assert checkpoint.saves >= 1 and saved["episodes"] == 1  # after episode 1's update (episode 2 ends the run)
    resumed = resume_model(build(), tmp_path, saved, "cpu")
    assert resumed.num_timesteps == 200
    resumed.learn(400, callback=EpisodePerformanceCallback(max_episodes=1), reset_num_timesteps=False)
    assert resumed.num_timesteps == 400
