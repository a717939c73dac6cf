"""Fast path of DENFAC's end-of-episode update (issue 7): the same arithmetic as the plain autograd path, fewer ops.

The update fits tiny networks (e.g. 5-50-7-1) on a few thousand samples hundreds of times, so per-op dispatch and
memory passes dominate, not FLOPs. :class:`FlatBNMLP` runs a ``create_bn_mlp`` network functionally:

- parameters live in one flat tensor (the module's parameters become views of it), so Adam and gradient clipping are
  a handful of ops per step instead of a handful per parameter tensor;
- batch norm is folded into the following linear layer (``W diag(gamma rstd)``, shifted bias); its backward uses the
  reductions the weight-gradient matmul already computes, so a BN layer costs one ``var_mean`` pass forward and one
  ``addcmul`` pass backward;
- hand-written backward (no autograd graph); the critic's input layer in eval mode is split into an observation part,
  computed once per fitted iteration, and an action part for the G actor steps.

Running statistics, Adam moments and the step count follow PyTorch's ``BatchNorm1d`` and ``Adam`` exactly (up to float
rounding), so the fast and plain paths give the same result for the same seed (tested). Everything stays on the
networks' device; nothing synchronises with the host inside the loops.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch as th
from torch import nn

from sb3_denfac.common.inverting_gradients import invert_gradients


def row_var_mean(x: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
    """Biased variance and mean of each row of a feature-major (C, N) tensor (two-pass, centred).

    ``th.var_mean`` is many times slower than these two contiguous reductions on CPU.
    """
    mean = x.mean(1)
    var = (x - mean.unsqueeze(1)).square_().mean(1)
    return var, mean


def _leaky_relu_backward(grad: th.Tensor, out: th.Tensor, slope: float) -> th.Tensor:
    """d leaky_relu from its output (one fused kernel; ``where(out > 0, ...)`` takes three passes)."""
    return th.ops.aten.leaky_relu_backward(grad, out, slope, True)


@dataclass
class _Layer:
    linear: nn.Linear
    bn: nn.BatchNorm1d | None
    slope: float | None  # leaky-ReLU slope after the linear layer, None for the linear output layer


def parse_bn_mlp(net: nn.Module) -> list[_Layer] | None:
    """Layers of a ``create_bn_mlp`` network ([BN] Linear act ... [BN] Linear), or None if it has another shape."""
    if not isinstance(net, nn.Sequential):
        return None
    layers: list[_Layer] = []
    pending_bn = None
    for module in net:
        if isinstance(module, nn.BatchNorm1d) and pending_bn is None:
            if not module.affine or not module.track_running_stats:
                return None
            pending_bn = module
        elif isinstance(module, nn.Linear) and module.bias is not None:
            layers.append(_Layer(module, pending_bn, None))
            pending_bn = None
        elif isinstance(module, (nn.LeakyReLU, nn.ReLU)) and layers and layers[-1].slope is None:
            layers[-1].slope = module.negative_slope if isinstance(module, nn.LeakyReLU) else 0.0
        else:
            return None
    if not layers or pending_bn is not None or layers[-1].slope is not None:
        return None
    return layers


class FlatAdam:
    """torch.optim.Adam (no weight decay, no amsgrad) on one flat tensor, with global-norm gradient clipping.

    Reads its moments from / writes them back to the module's ``torch.optim.Adam`` state so both paths interoperate.
    """

    def __init__(self, flat: th.Tensor, params: list[nn.Parameter], optimizer: th.optim.Optimizer):
        group = optimizer.param_groups[0]
        self.lr, (self.beta1, self.beta2), self.eps = group["lr"], group["betas"], group["eps"]
        self.flat, self.params, self.optimizer = flat, params, optimizer
        self.exp_avg, self.exp_avg_sq = th.zeros_like(flat), th.zeros_like(flat)
        self.step_count = 0
        states = [optimizer.state.get(p) for p in params]
        if all(s for s in states):
            self.exp_avg.copy_(th.cat([s["exp_avg"].reshape(-1) for s in states]))  # type: ignore[index]
            self.exp_avg_sq.copy_(th.cat([s["exp_avg_sq"].reshape(-1) for s in states]))  # type: ignore[index]
            self.step_count = int(float(states[0]["step"]))  # type: ignore[index]

    def reset(self) -> None:
        self.exp_avg.zero_()
        self.exp_avg_sq.zero_()
        self.step_count = 0

    def step(self, grad: th.Tensor, max_grad_norm: float | None) -> None:
        if max_grad_norm is not None:  # as clip_grad_norm_, without a host sync
            coef = max_grad_norm / (th.linalg.vector_norm(grad) + 1e-6)
            grad.mul_(th.clamp(coef, max=1.0))
        self.step_count += 1
        self.exp_avg.lerp_(grad, 1 - self.beta1)
        self.exp_avg_sq.mul_(self.beta2).addcmul_(grad, grad, value=1 - self.beta2)
        bias_correction1 = 1 - self.beta1**self.step_count
        bias_correction2_sqrt = math.sqrt(1 - self.beta2**self.step_count)
        denom = (self.exp_avg_sq.sqrt() / bias_correction2_sqrt).add_(self.eps)
        self.flat.addcdiv_(self.exp_avg, denom, value=-self.lr / bias_correction1)

    def write_back(self) -> None:
        """Store the moments in the torch optimizer's state (a later plain update or a save sees them)."""
        self.optimizer.state.clear()
        if self.step_count == 0:
            return
        offset = 0
        for p in self.params:
            n = p.numel()
            self.optimizer.state[p] = {
                "step": th.tensor(float(self.step_count)),
                "exp_avg": self.exp_avg[offset : offset + n].view_as(p).clone(),
                "exp_avg_sq": self.exp_avg_sq[offset : offset + n].view_as(p).clone(),
            }
            offset += n


