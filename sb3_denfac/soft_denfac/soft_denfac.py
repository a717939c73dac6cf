"""SoftDENFAC: DENFAC's Algorithm 1 with SAC's stochastic actor and soft targets inside the fitted iterations."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import torch as th
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, Schedule
from stable_baselines3.common.utils import update_learning_rate

from sb3_denfac.common.docstrings import with_parent_params
from sb3_denfac.common.model_files import stored_values
from sb3_denfac.denfac.denfac import DENFAC
from sb3_denfac.denfac.options import FittedIterations, clip_bootstrap
from sb3_denfac.denfac.policies import DENFACPolicy
from sb3_denfac.denfac.update_paths import UpdaterClasses
from sb3_denfac.denfac.updaters import Updater
from sb3_denfac.soft_denfac.policies import MlpPolicy, MultiInputPolicy, SoftDENFACPolicy, check_target_entropy, parse_ent_coef
from sb3_denfac.soft_denfac.updaters import SOFT_UPDATERS, SoftActorFit


@with_parent_params(DENFAC)
class SoftDENFAC(DENFAC):
    """DENFAC (Algorithm 1: K fitted iterations over the whole replay buffer D after every episode) with SB3 SAC's
    actor in place of the deterministic mu(s) of eq. (5) (Haarnoja et al. 2018).

    - The actor is a squashed Gaussian pi(a|s) (:class:`~.policies.SoftDENFACActor`), played as sampled.
    - At every fitted iteration, after the critic's fit on eq. (4), G steps of SAC's actor objective,
      alpha log pi(a|s) - min_j Q_j(s, a) (eq. 7), each followed by a step of the tuned alpha (eq. 18).
    - The targets of eq. (4) are soft: r + gamma (Q_{k-1}(s', a') - alpha log pi_{k-1}(a'|s')), a' ~ pi_{k-1}(.|s')
      (eq. 3), drawn anew at every fitted iteration.

    What belongs to DENFAC's deterministic actor is not an argument here: the truncated Gaussian's ``sigma``, the
    importance ``weighting`` of its behaviour density, ``inverting_gradients`` (tanh bounds the actions), the proximal
    term and TD3's target smoothing; nor is ``frozen_targets`` (the soft targets are computed once per fitted
    iteration, as eq. (4)'s). Why a soft actor inside DENFAC and where it stands against the deterministic one:
    docs/algorithms.md.

    :param ent_coef: alpha, SB3 SAC's ``ent_coef``: "auto" (default; tuned towards ``target_entropy``, from 1),
        "auto_<x>" (tuned, from x) or a float (fixed)
    :param target_entropy: the entropy the tuned alpha steers towards (SAC's eq. 18; "auto": -dim(A))
    :param bootstrap_bounds: clip eq. (4)'s bootstrap value Q_{k-1}(s', a') to the range of discounted returns the
        rewards in D allow, before the entropy term (:mod:`~sb3_denfac.denfac.options`; default True, unlike DENFAC's:
        the soft targets' value estimates grow unbounded without it)
    :param prioritized: "none" (default) or "critic" (the critic's mini-batches by TD error; the actor's stay uniform),
        or DENFAC's dict with ``on="critic"``
    :param policy_kwargs: :class:`~.policies.SoftDENFACPolicy`'s: ``net_arch`` (default ``dict(pi=[64, 64],
        qf=[64, 64])``), ``n_critics`` (default 2), ``init`` and ``layer_norm`` (the critic's), ``activation_fn``; no
        batch norm (SAC's actor has none)

    The other parameters are :class:`~sb3_denfac.denfac.denfac.DENFAC`'s, with its defaults (their entries below are
    DENFAC's).
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"MlpPolicy": MlpPolicy, "MultiInputPolicy": MultiInputPolicy}
    updater_classes: ClassVar[UpdaterClasses] = SOFT_UPDATERS
    policy: SoftDENFACPolicy

    def __init__(
        self,
        policy: str | type[SoftDENFACPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 1e-3,
        actor_learning_rate: float | Schedule | None = None,
        critic_learning_rate: float | Schedule | None = None,
        buffer_size: int = 100_000,
        learning_starts: int = 0,
        batch_size: int | None = 256,
        gamma: float = 0.99,
        n_fitted_iterations: FittedIterations = 10,
        critic_steps: int = 50,
        actor_steps: int = 25,
        reset_critic: bool = False,
        reset_actor: bool = False,
        max_grad_norm: float | None = 10.0,
        bootstrap_on_timeout: bool = True,
        update_path: str = "auto",
        prioritized: str | dict[str, Any] = "none",
        update_to_data_ratio: float | None = None,
        critic_target: str = "mean",
        bootstrap_bounds: bool = True,
        ent_coef: str | float = "auto",
        target_entropy: str | float = "auto",
        async_update: bool = False,
        reset_every: int | None = None,
        replay_buffer_class: type[ReplayBuffer] | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        torch_threads: int | None = 1,
        _init_setup_model: bool = True,
    ):
        parse_ent_coef(ent_coef)  # a ValueError naming the accepted values
        if not (isinstance(target_entropy, str) and target_entropy == "auto"):
            check_target_entropy(target_entropy, None)  # type: ignore[arg-type]  # a float: no space needed
        if (prioritized.get("on") if isinstance(prioritized, dict) else prioritized) == "both":
            raise ValueError(
                "prioritized='both' draws the actor's mini-batches by TD error, which SoftDENFAC's actor steps do not "
                "implement: use prioritized='critic'"
            )
        self.ent_coef, self.target_entropy = ent_coef, target_entropy
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            actor_learning_rate=actor_learning_rate,
            critic_learning_rate=critic_learning_rate,
            buffer_size=buffer_size,
            learning_starts=learning_starts,
            batch_size=batch_size,
            gamma=gamma,
            n_fitted_iterations=n_fitted_iterations,
            critic_steps=critic_steps,
            actor_steps=actor_steps,
            reset_critic=reset_critic,
            reset_actor=reset_actor,
            # the deterministic actor's settings, pinned: no behaviour-density weights (c = 1), no inverting gradients
            # (tanh bounds the actions), no proximal term, no target smoothing (the next actions are sampled)
            inverting_gradients=False,
            weighting="none",
            actor_proximal=0.0,
            target_policy_noise=0.0,
            max_grad_norm=max_grad_norm,
            bootstrap_on_timeout=bootstrap_on_timeout,
            update_path=update_path,
            prioritized=prioritized,
            update_to_data_ratio=update_to_data_ratio,
            critic_target=critic_target,
            bootstrap_bounds=bootstrap_bounds,
            async_update=async_update,
            reset_every=reset_every,
            replay_buffer_class=replay_buffer_class,
            replay_buffer_kwargs=replay_buffer_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            policy_kwargs=policy_kwargs,
            verbose=verbose,
            seed=seed,
            device=device,
            torch_threads=torch_threads,
            _init_setup_model=_init_setup_model,
        )

    @classmethod
    def load(cls, path: Any, *args: Any, **kwargs: Any) -> Any:
        """SB3's ``load``; also takes the files of the 0.5 development builds' ``DENFAC(..., ent_coef=...)``, this
        algorithm before it had its own class (a DENFACPolicy with ``soft_actor`` in its ``policy_kwargs``)."""
        saved = stored_values(path, "policy_class", "policy_kwargs")
        saved_kwargs = saved.get("policy_kwargs")
        if saved.get("policy_class") is DENFACPolicy and isinstance(saved_kwargs, dict) and saved_kwargs.get("soft_actor"):
            kwargs["custom_objects"] = {"policy_class": SoftDENFACPolicy, **(kwargs.get("custom_objects") or {})}
        return super().load(path, *args, **kwargs)

    def _setup_model(self) -> None:
        self.policy_kwargs.pop("soft_actor", None)  # the 0.5 development builds' flag (:meth:`load`)
        super()._setup_model()

    def _policy_settings(self) -> dict[str, Any]:
        return dict(ent_coef=self.ent_coef, target_entropy=self.target_entropy)

    def _apply_learning_rates(self, progress_remaining: float) -> dict[str, float]:
        """DENFAC's rates, and the tuned alpha's at the actor's rate (as SB3's SAC)."""
        rates = super()._apply_learning_rates(progress_remaining)
        if self.policy.ent_coef_optimizer is not None:
            update_learning_rate(self.policy.ent_coef_optimizer, rates["actor"])
        return rates

    def _explore(self, observation: Any) -> tuple[np.ndarray, np.ndarray]:
        """a ~ pi(.|s), SAC's squashed Gaussian; D's behaviour mean is the actor's deterministic action tanh(m(s)),
        from the same forward pass."""
        self.policy.set_training_mode(False)
        obs, _ = self.policy.obs_to_tensor(observation)
        with th.no_grad():
            mean, log_std, _ = self.actor.get_action_dist_params(obs)
            sampled = self.actor.action_dist.actions_from_params(mean, log_std)
        shape = (-1, *self.action_space.shape)  # the actor's (n_envs, dim(A)) as the action space's shape
        actions, means = (x.cpu().numpy().reshape(shape).astype(np.float32) for x in (sampled, th.tanh(mean)))
        return actions, means

    def _bootstrap_value(
        self, updater: Updater, next_obs: th.Tensor, bounds: tuple[float, float] | None
    ) -> tuple[th.Tensor, th.Tensor]:
        """SAC's soft value of eq. (4)'s next state, Q_{k-1}(s', a') - alpha log pi_{k-1}(a'|s') with a' sampled, the
        Q term clipped to ``bounds``; and the fraction clipped."""
        assert isinstance(updater, SoftActorFit)
        actions, log_prob = updater.sample_actor(next_obs)
        next_q, clipped = clip_bootstrap(updater.critic(next_obs, actions), bounds)
        return next_q - updater.policy.entropy_coefficient() * log_prob, clipped  # the fitted copy's alpha

    def _record_update(self, updater: Updater, *args: Any) -> None:
        """DENFAC's keys, and SB3 SAC's ``train/ent_coef`` and ``train/ent_coef_loss``."""
        super()._record_update(updater, *args)
        assert isinstance(updater, SoftActorFit)
        self.logger.record("train/ent_coef", self.policy.entropy_coefficient().item())
        self.logger.record("train/ent_coef_loss", updater.ent_coef_loss.item())

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        state_dicts, variables = super()._get_torch_save_params()
        if self.policy.ent_coef_optimizer is not None:  # the tuned alpha's Adam (log alpha is in the policy's)
            state_dicts.append("policy.ent_coef_optimizer")
        return state_dicts, variables
