"""Compute cost of one DENFAC end-of-episode update on replay buffers filled by real training episodes.

For each paper env (Figure 5 settings from ``hyperparams/denfac.yml``) and each buffer, it times in one
interleaved run, with the same thread count:

- ``fast``: the :class:`~sb3_denfac.denfac.fast.FastUpdater` (``update_path="fast"``, the default);
- ``autograd``: the :class:`~sb3_denfac.denfac.updaters.AutogradUpdater` (``update_path="plain"``), the reference;
- ``fast_ftz``: the fast updater with ``torch.set_flush_denormal(True)`` around it, which shows whether any
  subnormal arithmetic is left to flush;
- ``floor``: the update's matrix-multiply FLOPs divided by the GFLOP/s of a large matmul timed in the same repeats;
- ``gemms``: the update's matrix products alone, at their own shapes and counts (what BLAS takes for that arithmetic);
- ``ddpg``: SB3 DDPG's ``train()`` for one episode of data (one batch-64 step per transition; x9 with the paper's 8
  additional updates per step), on the same transitions.

Buffers: ``early``, D transitions of real episodes played with uniform warm-up actions (``learning_starts`` beyond the
budget, the first thing a user's run holds); ``trained``, the buffer and networks after ``--episodes`` episodes of
training with the YAML settings (the networks have moved and the data is the actor's own). Both updaters start every
repeat from copies of the same saved model and buffer.

``--training-run`` also times every update of a quickstart-like run (Acrobot, 50 episodes, seed 0) and reports the
median and the slowest.

Results: ``results/update_cost/update_cost.{json,md}``. Usage:
``python -m benchmarks.studies.update_cost [--repeats 9] [--threads 1 2] [--envs acrobot half_cheetah] [--training-run]``
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import tempfile
import time
from collections import Counter
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th

from benchmarks.runner.task import git_state, machine_info

RESULTS = Path(__file__).resolve().parents[1] / "results" / "update_cost"
ENVS = {
    "acrobot": "sb3_denfac/ContinuousAcrobot-v0",
    "cartpole": "sb3_denfac/ContinuousCartPole-v0",
    "half_cheetah": "sb3_denfac/HalfCheetahPaper-v0",
}
TRAINED_EPISODES = {"acrobot": 30, "cartpole": 30, "half_cheetah": 20}
MATMUL_SIZE = 1024  # the "large matmul" whose GFLOP/s defines the arithmetic floor
DDPG_BATCH = 64


def yaml_settings(env_id: str) -> dict:
    from sb3_denfac.zoo import load_hyperparams

    hyperparams = load_hyperparams("denfac", env_id)
    for key in ("n_timesteps", "policy", "monitor_kwargs"):
        hyperparams.pop(key, None)
    return hyperparams


def make_buffers(name: str, folder: Path, episodes: int) -> dict[str, Path]:
    """Saved (model, buffer) pairs for the ``early`` and ``trained`` buffers of one env."""
    from sb3_denfac import DENFAC
    from sb3_denfac.common.callbacks import EpisodePerformanceCallback

    env_id, settings = ENVS[name], yaml_settings(ENVS[name])
    out = {}
    early = DENFAC("MlpPolicy", gym.make(env_id), learning_starts=10**9, seed=0, **settings)
    early.learn(settings["buffer_size"])
    trained = DENFAC("MlpPolicy", gym.make(env_id), seed=0, **settings)
    trained.learn(10**8, callback=EpisodePerformanceCallback(max_episodes=episodes))
    for tag, model in (("early", early), ("trained", trained)):
        model.save(folder / f"{name}_{tag}.zip")
        model.save_replay_buffer(folder / f"{name}_{tag}_buffer.pkl")
        out[tag] = folder / f"{name}_{tag}"
    return out


def load_denfac(path: Path, update_path: str):
    from stable_baselines3.common.logger import configure

    from sb3_denfac import DENFAC

    model = DENFAC.load(f"{path}.zip", update_path=update_path)
    model.load_replay_buffer(f"{path}_buffer.pkl")
    model.set_logger(configure(None, []))
    return model


@contextlib.contextmanager
def flush_denormal():
    """Flush-to-zero for the block only (``set_flush_denormal`` has no getter: the default, off, is restored)."""
    th.set_flush_denormal(True)
    try:
        yield
    finally:
        th.set_flush_denormal(False)


# ----- arithmetic floor ----------------------------------------------------------------------------------------------
def mlp_matmuls(n: int, sizes: list[int], weight_grad: bool, input_grad_from: int | None) -> list[tuple[int, int, int]]:
    """The (m, k, p) products (m x k @ k x p, feature-major as the fast updater) of an MLP pass over n samples:
    forward W X, optionally the weight gradient G X^T and the input gradient W^T G of layers >= ``input_grad_from``."""
    shapes = []
    for i in range(len(sizes) - 1):
        fan_in, fan_out = sizes[i], sizes[i + 1]
        shapes.append((fan_out, fan_in, n))
        if weight_grad:
            shapes.append((fan_out, n, fan_in))
        if input_grad_from is not None and i >= input_grad_from:
            shapes.append((fan_in, fan_out, n))
    return shapes


def update_matmuls(model) -> Counter:
    """The matrix products of one update of ``model`` (full batch over its buffer), with their counts."""
    n = model.replay_buffer.size()
    o, a = model.observation_space.shape[0], model.action_space.shape[0]
    arch = model.policy.net_arch
    actor, critic = [o, *arch["pi"], a], [o + a, *arch["qf"], 1]
    hidden = arch["qf"][0]
    targets = 2 * mlp_matmuls(n, actor, False, None) + mlp_matmuls(n, critic, False, None)
    critic_step = mlp_matmuls(n, critic, True, 1)
    # actor step: actor forward + backward, critic forward + d/d action. The critic's first layer only through its
    # action columns (forward and input gradient): its observation part is fixed over the G steps, once per iteration.
    actor_step = mlp_matmuls(n, actor, True, 1) + [(hidden, a, n), (a, hidden, n)] + mlp_matmuls(n, critic[1:], False, 0)
    per_iteration = targets + [(hidden, o, n)] + model.critic_steps * critic_step + model.actor_steps * actor_step
    return Counter({shape: count * model.n_fitted_iterations for shape, count in Counter(per_iteration).items()})


def matmul_flops(shapes: Counter) -> float:
    return float(sum(2 * m * k * p * count for (m, k, p), count in shapes.items()))


def matmul_replay(shapes: Counter) -> callable:
    """Only the update's matrix products, at its shapes and counts (random operands, preallocated outputs)."""
    operands = [(th.randn(m, k), th.randn(k, p), th.empty(m, p), count) for (m, k, p), count in shapes.items()]

    def replay() -> None:
        for left, right, out, count in operands:
            for _ in range(count):
                th.mm(left, right, out=out)

    return replay


