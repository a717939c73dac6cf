"""A benchmark run's checkpoints: saved after an episode's update every so many seconds, and resumed by a rerun.

:class:`RunCheckpoint` saves the run (SB3's own files and the run's records so far) into one folder per cell
(:func:`checkpoint_folder`); :func:`resume_or_start` gives the run back its model, replay buffer and normalisation
statistics from there (:func:`resume_model`) and its callbacks their records (:func:`restore_callbacks`), or starts it
afresh where the checkpoint does not fit. ``benchmarks.runner.task.run_one`` uses them.
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback


def replace_file(path: Path, data: bytes) -> None:
    """Write ``data`` aside, then rename it over ``path``: a reader or a kill never sees half a file."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


class RunCheckpoint(BaseCallback):
    """Save the run so far into ``folder`` at the first point after an episode's update once ``every`` seconds (wall)
    have passed since the last save, so that a run killed with its sweep resumes there (:func:`load_checkpoint`).

    A checkpoint is SB3's own files (``model.save``, ``save_replay_buffer``, ``VecNormalize.save``) and ``state.pkl``,
    the run's records so far (``state()``). Each save writes new files, then replaces ``state.pkl`` (which names them),
    then removes the old ones: a kill at any point leaves the previous checkpoint or the new one whole."""

    def __init__(self, folder: Path, every: float, state: Any, clock: Any = None) -> None:
        """``state()``: the run's records to save beside the model; ``clock``: a ``benchmarks.runner.task.RunClock``, whose
        ``checkpoint_cpu_time`` counts the saves' CPU seconds (left out of the run's)."""
        super().__init__()
        self.folder, self.every, self.state, self.clock = Path(folder), every, state, clock
        self._last, self._episode_ended, self.saves = time.perf_counter(), False, 0

    def _on_step(self) -> bool:
        # the rollout's last step ended an episode (a rollout that stops mid-episode, CACLA's n_steps, is no point to
        # resume from: the env restarts on a resume)
        self._episode_ended = bool(all(self.locals["dones"]))
        return True

    def _on_rollout_start(self) -> None:  # after the update that followed the last rollout
        if self._episode_ended and time.perf_counter() - self._last >= self.every:
            before = time.process_time()
            try:
                self.save()
            except Exception as error:  # noqa: BLE001  (a run that cannot be saved still trains; it is redone if killed)
                print(f"checkpoints off for this run: {type(error).__name__}: {error}")
                self.every = float("inf")
            if self.clock is not None:  # not training: left out of the run's CPU seconds, as evaluations are
                self.clock.checkpoint_cpu_time += time.process_time() - before
        self._episode_ended = False

    def save(self) -> None:
        import pickle

        from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

        self.folder.mkdir(parents=True, exist_ok=True)
        tag = f"{self.model.num_timesteps}"
        files = {"model": f"model_{tag}.zip"}
        self.model.save(self.folder / files["model"])
        if isinstance(self.model, OffPolicyAlgorithm):
            files["replay_buffer"] = f"replay_buffer_{tag}.pkl"
            self.model.save_replay_buffer(self.folder / files["replay_buffer"])
        if self.model.get_vec_normalize_env() is not None:
            files["vec_normalize"] = f"vec_normalize_{tag}.pkl"
            self.model.get_vec_normalize_env().save(str(self.folder / files["vec_normalize"]))
        replace_file(self.folder / "state.pkl", pickle.dumps({**self.state(), "files": files}))
        for path in self.folder.iterdir():  # the last checkpoint's, and any left by a save a kill cut short
            if path.name != "state.pkl" and path.name not in files.values():
                path.unlink(missing_ok=True)
        self._last, self.saves = time.perf_counter(), self.saves + 1


def load_checkpoint(folder: Path | None) -> dict[str, Any] | None:
    """The state a :class:`RunCheckpoint` saved in ``folder`` (None: no checkpoint there)."""
    import pickle

    path = None if folder is None else Path(folder) / "state.pkl"
    return pickle.loads(path.read_bytes()) if path is not None and path.exists() else None


