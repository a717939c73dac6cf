"""Fast paths of DENFAC's end-of-episode update (issue 7): the same arithmetic as the plain autograd path, fewer ops.

The update fits tiny networks (e.g. 5-50-7-1) on a few thousand samples hundreds of times, so per-op dispatch and
memory passes dominate, not FLOPs. Each critic step and each actor step is one pure function of tensors:

- parameters live in one flat tensor (the module's parameters become views of it), so Adam and gradient clipping are
  a handful of ops per step instead of a handful per parameter tensor;
- activations are feature-major (features, N): the long sample axis is the matmuls' inner/outer dimension and the
  per-feature batch-norm reductions are contiguous;
- batch norm is folded into the following linear layer (``W diag(gamma rstd)``, shifted bias); its backward uses the
  reductions the weight-gradient matmul already computes (one extra element-wise pass per BN layer);
- hand-written backward (no autograd graph); the critic's input layer in eval mode is split into an observation part,
  computed once per fitted iteration, and an action part for the G actor steps;
- ``update_path="compiled"`` runs the same step functions through ``torch.compile`` with static shapes for the sample
  count that repeats (the full buffer, or the mini-batch size), which fuses the element-wise passes around the matmuls;
  while the buffer fills, the eager step functions run (a static compilation per N would be paid every episode).

Running statistics, Adam moments and the step count follow PyTorch's ``BatchNorm1d`` and ``Adam`` exactly (up to float
rounding), so the fast and plain paths give the same result for the same seed (tested). Everything stays on the
networks' device; the loops never wait for the device (per-step scalars go host -> device, nothing comes back).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch as th
from torch import nn

from sb3_denfac.common.inverting_gradients import invert_gradients
from sb3_denfac.denfac import eager_steps


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


@dataclass(frozen=True)
class _Spec:
    """Static description of a ``create_bn_mlp`` network for the step functions (hashable: compile-cache key)."""

    sizes: tuple[int, ...]  # in, hidden..., out
    bn: tuple[bool, ...]  # per linear layer: batch norm before it
    slopes: tuple[float | None, ...]  # per linear layer: leaky-ReLU slope after it (None: linear output)
    eps: tuple[float, ...]  # per linear layer: BN epsilon (0 without BN)

    @staticmethod
    def of(layers: list[_Layer]) -> _Spec:
        return _Spec(
            sizes=(layers[0].linear.in_features, *(layer.linear.out_features for layer in layers)),
            bn=tuple(layer.bn is not None for layer in layers),
            slopes=tuple(layer.slope for layer in layers),
            eps=tuple(float(layer.bn.eps) if layer.bn is not None else 0.0 for layer in layers),
        )

    def unpack(self, flat: th.Tensor) -> list[tuple[th.Tensor | None, th.Tensor | None, th.Tensor, th.Tensor]]:
        """(gamma, beta, W, b) views per linear layer, in ``nn.Sequential.parameters()`` order."""
        out, offset = [], 0
        for i in range(len(self.bn)):
            d_in, d_out = self.sizes[i], self.sizes[i + 1]
            gamma = beta = None
            if self.bn[i]:
                gamma, beta = flat[offset : offset + d_in], flat[offset + d_in : offset + 2 * d_in]
                offset += 2 * d_in
            weight = flat[offset : offset + d_in * d_out].view(d_out, d_in)
            offset += d_in * d_out
            out.append((gamma, beta, weight, flat[offset : offset + d_out]))
            offset += d_out
        return out


def _linear(weight: th.Tensor, bias: th.Tensor, h: th.Tensor, fuse_bias: bool) -> th.Tensor:
    """weight @ h + bias[:, None]. Eagerly one addmm; compiled, mm + add so the add fuses into the next pointwise."""
    if fuse_bias:
        return th.mm(weight, h) + bias.unsqueeze(1)
    return th.addmm(bias.unsqueeze(1), weight, h)


def _train_forward(spec: _Spec, flat: th.Tensor, x: th.Tensor, stats0: tuple[th.Tensor, th.Tensor] | None, fuse: bool = False):
    """Train-mode forward on feature-major x (features, N); returns output, cache and BN batch (mean, var)s."""
    cache, stats = [], []
    h = x
    for i, (gamma, beta, weight, bias) in enumerate(spec.unpack(flat)):
        if gamma is not None:
            var, mean = stats0 if (i == 0 and stats0 is not None) else row_var_mean(h)
            rstd = th.rsqrt(var + spec.eps[i])
            scale = gamma * rstd
            w_eff = weight * scale
            b_eff = bias + weight @ (beta - mean * scale)
            stats.append((mean, var))
            cache.append((h, mean, rstd, w_eff))
        else:
            w_eff, b_eff = weight, bias
            cache.append((h, None, None, w_eff))
        z = _linear(w_eff, b_eff, h, fuse)
        h = th.nn.functional.leaky_relu(z, spec.slopes[i]) if spec.slopes[i] is not None else z
    cache.append((h, None, None, None))
    return h, cache, stats


def _backward(spec: _Spec, flat: th.Tensor, cache: list, grad_out: th.Tensor, input_grad: bool = False):
    """Flat parameter gradient (and d loss / d input if ``input_grad``) of a train-mode forward."""
    params = spec.unpack(flat)
    grads: list[th.Tensor] = []
    n = grad_out.shape[1]
    dz, dx = grad_out, None
    for i in range(len(params) - 1, -1, -1):
        gamma, beta, weight, _ = params[i]
        if spec.slopes[i] is not None:
            dz = _leaky_relu_backward(dz, cache[i + 1][0], spec.slopes[i])
        h, mean, rstd, w_eff = cache[i]
        row_sum = dz.sum(1)
        m = dz @ h.t()  # sum_n dz x^T, (out, in)
        need_dx = i > 0 or input_grad
        if gamma is None:
            layer_grads = [m, row_sum]
            if need_dx:
                dx = weight.t() @ dz
        else:
            t = (m - row_sum[:, None] * mean[None, :]) * rstd  # sum_n dz xhat^T
            d_weight = t * gamma + row_sum[:, None] * beta[None, :]
            d_beta = row_sum @ weight  # sum_n dL/dh
            d_gamma = (weight * t).sum(0)  # sum_n dL/dh * xhat
            layer_grads = [d_gamma, d_beta, d_weight, row_sum]
            if need_dx:
                # dx = rstd (g - mean_n g - xhat mean_n(g xhat)), g = gamma dL/dh: an affine map of x per feature
                rstd2_b = rstd * rstd * gamma * d_gamma / n
                dx = th.addmm((rstd2_b * mean - rstd * gamma * d_beta / n).unsqueeze(1), w_eff.t(), dz)
                dx = dx - h * rstd2_b.unsqueeze(1)
        grads = layer_grads + grads
        dz = dx  # type: ignore[assignment]
    return th.cat([g.reshape(-1) for g in grads]), dx


def _adam_(flat, grad, exp_avg, exp_avg_sq, step_size, bias_correction2_sqrt, beta1, beta2, eps, max_grad_norm) -> None:
    """In-place Adam step (torch.optim.Adam's arithmetic) after global-norm clipping (clip_grad_norm_'s)."""
    if max_grad_norm is not None:
        grad = grad * th.clamp(max_grad_norm / (th.linalg.vector_norm(grad) + 1e-6), max=1.0)
    exp_avg.lerp_(grad, 1 - beta1)
    exp_avg_sq.mul_(beta2).addcmul_(grad, grad, value=1 - beta2)
    denom = (exp_avg_sq.sqrt() / bias_correction2_sqrt).add_(eps)
    flat.sub_(step_size * exp_avg / denom)


def _update_running_(running: list, stats: list, scalars: th.Tensor, n: int) -> None:
    """BatchNorm1d's running-statistics update; ``scalars[2 + j]`` is BN layer j's averaging factor."""
    for j in range(len(running)):
        running_mean, running_var, batches = running[j]
        mean, var = stats[j]
        batches.add_(1)
        running_mean.lerp_(mean, scalars[2 + j])
        running_var.lerp_(var * (n / (n - 1)), scalars[2 + j])


def _make_critic_step(spec: _Spec, betas: tuple[float, float], eps: float, max_grad_norm: float | None, fuse: bool = False):
    def critic_step(flat, exp_avg, exp_avg_sq, scalars, running, x, stats0, q, c):
        out, cache, stats = _train_forward(spec, flat, x, stats0, fuse)
        _update_running_(running, stats, scalars, x.shape[1])
        diff = out - q
        weighted = c * diff
        loss = (weighted * diff).mean()
        grad, _ = _backward(spec, flat, cache, weighted * (2.0 / x.shape[1]))
        _adam_(flat, grad, exp_avg, exp_avg_sq, scalars[0], scalars[1], betas[0], betas[1], eps, max_grad_norm)
        return loss

    return critic_step


def _make_actor_step(
    spec: _Spec,
    critic_slopes: tuple,
    betas: tuple[float, float],
    eps: float,
    max_grad_norm: float | None,
    inverting: bool,
    fuse: bool = False,
):
    def actor_step(flat, exp_avg, exp_avg_sq, scalars, running, obs, obs_part, w_act, critic_affines):
        pi, cache, stats = _train_forward(spec, flat, obs, None, fuse)
        _update_running_(running, stats, scalars, obs.shape[1])
        # Critic in eval mode on (s, pi(s)) (BN folded with running statistics), then d mean(Q) / d pi by hand.
        if fuse:  # obs_part + w_act @ pi as broadcasts: one fused pass with the activation (few actions)
            z = obs_part
            for a in range(pi.shape[0]):
                z = z + w_act[:, a : a + 1] * pi[a : a + 1]
        else:
            z = th.addmm(obs_part, w_act, pi)
        outs = []
        for i, (weight, bias) in enumerate(critic_affines):
            if i > 0:
                z = _linear(weight, bias, outs[-1], fuse)
            outs.append(th.nn.functional.leaky_relu(z, critic_slopes[i]) if critic_slopes[i] is not None else z)
        objective = outs[-1].mean()
        dz = th.full_like(outs[-1], 1.0 / pi.shape[1])
        n_layers = len(critic_affines)
        last = 1 if (fuse and n_layers > 1) else 0
        for i in range(n_layers - 1, last - 1, -1):
            if critic_slopes[i] is not None:
                dz = _leaky_relu_backward(dz, outs[i], critic_slopes[i])
            if i == last == 1:
                break  # dz = dL/dz_2, finished below
            dz = (critic_affines[i][0] if i > 0 else w_act).t() @ dz
        if last == 1:
            # dz = dL/dz_2 (small). d/dpi_a = sum_k dz[k] sum_j W2[k, j] w_act[j, a] D1[j]: one (A*K, H) @ (H, N) matmul on
            # the activation derivative D1, instead of materialising the wide (H, N) gradient twice.
            slope0 = critic_slopes[0]
            d1 = th.where(outs[0] > 0, 1.0, slope0) if slope0 is not None else th.ones_like(outs[0])
            w2 = critic_affines[1][0]
            stacked = (w2.unsqueeze(0) * w_act.t().unsqueeze(1)).reshape(-1, w2.shape[1])  # (A*K, H)
            dz = (th.mm(stacked, d1).view(w_act.shape[1], w2.shape[0], -1) * dz.unsqueeze(0)).sum(1)
        if inverting:
            dz = invert_gradients(dz, pi, -th.ones_like(objective), th.ones_like(objective))
        grad, _ = _backward(spec, flat, cache, -dz)
        _adam_(flat, grad, exp_avg, exp_avg_sq, scalars[0], scalars[1], betas[0], betas[1], eps, max_grad_norm)
        return objective

    return actor_step


_STEP_FUNCTIONS: dict = {}


def _step_function(kind: str, compiled_size: int | None, *key):
    """The step function for a static key: eager, or ``torch.compile``d for the fixed sample count ``compiled_size``.

    Compiled functions are specialised to one N (static shapes generate much faster code than dynamic ones), so they
    are used only for the size that repeats: the full buffer (or the mini-batch size); a filling buffer runs eagerly.
    Cached per process, so the compilation is paid once.
    """
    cache_key = (kind, compiled_size, key)
    if cache_key not in _STEP_FUNCTIONS:
        factory = _make_critic_step if kind == "critic" else _make_actor_step
        if compiled_size is None:
            _STEP_FUNCTIONS[cache_key] = factory(*key)
        else:
            _STEP_FUNCTIONS[cache_key] = th.compile(factory(*key, fuse=True), dynamic=False)
    return _STEP_FUNCTIONS[cache_key]


class _FlatNet:
    """A ``create_bn_mlp`` network bound to one flat parameter tensor, with flat Adam state and BN bookkeeping."""

    def __init__(self, net: nn.Module, layers: list[_Layer], optimizer: th.optim.Optimizer):
        self.net, self.layers, self.spec = net, layers, _Spec.of(layers)
        self.params = list(net.parameters())
        self.flat = th.cat([p.detach().reshape(-1) for p in self.params])
        offset = 0
        for p in self.params:  # module parameters become views of ``flat`` (in-place resets write into it)
            p.data = self.flat[offset : offset + p.numel()].view_as(p)
            offset += p.numel()
        self.bn_layers = [layer.bn for layer in layers if layer.bn is not None]
        self.bn_counts = [int(bn.num_batches_tracked) for bn in self.bn_layers]  # type: ignore[arg-type]
        self.optimizer = optimizer
        group = optimizer.param_groups[0]
        self.lr, self.betas, self.eps = float(group["lr"]), tuple(group["betas"]), float(group["eps"])
        self.views = self.spec.unpack(self.flat)
        self.weights_t = [weight.t() for _, _, weight, _ in self.views]
        self.grad = th.zeros_like(self.flat)
        self.grad_views = self.spec.unpack(self.grad)
        self.exp_avg, self.exp_avg_sq = th.zeros_like(self.flat), th.zeros_like(self.flat)
        self.step_tensor = th.zeros((), dtype=self.flat.dtype, device=self.flat.device)  # fused Adam's step
        self.step_count = 0
        states = [optimizer.state.get(p) for p in self.params]
        if all(states):
            self.exp_avg.copy_(th.cat([st["exp_avg"].reshape(-1) for st in states]))  # type: ignore[index]
            self.exp_avg_sq.copy_(th.cat([st["exp_avg_sq"].reshape(-1) for st in states]))  # type: ignore[index]
            self.step_count = int(float(states[0]["step"]))  # type: ignore[index]

    def reset_adam(self) -> None:
        self.exp_avg.zero_()
        self.exp_avg_sq.zero_()
        self.step_count = 0

    def reset_bn_counts(self) -> None:
        """Call after the running statistics were reset outside (num_batches_tracked back to 0)."""
        self.bn_counts = [0] * len(self.bn_layers)

    def advance(self) -> list[float]:
        """Advance the Adam step and the BN counts (host copies: no device sync); the BN averaging factors."""
        self.step_count += 1
        factors = []
        for j, bn in enumerate(self.bn_layers):
            self.bn_counts[j] += 1
            factors.append(bn.momentum if bn.momentum is not None else 1.0 / self.bn_counts[j])
        return factors

    def step_scalars(self) -> th.Tensor:
        """:meth:`advance`, as one tensor [lr / (1 - beta1^t), sqrt(1 - beta2^t), BN factors...] for the compiled
        steps (values change every step: tensors avoid recompilation)."""
        factors = self.advance()
        t = self.step_count
        values = [self.lr / (1 - self.betas[0] ** t), math.sqrt(1 - self.betas[1] ** t), *factors]
        return th.tensor(values, dtype=self.flat.dtype, device=self.flat.device)

    def finish_fit(self, fixed) -> None:
        """After an eager fit: the first BN layer's deferred running update, and the host BN counts written into
        ``num_batches_tracked`` (the eager steps count on the host only)."""
        if fixed is not None:
            fixed.apply(self.bn_layers[0])
        for bn, count in zip(self.bn_layers, self.bn_counts, strict=True):
            bn.num_batches_tracked.fill_(count)  # type: ignore[union-attr]

    def running(self) -> list[tuple[th.Tensor, th.Tensor, th.Tensor]]:
        return [(bn.running_mean, bn.running_var, bn.num_batches_tracked) for bn in self.bn_layers]  # type: ignore[misc]

    @th.no_grad()
    def eval_affines(self) -> list[tuple[th.Tensor, th.Tensor]]:
        """Eval-mode (running statistics) weight and bias of every linear layer, BN folded in."""
        out = []
        for layer, (gamma, beta, weight, bias) in zip(self.layers, self.spec.unpack(self.flat), strict=True):
            if layer.bn is None:
                out.append((weight, bias))
            else:
                scale = gamma * th.rsqrt(layer.bn.running_var + layer.bn.eps)  # type: ignore[operator]
                out.append((weight * scale, bias + weight @ (beta - layer.bn.running_mean * scale)))  # type: ignore[operator]
        return out

    def eval_forward(self, x: th.Tensor) -> th.Tensor:
        """Eval-mode forward on feature-major x (features, N), batch norm folded into the linear layers."""
        h = x
        for (weight, bias), slope in zip(self.eval_affines(), self.spec.slopes, strict=True):
            h = th.addmm(bias.unsqueeze(1), weight, h)
            if slope is not None:
                th.nn.functional.leaky_relu_(h, slope)
        return h

    def write_back(self) -> None:
        """Store the Adam moments in the torch optimizer's state (a later plain update or a save sees them)."""
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
    """Critic fit and actor fit of one DENFAC update with the step functions above (eager or compiled)."""

    def __init__(
        self,
        policy,
        actor_layers: list[_Layer],
        critic_layers: list[_Layer],
        batch_size: int | None = None,
        compiled_size: int | None = None,
    ):
        """``batch_size``: mini-batch size (None: full batch); ``compiled_size``: sample count N whose steps run
        compiled (None: all eager)."""
        self.batch_size = batch_size
        self.actor = _FlatNet(policy.actor.mu, actor_layers, policy.actor.optimizer)
        self.critic = _FlatNet(policy.critic.qf, critic_layers, policy.critic.optimizer)
        self.compiled_size = compiled_size

    def _sample_count(self, n_full: int) -> int:
        """Samples per step: the whole buffer, or the mini-batch (as ``DENFAC._batch_indices`` draws it)."""
        return n_full if self.batch_size is None or self.batch_size >= n_full else self.batch_size

    def _size_key(self, n: int) -> int | None:
        return n if n == self.compiled_size else None

    def write_back(self) -> None:
        self.actor.write_back()
        self.critic.write_back()

    @th.no_grad()
    def actor_eval(self, obs: th.Tensor) -> th.Tensor:
        """pi(s) in eval mode (running statistics), (N, A) like ``policy.actor(obs)``, from the flat parameters."""
        return self.actor.eval_forward(obs.float().t()).t()

    @th.no_grad()
    def critic_eval(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """Q(s, a) in eval mode, (N, 1) like ``policy.critic(obs, actions)``."""
        return self.critic.eval_forward(th.cat([obs.float(), actions], dim=1).t()).t()

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
        inputs = th.cat([obs.float(), actions], dim=1).t().contiguous()  # feature-major (obs + act, N)
        q_t, c_t = q_targets.reshape(1, -1), weights.reshape(1, -1)
        n_full = inputs.shape[1]
        n = self._sample_count(n_full)
        if self._size_key(n) is not None:
            return self._fit_critic_compiled(inputs, q_t, c_t, steps, max_grad_norm, batch_indices)
        # Eager: the first layer's BN statistics of the fixed data are computed once per fit (full batch).
        ws = eager_steps.Workspace(net.spec.sizes, n, inputs)
        fixed = eager_steps.FixedStats(inputs, ws.centred, net.spec.eps[0]) if net.spec.bn[0] and n == n_full else None
        scaled_full = c_t * (2.0 / n_full)
        loss = None
        for step in range(steps):
            idx = batch_indices(n_full)
            if idx is None:
                x, q, c2 = inputs, q_t, scaled_full
            else:
                x, q, c2 = inputs[:, idx], q_t[:, idx], c_t[:, idx] * (2.0 / n)
            loss = eager_steps.critic_step(net, ws, x, fixed, q, c2, max_grad_norm, want_loss=step == steps - 1)
        net.finish_fit(fixed)
        return loss  # type: ignore[return-value]

    def _fit_critic_compiled(self, inputs, q_t, c_t, steps, max_grad_norm, batch_indices) -> th.Tensor:
        net = self.critic
        full_stats = row_var_mean(inputs) if net.spec.bn[0] else None  # fixed data: once per fit
        loss = th.zeros((), device=inputs.device)
        running = net.running()
        for _ in range(steps):
            idx = batch_indices(inputs.shape[1])
            x, q, c = (inputs, q_t, c_t) if idx is None else (inputs[:, idx], q_t[:, idx], c_t[:, idx])
            step = _step_function("critic", self._size_key(x.shape[1]), net.spec, net.betas, net.eps, max_grad_norm)
            stats0 = full_stats if idx is None else None
            loss = step(net.flat, net.exp_avg, net.exp_avg_sq, net.step_scalars(), running, x, stats0, q, c)
        return loss

    @th.no_grad()
    def fit_actor(self, obs: th.Tensor, steps: int, max_grad_norm: float | None, inverting: bool, batch_indices) -> th.Tensor:
        """G Adam steps ascending 1/N sum Q(s, pi(s)) (critic in eval mode); returns the last objective."""
        net = self.actor
        obs_t = obs.float().t().contiguous()
        action_dim = net.spec.sizes[-1]
        critic_affines = self.critic.eval_affines()
        w_first, b_first = critic_affines[0]
        w_act = w_first[:, -action_dim:].contiguous()
        obs_part_full = th.addmm(b_first.unsqueeze(1), w_first[:, :-action_dim], obs_t)  # fixed over the G steps
        n_full = obs_t.shape[1]
        n = self._sample_count(n_full)
        if self._size_key(n) is not None:
            return self._fit_actor_compiled(
                obs_t, critic_affines, w_act, obs_part_full, steps, max_grad_norm, inverting, batch_indices
            )
        ws = eager_steps.Workspace(net.spec.sizes, n, obs_t)
        fixed = eager_steps.FixedStats(obs_t, ws.centred, net.spec.eps[0]) if net.spec.bn[0] and n == n_full else None
        critic_full = eager_steps.EvalCritic(
            critic_affines, self.critic.spec.slopes, obs_part_full, action_dim, self.critic.spec.sizes, n
        )
        objective = None
        for step in range(steps):
            idx = batch_indices(n_full)
            o, critic = (obs_t, critic_full) if idx is None else (obs_t[:, idx], critic_full.subset(idx))
            objective = eager_steps.actor_step(
                net, ws, o, fixed, critic, max_grad_norm, inverting, want_objective=step == steps - 1
            )
        net.finish_fit(fixed)
        return objective  # type: ignore[return-value]

    def _fit_actor_compiled(self, obs_t, critic_affines, w_act, obs_part_full, steps, max_grad_norm, inverting, batch_indices):
        net = self.actor
        objective = th.zeros((), device=obs_t.device)
        running = net.running()
        for _ in range(steps):
            idx = batch_indices(obs_t.shape[1])
            o, obs_part = (obs_t, obs_part_full) if idx is None else (obs_t[:, idx], obs_part_full[:, idx])
            key = (net.spec, self.critic.spec.slopes, net.betas, net.eps, max_grad_norm, inverting)
            step = _step_function("actor", self._size_key(o.shape[1]), *key)
            objective = step(
                net.flat, net.exp_avg, net.exp_avg_sq, net.step_scalars(), running, o, obs_part, w_act, critic_affines
            )
        return objective