# ----- SB3 DDPG ------------------------------------------------------------------------------------------------------
def ddpg_episode(denfac, env_id: str) -> callable:
    """SB3 DDPG's train() for one episode of data, its buffer holding the DENFAC buffer's transitions."""
    from stable_baselines3 import DDPG
    from stable_baselines3.common.logger import configure

    rb_src = denfac.replay_buffer
    env = gym.make(env_id)
    arch = denfac.policy.net_arch
    model = DDPG(
        "MlpPolicy",
        env,
        buffer_size=rb_src.buffer_size,
        batch_size=DDPG_BATCH,
        learning_starts=0,
        policy_kwargs=dict(net_arch=dict(pi=arch["pi"], qf=arch["qf"])),
        seed=0,
    )
    model.set_logger(configure(None, []))
    rb = model.replay_buffer
    for key in ("observations", "next_observations", "actions", "rewards", "dones"):
        getattr(rb, key)[:] = getattr(rb_src, key)
    rb.full, rb.pos = rb_src.full, rb_src.pos
    return lambda: model.train(gradient_steps=env.spec.max_episode_steps, batch_size=DDPG_BATCH)


def time_buffer(path: Path, env_id: str, repeats: int) -> dict:
    """Interleaved medians of every variant for one saved buffer at the current thread count."""
    models = {key: load_denfac(path, update_path) for key, update_path in (("fast", "fast"), ("autograd", "plain"))}
    models["fast_ftz"] = load_denfac(path, "fast")
    big = (th.randn(MATMUL_SIZE, MATMUL_SIZE), th.randn(MATMUL_SIZE, MATMUL_SIZE))
    shapes = update_matmuls(models["fast"])

    def fast_ftz():
        with flush_denormal():
            models["fast_ftz"]._update()

    variants = dict(
        fast=models["fast"]._update,
        autograd=models["autograd"]._update,
        fast_ftz=fast_ftz,
        ddpg=ddpg_episode(models["fast"], env_id),
        matmul=lambda: big[0] @ big[1],
        gemms=matmul_replay(shapes),
    )
    times: dict[str, list[float]] = {k: [] for k in variants}
    for fn in variants.values():
        fn()  # warm-up
    for _ in range(repeats):  # interleaved: load changes on the shared machine hit every variant
        for key, fn in variants.items():
            start = time.perf_counter()
            fn()
            times[key].append(time.perf_counter() - start)
    med = {k: float(np.median(v)) for k, v in times.items()}
    gflops = 2 * MATMUL_SIZE**3 / med["matmul"] / 1e9
    flops = matmul_flops(shapes)
    floor = flops / (gflops * 1e9)
    return dict(
        buffer_size=models["fast"].replay_buffer.size(),
        threads=th.get_num_threads(),
        update_gflop=flops / 1e9,
        matmul_gflops_per_s=gflops,
        floor_s=floor,
        fast_s=med["fast"],
        autograd_s=med["autograd"],
        fast_ftz_s=med["fast_ftz"],
        ddpg_episode_s=med["ddpg"],
        autograd_over_fast=med["autograd"] / med["fast"],
        fast_over_floor=med["fast"] / floor,
        gemms_s=med["gemms"],
        gemms_over_floor=med["gemms"] / floor,
        fast_over_gemms=med["fast"] / med["gemms"],
        fast_over_fast_ftz=med["fast"] / med["fast_ftz"],
        times_s=times,
    )


