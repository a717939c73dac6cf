"""The policy of NFAC and CACLA: the deterministic actor mu(s) with a state-value critic V(s) (paper, section 2), and
the gradient-free refresh of the batch-norm running statistics they use (see :mod:`sb3_denfac.common.on_policy`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, FlattenExtractor
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from torch import nn

from sb3_denfac.common.actor import DeterministicActor, parse_net_arch
from sb3_denfac.common.compat import LegacyOptimizerAliasesMixin
from sb3_denfac.common.networks import create_bn_mlp, reset_parameters_, set_bn_training_mode

#: Hidden sizes: the paper's Cartpole actor and its critics.
DEFAULT_NET_ARCH: dict[str, list[int]] = {"pi": [20], "vf": [50, 7]}


class DeterministicActorValuePolicy(LegacyOptimizerAliasesMixin, DeterministicActor):
    """Deterministic actor mu(s) (linear output in the [-1, 1]-scaled action space) and state-value critic V(s).

    The actor is :class:`~sb3_denfac.common.actor.DeterministicActor` (this policy is one, its MLP at ``actor``, the
    critic's at ``critic``); both networks are :func:`~sb3_denfac.common.networks.create_bn_mlp` MLPs (leaky ReLU,
    batch norm before every linear layer but the last, i.e. "except on the last two layers").
    ``predict(deterministic=True)`` returns mu(s) clipped to the action bounds; ``deterministic=False`` samples the
    truncated Gaussian exploration policy. Each network carries its optimizer (``actor.optimizer``,
    ``critic.optimizer``), as in SB3's TD3.

    :param observation_space: observation space (Box, Discrete, MultiDiscrete or MultiBinary: SB3's preprocessing).
    :param action_space: Box action space with finite bounds.
    :param lr_schedule: initial learning rate of both networks (the algorithm sets alpha_a and alpha_c).
    :param critic_lr_schedule: initial critic rate; defaults to ``lr_schedule``.
    :param sigma: standard deviation of the truncated Gaussian exploration in the scaled space (paper: 0.05).
    :param net_arch: hidden sizes, a list for both networks or ``dict(pi=[...], vf=[...])``
        (default: actor [20] as the paper's Cartpole actor, critic [50, 7] as the paper's critics).
    :param batch_norm: batch normalisation ("NFAC+", "CACLA+"); False gives plain MLPs.
    :param activation_fn: hidden activation (paper: leaky ReLU).
    :param bn_momentum: momentum of the batch-norm running statistics.
    :param init: "paper" (N(0, 0.01^2) weights, zero biases) or "default" (PyTorch).
    :param features_extractor_class: features extractor (default: flatten).
    :param features_extractor_kwargs: its keyword arguments.
    :param normalize_images: SB3 image normalisation flag.
    :param optimizer_class: optimiser of both networks (default Adam).
    :param optimizer_kwargs: its keyword arguments, except the learning rate.
    :param share_features_extractor: one features extractor for actor and critic (trained by both optimisers, as SB3's
        ActorCriticPolicy), else one each (``features_extractor`` is the actor's, ``vf_features_extractor`` the critic's).
    """

    mlp_name = "actor"  # the state-dict keys of the saved models (actor.0.weight, ...)

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        critic_lr_schedule: Schedule | None = None,
        sigma: float = 0.05,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        batch_norm: bool = True,
        activation_fn: type[nn.Module] = nn.LeakyReLU,
        bn_momentum: float = 0.1,
        init: str = "paper",
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        share_features_extractor: bool = True,
    ):
        archs = parse_net_arch(net_arch, DEFAULT_NET_ARCH)
        super().__init__(
            observation_space,
            action_space,
            archs["pi"],
            activation_fn=activation_fn,
            batch_norm=batch_norm,
            bn_momentum=bn_momentum,
            init=init,
            sigma=sigma,
            normalize_images=normalize_images,
            features_extractor_class=features_extractor_class,
            features_extractor_kwargs=features_extractor_kwargs,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
        )
        self.net_arch = dict(DEFAULT_NET_ARCH) if net_arch is None else net_arch
        # As SB3's ActorCriticPolicy: a shared extractor is trained by both optimisers, else each network has its own.
        self.share_features_extractor = share_features_extractor
        self.vf_features_extractor = self.features_extractor if share_features_extractor else self.make_features_extractor()
        self.critic = create_bn_mlp(self.features_dim, 1, archs["vf"], batch_norm, activation_fn, bn_momentum, init)

        self.lr_schedule = lr_schedule
        self.critic_lr_schedule = critic_lr_schedule or lr_schedule
        # As SB3's TD3/SAC: each network carries its optimizer (the features extractor with it, see actor_modules).
        self.actor.optimizer = self._make_optimizer(self.actor_modules(), lr_schedule)
        self.critic.optimizer = self._make_optimizer(self.critic_modules(), self.critic_lr_schedule)

    def actor_modules(self) -> list[nn.Module]:
        """mu(s) as trained by the actor optimiser: its features extractor and MLP."""
        return [self.features_extractor, self.actor]

    def critic_modules(self) -> list[nn.Module]:
        """V(s) as trained by the critic optimiser: its features extractor and MLP."""
        return [self.vf_features_extractor, self.critic]

    def _make_optimizer(self, modules: list[nn.Module], schedule: Schedule) -> th.optim.Optimizer:
        params = [p for module in modules for p in module.parameters()]
        return self.optimizer_class(params, lr=schedule(1), **self.optimizer_kwargs)  # type: ignore[call-arg]

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        for key in ("features_dim", "features_extractor", "tanh_output"):  # fixed here
            del data[key]
        data.update(
            dict(
                lr_schedule=self._dummy_schedule,
                critic_lr_schedule=self._dummy_schedule,
                sigma=self.sigma,
                net_arch=self.net_arch,
                batch_norm=self.batch_norm,
                activation_fn=self.activation_fn,
                bn_momentum=self.bn_momentum,
                init=self.init,
                features_extractor_class=self.features_extractor_class,
                features_extractor_kwargs=self.features_extractor_kwargs,
                optimizer_class=self.optimizer_class,
                optimizer_kwargs=self.optimizer_kwargs,
                share_features_extractor=self.share_features_extractor,
            )
        )
        return data

    def reset_critic(self) -> None:
        """Re-initialise V's MLP (weights and batch-norm statistics) and the critic optimiser state (NFAC's
        ``reset_critic``); a custom features extractor keeps its weights."""
        lr = self.critic.optimizer.param_groups[0]["lr"]
        reset_parameters_(self.critic, self.init)
        self.critic.optimizer = self._make_optimizer(self.critic_modules(), lambda _: lr)

    def predict_values(self, obs: PyTorchObs) -> th.Tensor:
        """V(s), shape (batch, 1)."""
        return self.critic(self.extract_features(obs, self.vf_features_extractor))

    @th.no_grad()
    def refresh_bn_statistics(self, obs: PyTorchObs, exact_when_fresh: bool = False, critic_only: bool = False) -> None:
        """Move the running statistics of the BN layers (features extractors included) toward those of ``obs`` by one
        gradient-free train-mode forward; see :func:`refresh_bn_statistics`. Needs at least two observations."""
        modules = self.critic_modules() if critic_only else [*self.actor_modules(), *self.critic_modules()]
        modules = list(dict.fromkeys(modules))  # a shared extractor once

        def forward() -> None:
            self.predict_values(obs)
            if not critic_only:
                self.actor_mean(obs)

        refresh_bn_statistics(modules, forward, len(obs), exact_when_fresh)  # type: ignore[arg-type]

    def forward(self, obs: PyTorchObs, deterministic: bool = False) -> th.Tensor:  # type: ignore[override]
        """The action in the scaled space (a policy's forward, as SB3's ActorCriticPolicy; mu(s) is ``actor_mean``)."""
        return self._predict(obs, deterministic=deterministic)


@th.no_grad()
def refresh_bn_statistics(
    modules: list[nn.Module], forward: Callable[[], Any], n_inputs: int, exact_when_fresh: bool = False
) -> None:
    """Update the running statistics of the BN layers of ``modules`` with ``forward()`` run once in BN train mode.

    The statistics move toward those of the forwarded batch with each layer's momentum; with ``exact_when_fresh``, a
    layer that has never seen a batch (new or re-initialised network) takes them as they are. Needs ``n_inputs`` >= 2.
    """
    if n_inputs < 2:
        return
    fresh = [
        m
        for module in modules
        for m in module.modules()
        if exact_when_fresh and isinstance(m, nn.modules.batchnorm._BatchNorm) and m.num_batches_tracked == 0
    ]
    momenta = [m.momentum for m in fresh]
    for layer in fresh:
        layer.momentum = 1.0
    for module in modules:
        set_bn_training_mode(module, True)
    try:
        forward()
    finally:
        for module in modules:
            set_bn_training_mode(module, False)
        for layer, momentum in zip(fresh, momenta, strict=True):
            layer.momentum = momentum
