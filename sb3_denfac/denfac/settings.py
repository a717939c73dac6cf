"""DENFAC's and SoftDENFAC's settings, each checked here and nowhere else.

The constructor's signature (``DENFAC.__init__``) is the one home of their defaults. :func:`store_settings` is the
one place that validates them, with a ``ValueError`` naming the argument and what it must be, and stores DENFAC's own
settings, normalised (Python numbers, tuples), as attributes of the same names, one assignment each; SB3's
(``learning_rate``, ``buffer_size``, ``batch_size``, ``gamma``) are checked here too and stored by SB3.
:func:`check_soft_settings` checks what SoftDENFAC adds. Settings that need the env or the policy are checked where
those exist (the buffer's size against an episode: :func:`~.buffers.check_holds_one_episode`; HER's:
:func:`~.her.check_her`; the fast updater's reach: :func:`~.update_paths.check_update_path`).
"""

from __future__ import annotations

import inspect
import math
import numbers
import warnings
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.preprocessing import get_action_dim

from sb3_denfac.common.checks import (
    check_bool,
    check_choice,
    check_gamma,
    check_learning_rate,
    check_number,
    check_positive,
    check_sigma,
)
from sb3_denfac.common.compat import check_denfac_arguments
from sb3_denfac.common.threads import check_torch_threads
from sb3_denfac.denfac.options import check_fitted_iterations, check_prioritized
from sb3_denfac.denfac.policies import CRITIC_TARGETS

#: ``weighting``: c_t of eq. (4) from the truncated Gaussian (Retrace-style), the authors' code quirk, or 1.
WEIGHTINGS = ("retrace", "retrace_next_state_quirk", "none")
#: ``update_path``: the updaters of Algorithm 1 (:mod:`~.update_paths`).
UPDATE_PATHS = ("auto", "fast", "plain")

#: The constructor arguments :func:`store_settings` reads.
SETTINGS = (
    "learning_rate",
    "actor_learning_rate",
    "critic_learning_rate",
    "buffer_size",
    "batch_size",
    "gamma",
    "n_fitted_iterations",
    "critic_steps",
    "actor_steps",
    "reset_critic",
    "reset_actor",
    "inverting_gradients",
    "weighting",
    "sigma",
    "max_grad_norm",
    "bootstrap_on_timeout",
    "update_path",
    "prioritized",
    "actor_proximal",
    "update_to_data_ratio",
    "target_policy_noise",
    "target_noise_clip",
    "critic_target",
    "bootstrap_bounds",
    "async_update",
    "frozen_targets",
    "reset_every",
    "checkpoint_episodes",
    "torch_threads",
)


def store_settings(model: Any, arguments: dict[str, Any]) -> Any:
    """Check DENFAC's constructor ``arguments`` (at least :data:`SETTINGS`) and store DENFAC's own settings on
    ``model``, normalised; returns ``learning_rate`` (SB3 stores it)."""
    a = arguments
    check_number("batch_size", a["batch_size"], minimum=2, integer=True, none_ok=True, note=" (None: full batch)")
    check_number("buffer_size (D)", a["buffer_size"], minimum=2, integer=True)
    check_gamma(a["gamma"])
    check_denfac_arguments(a["update_path"])  # names of earlier versions
    m = model
    m.actor_learning_rate = check_learning_rate("actor_learning_rate", a["actor_learning_rate"])
    m.critic_learning_rate = check_learning_rate("critic_learning_rate", a["critic_learning_rate"])
    m.n_fitted_iterations = check_fitted_iterations(a["n_fitted_iterations"], a["update_to_data_ratio"])
    m.update_to_data_ratio = check_positive("update_to_data_ratio", a["update_to_data_ratio"], none_ok=True)
    m.critic_steps = check_number("critic_steps", a["critic_steps"], minimum=1, integer=True)
    m.actor_steps = check_number("actor_steps (G)", a["actor_steps"], minimum=0, integer=True)
    m.reset_critic = check_bool("reset_critic", a["reset_critic"])
    m.reset_actor = check_bool("reset_actor", a["reset_actor"])
    m.inverting_gradients = check_bool("inverting_gradients", a["inverting_gradients"])
    m.weighting = check_choice("weighting", a["weighting"], WEIGHTINGS)
    m.sigma = check_sigma(a["sigma"])
    m.max_grad_norm = check_positive("max_grad_norm", a["max_grad_norm"], none_ok=True)
    m.bootstrap_on_timeout = check_bool("bootstrap_on_timeout", a["bootstrap_on_timeout"])
    m.update_path = check_choice("update_path", a["update_path"], UPDATE_PATHS)
    # one argument, kept as four attributes (what FitSettings reads, and what files of every version saved)
    m.prioritized, m.priority_alpha, m.priority_beta, m.priority_eps = check_prioritized(a["prioritized"], a["batch_size"])
    m.actor_proximal = check_number("actor_proximal", a["actor_proximal"], minimum=0.0, note=" (0: off)")
    m.target_policy_noise = check_number("target_policy_noise", a["target_policy_noise"], minimum=0.0, note=" (0: off)")
    m.target_noise_clip = check_number("target_noise_clip", a["target_noise_clip"], minimum=0.0)
    m.critic_target = check_choice("critic_target", a["critic_target"], CRITIC_TARGETS)
    m.bootstrap_bounds = check_bool("bootstrap_bounds", a["bootstrap_bounds"])
    m.async_update = check_bool("async_update", a["async_update"])
    m.frozen_targets = check_bool("frozen_targets", a["frozen_targets"])
    m.reset_every = check_number("reset_every", a["reset_every"], minimum=1, integer=True, none_ok=True, note=" (env steps)")
    m.checkpoint_episodes = check_checkpoint_episodes(a["checkpoint_episodes"], m.async_update)
    m.torch_threads = check_torch_threads(a["torch_threads"])
    return check_learning_rate("learning_rate", a["learning_rate"])


