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


class _BatchRenormTraining(th.autograd.Function):
    """The training-mode function of :class:`BatchRenorm1d` with a hand-written backward (module docstring there).

    Per feature, with the batch's mean m and unbiased variance v of x, the centred input x_c = x - m, and r, d the
    renormalisation's corrections (detached, as sb3-contrib's): y = w (x_c + A) / D + b, where A = d sqrt(v) / r and
    D = sqrt(v / r^2 + eps) past the warm-up, A = 0 and D = sqrt(v + eps) during it. Backward, with g = dL/dy:
    dL/db = sum g, dL/dw = (sum g x_c + A sum g) / D, and dL/dx = (w / D)(g - mean g) + 2 x_c dL/dv / (N - 1), where
    dL/dv = w (A' sum g / D - B (sum g x_c + A sum g) / (2 D^3)), A' = dA/dv, B = 1 / r^2 (1 in the warm-up).
    """

    @staticmethod
    def forward(ctx, x, weight, bias, ra_mean, ra_var, eps, renorm, rmax, dmax):  # noqa: ANN001, ANN205
        n = x.shape[0]
        mean = x.mean(dim=0)
        centred = x - mean
        var = (centred * centred).sum(dim=0) / (n - 1)
        if renorm:
            running_std = (ra_var + eps).sqrt()
            r = ((var + eps).sqrt() / running_std).clamp(1 / rmax, rmax)
            d = ((mean - ra_mean) / running_std).clamp(-dmax, dmax)
            std = var.sqrt()
            shift, inv_r2 = d * std / r, r.pow(-2)
            denominator = (var * inv_r2 + eps).sqrt()
            # dA/dv = d / (2 r sqrt(v)); 0 where the feature is constant over the batch (autograd would give nan there)
            shift_slope = th.where(std > 0, d / (2 * r * std), th.zeros_like(std))
        else:
            shift = shift_slope = th.zeros_like(var)
            inv_r2 = th.ones_like(var)
            denominator = (var + eps).sqrt()
        gain = weight / denominator
        y = th.addcmul(bias + gain * shift, centred, gain)
        ctx.save_for_backward(centred, weight, denominator, shift, shift_slope, inv_r2)
        ctx.mark_non_differentiable(mean, var)
        return y, mean, var

    @staticmethod
    def backward(ctx, grad, _grad_mean, _grad_var):  # noqa: ANN001, ANN205
        centred, weight, denominator, shift, shift_slope, inv_r2 = ctx.saved_tensors
        n = centred.shape[0]
        grad_sum = grad.sum(dim=0)
        grad_u = (grad * centred).sum(dim=0) + shift * grad_sum  # sum g (x_c + A)
        grad_x = None
        if ctx.needs_input_grad[0]:
            gain = weight / denominator
            grad_var = weight * (shift_slope * grad_sum / denominator - inv_r2 * grad_u / (2 * denominator.pow(3)))
            grad_x = th.addcmul(-gain * grad_sum / n, grad, gain)
            grad_x.addcmul_(centred, 2 * grad_var / (n - 1))
        grad_weight = grad_u / denominator if ctx.needs_input_grad[1] else None
        grad_bias = grad_sum if ctx.needs_input_grad[2] else None
        return grad_x, grad_weight, grad_bias, None, None, None, None, None, None


class BatchRenorm1d(ContribBatchRenorm1d):
    """sb3-contrib's ``BatchRenorm1d`` (Ioffe 2017, as CrossQ's critic): its state, its function and its gradients
    (tested equal to sb3-contrib's to float32 rounding in both phases), computed with fewer passes over the (batch,
    features) tensor, which on CPU cost as much as the layers' matrix products.

    - the batch's unbiased variance in two passes, 1/(N-1) sum (x - mean)^2 (``Tensor.var`` alone costs about as much
      as a 256x256 layer's product);
    - the normalisation and the affine map folded into one scale and shift per feature;
    - in training mode a hand-written backward (:class:`_BatchRenormTraining`, checked against numerical derivatives)
      that reads the tensor about half as often as autograd's graph of the same arithmetic. It also differs where
      sb3-contrib's gradient is nan: a feature constant over the batch past the warm-up gets a finite one.

    Its state dict is sb3-contrib's, so saved models load either way.
    """

    def forward(self, x: th.Tensor) -> th.Tensor:
        if not self.training:  # the running statistics: w (x - mean) / sqrt(var + eps) + b as one scale and shift
            gain = (self.ra_var + self.eps).rsqrt()  # type: ignore[operator]
            if self.affine:
                gain = self.scale * gain
                return th.addcmul(self.bias - self.ra_mean * gain, x, gain)  # type: ignore[operator]
            return th.addcmul(-self.ra_mean * gain, x, gain)  # type: ignore[operator]
        weight, bias = (self.scale, self.bias) if self.affine else (th.ones_like(self.scale), th.zeros_like(self.bias))
        renorm = bool(self.steps > self.warmup_steps)  # type: ignore[operator]
        y, batch_mean, batch_var = _BatchRenormTraining.apply(
            x, weight, bias, self.ra_mean, self.ra_var, self.eps, renorm, self.rmax, self.dmax
        )
        self.ra_mean += self.momentum * (batch_mean - self.ra_mean)  # type: ignore[operator]
        self.ra_var += self.momentum * (batch_var - self.ra_var)  # type: ignore[operator]
        self.steps += 1  # type: ignore[operator]
        return y


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