class FlatBNMLP:
    """Functional forward/backward of a ``create_bn_mlp`` network whose parameters are bound to one flat tensor."""

    def __init__(self, net: nn.Module, layers: list[_Layer], optimizer: th.optim.Optimizer):
        self.net, self.layers = net, layers
        self.params = [p for p in net.parameters()]
        self.flat = th.cat([p.detach().reshape(-1) for p in self.params])
        self.grad = th.zeros_like(self.flat)
        # Bind: module parameters become views of ``flat`` (in-place resets then write into it).
        self.views: dict[int, tuple[th.Tensor, th.Tensor]] = {}
        offset = 0
        for p in self.params:
            n = p.numel()
            p.data = self.flat[offset : offset + n].view_as(p)
            self.views[id(p)] = (p.data, self.grad[offset : offset + n].view_as(p))
            offset += n
        self.adam = FlatAdam(self.flat, self.params, optimizer)
        self.bn_counts: dict[int, int] = {}  # host copy of num_batches_tracked per BN layer

    def reset_bn_counts(self) -> None:
        """Call after the running statistics were reset outside (num_batches_tracked back to 0)."""
        self.bn_counts = {i: 0 for i, layer in enumerate(self.layers) if layer.bn is not None}

    def _grad_of(self, p: th.Tensor) -> th.Tensor:
        return self.views[id(p)][1]

    @staticmethod
    def _fold(layer: _Layer, mean: th.Tensor, rstd: th.Tensor) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        """Weight and bias of Linear(BN(x)) as an affine map of x, and the BN scale gamma * rstd."""
        bn, lin = layer.bn, layer.linear
        scale = bn.weight * rstd  # type: ignore[union-attr]
        weight = lin.weight * scale
        bias = th.addmv(lin.bias, lin.weight, bn.bias - mean * scale)  # type: ignore[union-attr]
        return weight, bias, scale

    def _eval_affine(self, layer: _Layer) -> tuple[th.Tensor, th.Tensor]:
        if layer.bn is None:
            return layer.linear.weight, layer.linear.bias
        rstd = th.rsqrt(layer.bn.running_var + layer.bn.eps)  # type: ignore[operator]
        weight, bias, _ = self._fold(layer, layer.bn.running_mean, rstd)  # type: ignore[arg-type]
        return weight, bias

    @th.no_grad()
    def forward_train(self, x_t: th.Tensor, input_stats: tuple[th.Tensor, th.Tensor] | None = None) -> tuple[th.Tensor, list]:
        """Train-mode forward on feature-major input (features, N): batch statistics, running statistics updated as
        BatchNorm1d. Returns the output (out, N) and the cache for :meth:`backward`."""
        cache = []
        h = x_t
        n = x_t.shape[1]
        for i, layer in enumerate(self.layers):
            if layer.bn is not None:
                bn = layer.bn
                var, mean = input_stats if (i == 0 and input_stats is not None) else row_var_mean(h)
                rstd = th.rsqrt(var + bn.eps)
                weight, bias, _ = self._fold(layer, mean, rstd)
                bn.num_batches_tracked.add_(1)  # type: ignore[union-attr, operator]
                if bn.momentum is not None:
                    factor = bn.momentum
                else:  # cumulative average; counted on the host so no device sync is needed
                    self.bn_counts[i] = self.bn_counts.get(i, int(bn.num_batches_tracked) - 1) + 1  # type: ignore[arg-type]
                    factor = 1.0 / self.bn_counts[i]
                bn.running_mean.lerp_(mean, factor)  # type: ignore[union-attr]
                bn.running_var.lerp_(var * (n / (n - 1)), factor)  # type: ignore[union-attr]
                cache.append((h, mean, rstd, weight))
            else:
                weight, bias = layer.linear.weight, layer.linear.bias
                cache.append((h, None, None, weight))
            z = th.addmm(bias.unsqueeze(1), weight, h)
            h = th.nn.functional.leaky_relu(z, layer.slope) if layer.slope is not None else z
        cache.append((h, None, None, None))
        return h, cache

    @th.no_grad()
    def backward(self, grad_out: th.Tensor, cache: list, input_grad: bool = False) -> th.Tensor | None:
        """Write parameter gradients into ``self.grad`` (overwritten); optionally return d loss / d input (feature-major)."""
        dz = grad_out
        n = grad_out.shape[1]
        dx = None
        for i in range(len(self.layers) - 1, -1, -1):
            layer = self.layers[i]
            if layer.slope is not None:
                dz = _leaky_relu_backward(dz, cache[i + 1][0], layer.slope)
            h, mean, rstd, weight_eff = cache[i]
            lin = layer.linear
            row_sum = dz.sum(1)
            m = dz @ h.t()  # sum_n dz x^T, (out, in)
            self._grad_of(lin.bias).copy_(row_sum)
            need_dx = i > 0 or input_grad
            if layer.bn is None:
                self._grad_of(lin.weight).copy_(m)
                if need_dx:
                    dx = lin.weight.t() @ dz
            else:
                bn = layer.bn
                t = (m - row_sum[:, None] * mean[None, :]) * rstd  # sum_n dz xhat^T
                th.addcmul(t * bn.weight, row_sum[:, None], bn.bias[None, :], out=self._grad_of(lin.weight))
                dbeta = row_sum @ lin.weight  # sum_n dL/dh
                dgamma = (lin.weight * t).sum(0)  # sum_n dL/dh * xhat
                self._grad_of(bn.weight).copy_(dgamma)
                self._grad_of(bn.bias).copy_(dbeta)
                if need_dx:
                    # dx = rstd (g - mean_n g - xhat mean_n(g xhat)), g = gamma dL/dh, as an affine map of x per feature
                    rstd2_b = rstd * rstd * bn.weight * dgamma / n
                    dx = th.addmm((rstd2_b * mean - rstd * bn.weight * dbeta / n).unsqueeze(1), weight_eff.t(), dz)
                    dx.addcmul_(h, -rstd2_b.unsqueeze(1))
            dz = dx  # type: ignore[assignment]
        return dx

    @th.no_grad()
    def eval_affines(self) -> list[tuple[th.Tensor, th.Tensor]]:
        """Eval-mode (running statistics) weight and bias of every layer, BN folded in."""
        return [self._eval_affine(layer) for layer in self.layers]


