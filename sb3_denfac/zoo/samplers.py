"""Optuna samplers and converters for the RL Zoo (``rl_zoo3.hyperparams_opt`` conventions).

Each ``sample_<algo>_params(trial, n_actions, n_envs, additional_args)`` suggests values under the names stored in
``trial.params`` and returns ``convert_<algo>_params(those values)`` (with the entry's ``policy_kwargs``, below), so the
zoo's ``--trial-id`` path (which calls the converter on a stored trial's params) rebuilds exactly the hyperparameters
that trial trained with.

Search spaces follow the dimensions of the paper's Figure 5 (learning rates alpha_a / alpha_c, inverting gradient,
mini-batch size, tau, additional updates, K, G, D, reset critic) plus the exploration sigma and the network sizes;
DENFAC's also offers the stability options of its default configuration (``actor_proximal`` lambda, 0 = the
paper's plain ascent of eq. (5); ``n_critics``, 1 = the paper's single critic in the targets of eq. (4);
``critic_target``, the critics' mean or minimum in those targets; ``target_policy_noise``, 0 = the paper's
deterministic next action pi(s'); ``bootstrap_bounds``, False = the paper's unbounded bootstrap value), since none is
right everywhere: the minimum over critics also lowers the value of a
sparse reward.
gamma is not tuned: the paper fixes it per environment (it stays as in the YAML entry). None of these samplers sets
``train_freq``: DENFAC, NFAC and CMA-ES update per episode and the zoo's TD3 sampler would override that.

The converters return only what was sampled (``policy_kwargs`` holds just the sampled ``net_arch``, and DENFAC's
``n_critics``). The zoo would let
that replace the YAML entry's ``policy_kwargs`` (batch norm, init, activation); :func:`with_entry_policy_kwargs` merges
it over them instead. The samplers read the entry's ``policy_kwargs`` from the trial's user attribute
:data:`ENTRY_POLICY_KWARGS`, which ``sb3_denfac.zoo.cli``'s ExperimentManager sets before sampling (so the study records
them too); that manager applies the same merge to a converted ``--trial-id``.
"""

from __future__ import annotations

from typing import Any

import optuna

#: Trial user attribute with the YAML entry's ``policy_kwargs`` (a mapping), set by ``sb3_denfac.zoo`` for each trial.
ENTRY_POLICY_KWARGS = "entry_policy_kwargs"

#: Network sizes offered to Optuna, by name (categorical choices must be plain values).
ACTOR_ARCHS: dict[str, list[int]] = {"5": [5], "20": [20], "20-10": [20, 10], "64-64": [64, 64]}
CRITIC_ARCHS: dict[str, list[int]] = {"50-7": [50, 7], "64-64": [64, 64], "256-256": [256, 256]}


def with_entry_policy_kwargs(hyperparams: dict[str, Any], entry_policy_kwargs: dict[str, Any]) -> dict[str, Any]:
    """``hyperparams`` with their ``policy_kwargs`` merged over the YAML entry's (sampled keys win)."""
    return {**hyperparams, "policy_kwargs": {**entry_policy_kwargs, **hyperparams.get("policy_kwargs", {})}}


def _sampled(trial: optuna.Trial, hyperparams: dict[str, Any]) -> dict[str, Any]:
    return with_entry_policy_kwargs(hyperparams, trial.user_attrs.get(ENTRY_POLICY_KWARGS) or {})


def _policy_kwargs(params: dict[str, Any], critic: bool = True, critic_key: str = "qf") -> dict[str, Any]:
    """The sampled ``net_arch``, as policy_kwargs."""
    policy_kwargs: dict[str, Any] = {}
    if "actor_arch" in params:
        net_arch: dict[str, list[int]] = {"pi": list(ACTOR_ARCHS[params["actor_arch"]])}
        if critic and "critic_arch" in params:
            net_arch[critic_key] = list(CRITIC_ARCHS[params["critic_arch"]])
        policy_kwargs["net_arch"] = net_arch
    return policy_kwargs


def _copy_except(params: dict[str, Any], *names: str) -> dict[str, Any]:
    return {k: v for k, v in params.items() if k not in names}


# --------------------------------------------------------------------------------------------------------------------
# DENFAC
# --------------------------------------------------------------------------------------------------------------------


def convert_denfac_params(params: dict[str, Any]) -> dict[str, Any]:
    """DENFAC's and SoftDENFAC's trial parameters as constructor arguments."""
    hyperparams = _copy_except(params, "actor_arch", "critic_arch", "n_critics")
    hyperparams["policy_kwargs"] = _policy_kwargs(params)
    if "n_critics" in params:  # a policy keyword argument (the critic), as in SB3's TD3 and SAC
        hyperparams["policy_kwargs"]["n_critics"] = params["n_critics"]
    return hyperparams


