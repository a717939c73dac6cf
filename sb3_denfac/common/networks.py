"""Batch-normalised MLPs shared by all algorithms (paper, section 4).

"The neural networks use (1) Adam, (2) the leaky rectified linearity, and (3) batch normalization. [...] The last layer
of the critic and actor networks is linear. [...] Each weight is initialized from a normal distribution N(0, 0.01).
Batch normalization is applied on each layer for both the actor and the critic, except on the last two layers."

Counting the input as layer 0 of units u_0, ..., u_n, batch norm is applied to u_0 ... u_{n-2}, i.e. before every
linear layer except the last one. For the critic 50-7 on Acrobot: BN(input) -> 50 -> BN -> 7 -> 1; for the actor with
one hidden layer of 5: BN(input) -> 5 -> 1.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch as th
from sb3_contrib.common.torch_layers import BatchRenorm
from sb3_contrib.common.torch_layers import BatchRenorm1d as ContribBatchRenorm1d
from torch import nn

#: Weight initialisations: "paper" = N(0, 0.01^2) weights and zero biases (authors' code); "default" = PyTorch's.
INITS = ("paper", "default")


def paper_init_(module: nn.Module, std: float = 0.01) -> None:
    """Re-initialise every Linear layer of ``module`` in place with N(0, std^2) weights and zero biases."""
    for layer in module.modules():
        if isinstance(layer, nn.Linear):
            nn.init.normal_(layer.weight, mean=0.0, std=std)
            nn.init.zeros_(layer.bias)


def reset_parameters_(module: nn.Module, init: str = "paper") -> None:
    """Re-initialise ``module`` in place (weights and batch-norm statistics), keeping the same tensors.

    Used by the critic and actor resets of Algorithm 1: in-place re-initialisation keeps optimiser references valid.
    """
    if init not in INITS:
        raise ValueError(f"init must be one of {INITS}, got {init!r}")
    for layer in module.modules():
        if isinstance(layer, (nn.Linear, nn.BatchNorm1d, nn.LayerNorm)):
            layer.reset_parameters()
        elif isinstance(layer, BatchRenorm):  # sb3-contrib's has no reset_parameters: its initial state
            layer.ra_mean.zero_()
            layer.ra_var.fill_(1.0)
            layer.steps.zero_()
            with th.no_grad():
                layer.scale.fill_(1.0)
                layer.bias.zero_()
    if init == "paper":
        paper_init_(module)


class BatchRenorm1d(ContribBatchRenorm1d):
    """sb3-contrib's ``BatchRenorm1d`` (Ioffe 2017, as CrossQ's critic), its state and its arithmetic, with the batch's
    unbiased variance computed in two passes, 1/(N-1) sum (x - mean)^2, instead of ``Tensor.var``.

    The same function up to float rounding (tested to a relative 1e-4 on the gradients, in both phases), and a
    fifth less CPU per critic step (64 or 256 units): on CPU ``Tensor.var`` over the batch dimension costs as much as the
    layer's matrix product, forward and backward. Its state dict is sb3-contrib's, so saved models load either way.
    """

    def forward(self, x: th.Tensor) -> th.Tensor:
        if not self.training:
            return super().forward(x)  # the running statistics
        batch_mean = x.mean(dim=0)
        centred = x - batch_mean
        batch_var = (centred * centred).sum(dim=0) / (x.shape[0] - 1)
        if self.steps > self.warmup_steps:  # type: ignore[operator]
            # sb3-contrib's correction towards the running statistics: r, d detached, the batch's moments not
            running_std = (self.ra_var + self.eps).sqrt()  # type: ignore[operator]
            r = ((batch_var + self.eps).sqrt() / running_std).detach().clamp(1 / self.rmax, self.rmax)
            d = ((batch_mean - self.ra_mean) / running_std).detach().clamp(-self.dmax, self.dmax)  # type: ignore[operator]
            x = (centred + d * batch_var.sqrt() / r) / (batch_var / r**2 + self.eps).sqrt()
        else:  # warm-up: plain batch normalisation with the batch's moments
            x = centred / (batch_var + self.eps).sqrt()
        self.ra_mean += self.momentum * (batch_mean.detach() - self.ra_mean)  # type: ignore[operator]
        self.ra_var += self.momentum * (batch_var.detach() - self.ra_var)  # type: ignore[operator]
        self.steps += 1  # type: ignore[operator]
        return self.scale * x + self.bias if self.affine else x


def create_bn_mlp(
    input_dim: int,
    output_dim: int,
    net_arch: Sequence[int],
    batch_norm: bool = True,
    activation_fn: type[nn.Module] = nn.LeakyReLU,
    bn_momentum: float = 0.1,
    init: str = "paper",
    layer_norm: bool = False,
    dropout: float = 0.0,
    batch_renorm: bool = False,
) -> nn.Sequential:
    """Build ``input -> net_arch... -> output`` with a linear output layer and the paper's batch-norm placement.

    :param input_dim: size of the input (state, or state + action for a Q critic).
    :param output_dim: size of the linear output (action dimension, or 1 for a critic).
    :param net_arch: hidden layer sizes, e.g. ``[50, 7]`` for the paper's critic.
    :param batch_norm: apply BatchNorm1d before every linear layer except the last (paper); False gives a plain MLP.
    :param activation_fn: hidden activation (paper: leaky ReLU, slope 0.01).
    :param bn_momentum: PyTorch BatchNorm1d momentum for the running statistics.
    :param init: "paper" (N(0, 0.01^2) weights, zero biases) or "default" (PyTorch's initialisation).
    :param layer_norm: LayerNorm after every hidden linear layer, before its activation (Ba et al. 2016; the critics of
        DroQ, BRO and sbx's ``layer_norm``): each hidden layer's pre-activations keep unit scale however long the fit.
    :param dropout: rate of a Dropout after every hidden linear layer, before its layer norm (DroQ, Hiraoka et al.
        2022: ``Linear -> Dropout -> LayerNorm -> ReLU``); 0: none. Active in train mode only.
    :param batch_renorm: batch renormalisation (Ioffe 2017; sb3-contrib's, as :class:`BatchRenorm1d`: momentum 0.01,
        batch statistics for its first 100k training steps, then the running ones corrected towards the batch's)
        before every linear layer, the last one's too (CrossQ's critic, Bhatt et al. 2024), in place of ``batch_norm``.
    """
    if init not in INITS:
        raise ValueError(f"init must be one of {INITS}, got {init!r}")
    if any(int(h) <= 0 for h in net_arch):
        raise ValueError(f"hidden layer sizes must be positive integers, got {list(net_arch)}")
    sizes = [input_dim, *[int(h) for h in net_arch], output_dim]
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        is_last = i == len(sizes) - 2
        if batch_renorm:  # CrossQ's placement: before every linear layer, the output's too
            layers.append(BatchRenorm1d(sizes[i]))
        elif batch_norm and not is_last:
            layers.append(nn.BatchNorm1d(sizes[i], momentum=bn_momentum))
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if dropout > 0 and not is_last:
            layers.append(nn.Dropout(dropout))
        if layer_norm and not is_last:
            layers.append(nn.LayerNorm(sizes[i + 1]))
        if not is_last:
            layers.append(activation_fn())
    net = nn.Sequential(*layers)
    if init == "paper":
        paper_init_(net)
    return net


class ResidualBlock(nn.Module):
    """SimBa's pre-layer-norm residual block (Lee et al. 2025): x + W_2 act(W_1 LayerNorm(x)), inner width 4 x dim."""

    def __init__(self, dim: int, activation_fn: type[nn.Module] = nn.ReLU):
        super().__init__()
        self.path = nn.Sequential(nn.LayerNorm(dim), nn.Linear(dim, 4 * dim), activation_fn(), nn.Linear(4 * dim, dim))

    def forward(self, x: th.Tensor) -> th.Tensor:
        return x + self.path(x)


def create_residual_mlp(
    input_dim: int, output_dim: int, net_arch: Sequence[int], activation_fn: type[nn.Module] = nn.ReLU
) -> nn.Sequential:
    """SimBa's network (Lee et al. 2025): a linear embedding to ``net_arch[0]`` units, one :class:`ResidualBlock` per
    entry of ``net_arch`` (their width is the first entry's: a residual stream keeps one width), a final LayerNorm, and
    a linear output. PyTorch's initialisation."""
    if not net_arch or any(int(h) <= 0 for h in net_arch):
        raise ValueError(f"residual networks need positive hidden layer sizes, got {list(net_arch)}")
    width = int(net_arch[0])
    blocks = [ResidualBlock(width, activation_fn) for _ in net_arch]
    return nn.Sequential(nn.Linear(input_dim, width), *blocks, nn.LayerNorm(width), nn.Linear(width, output_dim))


def set_bn_training_mode(module: nn.Module, mode: bool) -> None:
    """Put only the batch-norm layers of ``module`` in train (batch statistics) or eval (running statistics) mode."""
    for layer in module.modules():
        if isinstance(layer, nn.modules.batchnorm._BatchNorm):
            layer.train(mode)


def flat_parameters(module: nn.Module) -> th.Tensor:
    """All parameters of ``module`` as one detached 1-d tensor (for tests and the CMA-ES search space)."""
    return th.cat([p.detach().reshape(-1) for p in module.parameters()])
