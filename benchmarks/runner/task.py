"""One benchmark run (``run_one``): train ``ALGO("MlpPolicy", env, **hyperparams)`` for a budget of episodes, record
every episode.

Per episode (``EpisodePerformanceCallback``): the paper's measure, its best so far, the return, the length, the step
count; plus (:class:`RunClock`) the run's CPU seconds so far. Every ``eval_every`` episodes, and at the last one, the
policy that played the episode is evaluated deterministically on a separate env for ``eval_episodes`` episodes; the
evaluation's own CPU time is left out of the run's CPU seconds.

A run saves checkpoints from which a rerun resumes it (``benchmarks.runner.checkpoints``). With ``BENCHMARK_PROGRESS_DIR``
set, each run also rewrites ``<algo>_<env>_<seed>.json`` there at every episode end (episodes, steps, CPU and wall
seconds so far): how far a run got when a lease or a session ends before it does.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import os
import platform
import subprocess
import time
import traceback
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from benchmarks.runner.algos import register_external
from benchmarks.runner.checkpoints import RunCheckpoint, checkpoint_folder, replace_file, restore_callbacks, resume_or_start
from benchmarks.runner.diagnostics import Diagnostics

_REPO = Path(__file__).resolve().parents[2]


def evaluate(model: Any, env: Any, n_episodes: int) -> list[float]:
    """The measure of ``n_episodes`` deterministic episodes: ``info["paper_performance"]``, else ``info["is_success"]``
    (a goal-conditioned env: 1.0 where the goal was reached at the episode's end), else the return. A model trained
    on a ``VecNormalize`` env (a zoo entry's ``normalize``) sees the observations normalised with its statistics."""
    normalizer = model.get_vec_normalize_env()
    scores = []
    for _ in range(n_episodes):
        obs, _ = env.reset()
        done, ret, info = False, 0.0, {}
        while not done:
            action, _ = model.predict(obs if normalizer is None else normalizer.normalize_obs(obs), deterministic=True)
            obs, reward, terminated, truncated, info = env.step(action)
            ret += float(reward)
            done = terminated or truncated
        scores.append(float(info.get("paper_performance", info.get("is_success", ret))))
    return scores


class RunClock(BaseCallback):
    """CPU seconds of the training process at each episode end, and the periodic deterministic evaluations.

    :param eval_env: env for the evaluations (``None``: no evaluation).
    :param eval_every: evaluate after every ``eval_every``-th episode and after episode ``max_episodes``; with
        ``in_steps``, at the first episode end at or after every multiple of ``eval_every`` env steps (the run then
        calls :meth:`evaluate` once more at its budget).
    """

    def __init__(
        self,
        eval_env: Any = None,
        eval_every: int = 10,
        eval_episodes: int = 1,
        max_episodes: int = 0,
        progress_path: Path | None = None,
        in_steps: bool = False,
    ):
        super().__init__()
        self.progress_path, self.in_steps = progress_path, in_steps
        self.eval_env, self.eval_every, self.eval_episodes, self.max_episodes = (
            eval_env,
            eval_every,
            eval_episodes,
            max_episodes,
        )
        self.cpu_times: list[float] = []  # cumulative training CPU seconds at each episode end
        self.evaluations: list[dict[str, Any]] = []
        self._start = self._wall_start = 0.0
        self.eval_cpu_time = 0.0  # this process's evaluations
        self.checkpoint_cpu_time = 0.0  # this process's checkpoints (RunCheckpoint)
        self.offset = self.wall_offset = 0.0  # training CPU and wall seconds of the processes before (a resumed run)

    def training_cpu(self) -> float:
        """Training CPU seconds so far, the earlier processes' included; evaluations and checkpoints left out."""
        return time.process_time() - self._start - self.eval_cpu_time - self.checkpoint_cpu_time + self.offset

    def _on_training_start(self) -> None:
        self._start, self._wall_start = time.process_time(), time.perf_counter()

    def _on_step(self) -> bool:
        for done in self.locals["dones"]:
            if not done:
                continue
            self.cpu_times.append(self.training_cpu())
            episode = len(self.cpu_times)
            if self.in_steps:  # the evaluation at the budget comes after learn() returns, after the last update
                due = self.next_evaluation_step() <= self.num_timesteps < self.model._total_timesteps
            else:
                due = episode % self.eval_every == 0 or episode == self.max_episodes
            if self.eval_env is not None and due:
                self.evaluate()
            if self.progress_path is not None:
                progress = {"episodes": episode, "timesteps": self.num_timesteps, "cpu_time": self.cpu_times[-1]}
                progress["wall_time"] = time.perf_counter() - self._wall_start + self.wall_offset
                replace_file(self.progress_path, json.dumps(progress).encode())
        return True

    def next_evaluation_step(self) -> int:
        """The env step count of the next evaluation of a step budget: the first multiple of ``eval_every`` past the
        last evaluation (read from ``evaluations``, so a resumed run goes on where it stopped)."""
        last = self.evaluations[-1]["timesteps"] if self.evaluations else 0
        return (last // self.eval_every + 1) * self.eval_every

    def evaluate(self) -> None:
        """Evaluate the policy now (its CPU seconds left out of training's), recorded with the episode and step."""
        before = time.process_time()
        scores = evaluate(self.model, self.eval_env, self.eval_episodes)
        self.eval_cpu_time += time.process_time() - before
        self.evaluations.append({"episode": len(self.cpu_times), "timesteps": int(self.model.num_timesteps), "scores": scores})


def git_state() -> dict[str, Any]:
    """The commit run and the benchmark's uncommitted changes; or the commit given in ``BENCHMARK_GIT_COMMIT``, for a
    tree that travelled without its own ``.git`` (a lent GPU machine's copy holds an older snapshot's)."""
    if os.environ.get("BENCHMARK_GIT_COMMIT"):  # given: it wins over a .git that may be another snapshot's
        return {"commit": os.environ["BENCHMARK_GIT_COMMIT"], "source": "BENCHMARK_GIT_COMMIT"}
    git: dict[str, Any] = {}
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        run = functools.partial(subprocess.run, cwd=_REPO, capture_output=True, text=True, timeout=10, check=True)
        git["commit"] = run(["git", "rev-parse", "HEAD"]).stdout.strip()
        # the code actually run: uncommitted changes to the package and the benchmark are listed
        git["modified"] = run(
            ["git", "status", "--porcelain", "--", "sb3_denfac", "benchmarks/*.py", "hyperparams"]
        ).stdout.splitlines()
    return git


def machine_info(device: str = "cpu") -> dict[str, Any]:
    """The machine a run trained on: host, CPU, torch; and ``device``, with the GPU's name when it is not the CPU."""
    import torch

    cpu = ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    info = {
        "host": platform.node(),
        "nproc": os.cpu_count(),
        "cpu_model": cpu or platform.processor(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        "platform": platform.platform(),
        "device": device,
    }
    if torch.device(device).type == "cuda":
        info["gpu"] = torch.cuda.get_device_name(torch.device(device))
        info["cuda"] = torch.version.cuda
    return info


class GradientSteps(BaseCallback):
    """Critic gradient steps taken so far, for a like-for-like count across algorithms.

    SB3's off-policy algorithms (TD3, SAC, CrossQ, this package's DDPG) count one ``_n_updates`` per critic gradient
    step. DENFAC counts updates (episode ends); each runs K_e fitted iterations of ``critic_steps`` critic steps, read
    from ``model.last_updates`` after every rollout (several updates when an assessment of policy checkpoints held
    them). On-policy and actor-only algorithms have no Q critic: None.
    """

    def __init__(self) -> None:
        super().__init__()
        self.denfac_steps = 0
        self._seen_updates = 0

    def _on_step(self) -> bool:
        return True

    def _on_rollout_start(self) -> None:  # after the update that followed the last rollout
        model = self.model
        if hasattr(model, "n_fitted_iterations") and model._n_updates != self._seen_updates:
            new = [stats for stats in model.last_updates if stats.n_updates > self._seen_updates]
            self.denfac_steps += sum(stats.fitted_iterations for stats in new) * int(model.critic_steps)
            self._seen_updates = model._n_updates

    def total(self) -> int | None:
        from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

        self._on_rollout_start()
        if hasattr(self.model, "n_fitted_iterations"):
            return self.denfac_steps
        return int(self.model._n_updates) if isinstance(self.model, OffPolicyAlgorithm) else None


class DiagnosticsCallback(BaseCallback):
    """Critic-fit diagnostics (``benchmarks.runner.diagnostics``) on the buffer after the update that follows every
    ``every``-th episode (DENFAC rows of the ablation)."""

    def __init__(self, every: int, performance: Any) -> None:
        super().__init__()
        self.diagnostics, self.performance, self._last = Diagnostics(every), performance, 0

    def _on_step(self) -> bool:
        return True

    def _on_rollout_start(self) -> None:
        episode = self.performance.n_episodes
        rb = getattr(self.model, "replay_buffer", None)
        if episode != self._last and episode % self.diagnostics.every == 0 and rb is not None and rb.size() > 1:
            self.diagnostics.measure(self.model, episode)
        self._last = episode


def columns(records: list[dict[str, Any]]) -> dict[str, list[Any]]:
    """Per-episode records -> per-field columns (the store's compact form)."""
    return {field: [r.get(field) for r in records] for field in EPISODE_FIELDS}


EPISODE_FIELDS = ("episode", "performance", "best_so_far", "return", "length", "timesteps", "wall_time", "cpu_time")


def run_key(task: dict[str, Any]) -> dict[str, Any]:
    """What identifies a run's cell in its record: row, env, seed and budget (``timesteps_requested`` only for a budget
    of env steps, so records of episode budgets keep their shape)."""
    key = {**{k: task[k] for k in ("algo", "env", "seed")}, "episodes_requested": task["episodes"]}
    return {**key, "timesteps_requested": task["timesteps"]} if task.get("timesteps") else key


def run_one(task: dict[str, Any]) -> dict[str, Any]:
    """One (algo, env, seed) run of ``task["zoo_algo"]`` with ``task["hyperparams"]`` (needs only the installed package).

    Returns the run's record for ``benchmarks.runner.store``: ``status`` ``"done"`` with its metadata, per-episode columns,
    critic-fit diagnostics (if ``task["diagnostics_every"]``) and log; or ``"failed"`` with the traceback."""
    import torch

    torch.set_num_threads(1)
    log = io.StringIO()
    load_start = os.getloadavg()
    key = run_key(task)
    device = task.get("device", "cpu")  # "cuda": the networks on the GPU; CPU seconds then leave out the GPU's work
    try:
        with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            import gymnasium as gym
            from stable_baselines3.common.callbacks import CallbackList

            import sb3_denfac  # noqa: F401  (registers the paper's envs)
            from sb3_denfac.common.callbacks import EpisodePerformanceCallback
            from sb3_denfac.envs.facts import env_facts
            from sb3_denfac.zoo import make_model

            register_external(task["zoo_algo"])  # a peer from outside the RL Zoo's registry (sbx)
            facts = env_facts(task["env"])
            hyperparams, source = task["hyperparams"], task["hyperparams_source"]
            start, cpu_start = time.perf_counter(), time.process_time()
            model = make_model(task["zoo_algo"], facts.gym_id, hyperparams, seed=task["seed"], device=device)
            folder = checkpoint_folder(task)
            settings = {k: repr(v) for k, v in hyperparams.items()}
            model, saved = resume_or_start(model, folder, settings, device)
            eval_env = gym.make(facts.gym_id, **task.get("eval_kwargs", {})) if task["eval_episodes"] > 0 else None
            if eval_env is not None:
                eval_env.reset(seed=10_000 + task["seed"])
            step_budget = task.get("timesteps")
            max_episodes = None if step_budget else task["episodes"]
            performance = EpisodePerformanceCallback(max_episodes=max_episodes, lower_is_better=facts.lower_is_better)
            progress = os.environ.get("BENCHMARK_PROGRESS_DIR")
            progress_path = Path(progress) / f"{task['algo']}_{task['env']}_{task['seed']}.json" if progress else None
            if progress_path is not None:
                progress_path.parent.mkdir(parents=True, exist_ok=True)
            clock = RunClock(
                eval_env, task["eval_every"], task["eval_episodes"], task["episodes"], progress_path, bool(step_budget)
            )
            steps = GradientSteps()
            callbacks = [performance, clock, steps]
            diagnose = bool(task.get("diagnostics_every")) and hasattr(model, "n_fitted_iterations")  # DENFAC's buffer
            if diagnose:
                diagnostics = DiagnosticsCallback(task["diagnostics_every"], performance)
                callbacks.append(diagnostics)
            earlier = {"cpu_time": 0.0, "wall_time": 0.0, "eval_cpu_time": 0.0, "resumed": [], "git": None}

            def excluded() -> float:  # this process's CPU seconds that are not training
                return clock.eval_cpu_time + clock.checkpoint_cpu_time

            if saved is not None:
                earlier = restore_callbacks(saved, performance, clock, steps, diagnostics if diagnose else None)

            def state() -> dict[str, Any]:  # the run so far, for its checkpoint
                return {
                    "key": key,
                    "hyperparams": settings,
                    "where": {"device": device, "host": platform.node()},
                    "episodes_wall": time.perf_counter() - performance._start_time,
                    "cpu_time": time.process_time() - cpu_start - excluded() + earlier["cpu_time"],
                    "wall_time": time.perf_counter() - start + earlier["wall_time"],
                    "eval_cpu_time": clock.eval_cpu_time + earlier["eval_cpu_time"],
                    "records": performance.records,
                    "cpu_times": clock.cpu_times,
                    "clock_cpu": clock.training_cpu(),
                    "evaluations": clock.evaluations,
                    "denfac_steps": (steps.denfac_steps, steps._seen_updates),
                    "diagnostics": diagnostics.diagnostics.rows if diagnose else None,
                    "resumed": earlier["resumed"],
                    "git": earlier["git"] or task.get("git"),
                }

            if folder is not None and task.get("checkpoint_every") is not None:
                callbacks.append(RunCheckpoint(folder, task["checkpoint_every"], state, clock))
            max_steps = gym.spec(facts.gym_id).max_episode_steps or 10_000
            # The step budget only guards against a run that never ends an episode; the episode budget stops training.
            # A resumed run's learn() counts on from its saved steps to the same total.
            total = step_budget or task["episodes"] * max_steps + 1
            model.learn(total - model.num_timesteps, callback=CallbackList(callbacks), reset_num_timesteps=saved is None)
            last = clock.evaluations[-1]["timesteps"] if clock.evaluations else -1
            if step_budget and eval_env is not None and last < model.num_timesteps:
                clock.evaluate()  # the policy at the budget (learn stops there, inside an episode, after its update)
            wall_time = time.perf_counter() - start + earlier["wall_time"]
            cpu_time = time.process_time() - cpu_start - excluded() + earlier["cpu_time"]
            model.get_env().close()
            if eval_env is not None:
                eval_env.close()
    except Exception:
        return {**key, "status": "failed", "error": traceback.format_exc(), "log": log.getvalue(), "task": task}
    episodes = performance.records[: task["episodes"] or None]
    for record, cpu in zip(episodes, clock.cpu_times, strict=False):
        record["cpu_time"] = cpu
    return {
        **key,
        "status": "done",
        **{k: task[k] for k in ("eval_every", "eval_episodes")},
        "eval_kwargs": task.get("eval_kwargs", {}),
        "zoo_algo": task["zoo_algo"],
        "gym_id": facts.gym_id,
        "n_episodes": len(episodes),
        "timesteps": int(model.num_timesteps),
        "gradient_steps": steps.total(),
        "wall_time": wall_time,
        "cpu_time": cpu_time,
        "eval_cpu_time": clock.eval_cpu_time + earlier["eval_cpu_time"],
        "checkpoint_cpu_time": clock.checkpoint_cpu_time,
        "evaluations": clock.evaluations,
        "hyperparams_source": source,
        "hyperparams": settings,
        "lower_is_better": facts.lower_is_better,
        "git": earlier["git"] or task.get("git") or git_state(),
        **({"resumed": earlier["resumed"], "git_resumed": task.get("git")} if earlier["resumed"] else {}),
        "machine": machine_info(device),
        "load_average": {"start": load_start, "end": os.getloadavg()},
        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "episodes": columns(episodes),
        **({"diagnostics": diagnostics.diagnostics.rows} if diagnose else {}),
        "log": log.getvalue()[-20_000:],
    }
