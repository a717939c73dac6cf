"""The two fixes the paper names as future work as DENFAC options, a bound on updates per collected step, and the
options of eq. (4)'s targets (next actions, importance weights, bootstrap bounds).

The paper says DENFAC "lacks stability" and names two remedies it did not try: a replay memory D that is not sampled
as a plain FIFO queue (transitions weighted by their delta error, with the open question of whether the actor and the
critic should sample D the same way) and a slower change of the policy. The autograd updater
(:class:`~sb3_denfac.denfac.updaters.AutogradUpdater`) implements both; the fast updater
(:class:`~sb3_denfac.denfac.fast.FastUpdater`) implements the proximal actor, not the prioritised sampling.

**Prioritised sampling of D** (``prioritized``, one argument: :func:`check_prioritized`; Schaul et al. 2016,
"Prioritized Experience Replay", proportional variant). At every fitted iteration k, with the targets q_k of eq. (4),
the TD errors of the whole buffer are recomputed with the eval-mode critic before it is fitted (DENFAC recomputes
every target anyway, so no priority is stale)::

    delta_i = q_i - Q_{k-1}(s_i, a_i),   p_i = (|delta_i| + eps)^alpha,   P(i) = p_i / sum_j p_j
    w_i = (N P(i))^-beta / max_j (N P(j))^-beta                         (importance correction, in (0, 1])

Each step's mini-batch of ``batch_size`` is drawn from P with replacement (also while D holds fewer transitions;
a full batch is refused: it has nothing to draw); the critic minimises
1/B sum_B w_i c_i (Q(s_i, a_i) - q_i)^2. ``"critic"`` prioritises the critic's mini-batches only (the actor keeps
uniform ones); ``"both"`` also draws the actor's from the same P and ascends 1/B sum_B w_i Q(s_i, pi(s_i)).

**Proximal actor** (``actor_proximal`` = lambda > 0). pi_old is the actor at the start of the end-of-episode update
(before fitted iteration 1 and any reset). Each actor step minimises, on its mini-batch B,

    L = - 1/B sum_B ghat_i . pi(s_i) + lambda 1/B sum_B ||pi(s_i) - pi_old(s_i)||^2,
    ghat_i = g_i / S,   S = 1/B sum_B ||g_i||_2   (detached),

with g_i = dQ/da at (s_i, pi(s_i)) of eq. (5), after inverting gradients if ``inverting_gradients`` (and times w_i
with ``prioritized="both"``). The Q term has unit action gradient per sample on average, so the action change at which
the two terms balance is about 1/(2 lambda) in the scaled action space [-1, 1], whatever the scale of the rewards.

**Update-to-data ratio** (``update_to_data_ratio`` = rho, off by default). Algorithm 1 runs K fitted iterations at every
episode end, i.e. K x ``critic_steps`` critic steps whatever the episode's length: many steps per new transition after
a short episode. With rho, the update after an episode (rollout) of n steps (SB3's ``gradient_steps=-1`` count,
``episode_timesteps``: warm-up rollouts without an update are not carried over) runs

    K_e = min(K, ceil(rho n / critic_steps))   fitted iterations,

i.e. about rho critic steps per collected step, never more than K iterations. ``n_fitted_iterations`` may also give
the range of K_e, ``(K_min, K_max)``: K_e = clip(ceil(rho n / critic_steps), K_min, K_max), with K_max None for no cap
(``None`` alone is ``(1, None)``). This is DENFAC's compute dial: ``(K, None)`` keeps at least Algorithm 1's update
after every episode, however short, and adds iterations as the episodes grow, about rho critic steps per env step, from
a fraction of a step to the frontier's 1-20 (REDQ, DroQ: 20). Each fitted iteration keeps Algorithm 1's shape (targets from
(Q_{k-1}, pi_{k-1}), ``critic_steps`` critic steps, G actor steps), so a larger rho means more iterations, each one
refreshing the targets of eq. (4), not longer ones.

**Bootstrap bounds** (``bootstrap_bounds``, off by default). No discounted return of at least one reward in
[r_min, r_max] leaves

    [min(r_min, r_min / (1 - gamma)),  max(r_max, r_max / (1 - gamma))]

(one step's reward where an episode can end at once, the infinite sum where it cannot). With r_min, r_max the smallest
and largest reward in D at the update (the rewards eq. (4) fits, after any VecNormalize scaling: no env knowledge, and
the range widens as new rewards come), the bootstrap value of eq. (4) is clipped to it:

    q_t = r_t + gamma (1 - d_t) clip(Q_{k-1}(s_{t+1}, a'), low, high),

which stops a critic whose values leave what the rewards allow from feeding on itself (a critic of 64-64 networks
fitted 500 steps per episode can grow tenfold every few episodes on a task with a survival bonus). Where the values stay
inside, it changes nothing. ``train/bootstrap_clip_fraction`` logs the share of the bootstrap values it clipped.
"""

