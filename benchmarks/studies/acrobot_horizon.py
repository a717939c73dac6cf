"""Can the Acrobot goal be reached within a short horizon on this package's dynamics?

The authors' code gives an Acrobot episode 75 decisions (1500 ODE steps of 0.01 s, one decision per 20), i.e. 15 s;
``sb3_denfac/ContinuousAcrobot-v0`` has 500 decisions of 0.2 s. This script searches for the fastest swing-up from the
hanging rest state on :class:`sb3_denfac.envs.acrobot.ContinuousAcrobotEnv` (gymnasium's dynamics, ``max_torque``
1.5 N m) with three families of controllers, each scored by the first decision at which the normalised tip height
reaches the goal (0.99), and by the best height within the horizon:

- energy pumping, ``a = sign(dtheta2)`` (the controller of ``scripts/acrobot_reachability.py``) and its variants
  ``a = clip(k * dtheta2)`` and ``a = sign(dtheta1)``, ``a = -sign(dtheta1)``;
- bang-bang sequences with up to ``--switches`` switching times, on a grid;
- open-loop torque sequences of ``--horizon`` decisions optimised with CMA-ES (several restarts), with a smooth
  objective (the best height, plus a bonus for reaching the goal early).

The goal is checked at every decision (as the env does) and, with ``--substeps`` > 1, also at intermediate integration
points (the authors' reward takes the maximum over the 20 ODE steps of a decision).
Writes ``benchmarks/results/acrobot_horizon/acrobot_horizon.{json,md}``.

Usage: ``python -m benchmarks.studies.acrobot_horizon [--horizon 75] [--restarts 6] [--generations 300]``
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parents[1] / "results" / "acrobot_horizon"
GOAL = 0.99


class Acrobot:
    """Thin, fast access to the env's dynamics: one decision = ``dt`` seconds, integrated with RK4 in ``substeps`` steps."""

    def __init__(self, max_torque: float = 1.5, substeps: int = 1) -> None:
        from gymnasium.envs.classic_control.acrobot import bound, rk4, wrap

        from sb3_denfac.envs.acrobot import ContinuousAcrobotEnv

        self.env = ContinuousAcrobotEnv(max_torque=max_torque)
        self.env.reset(seed=0)
        self.max_torque = max_torque
        self.substeps = substeps
        self._rk4, self._wrap, self._bound = rk4, wrap, bound

    def height(self, s: np.ndarray) -> float:
        e = self.env
        h = -e.LINK_LENGTH_1 * np.cos(s[0]) - e.LINK_LENGTH_2 * np.cos(s[0] + s[1])
        return float((h + e.LINK_LENGTH_1 + e.LINK_LENGTH_2) / (2.0 * (e.LINK_LENGTH_1 + e.LINK_LENGTH_2)))

    def step(self, s: np.ndarray, a: float) -> tuple[np.ndarray, float]:
        """One decision; returns the new state and the best height at the integration points of the decision."""
        e, best = self.env, 0.0
        torque = float(np.clip(a, -1.0, 1.0)) * self.max_torque
        for _ in range(self.substeps):
            ns = self._rk4(e._dsdt, np.append(s, torque), [0.0, e.dt / self.substeps])
            ns[0] = self._wrap(ns[0], -np.pi, np.pi)
            ns[1] = self._wrap(ns[1], -np.pi, np.pi)
            ns[2] = self._bound(ns[2], -e.MAX_VEL_1, e.MAX_VEL_1)
            ns[3] = self._bound(ns[3], -e.MAX_VEL_2, e.MAX_VEL_2)
            s = np.asarray(ns, dtype=np.float64)
            best = max(best, self.height(s))
        return s, best

    def rollout(self, policy: Callable[[int, np.ndarray], float], horizon: int) -> tuple[int | None, float]:
        """(first decision at the goal or None, best height) of ``a_t = policy(t, state)`` from the hanging rest state."""
        s, best = np.zeros(4), 0.0
        for t in range(horizon):
            s, h = self.step(s, policy(t, s))
            best = max(best, h)
            if h >= GOAL:
                return t + 1, best
        return None, best


def energy_pumping(sim: Acrobot, horizon: int) -> list[dict]:
    rows = []
    controllers: dict[str, Callable[[int, np.ndarray], float]] = {
        "sign(dtheta2)": lambda t, s: 1.0 if s[3] >= 0 else -1.0,
        "sign(dtheta1)": lambda t, s: 1.0 if s[2] >= 0 else -1.0,
        "-sign(dtheta1)": lambda t, s: -1.0 if s[2] >= 0 else 1.0,
    }
    for k in (0.5, 1.0, 2.0, 5.0):
        # a = 0 at rest would never move: a full kick at the first decision
        controllers[f"clip({k} * dtheta2)"] = lambda t, s, k=k: float(np.clip(k * s[3], -1, 1)) if t else 1.0
    for name, policy in controllers.items():
        steps, best = sim.rollout(policy, horizon)
        rows.append({"family": "energy pumping", "controller": name, "steps_to_goal": steps, "best_height": best})
    return rows


