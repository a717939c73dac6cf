"""SoftDENFAC's networks: SB3 SAC's squashed Gaussian actor, DENFAC's critics, and SAC's entropy coefficient alpha."""

from __future__ import annotations

from typing import Any

import torch as th
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, CombinedExtractor
from stable_baselines3.common.type_aliases import PyTorchObs
from stable_baselines3.sac.policies import Actor as SACActor
from torch import nn

from sb3_denfac.common.networks import reset_parameters_
from sb3_denfac.denfac.policies import DENFACBasePolicy
from sb3_denfac.denfac.settings import check_target_entropy, parse_ent_coef


class SoftDENFACActor(SACActor):
    """SB3's SAC actor (Haarnoja et al. 2018): a squashed Gaussian pi(a|s) = tanh(N(m(s), exp(l(s))^2)) whose mean m and
    log std l (clamped to [-20, 2]) are two linear heads on one MLP (``net_arch`` pi, no batch norm);
    ``action_log_prob(s)`` gives a reparameterised sample and its log-density.

    ``forward(s)`` is the deterministic action tanh(m(s)), as DENFAC's actor's ``forward`` is mu(s) (what exploration
    and evaluation read as the actor's mean); ``predict(deterministic=False)`` samples pi(.|s). Its weights start (and
    ``reset_actor`` restarts them) from PyTorch's initialisation, SAC's; the policy's ``init`` applies to the critic.
    """

    def forward(self, obs: PyTorchObs, deterministic: bool = True) -> th.Tensor:
        return super().forward(obs, deterministic=deterministic)

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return super().forward(observation, deterministic=deterministic)


class SoftDENFACPolicy(DENFACBasePolicy):
    """DENFAC's critic (:class:`~sb3_denfac.denfac.policies.DENFACBasePolicy`) with :class:`SoftDENFACActor`, and the
    entropy coefficient of SAC's objective: ``log_ent_coef`` (with its optimiser ``ent_coef_optimizer`` when tuned).

    :param ent_coef: alpha (SB3 SAC's ``ent_coef``): "auto" (tuned, from 1), "auto_<x>" (tuned, from x) or a float
        (fixed); SoftDENFAC passes its own
    :param target_entropy: the entropy the tuned alpha steers towards (SAC's eq. 18); "auto": -dim(A)

    The other parameters are :class:`~sb3_denfac.denfac.policies.DENFACBasePolicy`'s, but for ``batch_norm`` (SAC's actor
    has none) and ``sigma`` (the actor explores by sampling; accepted and ignored, as DENFAC's policies get it).
    """

    actor: SoftDENFACActor  # type: ignore[assignment]

    def __init__(self, *args: Any, ent_coef: str | float = "auto", target_entropy: str | float = "auto", **kwargs: Any):
        if kwargs.get("batch_norm"):
            raise ValueError("SoftDENFAC's actor is SAC's squashed Gaussian, which has no batch norm: use batch_norm=False")
        self.ent_coef, self.target_entropy = ent_coef, target_entropy
        super().__init__(*args, **kwargs)

    def make_actor(self) -> nn.Module:
        kwargs = self._update_features_extractor(self.actor_kwargs)
        for key in ("batch_norm", "bn_momentum", "init", "sigma"):  # DENFAC's deterministic actor's
            kwargs.pop(key)
        return SoftDENFACActor(**kwargs)  # type: ignore[arg-type]

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        # alpha = exp(log_ent_coef): a parameter with its own Adam optimiser at the actor's rate when tuned (SAC's
        # ``ent_coef="auto"``), a constant buffer when fixed; the target entropy of the tuning (SAC's eq. 18)
        initial, tuned = parse_ent_coef(self.ent_coef)
        log_value = th.log(th.tensor([initial]))
        self.target_entropy_value = check_target_entropy(self.target_entropy, self.action_space)
        self.ent_coef_optimizer: th.optim.Optimizer | None = None
        if tuned:
            self.log_ent_coef = nn.Parameter(log_value)
            self.ent_coef_optimizer = th.optim.Adam([self.log_ent_coef], lr=self.actor.optimizer.param_groups[0]["lr"])
        else:
            # not saved: a fixed alpha is the model's ``ent_coef`` (a load with another ``ent_coef`` uses it, as SB3's SAC)
            self.register_buffer("log_ent_coef", log_value, persistent=False)

    def entropy_coefficient(self) -> th.Tensor:
        """alpha, detached, shape (1,)."""
        return self.log_ent_coef.detach().exp()

    def temperature_step(self, log_prob: th.Tensor) -> th.Tensor:
        """With a tuned alpha, one Adam step on SAC's eq. 18, -log alpha (log pi(a|s) + target entropy) averaged over
        the samples of ``log_prob`` (detached); returns that loss (0 with a fixed alpha)."""
        if self.ent_coef_optimizer is None:
            return th.zeros(())
        loss = -(self.log_ent_coef * (log_prob.detach() + self.target_entropy_value)).mean()
        self.ent_coef_optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.ent_coef_optimizer.step()
        return loss.detach()

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), "ent_coef": self.ent_coef, "target_entropy": self.target_entropy}

    def reset_actor(self) -> None:
        """Re-initialise the actor from PyTorch's initialisation (SAC's) and forget its Adam state."""
        reset_parameters_(self.actor, "default")
        self.actor.optimizer.state.clear()


class MultiInputPolicy(SoftDENFACPolicy):
    """:class:`SoftDENFACPolicy` for Dict observations (goal-conditioned envs): SB3's ``CombinedExtractor`` by default."""

    def __init__(self, *args: Any, features_extractor_class: type[BaseFeaturesExtractor] = CombinedExtractor, **kwargs: Any):
        super().__init__(*args, features_extractor_class=features_extractor_class, **kwargs)


MlpPolicy = SoftDENFACPolicy
