"""DENFAC's two configurations: the general default and the paper's Algorithm 1, one argument set apart.

``DENFAC("MlpPolicy", env)`` uses the constructor's defaults and :data:`DEFAULT_POLICY_KWARGS`: fitted iterations
of mini-batch Adam steps on a kept actor and critic, a proximal actor update, two critics whose minimum makes the
targets, wide networks without batch norm, no importance weights (why: the class docstring; measurements:
``benchmarks/results/denfac_ablation/``).

``DENFAC("MlpPolicy", env, **PAPER)`` is Algorithm 1 with the paper's section 4 networks and Figure 5's common
values: full-batch steps, the actor re-initialised at every fitted iteration and ascending eq. (5) as written (no
proximal term), one critic, Retrace-style weights, batch norm, N(0, 0.01) weights, Adam step 0.1 with beta1 = 0 (the
authors' solver), sigma = 0.05. The per-env values of Figure 5
(D, reset critic, inverting gradients, gamma, actor sizes) are in the zoo YAML entries of the paper's envs.
"""

from __future__ import annotations

from typing import Any

#: Policy keyword arguments of ``DENFAC("MlpPolicy", env)`` where ``policy_kwargs`` does not set them.
DEFAULT_POLICY_KWARGS: dict[str, Any] = {
    "net_arch": {"pi": [64, 64], "qf": [64, 64]},
    "batch_norm": False,
    "init": "default",
    "n_critics": 2,
}

#: Constructor arguments that turn the default DENFAC into the paper's Algorithm 1 (section 4, Figure 5).
PAPER: dict[str, Any] = {
    "learning_rate": 0.1,
    "adam_betas": (0.0, 0.999),
    "buffer_size": 3000,
    "batch_size": None,
    "n_fitted_iterations": 10,
    "critic_steps": 10,
    "actor_steps": 25,
    "reset_actor": True,
    "reset_critic": False,
    "weighting": "retrace",
    "actor_proximal": 0.0,
    "sigma": 0.05,
    "policy_kwargs": {"net_arch": {"pi": [20], "qf": [50, 7]}, "batch_norm": True, "init": "paper", "n_critics": 1},
}


def paper(**overrides: Any) -> dict[str, Any]:
    """:data:`PAPER` with ``overrides`` (``policy_kwargs`` merged key by key), as constructor arguments."""
    kwargs = {**PAPER, **overrides}
    kwargs["policy_kwargs"] = {**PAPER["policy_kwargs"], **overrides.get("policy_kwargs", {})}
    return kwargs
