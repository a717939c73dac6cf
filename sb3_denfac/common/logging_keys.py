"""The ``train/`` keys the algorithms write to SB3's logger (TensorBoard, CSV...): their one list.

A key means the same thing in every algorithm that writes it; SB3's own names are used where SB3 has one
(``train/n_updates``, ``train/actor_loss``, ``train/critic_loss``; SB3's single ``train/learning_rate`` is split into
the two networks' rates). docs/conventions.md shows this list as a table, and tests/test_conformance_logging.py checks
that each algorithm writes exactly the keys :data:`WRITTEN_BY` gives it (and those of :data:`WITH_AN_OPTION` with
the option on). SB3's ``rollout/`` and ``time/`` keys are
written by SB3 (CMA-ES writes the same ones itself) and are not listed here.
"""

from __future__ import annotations

#: ``train/`` key -> what it holds (at the update that wrote it).
TRAIN_KEYS: dict[str, str] = {
    "train/n_updates": "updates so far: DENFAC one per Algorithm 1 update, DDPG and CACLA one per gradient step, NFAC one "
    "per fit, CMA-ES one per generation (SB3's key, excluded from TensorBoard as in SB3)",
    "train/critic_loss": "the critic's loss at the last step of the update (DENFAC: Q_1's weighted squared error of eq. (4); "
    "DDPG: the sum over its Q networks; NFAC, CACLA: V's squared error), averaged over the steps for DDPG and CACLA",
    "train/actor_loss": "the actor's loss: DENFAC and DDPG -mean Q_1(s, pi(s)) at the last actor step (the proximal "
    "penalty and the inverted gradient not included), NFAC and CACLA the squared distance of mu(s) to the actions with a "
    "positive TD error; averaged over the steps for DDPG and CACLA",
    "train/actor_learning_rate": "alpha_a, the actor's learning rate used by this update",
    "train/critic_learning_rate": "alpha_c, the critic's learning rate used by this update",
    "train/q_target_mean": "mean of the critic's regression targets r + gamma Q(s', pi(s')) (DENFAC: q_t of eq. (4) at the "
    "last fitted iteration, over the rows its mini-batches read, or over D with a full batch; DDPG: over the "
    "mini-batches, with the target networks)",
    "train/n_transitions": "transitions the update fitted on (DENFAC: the whole replay buffer D; NFAC: the episodes "
    "collected)",
    "train/update_time": "wall-clock seconds of the update (CACLA: of its online steps since the last log)",
    "train/positive_td_fraction": "fraction of transitions with a positive TD error delta (the actions the actor moves to)",
    "train/importance_weight_mean": "mean of the truncated importance weights c_t (1 with weighting='none'), over the "
    "rows of q_target_mean",
    "train/importance_weight_min": "minimum of the truncated importance weights c_t over the rows of q_target_mean",
    "train/fitted_iterations": "K_e, fitted iterations run by the update (K unless update_to_data_ratio is set)",
    "train/bootstrap_clip_fraction": "share of eq. (4)'s bootstrap values at the last fitted iteration that "
    "bootstrap_bounds clipped to the rewards' range, over the rows of q_target_mean (0 without the bounds)",
    "train/ent_coef": "SAC's entropy coefficient alpha after the update (SoftDENFAC)",
    "train/ent_coef_loss": "the tuned alpha's loss of SAC's eq. 18 at the last actor step (0 with a fixed alpha)",
    "train/actor_out_of_bounds": "fraction of the actor's raw outputs outside [-1, 1] (unbounded actor)",
    "train/cma_sigma": "CMA-ES's step size sigma after the generation",
    "train/best_return": "best candidate return seen so far (CMA-ES: of the candidates evaluated; DENFAC and SoftDENFAC "
    "with checkpoint_episodes: the kept actor's assessment, model.checkpoint_return, written at episode ends)",
    "train/generation_mean_return": "mean return of the generation's candidates",
    "train/generation_best_return": "best return of the generation's candidates",
    "train/population_size": "candidates in the generation",
}

_ACTOR_CRITIC = (
    "train/n_updates",
    "train/critic_loss",
    "train/actor_loss",
    "train/actor_learning_rate",
    "train/critic_learning_rate",
)

_DENFAC = (
    *_ACTOR_CRITIC,
    "train/q_target_mean",
    "train/n_transitions",
    "train/update_time",
    "train/importance_weight_mean",
    "train/importance_weight_min",
    "train/fitted_iterations",
    "train/bootstrap_clip_fraction",
)

#: algorithm (zoo name) -> the ``train/`` keys it writes, each a key of :data:`TRAIN_KEYS`.
WRITTEN_BY: dict[str, tuple[str, ...]] = {
    "denfac": _DENFAC,
    "soft_denfac": (*_DENFAC, "train/ent_coef", "train/ent_coef_loss"),  # and SB3 SAC's
    "ddpg": (*_ACTOR_CRITIC, "train/q_target_mean", "train/actor_out_of_bounds"),
    "nfac": (*_ACTOR_CRITIC, "train/n_transitions", "train/update_time", "train/positive_td_fraction"),
    "cacla": (*_ACTOR_CRITIC, "train/update_time", "train/positive_td_fraction"),
    "cmaes": (
        "train/n_updates",
        "train/cma_sigma",
        "train/best_return",
        "train/generation_mean_return",
        "train/generation_best_return",
        "train/population_size",
    ),
}

#: ``train/`` key -> the option with which, and the algorithms (zoo names) that, also write it (not in their
#: :data:`WRITTEN_BY`, which holds what they write with their defaults).
WITH_AN_OPTION: dict[str, tuple[str, tuple[str, ...]]] = {
    "train/best_return": ("checkpoint_episodes", ("denfac", "soft_denfac")),
}

#: Keys written by sb3-denfac 0.4 and earlier -> their names since 0.5 (CHANGELOG.md).
RENAMED: dict[str, str] = {
    "train/actor_objective": "train/actor_loss",  # DENFAC; the value is negated (a loss: -mean Q)
    "train/q_mean": "train/q_target_mean",  # DENFAC
    "train/q_value": "train/q_target_mean",  # DDPG; was mean Q(s, mu(s)) (= -actor_loss), now the targets' mean
    "train/buffer_size": "train/n_transitions",  # DENFAC
    "train/generation": "train/n_updates",  # CMA-ES
}
