"""Actor-only policy searched by CMA-ES: the paper's actor network, without batch norm by default (section 4)."""

from __future__ import annotations

from typing import Any

from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, FlattenExtractor
from torch import nn

from sb3_denfac.common.actor import DeterministicActor, parse_net_arch


class CMAESPolicy(DeterministicActor):
    """The actor mu(s) alone (:class:`~sb3_denfac.common.actor.DeterministicActor`, linear output), clamped to
    [-1, 1] by ``predict`` (then un-scaled); ``forward`` gives mu(s) unclamped.

    "Only CMA-ES do not use batch normalization for its policy as it does not rely on the gradient." With
    ``batch_norm=True`` the batch-norm layers stay in eval mode (their running statistics never move) and only their
    affine parameters are searched.

    :param observation_space: observation space
    :param action_space: action space (Box)
    :param net_arch: hidden layer sizes (paper: [5] Acrobot, [20] Cartpole, [20, 10] Half-Cheetah; default [20]), or
        a dict whose ``pi`` entry is used
    :param activation_fn: hidden activation (paper: leaky ReLU)
    :param batch_norm: batch norm before every linear layer except the last (paper: False for CMA-ES)
    :param init: "paper" (N(0, 0.01^2) weights, zero biases: the search starts near the zero policy) or "default"
    :param features_extractor_class: features extractor (flatten for vectors)
    :param features_extractor_kwargs: its keyword arguments
    :param normalize_images: divide images by 255
    """

    mlp_name = "actor"  # the state-dict keys of the saved models (actor.0.weight, ...)

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        activation_fn: type[nn.Module] = nn.LeakyReLU,
        batch_norm: bool = False,
        init: str = "paper",
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
    ):
        if isinstance(net_arch, dict):
            net_arch = net_arch.get("pi")
        super().__init__(
            observation_space,
            action_space,
            parse_net_arch(net_arch, {"pi": [20]})["pi"],
            activation_fn=activation_fn,
            batch_norm=batch_norm,
            init=init,
            normalize_images=normalize_images,
            features_extractor_class=features_extractor_class,
            features_extractor_kwargs=features_extractor_kwargs,
        )
        self.set_training_mode(False)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        for key in ("features_dim", "features_extractor", "bn_momentum", "tanh_output", "sigma"):  # fixed here
            del data[key]
        data.update(
            features_extractor_class=self.features_extractor_class, features_extractor_kwargs=self.features_extractor_kwargs
        )
        return data

    def set_training_mode(self, mode: bool) -> None:
        # Never trained by gradient: batch norm (if any) always uses its fixed running statistics.
        super().set_training_mode(False)


MlpPolicy = CMAESPolicy
