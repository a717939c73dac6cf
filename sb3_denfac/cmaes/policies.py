"""Actor-only policy searched by CMA-ES: the paper's actor network, without batch norm by default (section 4)."""

from __future__ import annotations

from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.preprocessing import get_action_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, FlattenExtractor
from stable_baselines3.common.type_aliases import PyTorchObs
from torch import nn

from sb3_denfac.common.networks import create_bn_mlp


class CMAESPolicy(BasePolicy):
    """Deterministic actor mu(s) with a linear output, clamped to [-1, 1] by ``predict`` (then un-scaled).

    "Only CMA-ES do not use batch normalization for its policy as it does not rely on the gradient." With
    ``batch_norm=True`` the batch-norm layers stay in eval mode (their running statistics never move) and only their
    affine parameters are searched.

    :param observation_space: observation space
    :param action_space: action space (Box)
    :param net_arch: hidden layer sizes (paper: [5] Acrobot, [20] Cartpole, [20, 10] Half-Cheetah; default [20])
    :param activation_fn: hidden activation (paper: leaky ReLU)
    :param batch_norm: batch norm before every linear layer except the last (paper: False for CMA-ES)
    :param init: "paper" (N(0, 0.01^2) weights, zero biases: the search starts near the zero policy) or "default"
    :param features_extractor_class: features extractor (flatten for vectors)
    :param features_extractor_kwargs: its keyword arguments
    :param normalize_images: divide images by 255
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int] | None = None,
        activation_fn: type[nn.Module] = nn.LeakyReLU,
        batch_norm: bool = False,
        init: str = "paper",
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
    ):
        super().__init__(
            observation_space,
            action_space,
            features_extractor_class,
            features_extractor_kwargs,
            normalize_images=normalize_images,
            squash_output=True,  # predict() un-scales from [-1, 1]
        )
        if isinstance(net_arch, dict):
            net_arch = net_arch.get("pi")
        self.net_arch = [20] if net_arch is None else list(net_arch)
        self.activation_fn = activation_fn
        self.batch_norm = batch_norm
        self.init = init
        self.features_extractor = self.make_features_extractor()
        self.actor = create_bn_mlp(
            self.features_extractor.features_dim,
            get_action_dim(action_space),
            self.net_arch,
            batch_norm=batch_norm,
            activation_fn=activation_fn,
            init=init,
        )
        self.set_training_mode(False)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            dict(
                net_arch=self.net_arch,
                activation_fn=self.activation_fn,
                batch_norm=self.batch_norm,
                init=self.init,
                features_extractor_class=self.features_extractor_class,
                features_extractor_kwargs=self.features_extractor_kwargs,
            )
        )
        return data

    def set_training_mode(self, mode: bool) -> None:
        # Never trained by gradient: batch norm (if any) always uses its fixed running statistics.
        super().set_training_mode(False)

    def forward(self, obs: PyTorchObs) -> th.Tensor:
        """Raw (unclamped) actor output in the scaled action space."""
        return self.actor(self.extract_features(obs, self.features_extractor))

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return th.clamp(self(observation), -1.0, 1.0)


MlpPolicy = CMAESPolicy