def checkpoint_folder(task: dict[str, Any]) -> Path | None:
    """Where the run of ``task`` keeps its checkpoint: one folder per cell under ``task["checkpoint_dir"]``."""
    if not task.get("checkpoint_dir"):
        return None
    budget = f"{task['timesteps']}steps" if task.get("timesteps") else task["episodes"]
    return Path(task["checkpoint_dir"]) / f"{task['algo'].replace(':', '-')}_{task['env']}_{task['seed']}_{budget}"


def resume_model(model: Any, folder: Path, saved: dict[str, Any], device: str) -> Any:
    """The checkpoint's model on the env ``model`` was built with (the same zoo wrappers), its replay buffer and
    normalisation statistics loaded; its next episode starts from a reset (the saved run stopped at an episode end)."""
    env = model.get_env()
    files = saved["files"]
    if "vec_normalize" in files:
        from stable_baselines3.common.vec_env import VecNormalize

        env = VecNormalize.load(str(folder / files["vec_normalize"]), model.get_vec_normalize_env().venv)
    resumed = type(model).load(folder / files["model"], env=env, device=device)
    if "replay_buffer" in files:
        resumed.load_replay_buffer(folder / files["replay_buffer"])
    # load() seeded everything with the run's seed again: the next episodes would replay the first ones' start states
    # and noise. Each resume gets its own streams instead (not an uninterrupted run's, which are not saved).
    if resumed.seed is not None:
        resumed.set_random_seed(resumed.seed + 1_000_003 * (len(saved.get("resumed", [])) + 1))
    resumed._last_obs = None  # learn() resets the env
    return resumed


def restore_callbacks(saved: dict[str, Any], performance: Any, clock: Any, steps: Any, diagnostics: Any) -> dict:
    """Put a checkpoint's records back into the run's callbacks; return what the earlier processes spent."""
    performance.records = list(saved["records"])
    performance._start_time = time.perf_counter() - saved["episodes_wall"]  # the episodes' wall times count on
    clock.cpu_times, clock.evaluations = list(saved["cpu_times"]), list(saved["evaluations"])
    clock.offset = saved["clock_cpu"]  # its training CPU up to the checkpoint, the update after its last episode too
    clock.wall_offset = saved["episodes_wall"]
    steps.denfac_steps, steps._seen_updates = saved["denfac_steps"]
    if diagnostics is not None and saved["diagnostics"] is not None:
        diagnostics.diagnostics.rows = list(saved["diagnostics"])
        diagnostics._last = len(saved["records"])
    last = saved["records"][-1]
    resumed = [*saved["resumed"], {"episodes": len(saved["records"]), "timesteps": last["timesteps"], **saved["where"]}]
    return {**{k: saved[k] for k in ("cpu_time", "wall_time", "eval_cpu_time", "git")}, "resumed": resumed}


def resume_or_start(model: Any, folder: Path | None, settings: dict[str, str], device: str) -> tuple[Any, dict | None]:
    """``model`` resumed from the checkpoint in ``folder`` and its saved state, or ``(model, None)``: no checkpoint, or
    one that was made with other settings or on another device, or that cannot be read (the run starts afresh, its
    log says why, and the stale checkpoint is removed)."""
    try:
        saved = load_checkpoint(folder)
        if saved is None:
            return model, None
        made_on = saved.get("where", {}).get("device")
        if (saved.get("hyperparams"), made_on) != (settings, device):
            reason = f"it was made with other settings or on another device ({made_on})"
        else:
            return resume_model(model, folder, saved, device), saved
    except Exception as error:  # noqa: BLE001  (a truncated file, a library that changed)
        reason = f"it cannot be loaded: {type(error).__name__}: {error}"
    print(f"checkpoint in {folder} ignored, the run starts afresh: {reason}")
    shutil.rmtree(folder, ignore_errors=True)
    return model, None