def check_checkpoint_episodes(checkpoint_episodes: Any, async_update: bool) -> int:
    """``checkpoint_episodes``, an int >= 0, and not with ``async_update`` (also checked at ``load``, which may change
    either)."""
    n = check_number("checkpoint_episodes", checkpoint_episodes, minimum=0, integer=True, note=" (0: off)")
    if n and async_update:
        raise ValueError(
            "checkpoint_episodes assesses an actor on the episodes it plays whole, and async_update=True changes the "
            "actor inside every episode (the update runs beside it): use one or the other"
        )
    return n


def check_soft_settings(ent_coef: Any, target_entropy: Any, prioritized: Any) -> None:
    """SoftDENFAC's own settings: SAC's ``ent_coef`` and ``target_entropy``; ``prioritized`` without the actor's
    mini-batches by TD error, which SAC's actor steps do not implement."""
    parse_ent_coef(ent_coef)  # a ValueError naming the accepted values
    if not (isinstance(target_entropy, str) and target_entropy == "auto"):
        check_target_entropy(target_entropy, None)  # a float: no space needed
    if (prioritized.get("on") if isinstance(prioritized, dict) else prioritized) == "both":
        raise ValueError(
            "prioritized='both' draws the actor's mini-batches by TD error, which SoftDENFAC's actor steps do not "
            "implement: use prioritized='critic'"
        )


def parse_ent_coef(ent_coef: str | float) -> tuple[float, bool]:
    """(initial alpha, tuned) of SB3 SAC's ``ent_coef``: "auto" (1, tuned), "auto_<x>" (x, tuned), a float (fixed)."""
    tuned = isinstance(ent_coef, str) and (ent_coef == "auto" or ent_coef.startswith("auto_"))
    value = ("1.0" if ent_coef == "auto" else ent_coef[len("auto_") :]) if tuned else ent_coef  # type: ignore[index]
    try:
        initial = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        initial = float("nan")
    if isinstance(ent_coef, bool) or not 0 < initial < float("inf"):
        raise ValueError(
            'ent_coef must be "auto", "auto_<initial value>" or a positive float (SAC\'s entropy coefficient alpha), '
            f"got {ent_coef!r}"
        )
    return initial, tuned


def check_target_entropy(target_entropy: str | float, action_space: spaces.Space | None) -> float:
    """The target entropy of the tuned alpha: "auto" is -dim(A) (SAC's), else a float."""
    if isinstance(target_entropy, str) and target_entropy == "auto":
        assert action_space is not None, '"auto" needs the action space'
        return -float(get_action_dim(action_space))
    is_real = isinstance(target_entropy, numbers.Real) and not isinstance(target_entropy, (bool, np.bool_))
    if not is_real or not math.isfinite(float(target_entropy)):  # type: ignore[arg-type]
        raise ValueError(f'target_entropy must be "auto" (-dim(A)) or a finite float, got {target_entropy!r}')
    return float(target_entropy)  # type: ignore[arg-type]


def warn_ignored_settings(model: Any) -> list[str]:
    """Warn, once per constructor call, about settings given a value that the others make meaningless (a value other
    than the signature's default, which the algorithm then ignores); returns the names warned about."""
    defaults = {name: p.default for name, p in inspect.signature(type(model).__init__).parameters.items()}
    ignored = {
        "critic_target": model.policy_kwargs.get("n_critics", 2) == 1,  # one critic: its value, whatever combines it
        "target_noise_clip": model.target_policy_noise == 0,  # no noise to clip
    }
    names = [
        name for name, unused in ignored.items() if unused and name in defaults and getattr(model, name) != defaults[name]
    ]
    if names:
        warnings.warn(
            f"{type(model).__name__} ignores {', '.join(f'{n}={getattr(model, n)!r}' for n in names)}: "
            "critic_target needs n_critics > 1, target_noise_clip a target_policy_noise > 0",
            UserWarning,
            stacklevel=3,
        )
    return names
