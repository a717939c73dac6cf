"""What a normalised critic does to DENFAC's proximal actor step: one line per update of the actor's move and the
critic's action gradients, with and without the critics' layer norm.

At every rollout start (after the update of the episode just finished) the callback compares the actor before and
after that update on a fixed sample of D's states:

- ``move``: mean ||pi_after(s) - pi_before(s)|| in the scaled action space (the proximal term bounds it near
  1 / (2 lambda) per actor step's balance, docs/algorithms.md);
- ``gain``: mean Q(s, pi_after(s)) - Q(s, pi_before(s)) under the updated critic (what the move bought);
- ``grad``: mean ||dQ/da|| at (s, pi_after(s)), and ``agree``: the norm of the mean of the unit gradients
  (1: all states ask for the same direction, 0: no common direction);
- ``q_spread``: the standard deviation of Q(s, pi(s)) over the sample, the scale of the values the actor ascends.

    python -m research.frontier_critics.actor_step --env HalfCheetah-v5 --steps 20000
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import gymnasium as gym
import torch as th
from stable_baselines3.common.callbacks import BaseCallback

from benchmarks.rows import load_rows

HERE = Path(__file__).parent


class ActorStep(BaseCallback):
    def __init__(self, n_states: int = 512) -> None:
        super().__init__()
        self.n_states = n_states
        self.before: th.Tensor | None = None
        self.states: th.Tensor | None = None
        self.lines: list[dict] = []

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:  # before the update (SB3 calls train() after the rollout ends)
        buffer = self.model.replay_buffer
        if buffer.size() < 2:
            return
        idx = th.randint(buffer.size(), (self.n_states,))
        self.states = th.as_tensor(buffer.observations[idx.numpy(), 0], dtype=th.float32)
        with th.no_grad():
            self.before = self.model.actor(self.states)

    def _on_rollout_start(self) -> None:  # after the update
        if self.states is None or self.before is None:
            return
        actor, critic = self.model.actor, self.model.critic
        actor.set_training_mode(False)
        critic.set_training_mode(False)
        with th.no_grad():
            after = actor(self.states)
            gain = (critic(self.states, after) - critic(self.states, self.before)).mean().item()
        a = after.clone().requires_grad_(True)
        q = critic(self.states, a)
        (grad,) = th.autograd.grad(q.sum(), a)
        unit = grad / grad.norm(dim=1, keepdim=True).clamp_min(1e-12)
        self.lines.append(
            {
                "timesteps": int(self.model.num_timesteps),
                "move": (after - self.before).norm(dim=1).mean().item(),
                "gain": gain,
                "grad": grad.norm(dim=1).mean().item(),
                "agree": unit.mean(dim=0).norm().item(),
                "q_spread": q.detach().std().item(),
            }
        )
        self.states = self.before = None


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="HalfCheetah-v5")
    parser.add_argument("--rows", nargs="+", default=["rho2", "ln"])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=HERE / "actor_step.jsonl")
    args = parser.parse_args(argv)
    import sb3_denfac  # noqa: F401
    from sb3_denfac import DENFAC

    th.set_num_threads(1)
    rows = load_rows(HERE / "rows.yml")
    for name in args.rows:
        callback = ActorStep()
        model = DENFAC("MlpPolicy", gym.make(args.env), seed=args.seed, **rows[name])
        model.learn(args.steps, callback=callback)
        with args.out.open("a") as f:
            f.write(json.dumps({"row": name, "env": args.env, "seed": args.seed, "updates": callback.lines}) + "\n")
        lines = callback.lines[len(callback.lines) // 2 :]  # the second half of the run
        summary = {k: sum(line[k] for line in lines) / len(lines) for k in ("move", "gain", "grad", "agree", "q_spread")}
        print(name, args.env, {k: round(v, 4) for k, v in summary.items()}, flush=True)


if __name__ == "__main__":
    main()