def bang_bang_grid(sim: Acrobot, horizon: int, max_switches: int, stride: int) -> dict:
    """Best bang-bang sequence (start sign +-1, switches on a grid of ``stride`` decisions) by best height."""
    best_row: dict = {"best_height": -1.0}
    grid = range(stride, horizon, stride)
    n = 0
    for k in range(max_switches + 1):
        for switches in itertools.combinations(grid, k):
            for first in (1.0, -1.0):
                seq = np.full(horizon, first)
                for i, t in enumerate(switches):
                    seq[t:] = first * (-1) ** (i + 1)
                steps, height = sim.rollout(lambda t, s, seq=seq: seq[t], horizon)
                n += 1
                if (steps is not None and (best_row.get("steps_to_goal") is None or steps < best_row["steps_to_goal"])) or (
                    best_row.get("steps_to_goal") is None and height > best_row["best_height"]
                ):
                    best_row = {"steps_to_goal": steps, "best_height": height, "first": first, "switches": list(switches)}
    return {"family": f"bang-bang, <= {max_switches} switches on a {stride}-decision grid", "candidates": n, **best_row}


def cmaes_open_loop(sim: Acrobot, horizon: int, restarts: int, generations: int, seed: int) -> dict:
    """CMA-ES over the ``horizon`` torques (clipped to [-1, 1]); returns the best sequence found over all restarts."""
    import cma

    def score(x: np.ndarray) -> tuple[float, int | None, float]:
        steps, height = sim.rollout(lambda t, s: x[t], horizon)
        bonus = 0.0 if steps is None else 1.0 + (horizon - steps) / horizon
        return -(height + bonus), steps, height

    best: dict = {"best_height": -1.0, "steps_to_goal": None}
    evaluations = 0
    for r in range(restarts):
        rng = np.random.default_rng(seed + r)
        x0 = rng.choice([-1.0, 1.0], size=horizon) * 0.5
        es = cma.CMAEvolutionStrategy(
            x0, 0.8, {"seed": seed + r + 1, "verbose": -9, "maxiter": generations, "bounds": [-1, 1]}
        )
        while not es.stop():
            xs = es.ask()
            results = [score(np.asarray(x)) for x in xs]
            evaluations += len(xs)
            es.tell(xs, [f for f, _, _ in results])
            for x, (_, steps, height) in zip(xs, results, strict=True):
                better = (steps is not None and (best["steps_to_goal"] is None or steps < best["steps_to_goal"])) or (
                    best["steps_to_goal"] is None and steps is None and height > best["best_height"]
                )
                if better:
                    best = {"steps_to_goal": steps, "best_height": height, "restart": r, "actions": np.round(x, 3).tolist()}
    return {
        "family": f"open-loop CMA-ES ({restarts} restarts x {generations} generations)",
        "evaluations": evaluations,
        **best,
    }


def replay_on_env(row: dict, horizon: int, max_torque: float) -> float | None:
    """Replay a bang-bang row on the registered env (``episode_length=horizon``); its ``paper_performance``."""
    import gymnasium as gym

    import sb3_denfac  # noqa: F401  (registers the environments)

    if "switches" not in row:
        return None
    seq = np.full(horizon, row["first"])
    for i, t in enumerate(row["switches"]):
        seq[t:] = row["first"] * (-1) ** (i + 1)
    env = gym.make("sb3_denfac/ContinuousAcrobot-v0", episode_length=horizon, max_torque=max_torque)
    env.reset(seed=0)
    for a in seq:
        _, _, terminated, truncated, info = env.step(np.array([a], dtype=np.float32))
        if terminated or truncated:
            return float(info["paper_performance"])
    return None


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--horizon", type=int, default=75)
    parser.add_argument("--max-torque", type=float, default=1.5)
    parser.add_argument("--substeps", type=int, default=1, help="integration points per decision checked for the goal")
    parser.add_argument("--switches", type=int, default=4)
    parser.add_argument("--stride", type=int, default=3)
    parser.add_argument("--restarts", type=int, default=6)
    parser.add_argument("--generations", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tag", default="")
    parser.add_argument("--output", default=str(RESULTS), help="results folder")
    args = parser.parse_args(argv)
    start = time.process_time()
    sim = Acrobot(args.max_torque, args.substeps)
    rows = energy_pumping(sim, 500)  # their full-length reference: how long the classic pumping needs
    rows += [{**r, "horizon": args.horizon} for r in energy_pumping(sim, args.horizon)]
    grid = bang_bang_grid(sim, args.horizon, args.switches, args.stride)
    rows.append({**grid, "horizon": args.horizon, "replayed_on_env": replay_on_env(grid, args.horizon, args.max_torque)})
    rows.append({**cmaes_open_loop(sim, args.horizon, args.restarts, args.generations, args.seed), "horizon": args.horizon})
    out = {"args": vars(args), "goal_height": GOAL, "cpu_seconds": time.process_time() - start, "results": rows}
    Path(args.output).mkdir(parents=True, exist_ok=True)
    stem = Path(args.output) / f"acrobot_horizon{args.tag}"
    stem.with_suffix(".json").write_text(json.dumps(out, indent=1))
    lines = [
        f"# Acrobot goal within {args.horizon} decisions (max_torque {args.max_torque} N m, goal height {GOAL}, "
        f"{args.substeps} integration point(s) per decision checked)",
        "",
        "| family | controller / search | horizon | steps to goal | best height |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        steps = "not reached" if r.get("steps_to_goal") is None else str(r["steps_to_goal"])
        what = r.get("controller", r["family"])
        if "switches" in r:
            what = f"start {r['first']:+.0f}, switch after decisions {r['switches']}; on the env: {r['replayed_on_env']}"
        lines.append(f"| {r['family']} | {what} | {r.get('horizon', 500)} | {steps} | {r['best_height']:.4f} |")
    lines += [
        "",
        f"CPU seconds: {out['cpu_seconds']:.0f}. Command: `python -m benchmarks.studies.acrobot_horizon` with {vars(args)}.",
    ]
    stem.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