from __future__ import annotations

import math
from typing import Any

import torch as th

from sb3_denfac.common.checks import check_choice, check_number
from sb3_denfac.common.inverting_gradients import invert_gradients
from sb3_denfac.common.truncated_normal import truncated_importance_weights, truncated_normal_log_prob

PRIORITIZED = ("none", "critic", "both")


#: ``prioritized`` as a mapping: where the priorities apply ("on") and the three constants of the module docstring.
PRIORITY_DEFAULTS: dict[str, Any] = {"on": "none", "alpha": 0.6, "beta": 0.4, "eps": 1e-3}


def check_prioritized(prioritized: Any, batch_size: int | None) -> tuple[str, float, float, float]:
    """``prioritized``, one argument: "none", "critic" or "both" (with alpha 0.6, beta 0.4, eps 1e-3), or a mapping
    ``dict(on="critic", alpha=..., beta=..., eps=...)`` (keys left out take those values); returns (on, alpha, beta,
    eps) validated, or a ValueError naming the cause."""
    if isinstance(prioritized, str) and prioritized in PRIORITIZED:
        prioritized = {"on": prioritized}
    if not isinstance(prioritized, dict) or set(prioritized) - set(PRIORITY_DEFAULTS):
        raise ValueError(
            f"prioritized must be one of {PRIORITIZED} or a dict with keys among {list(PRIORITY_DEFAULTS)} (e.g. "
            f'dict(on="critic", alpha=0.7)), got {prioritized!r}'
        )
    settings = {**PRIORITY_DEFAULTS, **prioritized}
    on = check_choice("prioritized (on)", settings["on"], PRIORITIZED)
    alpha = check_number("prioritized alpha", settings["alpha"], minimum=0.0, note=" (0: uniform)")
    beta = check_number("prioritized beta", settings["beta"], minimum=0.0, maximum=1.0)
    eps = check_number("prioritized eps", settings["eps"], minimum=0.0, exclusive_minimum=True)
    if on != "none" and batch_size is None:
        raise ValueError(
            f"prioritized={on!r} draws mini-batches from the priorities and needs an int batch_size, "
            "got batch_size=None (full batch)"
        )
    return on, alpha, beta, eps


#: ``n_fitted_iterations``: K (an int), or with ``update_to_data_ratio`` the range (K_min, K_max) of K_e (None: no cap)
FittedIterations = int | tuple[int, int | None] | None


def check_fitted_iterations(value: Any, ratio: float | None) -> FittedIterations:
    """``n_fitted_iterations`` validated (module docstring): an int K >= 1; with ``update_to_data_ratio``, also None (no
    cap) or a range (K_min, K_max), K_max None for no cap; else a ValueError that names the cause."""
    name = "n_fitted_iterations (K)"
    if value is None:
        if ratio is None:
            raise ValueError(
                "n_fitted_iterations=None (no cap on the fitted iterations) needs update_to_data_ratio, which then sets "
                "K_e from the steps collected; without it every update runs K iterations: give K an int"
            )
        return None
    if not isinstance(value, tuple | list):
        return check_number(name, value, minimum=1, integer=True)
    if len(value) != 2:
        raise ValueError(f"{name} must be an int K, or with update_to_data_ratio None or (K_min, K_max), got {value!r}")
    if ratio is None:
        raise ValueError(
            f"n_fitted_iterations={tuple(value)!r} bounds K_e, the iterations update_to_data_ratio asks for; without it "
            "every update runs K iterations: give K an int"
        )
    low = check_number("n_fitted_iterations[0] (K_min)", value[0], minimum=1, integer=True)
    high = check_number("n_fitted_iterations[1] (K_max)", value[1], minimum=low, integer=True, none_ok=True)
    return low, high


def fitted_iterations(n_fitted_iterations: FittedIterations, critic_steps: int, ratio: float | None, n_steps: int) -> int:
    """K_e of the update after a rollout of ``n_steps`` steps (module docstring); ``ratio`` None: always K."""
    if ratio is None:
        assert isinstance(n_fitted_iterations, int)  # checked by check_fitted_iterations
        return n_fitted_iterations
    wanted = math.ceil(round(ratio * n_steps / critic_steps, 9))  # 0.07 * 100 / 7 is 1.0000000000000002 in floats
    if n_fitted_iterations is None:
        low, high = 1, None
    elif isinstance(n_fitted_iterations, int):
        low, high = 1, n_fitted_iterations
    else:
        low, high = n_fitted_iterations
    return max(low, wanted if high is None else min(high, wanted))


