"""HER's goal draws and the plain call on PandaReach-v3: episodes to 90% of 20 test goals, and CPU seconds.

    python -m research.robotics.her_relabel VARIANT SEED [SEED ...]

Variants (each DENFAC + SB3's ``HerReplayBuffer``, ``n_sampled_goal`` 4, "future" goals):

- ``entry_once``: the zoo entry (gamma 0.95, ``update_to_data_ratio`` 10, ``n_fitted_iterations`` (1, 10),
  ``actor_proximal`` 0), the relabelled copies' goals drawn once per update (the buffer's ``redraw_goals`` removed);
- ``entry``: the zoo entry, goals drawn anew at every fitted iteration (the library's relabelling);
- ``entry_goals8``: ``entry`` with ``n_sampled_goal`` 8 (twice the goals per transition in each draw);
- ``plain``: ``DENFAC("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer)``, nothing else (on a goal env
  with HER it takes ``presets.GOALS`` for the settings not given: the entry's);
- ``plain_gamma``: the plain call with ``gamma=0.95``;
- ``soft``: the plain call with ``SoftDENFAC`` (SAC's squashed-Gaussian actor and soft targets inside the fitted
  iterations; it takes ``presets.GOALS`` too, ``actor_proximal`` being pinned to 0 by its class, and keeps its own
  ``bootstrap_bounds=True``);
- ``sigma02``, ``sigma03``: the plain call with DENFAC's exploration ``sigma`` 0.2 / 0.3 (default 0.1);
- ``warmup``: the plain call with ``learning_starts=100`` (two episodes of uniform actions before the first update);
- ``bounds``: the plain call with ``bootstrap_bounds=True`` (SoftDENFAC's default: the bootstrap clipped to the
  returns the rewards allow), and ``soft_nobounds``: ``soft`` with ``bootstrap_bounds=False`` (DENFAC's default):
  which of the two differences between ``soft`` and ``plain`` matters;
- ``soft_warmup``: ``soft`` with ``learning_starts=100``;
- ``soft_alpha01``: ``soft`` with the tuned alpha starting at 0.1 instead of 1 (``ent_coef="auto_0.1"``): less
  entropy in the first episodes' exploration and targets.

And the robotics suite's peers on DENFAC's schedule, built as the suite builds them: ``sac_matched``,
``td3_matched`` (SB3's SAC and TD3 + HER): the row's settings on PandaReach-v3 from
``benchmarks.runner.hyperparams.load_hyperparams`` (``hyperparams/sac.yml`` / ``td3.yml``, entry ``PandaReach-v3``,
with ``algos.MATCHED_SCHEDULE`` on top: ``train_freq=(1, "episode")``, ``gradient_steps=500``), the env and model
from ``sb3_denfac.zoo.make_model`` as ``benchmarks.runner.task.run_one`` does (the zoo's ``VecNormalize``, its action
noise; one torch thread), with ``SeededResets`` added as the entry's ``env_wrapper`` for the seeded training goals.
The test episodes see the observations normalised with the model's statistics, as the suite's evaluation does.

pybullet prints its build flags on stdout: keep only the JSON lines (``| grep '^{'``) when appending to the results.

The robotics suite's protocol: training goals seeded (every reset of the training env carries a seed: in effect
``SEED``, ``SEED + 1``... and not ``SEED * 1000`` and up, as the model's seeding seeds the first reset and
``SeededResets`` counts on from it; the same for every variant), 20 deterministic test episodes on goals of their
own (seeds 10,000 and up, the same at every evaluation) every 5 training episodes; a run stops at the first
evaluation at 90% or after 60 episodes. One JSON line per run on stdout: the evaluations (episode, share of goals
reached), the episode of the first at 90% (None: not within 60) and the CPU seconds of training (process time inside
``learn``, the evaluations left out) to there. Unlike the suite's single ``learn`` call, the stop every 5 episodes
(``StopTrainingOnMaxEpisodes``) drops that episode's last transition and the update after it, for every variant
alike. Results: README.md beside this file.
"""

from __future__ import annotations

import json
import sys
import time

import gymnasium as gym
import numpy as np
import panda_gym  # noqa: F401  (registers PandaReach-v3)
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes

from sb3_denfac import DENFAC, SoftDENFAC
from sb3_denfac.denfac import DENFACHerReplayBuffer

ENV_ID = "PandaReach-v3"

MAX_EPISODES, EVERY, TEST_GOALS = 60, 5, 20
HER_KWARGS = dict(goal_selection_strategy="future", n_sampled_goal=4)
ENTRY = dict(gamma=0.95, update_to_data_ratio=10, n_fitted_iterations=(1, 10), actor_proximal=0.0)
#: variants of the plain call: the class and the settings given on top of ``replay_buffer_class=HerReplayBuffer``
PLAIN = {
    "plain": (DENFAC, {}),
    "plain_gamma": (DENFAC, dict(gamma=0.95)),
    "soft": (SoftDENFAC, {}),
    "sigma02": (DENFAC, dict(sigma=0.2)),
    "sigma03": (DENFAC, dict(sigma=0.3)),
    "warmup": (DENFAC, dict(learning_starts=100)),
    "bounds": (DENFAC, dict(bootstrap_bounds=True)),
    "soft_nobounds": (SoftDENFAC, dict(bootstrap_bounds=False)),
    "soft_warmup": (SoftDENFAC, dict(learning_starts=100)),
    "soft_alpha01": (SoftDENFAC, dict(ent_coef="auto_0.1")),
}
#: the robotics suite's rows run here as that suite builds them (``benchmarks.runner.algos.ALGOS``)
SUITE_ROWS = ("sac_matched", "td3_matched")


