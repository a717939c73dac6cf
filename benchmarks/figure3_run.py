"""One benchmark run: train ``ALGO("MlpPolicy", env, **hyperparams)`` for a budget of episodes and record every episode.

Per episode (``EpisodePerformanceCallback``): the paper's measure, its best so far, the return, the length, the step
count; plus (:class:`RunClock`) the run's CPU seconds so far. Every ``eval_every`` episodes, and at the last one, the
policy that played the episode is evaluated deterministically on a separate env for ``eval_episodes`` episodes; the
evaluation's own CPU time is left out of the run's CPU seconds.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import platform
import subprocess
import time
import traceback
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

_REPO = Path(__file__).resolve().parent.parent


def evaluate(model: Any, env: Any, n_episodes: int) -> list[float]:
    """The measure of ``n_episodes`` deterministic episodes (``info["paper_performance"]``, else the return)."""
    scores = []
    for _ in range(n_episodes):
        obs, _ = env.reset()
        done, ret, info = False, 0.0, {}
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, info = env.step(action)
            ret += float(reward)
            done = terminated or truncated
        scores.append(float(info.get("paper_performance", ret)))
    return scores


class RunClock(BaseCallback):
    """CPU seconds of the training process at each episode end, and the periodic deterministic evaluations.

    :param eval_env: env for the evaluations (``None``: no evaluation).
    :param eval_every: evaluate after every ``eval_every``-th episode and after episode ``max_episodes``.
    """

    def __init__(self, eval_env: Any = None, eval_every: int = 10, eval_episodes: int = 1, max_episodes: int = 0):
        super().__init__()
        self.eval_env, self.eval_every, self.eval_episodes, self.max_episodes = (
            eval_env,
            eval_every,
            eval_episodes,
            max_episodes,
        )
        self.cpu_times: list[float] = []  # cumulative training CPU seconds at each episode end
        self.evaluations: list[dict[str, Any]] = []
        self._start = 0.0
        self.eval_cpu_time = 0.0

    def _on_training_start(self) -> None:
        self._start = time.process_time()

    def _on_step(self) -> bool:
        for done in self.locals["dones"]:
            if not done:
                continue
            self.cpu_times.append(time.process_time() - self._start - self.eval_cpu_time)
            episode = len(self.cpu_times)
            if self.eval_env is not None and (episode % self.eval_every == 0 or episode == self.max_episodes):
                before = time.process_time()
                scores = evaluate(self.model, self.eval_env, self.eval_episodes)
                self.eval_cpu_time += time.process_time() - before
                self.evaluations.append({"episode": episode, "scores": scores})
        return True


def git_state() -> dict[str, Any]:
    git: dict[str, Any] = {}
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        run = functools.partial(subprocess.run, cwd=_REPO, capture_output=True, text=True, timeout=10, check=True)
        git["commit"] = run(["git", "rev-parse", "HEAD"]).stdout.strip()
        # the code actually run: uncommitted changes to the package and the benchmark are listed
        git["modified"] = run(["git", "status", "--porcelain", "--", "sb3_denfac", "benchmarks/*.py"]).stdout.splitlines()
    return git


def machine_info() -> dict[str, Any]:
    import torch

    cpu = ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    return {
        "host": platform.node(),
        "nproc": os.cpu_count(),
        "cpu_model": cpu or platform.processor(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        "platform": platform.platform(),
    }


def run_one(task: dict[str, Any]) -> dict[str, Any]:
    """One (algo, env, seed) run of ``task["zoo_algo"]`` with ``task["hyperparams"]`` (needs only the installed package).

    Returns ``{"task", "meta", "episodes", "log"}`` or ``{"task", "error", "log"}``."""
    import torch

    torch.set_num_threads(1)
    log = io.StringIO()
    load_start = os.getloadavg()
    try:
        with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            import gymnasium as gym
            from stable_baselines3.common.callbacks import CallbackList

            import sb3_denfac  # noqa: F401  (registers the paper's envs)
            from sb3_denfac.common.callbacks import EpisodePerformanceCallback
            from sb3_denfac.envs.facts import env_facts
            from sb3_denfac.zoo import make_model

            facts = env_facts(task["env"])
            hyperparams, source = task["hyperparams"], task["hyperparams_source"]
            start, cpu_start = time.perf_counter(), time.process_time()
            model = make_model(task["zoo_algo"], facts.gym_id, hyperparams, seed=task["seed"], device="cpu")
            eval_env = gym.make(facts.gym_id, **task.get("eval_kwargs", {})) if task["eval_episodes"] > 0 else None
            if eval_env is not None:
                eval_env.reset(seed=10_000 + task["seed"])
            performance = EpisodePerformanceCallback(max_episodes=task["episodes"], lower_is_better=facts.lower_is_better)
            clock = RunClock(eval_env, task["eval_every"], task["eval_episodes"], task["episodes"])
            max_steps = gym.spec(facts.gym_id).max_episode_steps or 10_000
            # The step budget only guards against a run that never ends an episode; the episode budget stops training.
            model.learn(total_timesteps=task["episodes"] * max_steps + 1, callback=CallbackList([performance, clock]))
            wall_time, cpu_time = time.perf_counter() - start, time.process_time() - cpu_start - clock.eval_cpu_time
            model.get_env().close()
            if eval_env is not None:
                eval_env.close()
    except Exception:
        return {"task": task, "error": traceback.format_exc(), "log": log.getvalue()}
    episodes = performance.records[: task["episodes"]]
    for record, cpu in zip(episodes, clock.cpu_times, strict=False):
        record["cpu_time"] = cpu
    meta = {
        **{k: task[k] for k in ("algo", "env", "seed", "eval_every", "eval_episodes")},
        "eval_kwargs": task.get("eval_kwargs", {}),
        "zoo_algo": task["zoo_algo"],
        "gym_id": facts.gym_id,
        "episodes_requested": task["episodes"],
        "episodes": len(episodes),
        "timesteps": int(model.num_timesteps),
        "wall_time": wall_time,
        "cpu_time": cpu_time,
        "eval_cpu_time": clock.eval_cpu_time,
        "evaluations": clock.evaluations,
        "hyperparams_source": source,
        "hyperparams": {k: repr(v) for k, v in hyperparams.items()},
        "lower_is_better": facts.lower_is_better,
        "git": task.get("git") or git_state(),
        "machine": machine_info(),
        "load_average": {"start": load_start, "end": os.getloadavg()},
        "finished_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    return {"task": task, "meta": meta, "episodes": episodes, "log": log.getvalue()}