def training_run(episodes: int = 50) -> dict:
    """Every update's wall time in a quickstart-like run (Acrobot, Figure 5 settings, seed 0, current threads)."""
    from sb3_denfac import DENFAC
    from sb3_denfac.common.callbacks import EpisodePerformanceCallback, UpdateStatsCallback

    model = DENFAC("MlpPolicy", gym.make(ENVS["acrobot"]), seed=0, **yaml_settings(ENVS["acrobot"]))
    durations: list[float] = []
    update_times = UpdateStatsCallback(lambda stats: durations.append(stats.seconds))
    model.learn(10**8, callback=[EpisodePerformanceCallback(max_episodes=episodes), update_times])
    full = durations[-(len(durations) // 2) :]  # the buffer is full (D = 6000) well before the second half
    return dict(
        episodes=episodes,
        threads=th.get_num_threads(),
        update_s=durations,
        median_s=float(np.median(durations)),
        max_s=float(np.max(durations)),
        max_over_median=float(np.max(durations) / np.median(durations)),
        second_half_max_over_median=float(np.max(full) / np.median(full)),
    )


def write_markdown(results: dict) -> str:
    meta = results["meta"]
    lines = [
        "# Cost of one DENFAC update on real replay buffers (Figure 5 settings, full batch)",
        "",
        f"{meta['machine']}; torch {meta['torch']}; commit {meta['commit']}; medians of {meta['repeats']} interleaved "
        f"repeats; load average {meta['load_average'][0]:.1f} at start, {meta['load_average_end'][0]:.1f} at end "
        "(other jobs ran on the machine: compare ratios within a row).",
        "",
        "| env | buffer | D | threads | fast (s) | autograd (s) | fast + FTZ (s) | floor (s) | GFLOP | matmul GFLOP/s "
        "| autograd / fast | fast / floor | GEMMs alone (s) | GEMMs / floor | fast / GEMMs | fast / (fast + FTZ) "
        "| DDPG episode (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results["runs"]:
        lines.append(
            f"| {r['env']} | {r['buffer']} | {r['buffer_size']} | {r['threads']} | {r['fast_s']:.3f} | "
            f"{r['autograd_s']:.3f} | {r['fast_ftz_s']:.3f} | {r['floor_s']:.3f} | {r['update_gflop']:.2f} | "
            f"{r['matmul_gflops_per_s']:.0f} | **{r['autograd_over_fast']:.1f}x** | **{r['fast_over_floor']:.1f}x** | "
            f"{r['gemms_s']:.3f} | {r['gemms_over_floor']:.1f}x | {r['fast_over_gemms']:.1f}x | "
            f"{r['fast_over_fast_ftz']:.2f} | {r['ddpg_episode_s']:.2f} |"
        )
    for run in results.get("training_runs", []):
        lines += [
            "",
            f"Training run (Acrobot, {run['episodes']} episodes, seed 0, {run['threads']} thread(s)): median update "
            f"{run['median_s']:.3f} s, slowest {run['max_s']:.3f} s ({run['max_over_median']:.1f}x the median; "
            f"{run['second_half_max_over_median']:.1f}x over the second half, full buffer).",
        ]
    lines += [
        "",
        "- early: D transitions of real episodes with uniform warm-up actions; trained: the buffer and networks after "
        f"{', '.join(f'{k} {v}' for k, v in TRAINED_EPISODES.items())} episodes of training.",
        '- fast: `update_path="fast"` (FastUpdater); autograd: `update_path="plain"` (AutogradUpdater, the reference); '
        "fast + FTZ: the fast updater inside `torch.set_flush_denormal(True)` (a ratio near 1 means no subnormal "
        "arithmetic is left).",
        "- floor: matmul FLOPs of the update (forward, weight and input gradients; elementwise work not counted) / "
        "GFLOP/s of a 1024x1024 float32 matmul timed in the same interleaved repeats and thread count.",
        "- GEMMs alone: the update's matrix products only, at its own shapes and counts (`th.mm` on preallocated "
        "random operands, feature-major), in the same repeats: the time BLAS needs for the arithmetic the floor counts, "
        "at these skinny shapes; fast / GEMMs is what the elementwise work and the Python around it add.",
        f"- DDPG: SB3 DDPG `train()` for one episode (one batch-{DDPG_BATCH} step per transition, the same networks "
        "without batch norm) on the same transitions; x9 with the paper's 8 additional updates per step.",
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="torch thread counts, each a full run")
    parser.add_argument("--envs", nargs="+", default=["acrobot", "half_cheetah"], choices=list(ENVS))
    parser.add_argument("--training-run", action="store_true", help="also time every update of a 50-episode run")
    parser.add_argument("--episodes", type=int, default=None, help="training episodes before the trained buffer")
    parser.add_argument("--output", default=str(RESULTS / "update_cost"), help="results path without extension")
    args = parser.parse_args(argv)
    th.set_num_threads(1)
    results: dict = dict(
        meta=dict(
            threads=args.threads,
            repeats=args.repeats,
            torch=th.__version__,
            commit=git_state().get("commit", "unknown")[:10],
            git=git_state(),
            machine=machine_info(),
            load_average=os.getloadavg(),
        ),
        runs=[],
        training_runs=[],
    )
    output = Path(args.output)
    output.parent.mkdir(parents=True, exist_ok=True)

    def save() -> None:  # after every run: an interrupted benchmark keeps what it measured
        results["meta"]["load_average_end"] = os.getloadavg()
        output.with_suffix(".json").write_text(json.dumps(results, indent=1))
        output.with_suffix(".md").write_text(write_markdown(results))

    with tempfile.TemporaryDirectory() as tmp:
        buffers = {name: make_buffers(name, Path(tmp), args.episodes or TRAINED_EPISODES[name]) for name in args.envs}
        for threads in args.threads:
            th.set_num_threads(threads)
            for name, paths in buffers.items():
                for tag, path in paths.items():
                    run = dict(env=name, buffer=tag, **time_buffer(path, ENVS[name], args.repeats))
                    results["runs"].append(run)
                    print(json.dumps({k: v for k, v in run.items() if k != "times_s"}), flush=True)
                    save()
            if args.training_run:
                results["training_runs"].append(training_run())
                print(json.dumps({k: v for k, v in results["training_runs"][-1].items() if k != "update_s"}), flush=True)
                save()
    print(output.with_suffix(".md").read_text())


if __name__ == "__main__":
    main()