def supported_networks(policy) -> tuple[list[_Layer], list[_Layer]] | None:
    """Parsed actor and critic layers if the fast path supports this policy (vector observations, Adam), else None."""
    from gymnasium import spaces
    from stable_baselines3.common.torch_layers import FlattenExtractor

    for net in (policy.actor, policy.critic):
        if not isinstance(net.features_extractor, FlattenExtractor):
            return None
        opt = net.optimizer
        group = opt.param_groups[0]
        if type(opt) is not th.optim.Adam or len(opt.param_groups) != 1:
            return None
        if group.get("weight_decay", 0) != 0 or group.get("amsgrad") or group.get("maximize"):
            return None
    if not isinstance(policy.observation_space, spaces.Box) or len(policy.observation_space.shape) != 1:
        return None
    actor_layers, critic_layers = parse_bn_mlp(policy.actor.mu), parse_bn_mlp(policy.critic.qf)
    if actor_layers is None or critic_layers is None:
        return None
    return actor_layers, critic_layers


class FastUpdate:
    """Critic fit and actor fit of one DENFAC update on flat, functional networks (see module docstring)."""

    def __init__(self, policy, actor_layers: list[_Layer], critic_layers: list[_Layer]):
        self.actor = FlatBNMLP(policy.actor.mu, actor_layers, policy.actor.optimizer)
        self.critic = FlatBNMLP(policy.critic.qf, critic_layers, policy.critic.optimizer)

    def write_back(self) -> None:
        self.actor.adam.write_back()
        self.critic.adam.write_back()

    @th.no_grad()
    def fit_critic(
        self,
        obs: th.Tensor,
        actions: th.Tensor,
        q_targets: th.Tensor,
        weights: th.Tensor,
        steps: int,
        max_grad_norm: float | None,
        batch_indices,
    ) -> th.Tensor:
        """``steps`` Adam steps on 1/N sum c (Q(s, a) - q)^2; returns the last loss (a tensor, no host sync)."""
        net = self.critic
        inputs_t = th.cat([obs.float(), actions], dim=1).t().contiguous()  # feature-major (obs + act, N)
        q_t, c_t = q_targets.reshape(1, -1), weights.reshape(1, -1)
        full_stats = row_var_mean(inputs_t) if net.layers[0].bn is not None else None  # fixed data: once
        loss = th.zeros((), device=obs.device)
        for _ in range(steps):
            idx = batch_indices(inputs_t.shape[1])
            x, q, c = (inputs_t, q_t, c_t) if idx is None else (inputs_t[:, idx], q_t[:, idx], c_t[:, idx])
            out, cache = net.forward_train(x, full_stats if idx is None else None)
            diff = out - q
            weighted = c * diff
            loss = (weighted * diff).mean()
            net.backward(weighted.mul_(2.0 / x.shape[1]), cache)
            net.adam.step(net.grad, max_grad_norm)
        return loss

    @th.no_grad()
    def fit_actor(self, obs: th.Tensor, steps: int, max_grad_norm: float | None, inverting: bool, batch_indices) -> th.Tensor:
        """G Adam steps ascending 1/N sum Q(s, pi(s)) (critic in eval mode); returns the last objective."""
        obs_t = obs.float().t().contiguous()
        action_dim = self.actor.layers[-1].linear.out_features
        critic_layers = self.critic.layers
        critic_affines = self.critic.eval_affines()
        w_first, b_first = critic_affines[0]
        w_obs, w_act = w_first[:, :-action_dim], w_first[:, -action_dim:]
        obs_part_full = th.addmm(b_first.unsqueeze(1), w_obs, obs_t)  # fixed over the G steps (critic and data fixed)
        low, high = -th.ones((), device=obs.device), th.ones((), device=obs.device)
        objective = th.zeros((), device=obs.device)
        for _ in range(steps):
            idx = batch_indices(obs_t.shape[1])
            o, obs_part = (obs_t, obs_part_full) if idx is None else (obs_t[:, idx], obs_part_full[:, idx])
            n = o.shape[1]
            pi, cache = self.actor.forward_train(o)
            # Critic forward in eval mode on (s, pi(s)), keeping the activations for d mean(Q) / d pi.
            outs = []
            z = th.addmm(obs_part, w_act, pi)
            for i, (layer, (weight, bias)) in enumerate(zip(critic_layers, critic_affines, strict=True)):
                if i > 0:
                    z = th.addmm(bias.unsqueeze(1), weight, outs[-1])
                outs.append(th.nn.functional.leaky_relu(z, layer.slope) if layer.slope is not None else z)
            objective = outs[-1].mean()
            dz = th.full_like(outs[-1], 1.0 / n)
            for i in range(len(critic_layers) - 1, -1, -1):
                if critic_layers[i].slope is not None:
                    dz = _leaky_relu_backward(dz, outs[i], critic_layers[i].slope)
                dz = (critic_affines[i][0] if i > 0 else w_act).t() @ dz
            if inverting:
                dz = invert_gradients(dz, pi, low, high)
            self.actor.backward(dz.neg_(), cache)
            self.actor.adam.step(self.actor.grad, max_grad_norm)
        return objective
