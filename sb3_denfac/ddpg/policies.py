"""Batch-normalised DDPG actor and critic (paper, section 4) with an optional unbounded actor for inverting gradients.

Networks come from :func:`sb3_denfac.common.networks.create_bn_mlp`: leaky ReLU, linear last layer, batch norm before
every linear layer except the last ("except the last two layers"), N(0, 0.01^2) weights. The actor ends with a tanh
(SB3's DDPG) unless ``tanh_output=False``, which inverting gradients (Hausknecht & Stone 2016) requires; the unbounded
actor's output is clamped to [-1, 1] by ``predict`` only, never inside the gradient path.
"""

from __future__ import annotations

from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BaseModel, ContinuousCritic
from stable_baselines3.common.preprocessing import get_action_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, FlattenExtractor, get_actor_critic_arch
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from stable_baselines3.td3.policies import TD3Policy
from torch import nn

from sb3_denfac.common.actor import DeterministicActor
from sb3_denfac.common.networks import INITS, create_bn_mlp


class BNActor(DeterministicActor):
    """DDPG's mu(s): :class:`~sb3_denfac.common.actor.DeterministicActor` (always deterministic, as SB3's TD3 ``Actor``)
    ending with a tanh unless ``tanh_output=False`` (inverting gradients)."""

    def __init__(self, *args: Any, tanh_output: bool = True, **kwargs: Any):
        super().__init__(*args, tanh_output=tanh_output, sigma=None, **kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        del data["sigma"]  # always None
        return data


class BNContinuousCritic(ContinuousCritic):
    """Q(s, a) critic(s) built by ``create_bn_mlp`` on the concatenated [features, action] input.

    Same interface as SB3's ``ContinuousCritic`` (``forward`` returns a tuple, ``q1_forward``).

    :param net_arch: hidden layer sizes (paper: [50, 7])
    :param n_critics: number of Q networks (DDPG: 1)
    :param share_features_extractor: share the actor's features extractor
    :param batch_norm: batch norm before every linear layer except the last (paper)
    :param init: "paper" or "default" initialisation
    :param bn_momentum: momentum of the batch-norm running statistics

    (the other arguments as in :class:`BNActor`)
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: BaseFeaturesExtractor,
        features_dim: int,
        activation_fn: type[nn.Module] = nn.LeakyReLU,
        normalize_images: bool = True,
        n_critics: int = 1,
        share_features_extractor: bool = False,
        batch_norm: bool = True,
        init: str = "paper",
        bn_momentum: float = 0.1,
    ):
        # Skip ContinuousCritic.__init__ (it builds SB3's MLPs); forward/q1_forward are inherited.
        BaseModel.__init__(
            self, observation_space, action_space, features_extractor=features_extractor, normalize_images=normalize_images
        )
        self.share_features_extractor = share_features_extractor
        self.n_critics = n_critics
        self.q_networks: list[nn.Module] = []
        for idx in range(n_critics):
            q_net = create_bn_mlp(
                features_dim + get_action_dim(action_space), 1, net_arch, batch_norm, activation_fn, bn_momentum, init
            )
            self.add_module(f"qf{idx}", q_net)
            self.q_networks.append(q_net)


class DDPGPolicy(TD3Policy):
    """Actor, critic and their targets for :class:`sb3_denfac.ddpg.DDPG`.

    :param observation_space: observation space
    :param action_space: action space (Box)
    :param lr_schedule: learning-rate schedule (the algorithm sets the actor and critic rates before each update)
    :param net_arch: ``dict(pi=[...], qf=[...])`` or one list for both; default ``dict(pi=[20], qf=[50, 7])`` (paper)
    :param activation_fn: hidden activation (paper: leaky ReLU)
    :param features_extractor_class: features extractor
    :param features_extractor_kwargs: its keyword arguments
    :param normalize_images: divide images by 255
    :param optimizer_class: optimizer (Adam)
    :param optimizer_kwargs: optimizer keyword arguments other than the learning rate
    :param n_critics: number of Q networks (DDPG: 1)
    :param share_features_extractor: share the features extractor between actor and critic
    :param batch_norm: batch norm in actor and critic (paper: True)
    :param tanh_output: tanh-bounded actor (True) or unbounded linear actor (False, needed by inverting gradients)
    :param init: "paper" (N(0, 0.01^2) weights, zero biases) or "default" (PyTorch)
    :param bn_momentum: momentum of the batch-norm running statistics
    """

    actor: BNActor
    actor_target: BNActor
    critic: BNContinuousCritic
    critic_target: BNContinuousCritic

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        activation_fn: type[nn.Module] = nn.LeakyReLU,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        n_critics: int = 1,
        share_features_extractor: bool = False,
        batch_norm: bool = True,
        tanh_output: bool = True,
        init: str = "paper",
        bn_momentum: float = 0.1,
    ):
        if init not in INITS:
            raise ValueError(f"init must be one of {INITS}, got {init!r}")
        if net_arch is None:
            net_arch = dict(pi=[20], qf=[50, 7])
        get_actor_critic_arch(net_arch)  # validates the format early
        self.batch_norm = batch_norm
        self.tanh_output = tanh_output
        self.init = init
        self.bn_momentum = bn_momentum
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            net_arch,
            activation_fn,
            features_extractor_class,
            features_extractor_kwargs,
            normalize_images,
            optimizer_class,
            optimizer_kwargs,
            n_critics,
            share_features_extractor,
        )

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            dict(batch_norm=self.batch_norm, tanh_output=self.tanh_output, init=self.init, bn_momentum=self.bn_momentum)
        )
        return data

    def make_actor(self, features_extractor: BaseFeaturesExtractor | None = None) -> BNActor:
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        extra = dict(batch_norm=self.batch_norm, tanh_output=self.tanh_output, init=self.init, bn_momentum=self.bn_momentum)
        return BNActor(**actor_kwargs, **extra).to(self.device)

    def make_critic(self, features_extractor: BaseFeaturesExtractor | None = None) -> BNContinuousCritic:
        critic_kwargs = self._update_features_extractor(self.critic_kwargs, features_extractor)
        extra = dict(batch_norm=self.batch_norm, init=self.init, bn_momentum=self.bn_momentum)
        return BNContinuousCritic(**critic_kwargs, **extra).to(self.device)

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self.actor._predict(observation, deterministic)


MlpPolicy = DDPGPolicy
