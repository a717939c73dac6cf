"""The DENFAC family's presets: constructor arguments, each for one algorithm (:data:`OWNERS`).

``DENFAC("MlpPolicy", env)`` is the library default: the constructor's defaults and :class:`~.policies.DENFACPolicy`'s
(fitted iterations of mini-batch Adam steps on a kept actor and critic, a proximal actor update, two critics whose
mean makes the targets of eq. (4), with TD3's target policy smoothing of the next action, 64-64 networks without batch
norm, no importance weights; why, with the measurements: docs/denfac.md, "Design rationale").

``DENFAC("MlpPolicy", env, **PAPER)`` is Algorithm 1 with the paper's section 4 networks and Figure 5's common values:
full-batch steps, the actor re-initialised at every fitted iteration and ascending eq. (5) as written (no proximal
term), one critic and the deterministic next action pi(s') in eq. (4), Retrace-style weights, batch norm, N(0, 0.01)
weights, Adam step 0.1 with beta1 = 0 (the authors' solver), sigma = 0.05. The per-env values of Figure 5 (D, reset
critic, inverting gradients, gamma, actor sizes, learning rates) are in the zoo YAML entries of the paper's envs, which
start from this preset (``preset: paper``, :mod:`sb3_denfac.zoo.config`).

``SoftDENFAC("MlpPolicy", env, **DATA_EFFICIENT)`` spends more compute per env step for fewer env steps: SAC's actor
with CrossQ's critic inside the fitted iterations. :data:`DENFAC_DATA_EFFICIENT` is the same dial on DENFAC's own
networks and deterministic actor, at a fraction of the CPU.
"""

from __future__ import annotations

import copy
from collections.abc import Collection
from typing import Any

from stable_baselines3.her.her_replay_buffer import HerReplayBuffer

#: Constructor arguments that turn the default DENFAC into the paper's Algorithm 1 (section 4, Figure 5).
PAPER: dict[str, Any] = {
    "learning_rate": 0.1,
    "buffer_size": 3000,
    "batch_size": None,
    "n_fitted_iterations": 10,
    "critic_steps": 10,
    "actor_steps": 25,
    "reset_actor": True,
    "reset_critic": False,
    "weighting": "retrace",
    "actor_proximal": 0.0,
    "target_policy_noise": 0.0,
    "bootstrap_bounds": False,
    "sigma": 0.05,
    "policy_kwargs": {
        "net_arch": {"pi": [20], "qf": [50, 7]},
        "batch_norm": True,
        "init": "paper",
        "n_critics": 1,
        # the authors' Caffe Adam: beta1 = 0 (with another optimizer_class, give optimizer_kwargs of its own)
        "optimizer_kwargs": {"betas": (0.0, 0.999), "eps": 1e-8},
    },
}


#: The data-efficient preset, SoftDENFAC's (docs/denfac.md, "The data-efficient preset"): SAC's squashed Gaussian actor
#: (eq. 7) with CrossQ's critic (Bhatt et al. 2024) inside Algorithm 1's fitted iterations. The critic is batch
#: renormalised and has no frozen copy: each step reads Q(s, a) and the bootstrap Q(s', a') of eq. (4) in one joint
#: pass, so both see the same normalisation statistics (``frozen_targets=False``, ``batch_renorm``). It is 256-256
#: wide (SAC's width) on mini-batches of 128 (a joint pass of 256 rows). The compute dial runs about rho = 1.5 critic
#: steps per collected env step (``update_to_data_ratio``) and at least Algorithm 1's K = 10 fitted iterations after
#: every episode (``n_fitted_iterations=(10, None)``, :mod:`~.options`). Eq. (4)'s bootstrap value stays inside the
#: discounted returns the rewards in D allow (``bootstrap_bounds``). Everything else is SoftDENFAC's default (64-64
#: actor, alpha tuned, Adam 1e-3). For DENFAC's own actor: :data:`DENFAC_DATA_EFFICIENT`.
DATA_EFFICIENT: dict[str, Any] = {
    "update_to_data_ratio": 1.5,
    "n_fitted_iterations": (10, None),
    "bootstrap_bounds": True,
    "frozen_targets": False,
    "batch_size": 128,
    "policy_kwargs": {"batch_renorm": True, "net_arch": {"pi": [64, 64], "qf": [256, 256]}},
}