def _fitted_iteration_params(trial: optuna.Trial) -> dict[str, Any]:
    """What DENFAC and SoftDENFAC share: alpha_a, alpha_c, K, G, critic steps, D, reset critic, network sizes, the
    number of critics, and how eq. (4)'s targets combine them (``critic_target``) and bound the bootstrap value."""
    n_critics = trial.suggest_categorical("n_critics", [1, 2])
    return {
        "actor_learning_rate": trial.suggest_float("actor_learning_rate", 1e-5, 0.1, log=True),
        "critic_learning_rate": trial.suggest_float("critic_learning_rate", 1e-5, 0.1, log=True),
        "n_fitted_iterations": trial.suggest_int("n_fitted_iterations", 1, 20),
        "actor_steps": trial.suggest_int("actor_steps", 5, 50),
        "critic_steps": trial.suggest_int("critic_steps", 5, 50),
        "buffer_size": trial.suggest_categorical("buffer_size", [1000, 3000, 6000, 10000, 100_000]),
        "reset_critic": trial.suggest_categorical("reset_critic", [False, True]),
        "actor_arch": trial.suggest_categorical("actor_arch", list(ACTOR_ARCHS)),
        "critic_arch": trial.suggest_categorical("critic_arch", list(CRITIC_ARCHS)),
        "n_critics": n_critics,
        # how several critics combine: with one there is nothing to combine (the constructor warns on "min")
        **({"critic_target": trial.suggest_categorical("critic_target", ["mean", "min"])} if n_critics > 1 else {}),
        "bootstrap_bounds": trial.suggest_categorical("bootstrap_bounds", [False, True]),
    }


def sample_denfac_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """DENFAC: the shared fitted-iteration parameters (:func:`_fitted_iteration_params`), and its deterministic actor's:
    inverting gradient, sigma, the proximal actor's lambda and the targets' next-action smoothing
    (``target_policy_noise``; 0 = the paper's pi(s'))."""
    params = {
        **_fitted_iteration_params(trial),
        "inverting_gradients": trial.suggest_categorical("inverting_gradients", [False, True]),
        "sigma": trial.suggest_float("sigma", 0.01, 0.5, log=True),
        "actor_proximal": trial.suggest_categorical("actor_proximal", [0.0, 0.3, 1.0, 3.0]),
        "target_policy_noise": trial.suggest_categorical("target_policy_noise", [0.0, 0.1, 0.2, 0.3]),
    }
    return _sampled(trial, convert_denfac_params(params))


def sample_soft_denfac_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """SoftDENFAC: the shared fitted-iteration parameters (:func:`_fitted_iteration_params`), and SAC's entropy
    coefficient: its start, tuned (``ent_coef="auto_<x>"``)."""
    params = {
        **_fitted_iteration_params(trial),
        "ent_coef": trial.suggest_categorical("ent_coef", ["auto", "auto_0.1", "auto_0.01"]),
    }
    return _sampled(trial, convert_denfac_params(params))


# --------------------------------------------------------------------------------------------------------------------
# DDPG (ours: inverting gradients, batch norm, truncated Gaussian exploration)
# --------------------------------------------------------------------------------------------------------------------


def convert_ddpg_params(params: dict[str, Any]) -> dict[str, Any]:
    hyperparams = _copy_except(params, "actor_arch", "critic_arch", "batch_size_pow")
    if "batch_size_pow" in params:
        hyperparams["batch_size"] = 2 ** params["batch_size_pow"]
    hyperparams["policy_kwargs"] = _policy_kwargs(params)
    return hyperparams


def sample_ddpg_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """DDPG: alpha_a, alpha_c, inverting gradient, mini-batch, tau, additional updates, sigma, network sizes."""
    params = {
        "actor_learning_rate": trial.suggest_float("actor_learning_rate", 1e-5, 0.1, log=True),
        "learning_rate": trial.suggest_float("learning_rate", 1e-5, 0.1, log=True),
        "inverting_gradients": trial.suggest_categorical("inverting_gradients", [False, True]),
        "batch_size_pow": trial.suggest_int("batch_size_pow", 5, 8),  # 32 .. 256 (paper: 64)
        "tau": trial.suggest_float("tau", 1e-3, 0.1, log=True),
        "gradient_steps": trial.suggest_int("gradient_steps", 1, 16),  # "additional updates" per env step
        "sigma": trial.suggest_float("sigma", 0.01, 0.5, log=True),
        "actor_arch": trial.suggest_categorical("actor_arch", list(ACTOR_ARCHS)),
        "critic_arch": trial.suggest_categorical("critic_arch", list(CRITIC_ARCHS)),
    }
    return _sampled(trial, convert_ddpg_params(params))