class GoalsOncePerUpdate(DENFACHerReplayBuffer):
    """The relabelling before fresh goals per fitted iteration: one goal set per update."""

    def all_samples(self, env=None):
        samples = super().all_samples(env)
        if hasattr(samples, "redraw_goals"):
            samples.redraw_goals = None
        return samples


class SeededResets(gym.Wrapper):
    """Passes a seed to every reset (``first``, ``first + 1``...): panda-gym draws each reset's goal from the OS's
    entropy where the reset has no seed."""

    def __init__(self, env: gym.Env, first: int) -> None:
        super().__init__(env)
        self.next_seed = first

    def reset(self, *, seed=None, options=None):
        self.next_seed = (self.next_seed if seed is None else seed) + 1
        return self.env.reset(seed=self.next_seed - 1, options=options)


def success(model) -> float:
    """The share of the 20 deterministic test episodes that end at the goal (the same goals at every call); a model
    trained on a ``VecNormalize`` env (the peers' zoo entries) sees the observations normalised with its statistics,
    as in ``benchmarks.runner.task.evaluate``."""
    env = SeededResets(gym.make(ENV_ID), first=10_000)
    normalizer = model.get_vec_normalize_env()
    reached = []
    for _ in range(TEST_GOALS):
        obs, _ = env.reset()
        done, info = False, {}
        while not done:
            action, _ = model.predict(obs if normalizer is None else normalizer.normalize_obs(obs), deterministic=True)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        reached.append(float(info.get("is_success", False)))
    env.close()
    return float(np.mean(reached))


def suite_row(row: str, seed: int) -> tuple:
    """``(model, source)``: the robotics suite's row ``row`` on PandaReach-v3, its settings resolved by the suite's
    code and the model built by the zoo's preprocessing, as ``benchmarks.runner.sweep`` and ``task.run_one`` do; the
    one addition is the entry's ``env_wrapper``: ``SeededResets`` from ``seed * 1000``, as the other variants' env."""
    import torch

    from benchmarks.runner.algos import ALGOS
    from benchmarks.runner.hyperparams import load_hyperparams
    from sb3_denfac.zoo import make_model

    torch.set_num_threads(1)  # as run_one (DENFAC's learn() takes one thread by default)
    hyperparams, source = load_hyperparams(row, ENV_ID)
    assert "env_wrapper" not in hyperparams, f"{source} has an env_wrapper of its own"
    hyperparams = {**hyperparams, "env_wrapper": {SeededResets: {"first": seed * 1000}}}
    return make_model(ALGOS[row].zoo_algo, ENV_ID, hyperparams, seed=seed), source


def make(variant: str, seed: int) -> DENFAC:
    env = SeededResets(gym.make(ENV_ID), first=seed * 1000)
    if variant in PLAIN:
        algorithm, given = PLAIN[variant]
        return algorithm("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, seed=seed, **given)
    buffer = {"entry": HerReplayBuffer, "entry_once": GoalsOncePerUpdate, "entry_goals8": HerReplayBuffer}[variant]
    her = {**HER_KWARGS, "n_sampled_goal": 8} if variant == "entry_goals8" else HER_KWARGS
    return DENFAC("MultiInputPolicy", env, replay_buffer_class=buffer, replay_buffer_kwargs=her, seed=seed, **ENTRY)


def run(variant: str, seed: int) -> dict:
    model, source = suite_row(variant, seed) if variant in SUITE_ROWS else (make(variant, seed), None)
    evaluations, cpu, reached = [], 0.0, None
    for episode in range(EVERY, MAX_EPISODES + 1, EVERY):
        start = time.process_time()
        model.learn(10**6, callback=StopTrainingOnMaxEpisodes(EVERY), reset_num_timesteps=episode == EVERY)
        cpu += time.process_time() - start
        evaluations.append((episode, success(model)))
        if evaluations[-1][1] >= 0.9:
            reached = episode
            break
    head = dict(variant=variant, seed=seed, episodes_to_90=reached, cpu_s=round(cpu, 1), evaluations=evaluations)
    if source is not None:  # an SB3 peer
        train_freq = [model.train_freq.frequency, model.train_freq.unit.value]
        settings = dict(gamma=model.gamma, train_freq=train_freq, gradient_steps=model.gradient_steps)
        settings.update(learning_starts=model.learning_starts, normalize=model.get_vec_normalize_env() is not None)
        settings.update(algorithm=type(model).__name__, hyperparams_source=source, n_updates=model._n_updates)
        return {**head, **settings}
    settings = dict(gamma=model.gamma, n_fitted_iterations=model.n_fitted_iterations, dial=model.update_to_data_ratio)
    settings["actor_proximal"] = model.actor_proximal
    sigma = None if isinstance(model, SoftDENFAC) else model.sigma  # SoftDENFAC's actor samples its own Gaussian
    settings.update(sigma=sigma, learning_starts=model.learning_starts, bootstrap_bounds=model.bootstrap_bounds)
    settings["algorithm"], settings["goal_settings_taken"] = type(model).__name__, model.goal_settings_taken
    return {**head, **settings}


def main() -> None:
    variant, seeds = sys.argv[1], [int(s) for s in sys.argv[2:]]
    for seed in seeds:
        print(json.dumps(run(variant, seed)), flush=True)


if __name__ == "__main__":
    main()