#: The compute dial's data-efficient end on DENFAC's default networks and deterministic actor (docs/denfac.md, "The
#: compute dial"), the preset of versions up to 0.5: at least Algorithm 1's K = 10 fitted iterations after every
#: episode, and about 4 critic steps per collected env step beyond (``update_to_data_ratio`` with the range
#: ``(10, None)``, :mod:`~.options`), with eq. (4)'s bootstrap value kept inside the discounted returns the rewards in D
#: allow (``bootstrap_bounds``), which stops the critic feeding on its own overestimates over the many more fitted
#: iterations. Everything else is the default's. ``DENFAC("MlpPolicy", env, **DENFAC_DATA_EFFICIENT)``.
DENFAC_DATA_EFFICIENT: dict[str, Any] = {
    "update_to_data_ratio": 4.0,
    "n_fitted_iterations": (10, None),
    "bootstrap_bounds": True,
}


#: Goal-conditioned tasks with hindsight goals (Dict observations with ``achieved_goal`` and ``desired_goal``, SB3's
#: ``HerReplayBuffer``; the robotics suite's PandaReach-v3 entry): ``DENFAC("MultiInputPolicy", env, **GOALS)``. The
#: plain call ``DENFAC("MultiInputPolicy", goal_env, replay_buffer_class=HerReplayBuffer)`` takes the same values for
#: the settings it is not given (``sb3_denfac.denfac.her.take_goal_settings``). Why each value (docs/results.md,
#: goal-conditioned tasks): ``gamma`` 0.95, a horizon 1 / (1 - gamma) of 20 steps, inside the 50-step episodes of the
#: goal suites (Fetch, panda-gym), where the sparse reward is -1 per step off the goal: the values stay within -20,
#: about what an episode that never reaches its goal returns, where 0.99 asks the critic for -100 from a time-limit
#: bootstrap that no episode shows (the RL Zoo's HER entries take 0.95 too); the compute dial
#: (``update_to_data_ratio`` 10, K_e in 1-10) because a goal env ends an episode at the goal: a policy that reaches
#: goals plays episodes of a few steps, and the default's K = 10 fitted iterations after each made the update's cost
#: per env step tenfold; ``actor_proximal`` 0 because with such short episodes and K_e = 1-2 the anchor held each
#: update's actor near the last one's. Everything else is the default's (``n_sampled_goal`` 4, "future" goals: SB3's
#: and the HER paper's).
GOALS: dict[str, Any] = {
    "replay_buffer_class": HerReplayBuffer,
    "gamma": 0.95,
    "update_to_data_ratio": 10.0,
    "n_fitted_iterations": (1, 10),
    "actor_proximal": 0.0,
}


def data_efficient(**overrides: Any) -> dict[str, Any]:
    """:data:`DATA_EFFICIENT` with ``overrides`` (:func:`with_overrides`), e.g. ``update_to_data_ratio=1`` (a third less
    compute)."""
    return with_overrides(DATA_EFFICIENT, overrides)


def with_overrides(preset: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """``preset`` with ``overrides``: a mapping in both (``policy_kwargs``, its ``net_arch``) is merged key by key, any
    other value of ``overrides`` replaces the preset's. Neither argument is modified."""
    merged = copy.deepcopy(preset)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = with_overrides(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def paper(**overrides: Any) -> dict[str, Any]:
    """:data:`PAPER` with ``overrides`` (:func:`with_overrides`), as constructor arguments."""
    return with_overrides(PAPER, overrides)


#: The presets by name (``presets.<NAME>``): constructor arguments of the algorithm :data:`OWNERS` names.
PRESETS: dict[str, dict[str, Any]] = {
    "PAPER": PAPER,
    "DATA_EFFICIENT": DATA_EFFICIENT,
    "DENFAC_DATA_EFFICIENT": DENFAC_DATA_EFFICIENT,
    "GOALS": GOALS,
}

#: Each preset's algorithm (its class name): the one whose constructor it is measured and documented with.
OWNERS: dict[str, str] = {
    "PAPER": "DENFAC",
    "DATA_EFFICIENT": "SoftDENFAC",
    "DENFAC_DATA_EFFICIENT": "DENFAC",
    "GOALS": "DENFAC",
}


def foreign_preset_message(algorithm: str, keywords: Collection[str], not_taken: Collection[str]) -> str | None:
    """Why ``algorithm``'s constructor refuses ``not_taken`` (keyword arguments it does not take) when ``keywords``, all
    those given, hold every key of one of :data:`PRESETS`: that preset is another algorithm's (:data:`OWNERS`). None
    when no preset was given."""
    for name, preset in PRESETS.items():
        if set(preset) <= set(keywords) and set(not_taken) & set(preset):
            keys = ", ".join(repr(key) for key in not_taken)
            owner = OWNERS[name]
            return (
                f"presets.{name} is {owner}'s preset, and {algorithm} does not take {keys}: use "
                f'{owner}("MlpPolicy", env, **presets.{name}), or give {algorithm} only arguments it takes'
            )
    return None