class PrioritisedSampler:
    """Mini-batches drawn with replacement from P(i) = p_i / sum p, p_i = (|delta_i| + eps)^alpha, with their
    importance weights w_i = (N P(i))^-beta / max_j (N P(j))^-beta (module docstring)."""

    def __init__(self, td_errors: th.Tensor, alpha: float, beta: float, eps: float, batch_size: int):
        priorities = (td_errors.detach().abs().flatten() + eps).pow(alpha)
        self.probabilities = priorities / priorities.sum()
        # max_j (N P(j))^-beta is at the least likely transition: w_i = (P(i) / min_j P(j))^-beta
        self.weights = (self.probabilities / self.probabilities.min()).pow(-beta).unsqueeze(1)
        self.batch_size = batch_size

    def batch(self) -> tuple[th.Tensor, th.Tensor]:
        """Indices of one mini-batch and their weights, shape (B,) and (B, 1)."""
        idx = th.multinomial(self.probabilities, self.batch_size, replacement=True)
        return idx, self.weights[idx]


def anchor_scale(action_grads: th.Tensor) -> th.Tensor:
    """The proximal actor's normaliser S = 1/B sum_B ||g_i||_2 (module docstring) of the per-sample action gradients
    ``action_grads`` = g, shape (B, A); floored at 1e-12 so that a flat critic divides by no zero."""
    return action_grads.detach().norm(dim=1).mean().clamp(min=1e-12)


def proximal_actor_backward(
    q_values: th.Tensor, actions: th.Tensor, old_actions: th.Tensor, coef: float, inverting_gradients: bool
) -> th.Tensor:
    """Back-propagate the proximal actor loss L (module docstring) into the actor parameters.

    ``actions`` = pi(s) (part of the graph), ``q_values`` = (w *) Q(s, actions) with the critic frozen,
    ``old_actions`` = pi_old(s). Returns the mean of ``q_values`` (detached), for logging.
    """
    (grad,) = th.autograd.grad(q_values.mean(), actions)
    grad = grad * actions.shape[0]  # g_i = dQ/da per sample (the mean's 1/B undone)
    if inverting_gradients:
        grad = invert_gradients(grad, actions.detach(), th.full_like(grad, -1.0), th.full_like(grad, 1.0))
    scale = anchor_scale(grad)
    loss = -(actions * (grad / scale)).sum(1).mean() + coef * (actions - old_actions).pow(2).sum(1).mean()
    loss.backward()
    return q_values.detach().mean()


def bootstrap_range(rewards: th.Tensor, gamma: float) -> tuple[float, float]:
    """(low, high) of the bootstrap bounds (module docstring) from the rewards of D."""
    r_min, r_max, scale = float(rewards.min()), float(rewards.max()), 1.0 / (1.0 - gamma)
    return min(r_min, r_min * scale), max(r_max, r_max * scale)


def clip_bootstrap(next_q: th.Tensor, bounds: tuple[float, float] | None) -> tuple[th.Tensor, th.Tensor]:
    """The bootstrap value of eq. (4) clipped to ``bounds`` (:func:`bootstrap_range`; None: as it is), and the
    fraction of its values that were clipped."""
    if bounds is None:
        return next_q, th.zeros(())
    clipped = ((next_q < bounds[0]) | (next_q > bounds[1])).float().mean()
    return next_q.clamp(*bounds), clipped


def target_actions(actions: th.Tensor, noise_std: float, noise_clip: float) -> th.Tensor:
    """The next actions of eq. (4)'s targets from ``actions`` = pi_{k-1}(s'): plus, with ``noise_std`` > 0 (DENFAC's
    ``target_policy_noise``), Gaussian noise clipped to +-``noise_clip`` (TD3's target policy smoothing, Fujimoto et al.
    2018, eq. 14), drawn anew at every call (every fitted iteration); clamped to the action bounds [-1, 1]."""
    if noise_std > 0:
        actions = actions + (th.randn_like(actions) * noise_std).clamp(-noise_clip, noise_clip)
    return actions.clamp(-1.0, 1.0)


def importance_weights(
    weighting: str, actor: Any, obs: th.Tensor, next_obs: th.Tensor, actions: th.Tensor, log_prob_b: th.Tensor, sigma: float
) -> th.Tensor:
    """c_t = min(1, pi_{k-1}(a_t|s_t) / pi_b(a_t|s_t)) of eq. (4), shape (N, 1), with pi_{k-1} = ``actor``'s truncated
    Gaussian of std ``sigma``: ``weighting`` "retrace"; "retrace_next_state_quirk" evaluates pi_{k-1} at s' (the authors'
    code); "none": c = 1."""
    if weighting == "none":
        return th.ones_like(log_prob_b).unsqueeze(1)
    weight_obs = next_obs if weighting == "retrace_next_state_quirk" else obs
    low, high = th.full_like(actions, -1.0), th.full_like(actions, 1.0)
    log_prob_target = truncated_normal_log_prob(actions, actor(weight_obs), sigma, low, high)
    return truncated_importance_weights(log_prob_target, log_prob_b).unsqueeze(1)
