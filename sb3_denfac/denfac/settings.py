"""DENFAC's settings, each checked here and nowhere else.

The constructor's signature (``DENFAC.__init__``) is the one home of their defaults; :func:`check_settings` is the one
place that validates them, with a ``ValueError`` naming the argument and what it must be. It returns DENFAC's own
settings normalised (Python numbers, tuples), which the constructor stores as attributes of the same names; SB3's
(``learning_rate``, ``buffer_size``, ``batch_size``, ``gamma``) are checked here too and stored by SB3.
"""

from __future__ import annotations

import inspect
import warnings
from typing import Any

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
from sb3_denfac.denfac.update_paths import UPDATE_PATHS

#: ``weighting``: c_t of eq. (4) from the truncated Gaussian (Retrace-style), the authors' code quirk, or 1.
WEIGHTINGS = ("retrace", "retrace_next_state_quirk", "none")

#: The constructor arguments :func:`check_settings` reads.
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
    "torch_threads",
)


def check_settings(arguments: dict[str, Any]) -> dict[str, Any]:
    """DENFAC's constructor ``arguments`` (at least :data:`SETTINGS`) checked; returns DENFAC's own settings,
    normalised, and ``learning_rate`` (SB3 stores it)."""
    a = arguments
    check_number("batch_size", a["batch_size"], minimum=2, integer=True, none_ok=True, note=" (None: full batch)")
    check_number("buffer_size (D)", a["buffer_size"], minimum=2, integer=True)
    check_gamma(a["gamma"])
    check_denfac_arguments(a["update_path"])  # names of earlier versions
    settings: dict[str, Any] = dict(
        learning_rate=check_learning_rate("learning_rate", a["learning_rate"]),
        actor_learning_rate=check_learning_rate("actor_learning_rate", a["actor_learning_rate"]),
        critic_learning_rate=check_learning_rate("critic_learning_rate", a["critic_learning_rate"]),
        n_fitted_iterations=check_fitted_iterations(a["n_fitted_iterations"], a["update_to_data_ratio"]),
        update_to_data_ratio=check_positive("update_to_data_ratio", a["update_to_data_ratio"], none_ok=True),
        critic_steps=check_number("critic_steps", a["critic_steps"], minimum=1, integer=True),
        actor_steps=check_number("actor_steps (G)", a["actor_steps"], minimum=0, integer=True),
        weighting=check_choice("weighting", a["weighting"], WEIGHTINGS),
        sigma=check_sigma(a["sigma"]),
        max_grad_norm=check_positive("max_grad_norm", a["max_grad_norm"], none_ok=True),
        update_path=check_choice("update_path", a["update_path"], UPDATE_PATHS),
        target_policy_noise=check_number("target_policy_noise", a["target_policy_noise"], minimum=0.0, note=" (0: off)"),
        target_noise_clip=check_number("target_noise_clip", a["target_noise_clip"], minimum=0.0),
        critic_target=check_choice("critic_target", a["critic_target"], CRITIC_TARGETS),
        torch_threads=check_torch_threads(a["torch_threads"]),
        actor_proximal=check_number("actor_proximal", a["actor_proximal"], minimum=0.0, note=" (0: off)"),
        reset_every=check_number("reset_every", a["reset_every"], minimum=1, integer=True, none_ok=True, note=" (env steps)"),
    )
    flags = (
        "reset_critic",
        "reset_actor",
        "inverting_gradients",
        "bootstrap_on_timeout",
        "bootstrap_bounds",
        "async_update",
        "frozen_targets",
    )
    for name in flags:
        settings[name] = check_bool(name, a[name])
    # one argument, kept as four attributes (what FitSettings reads, and what files of every version saved)
    names = ("prioritized", "priority_alpha", "priority_beta", "priority_eps")
    settings.update(zip(names, check_prioritized(a["prioritized"], a["batch_size"]), strict=True))
    return settings


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
