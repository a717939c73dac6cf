"""SoftDENFAC: DENFAC's Algorithm 1 with SAC's stochastic actor and soft targets inside the fitted iterations."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
import torch as th
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.utils import update_learning_rate

from sb3_denfac.common.docstrings import check_forwarded, with_parent_params
from sb3_denfac.common.model_files import stored_values
from sb3_denfac.denfac.denfac import DENFAC
from sb3_denfac.denfac.policies import DENFACPolicy
from sb3_denfac.denfac.settings import check_soft_settings
from sb3_denfac.denfac.update_paths import UpdaterClasses
from sb3_denfac.denfac.updaters import Updater
from sb3_denfac.soft_denfac.policies import MlpPolicy, MultiInputPolicy, SoftDENFACPolicy
from sb3_denfac.soft_denfac.updaters import SOFT_UPDATERS, SoftActorFit


@with_parent_params(DENFAC)
class SoftDENFAC(DENFAC):
    """DENFAC (Algorithm 1: K fitted iterations over the whole replay buffer D after every episode) with SB3 SAC's
    actor in place of the deterministic mu(s) of eq. (5) (Haarnoja et al. 2018).

    - The actor is a squashed Gaussian pi(a|s) (:class:`~.policies.SoftDENFACActor`), played as sampled.
    - At every fitted iteration, after the critic's fit on eq. (4), G steps of SAC's actor objective,
      alpha log pi(a|s) - min_j Q_j(s, a) (eq. 7), each followed by a step of the tuned alpha (eq. 18).
    - The targets of eq. (4) are soft: r + gamma (Q_{k-1}(s', a') - alpha log pi_{k-1}(a' | s')), a' ~ pi_{k-1}(.|s')
      (eq. 3), drawn anew at every fitted iteration.

    What belongs to DENFAC's deterministic actor is not an argument here: the truncated Gaussian's ``sigma``, the
    importance ``weighting`` of its behaviour density, ``inverting_gradients`` (tanh bounds the actions) and TD3's target
    smoothing (:attr:`PINNED`: each refused by name). ``frozen_targets=False`` (CrossQ's joint
    bootstrap) takes the soft value: every critic step reads Q(s', a') - alpha log pi(a' | s') at the iteration's
    sampled a'. Why a soft actor inside DENFAC and where it stands against the deterministic one: docs/algorithms.md.

    :param ent_coef: alpha, SB3 SAC's ``ent_coef``: "auto" (default; tuned towards ``target_entropy``, from 1),
        "auto_<x>" (tuned, from x) or a float (fixed)
    :param target_entropy: the entropy the tuned alpha steers towards (SAC's eq. 18; "auto": -dim(A))
    :param actor_proximal: lambda of DENFAC's proximal anchor on the soft actor's deterministic action tanh(m(s)): each
        actor step minimises SAC's objective divided by the mean norm of dQ/da plus lambda 1/B sum ||tanh(m(s)) -
        tanh(m_old(s))||^2, m_old the actor's mean at the start of the update (:meth:`~.updaters.SoftActorFit.fit_actor`;
        the action move at which the two balance is about 1/(2 lambda), whatever the rewards' scale); default 0.0,
        SAC's objective as written
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

    #: DENFAC's settings of its deterministic actor that SoftDENFAC pins, and why
    PINNED: ClassVar[dict[str, str]] = {
        "sigma": "SAC's actor samples from its own Gaussian (DENFAC's truncated Gaussian's sigma)",
        "weighting": "no importance weights of a behaviour density: c = 1",
        "inverting_gradients": "tanh bounds the actions",
        "target_policy_noise": "the next actions of the targets are sampled from pi",
        "target_noise_clip": "the next actions of the targets are sampled from pi",
    }
    #: the values SoftDENFAC gives them
    _PINNED_VALUES: ClassVar[dict[str, Any]] = dict(inverting_gradients=False, weighting="none", target_policy_noise=0.0)

    def __init__(
        self,
        policy: str | type[SoftDENFACPolicy],
        env: GymEnv | str,
        *,
        bootstrap_bounds: bool = True,
        prioritized: str | dict[str, Any] = "none",
        ent_coef: str | float = "auto",
        target_entropy: str | float = "auto",
        actor_proximal: float = 0.0,
        policy_kwargs: dict[str, Any] | None = None,
        **kwargs: Any,
    ):
        check_forwarded(type(self), kwargs, self.PINNED)
        check_soft_settings(ent_coef, target_entropy, prioritized)
        self.ent_coef, self.target_entropy = ent_coef, target_entropy
        super().__init__(
            policy,
            env,
            bootstrap_bounds=bootstrap_bounds,
            prioritized=prioritized,
            actor_proximal=actor_proximal,
            policy_kwargs=policy_kwargs,
            **self._PINNED_VALUES,
            **kwargs,
        )

    @classmethod
    def load(cls, path: Any, *args: Any, **kwargs: Any) -> Any:
        """SB3's ``load``; also takes the files of the 0.5 development builds' ``DENFAC(..., ent_coef=...)``, this
        algorithm before it had its own class (a DENFACPolicy with ``soft_actor`` in its ``policy_kwargs``), whose soft
        actor had no proximal anchor whatever their ``actor_proximal`` (DENFAC's 1.0): they load with 0."""
        saved = stored_values(path, "policy_class", "policy_kwargs")
        saved_kwargs = saved.get("policy_kwargs")
        development_build = saved.get("policy_class") is DENFACPolicy and isinstance(saved_kwargs, dict)
        development_build = development_build and bool(saved_kwargs.get("soft_actor"))  # type: ignore[union-attr]
        if development_build:
            kwargs["custom_objects"] = {
                "policy_class": SoftDENFACPolicy,
                "actor_proximal": 0.0,
                **(kwargs.get("custom_objects") or {}),
            }
        return super().load(path, *args, **kwargs)

    def _setup_model(self) -> None:
        self.policy_kwargs.pop("soft_actor", None)  # the 0.5 development builds' flag (:meth:`load`)
        super()._setup_model()

    def _policy_settings(self) -> dict[str, Any]:
        return {**super()._policy_settings(), "ent_coef": self.ent_coef, "target_entropy": self.target_entropy}

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

    def _next_actions(self, updater: Updater, next_obs: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """a' ~ pi_{k-1}(.|s') and alpha log pi_{k-1}(a' | s'): SAC's soft value of eq. (4)'s next state is
        Q_{k-1}(s', a') - alpha log pi_{k-1}(a' | s'), the Q term clipped to the bootstrap bounds."""
        assert isinstance(updater, SoftActorFit)
        actions, log_prob = updater.sample_actor(next_obs)
        return actions, updater.policy.entropy_coefficient() * log_prob  # the fitted copy's alpha

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
