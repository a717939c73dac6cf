"""The deterministic actor mu(s) of the algorithms other than SoftDENFAC (SAC's actor), and the one ``net_arch`` parser.

Paper, section 4: "The actor policy is a truncated Gaussian policy [...] where the mean is determined by the output of
the last linear layer"; every algorithm of the paper, CMA-ES included, uses that actor network. mu(s) is
:func:`~sb3_denfac.common.networks.create_bn_mlp` on the features of s (leaky ReLU, batch norm before every linear
layer but the last, linear output in SB3's scaled action space [-1, 1]); SB3's DDPG ends it with a tanh instead
(``tanh_output=True``). An unbounded output is clamped to [-1, 1] by ``predict`` only, never in the gradient path.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.preprocessing import get_action_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, FlattenExtractor
from stable_baselines3.common.type_aliases import PyTorchObs
from torch import nn

from sb3_denfac.common.networks import create_bn_mlp
from sb3_denfac.common.truncated_normal import sample_truncated_normal


def parse_net_arch(
    net_arch: Sequence[int] | dict[str, Sequence[int]] | None, defaults: dict[str, Sequence[int]]
) -> dict[str, list[int]]:
    """Hidden sizes per network from SB3's ``net_arch``: one list for every network, or a dict keyed like ``defaults``
    (``pi`` for the actor, ``qf`` or ``vf`` for the critic) whose missing keys take the default.

    :return: a dict with the keys of ``defaults``.
    """
    if net_arch is None:
        net_arch = {}
    if isinstance(net_arch, dict):
        unknown = set(net_arch) - set(defaults)
        if unknown:
            raise ValueError(f"net_arch keys must be among {sorted(defaults)}, got {sorted(unknown)}")
        return {key: [int(h) for h in net_arch.get(key, default)] for key, default in defaults.items()}
    return {key: [int(h) for h in net_arch] for key in defaults}


class DeterministicActor(BasePolicy):
    """Deterministic actor mu(s) (module doc); ``predict`` clamps mu(s) to [-1, 1], or, with ``sigma`` set and
    ``deterministic=False``, samples the truncated Gaussian N(mu(s), sigma^2) on [-1, 1].

    :param observation_space: observation space
    :param action_space: Box action space
    :param net_arch: hidden layer sizes (paper: [5] Acrobot, [20] Cartpole, [20, 10] Half-Cheetah)
    :param features_extractor: the features extractor, as SB3's TD3 ``Actor`` takes it; None builds one from
        ``features_extractor_class`` (an actor that is the whole policy, CMA-ES)
    :param features_dim: size of the features (None: the extractor's)
    :param activation_fn: hidden activation (paper: leaky ReLU)
    :param batch_norm: batch norm before every linear layer except the last (paper)
    :param bn_momentum: BatchNorm1d momentum (None: cumulative average)
    :param init: "paper" (N(0, 0.01^2) weights, zero biases) or "default" (PyTorch)
    :param tanh_output: end with a tanh (SB3's DDPG); False: linear output (paper, inverting gradients)
    :param sigma: std of the truncated Gaussian of ``predict(deterministic=False)``; None: always deterministic
    :param normalize_images: divide images by 255
    :param features_extractor_class: features extractor built when ``features_extractor`` is None
    :param features_extractor_kwargs: its keyword arguments
    """

    #: Attribute of the MLP: "mu" as in SB3's TD3 ``Actor`` (DENFAC, DDPG; DENFAC's fast updater reads
    #: ``policy.actor.mu``); a subclass that is a whole policy names it "actor" (CMA-ES, NFAC, CACLA), the state-dict
    #: keys its saved models use.
    mlp_name: ClassVar[str] = "mu"
    action_space: spaces.Box

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: BaseFeaturesExtractor | None = None,
        features_dim: int | None = None,
        activation_fn: type[nn.Module] = nn.LeakyReLU,
        batch_norm: bool = True,
        bn_momentum: float | None = 0.1,
        init: str = "paper",
        tanh_output: bool = False,
        sigma: float | None = None,
        normalize_images: bool = True,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        **base_kwargs: Any,
    ):
        super().__init__(
            observation_space,
            action_space,
            features_extractor_class,
            features_extractor_kwargs,
            features_extractor=features_extractor,
            normalize_images=normalize_images,
            squash_output=True,  # predict() un-scales from [-1, 1]
            **base_kwargs,
        )
        if self.features_extractor is None:
            self.features_extractor = self.make_features_extractor()
        self.net_arch = list(net_arch)
        self.features_dim = self.features_extractor.features_dim if features_dim is None else features_dim
        self.activation_fn = activation_fn
        self.batch_norm = batch_norm
        self.bn_momentum = bn_momentum
        self.init = init
        self.tanh_output = tanh_output
        self.sigma = sigma
        mlp = create_bn_mlp(
            self.features_dim, get_action_dim(action_space), self.net_arch, batch_norm, activation_fn, bn_momentum, init
        )  # type: ignore[arg-type]
        setattr(self, self.mlp_name, nn.Sequential(*mlp, nn.Tanh()) if tanh_output else mlp)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            dict(
                net_arch=self.net_arch,
                features_dim=self.features_dim,
                features_extractor=self.features_extractor,
                activation_fn=self.activation_fn,
                batch_norm=self.batch_norm,
                bn_momentum=self.bn_momentum,
                init=self.init,
                tanh_output=self.tanh_output,
                sigma=self.sigma,
            )
        )
        return data

    def actor_mean(self, obs: PyTorchObs) -> th.Tensor:
        """mu(s) in the scaled action space, unclamped (the behaviour mean of the exploration)."""
        return getattr(self, self.mlp_name)(self.extract_features(obs, self.features_extractor))

    def forward(self, obs: PyTorchObs) -> th.Tensor:
        """mu(s), as SB3's TD3 ``Actor.forward``."""
        return self.actor_mean(obs)

    def sample(self, mean: np.ndarray) -> np.ndarray:
        """Truncated Gaussian N(mean, sigma^2) on [-1, 1] (numpy, seeded by SB3 through ``np.random``)."""
        assert self.sigma is not None, "this actor has no exploration sigma"
        return sample_truncated_normal(mean, self.sigma, -1.0, 1.0)

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        mean = self.actor_mean(observation)
        if deterministic or self.sigma is None:
            return mean.clamp(-1.0, 1.0)
        return th.as_tensor(self.sample(mean.cpu().numpy()), device=mean.device)