# --------------------------------------------------------------------------------------------------------------------
# NFAC (on-policy, V critic, episode-wise)
# --------------------------------------------------------------------------------------------------------------------


def convert_value_critic_params(params: dict[str, Any]) -> dict[str, Any]:
    """NFAC and CACLA: a V critic, so the critic's architecture goes to ``net_arch["vf"]``."""
    hyperparams = _copy_except(params, "actor_arch", "critic_arch")
    hyperparams["policy_kwargs"] = _policy_kwargs(params, critic_key="vf")
    return hyperparams


def sample_nfac_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """NFAC: alpha_a, alpha_c, K, critic and actor steps, reset critic, negative-delta updates, sigma, network sizes."""
    params = {
        "learning_rate": trial.suggest_float("learning_rate", 1e-5, 0.1, log=True),
        "critic_learning_rate": trial.suggest_float("critic_learning_rate", 1e-5, 0.1, log=True),
        "n_fitted_iterations": trial.suggest_int("n_fitted_iterations", 1, 20),
        "critic_steps": trial.suggest_int("critic_steps", 5, 50),
        "actor_steps": trial.suggest_int("actor_steps", 5, 50),
        "reset_critic": trial.suggest_categorical("reset_critic", [False, True]),
        "update_delta_neg": trial.suggest_categorical("update_delta_neg", [False, True]),
        "sigma": trial.suggest_float("sigma", 0.01, 0.5, log=True),
        "actor_arch": trial.suggest_categorical("actor_arch", list(ACTOR_ARCHS)),
        "critic_arch": trial.suggest_categorical("critic_arch", list(CRITIC_ARCHS)),
    }
    return _sampled(trial, convert_value_critic_params(params))


# --------------------------------------------------------------------------------------------------------------------
# CACLA (online, on-policy, V critic)
# --------------------------------------------------------------------------------------------------------------------


def sample_cacla_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """CACLA: alpha_a, alpha_c, sigma, batch-norm statistics window, network sizes."""
    params = {
        "learning_rate": trial.suggest_float("learning_rate", 1e-5, 0.1, log=True),
        "critic_learning_rate": trial.suggest_float("critic_learning_rate", 1e-5, 0.1, log=True),
        "sigma": trial.suggest_float("sigma", 0.01, 0.5, log=True),
        "bn_window": trial.suggest_categorical("bn_window", [8, 32, 128]),
        "actor_arch": trial.suggest_categorical("actor_arch", list(ACTOR_ARCHS)),
        "critic_arch": trial.suggest_categorical("critic_arch", list(CRITIC_ARCHS)),
    }
    return _sampled(trial, convert_value_critic_params(params))


# --------------------------------------------------------------------------------------------------------------------
# CMA-ES (actor-only)
# --------------------------------------------------------------------------------------------------------------------


def convert_cmaes_params(params: dict[str, Any]) -> dict[str, Any]:
    hyperparams = _copy_except(params, "actor_arch")
    policy_kwargs: dict[str, Any] = {}
    if "actor_arch" in params:
        policy_kwargs["net_arch"] = list(ACTOR_ARCHS[params["actor_arch"]])  # one network: a plain list
    hyperparams["policy_kwargs"] = policy_kwargs
    return hyperparams


def sample_cmaes_params(trial: optuna.Trial, n_actions: int, n_envs: int, additional_args: dict) -> dict[str, Any]:
    """CMA-ES: population size, initial step size, episodes per candidate, action noise sigma, actor size."""
    params = {
        "population_size": trial.suggest_categorical("population_size", [None, 8, 16, 32]),  # None: cma's default
        "sigma0": trial.suggest_float("sigma0", 0.01, 2.0, log=True),
        "n_eval_episodes": trial.suggest_int("n_eval_episodes", 1, 5),
        "sigma": trial.suggest_float("sigma", 0.0, 0.3),
        "actor_arch": trial.suggest_categorical("actor_arch", list(ACTOR_ARCHS)),
    }
    return _sampled(trial, convert_cmaes_params(params))


#: Zoo name -> sampler / converter, registered into rl_zoo3.hyperparams_opt by :func:`sb3_denfac.zoo.config.register`.
SAMPLERS = {
    "denfac": sample_denfac_params,
    "soft_denfac": sample_soft_denfac_params,
    "ddpg": sample_ddpg_params,
    "nfac": sample_nfac_params,
    "cacla": sample_cacla_params,
    "cmaes": sample_cmaes_params,
}
CONVERTERS = {
    "denfac": convert_denfac_params,
    "soft_denfac": convert_denfac_params,
    "ddpg": convert_ddpg_params,
    "nfac": convert_value_critic_params,
    "cacla": convert_value_critic_params,
    "cmaes": convert_cmaes_params,
}
