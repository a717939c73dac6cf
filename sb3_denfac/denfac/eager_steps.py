"""Critic and actor steps of DENFAC's fast updater (``fast.py``): few ops, no per-step allocations.

At the paper's sizes (D = 6000 samples, critic 50-7) a critic step is ~70 tensor ops and an actor step ~35, around a
handful of matmuls over (50, N) activations, so two costs dominate: per-op dispatch (~2 us each, 350 steps per
update) and passes over the activations. These functions therefore

- write every (features, N) intermediate into buffers preallocated once per fit (:class:`Workspace`), with ``out=``
  and in-place ops: no per-step allocation with full batches (a fresh 1.2 MB tensor per op made glibc map and fault
  in pages, which slowed updates 2-3x at random) and fewer passes over memory; mini-batch steps allocate only the
  gathered batch;
- write gradients straight into views of one flat gradient tensor, and step Adam with PyTorch's fused Adam kernel
  (``torch._fused_adam_``, the kernel behind ``Adam(fused=True)``): one op instead of a dozen;
- use ``aten.leaky_relu_backward`` for the activations' backward in place.

The two kernels are private PyTorch APIs: where a torch version lacks one, the same arithmetic runs with public ops
(:data:`FUSED_ADAM`, :data:`LEAKY_RELU_BACKWARD`; tested by switching them off).
- skip what the algorithm never reads: the loss of every critic step but the last, the objective of every actor step
  but the last, the input gradient of the first layer;
- fold batch norm into the following linear layer (``W diag(gamma rstd)``, shifted bias), so normalised activations
  are never written.

The arithmetic is the autograd updater's (``clip_grad_norm_``, ``torch.optim.Adam``) up to float rounding. The tests
check the gradients against autograd, whole updates against the autograd updater, that no per-step allocation
happens, and that nothing assumes the CPU (a run on the "meta" device).
"""

from __future__ import annotations

import torch as th
from torch.nn import functional as F  # noqa: N812

from sb3_denfac.common.inverting_gradients import invert_gradients_unit_box

#: Whether this torch has the private fused Adam kernel (else: the same Adam step with public ops).
FUSED_ADAM = hasattr(th, "_fused_adam_")
#: Whether this torch has the private ``aten.leaky_relu_backward`` op (else: a multiply by the slope mask).
LEAKY_RELU_BACKWARD = hasattr(th.ops.aten, "leaky_relu_backward")


def leaky_relu_backward(grad: th.Tensor, activation: th.Tensor, slope: float, out: th.Tensor) -> th.Tensor:
    """``out`` <- ``grad`` * (1 where ``activation`` > 0 else ``slope``); ``activation`` may be the leaky ReLU's
    input or its output (same signs for a positive slope). ``out`` may be ``grad``."""
    if LEAKY_RELU_BACKWARD:
        return th.ops.aten.leaky_relu_backward.grad_input(grad, activation, slope, True, grad_input=out)
    return th.mul(grad, th.where(activation > 0, 1.0, slope), out=out)


def _activate_(h: th.Tensor, slope: float | None) -> th.Tensor:
    """In place leaky ReLU (None: linear)."""
    return h if slope is None else F.leaky_relu_(h, slope)


def _activation_backward_(grad: th.Tensor, out: th.Tensor, slope: float | None) -> th.Tensor:
    """In place: ``grad`` <- d leaky_relu / d input * ``grad``, from the activation's output ``out``."""
    if slope is None:
        return grad
    return leaky_relu_backward(grad, out, slope, out=grad)


class Workspace:
    """Preallocated feature-major (features, N) buffers of one network for one sample count N."""

    def __init__(self, sizes: tuple[int, ...], n: int, like: th.Tensor):
        def empty(rows: int) -> th.Tensor:
            return th.empty((rows, n), dtype=like.dtype, device=like.device)

        self.outputs = [empty(d) for d in sizes[1:]]  # post-activation output of every layer
        self.outputs_t = [out.t() for out in self.outputs]  # views, made once
        self.input_grads = [empty(d) for d in sizes[:-1]]  # d loss / d (input of layer i), i >= 1 used
        self.centred = empty(max(sizes[:-1]))  # scratch for the batch-norm variance


def batch_stats(h: th.Tensor, scratch: th.Tensor, eps: float) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
    """Batch mean, biased variance and 1/sqrt(var + eps) of each row of a (C, N) tensor (two-pass: no cancellation)."""
    mean = h.mean(1)
    centred = th.sub(h, mean.unsqueeze(1), out=scratch[: h.shape[0]])
    var = th.linalg.vector_norm(centred, dim=1).square_().div_(h.shape[1])
    return mean, var, (var + eps).rsqrt_()


def forward_train(net, ws: Workspace, x: th.Tensor, fixed: FixedStats | None) -> list:
    """Train-mode forward of a flat ``create_bn_mlp`` network on feature-major x; outputs land in ``ws.outputs``.

    ``fixed``: the first BN layer's statistics when x is the same at every step of the fit (x is then normalised once).
    Returns per layer (mean, var, rstd, effective weight, matmul input, its transpose) for the backward pass and the
    running statistics; rstd is None where the matmul input is the already normalised x.
    """
    spec, h, h_t, folds = net.spec, x, x.t(), []
    for i, (gamma, beta, weight, bias) in enumerate(net.views):
        if gamma is None:
            w_eff, b_col = weight, net.bias_cols[i]
            folds.append((None, None, None, w_eff, h, h_t))
        elif i == 0 and fixed is not None:  # BN(x) = gamma xhat + beta with xhat computed once per fit
            w_eff = weight * gamma
            b_col = th.addmv(bias, weight, beta).unsqueeze(1)
            h, h_t = fixed.normalized, fixed.normalized_t
            folds.append((fixed.mean, fixed.var, None, w_eff, h, h_t))
        else:
            mean, var, rstd = batch_stats(h, ws.centred, spec.eps[i])
            # BN(h) = gamma (h - mean) rstd + beta folded into the linear layer: W' = W diag(s), b' = b + W (beta - mean s)
            scale = gamma * rstd
            w_eff = weight * scale
            b_col = th.addmv(bias, weight, th.addcmul(beta, mean, scale, value=-1.0)).unsqueeze(1)
            folds.append((mean, var, rstd, w_eff, h, h_t))
        h = _activate_(th.addmm(b_col, w_eff, h, out=ws.outputs[i]), spec.slopes[i])
        h_t = ws.outputs_t[i]
    return folds


def update_running_stats(net, folds: list, n: int, factors: list[float], skip_first: bool) -> None:
    """BatchNorm1d's running-statistics update (unbiased variance); ``factors``: averaging factor per BN layer.

    ``skip_first``: the first BN layer sees the same data at every step of the fit; its running statistics are then
    updated once at the end (:class:`FixedStats`).
    """
    j = 0
    for layer_bn, (mean, var, *_) in zip(net.spec.bn, folds, strict=True):
        if not layer_bn:
            continue
        if not (j == 0 and skip_first):
            bn = net.bn_layers[j]
            bn.running_mean.lerp_(mean, factors[j])
            bn.running_var.lerp_(var * (n / (n - 1)), factors[j])
        j += 1


class FixedStats:
    """Batch statistics of the first BN layer's input when it is the same data at every step (full-batch fits).

    The input is normalised once (``normalized``). Its running statistics follow r <- r + f_t (x - r) at every step;
    with x fixed that is one update with weight 1 - prod_t (1 - f_t), applied by :meth:`apply` after the fit (exactly x
    when the statistics were reset, f_1 = 1).
    """

    def __init__(self, x: th.Tensor, scratch: th.Tensor, eps: float):
        self.mean, self.var, rstd = batch_stats(x, scratch, eps)
        self.normalized = (x - self.mean.unsqueeze(1)).mul_(rstd.unsqueeze(1))  # xhat, once per fit
        self.normalized_t = self.normalized.t()
        self.n = x.shape[1]
        self.keep = 1.0

    def step(self, factor: float) -> None:
        self.keep *= 1.0 - factor

    def apply(self, bn) -> None:
        bn.running_mean.lerp_(self.mean, 1.0 - self.keep)
        bn.running_var.lerp_(self.var * (self.n / (self.n - 1)), 1.0 - self.keep)


def backward(net, ws: Workspace, x: th.Tensor, folds: list, grad_out: th.Tensor) -> None:
    """Write d loss / d parameters of a :func:`forward_train` pass into ``net.grad`` (flat), given d loss / d output.

    Batch-norm layers use the folded form: with xhat = (h - mean) rstd and m = sum_n dz h^T,
    dW = gamma (m - sum(dz) mean^T) rstd + sum(dz) beta^T, and d loss / d h is an affine map of h per feature.
    """
    spec, n, dz = net.spec, x.shape[1], grad_out
    for i in range(len(net.views) - 1, -1, -1):
        gamma, beta, weight, _ = net.views[i]
        g_gamma, g_beta, g_weight, g_bias = net.grad_views[i]
        mean, _, rstd, w_eff, h, h_t = folds[i]
        th.sum(dz, 1, out=g_bias)
        if gamma is None:
            th.mm(dz, h_t, out=g_weight)
            dx = th.mm(net.weights_t[i], dz, out=ws.input_grads[i]) if i > 0 else None
        else:
            t = th.mm(dz, h_t)  # sum_n dz xhat^T (h = xhat already normalised when rstd is None)
            if rstd is not None:
                t.addr_(g_bias, mean, alpha=-1.0).mul_(rstd)
            th.mul(t, gamma, out=g_weight).addr_(g_bias, beta)
            th.mv(net.weights_t[i], g_bias, out=g_beta)  # sum_n dL/dBN(h)
            th.sum(weight * t, 0, out=g_gamma)  # sum_n dL/dBN(h) xhat
            dx = None
            if i > 0:  # dL/dh = rstd gamma (g - mean_n g - xhat mean_n(g xhat)), g = W^T dz: affine in h per feature
                k = rstd * gamma / n
                r = k * rstd * g_gamma
                shift = th.addcmul(r * mean, k, g_beta, value=-1.0)
                dx = th.addmm(shift.unsqueeze(1), w_eff.t(), dz, out=ws.input_grads[i])
                dx.addcmul_(h, r.unsqueeze(1), value=-1.0)
        if dx is not None:
            _activation_backward_(dx, h, spec.slopes[i - 1])
        dz = dx  # type: ignore[assignment]


def adam_step(net, max_grad_norm: float | None) -> None:
    """clip_grad_norm_ then one torch Adam step on the flat parameters (PyTorch's fused Adam kernel if available)."""
    grad = net.grad
    scale = None
    if max_grad_norm is not None:  # the clipping factor is 1 / scale: clip_grad_norm_'s max_norm / (norm + 1e-6), <= 1
        scale = ((th.linalg.vector_norm(grad) + 1e-6) / max_grad_norm).clamp_(min=1.0)
    if not FUSED_ADAM:
        _adam_step_public(net, grad if scale is None else grad / scale)
        return
    net.step_tensor.fill_(net.step_count)
    th._fused_adam_(
        [net.flat],
        [grad],
        [net.exp_avg],
        [net.exp_avg_sq],
        [],
        [net.step_tensor],
        lr=net.lr,
        beta1=net.betas[0],
        beta2=net.betas[1],
        weight_decay=0.0,
        eps=net.eps,
        amsgrad=False,
        maximize=False,
        grad_scale=scale,
    )


def _adam_step_public(net, grad: th.Tensor) -> None:
    """``torch.optim.Adam``'s step (no weight decay, no amsgrad) with public ops; ``net.step_count`` is the step t."""
    beta1, beta2 = net.betas
    t = net.step_count
    net.exp_avg.lerp_(grad, 1.0 - beta1)
    net.exp_avg_sq.mul_(beta2).addcmul_(grad, grad, value=1.0 - beta2)
    denom = (net.exp_avg_sq.sqrt() / (1.0 - beta2**t) ** 0.5).add_(net.eps)
    net.flat.addcdiv_(net.exp_avg, denom, value=-net.lr / (1.0 - beta1**t))


def step_forward(net, ws: Workspace, x, fixed: FixedStats | None) -> list:
    """The forward half of a training step (critic or actor): the network's output in train mode into
    ``ws.outputs[-1]``, its running statistics updated; returns what :func:`backward` needs."""
    factors = net.advance()
    folds = forward_train(net, ws, x, fixed)
    update_running_stats(net, folds, x.shape[1], factors, skip_first=fixed is not None)
    if fixed is not None:
        fixed.step(factors[0])
    return folds


def critic_step(net, ws: Workspace, x, fixed: FixedStats | None, q_targets, scaled_weights, max_grad_norm, want_loss: bool):
    """One Adam step on 1/N sum_n c_n (Q(s_n, a_n) - q_n)^2 (Algorithm 1, critic fit); ``scaled_weights`` = 2 c / N.

    Returns the loss before the step if ``want_loss`` (only the last step's is logged), else None.
    """
    folds = step_forward(net, ws, x, fixed)
    diff = ws.outputs[-1].sub_(q_targets)  # the output buffer is not read again
    loss = th.dot(diff[0], diff[0] * scaled_weights[0]) * 0.5 if want_loss else None
    backward(net, ws, x, folds, diff.mul_(scaled_weights))
    adam_step(net, max_grad_norm)
    return loss


class EvalCritic:
    """The critic in eval mode for an actor fit: BN folded into affines, first layer split into a fixed observation
    part W_s s + b (computed once per fit, all samples) and the action weights W_a, and buffers for n samples
    per step (the whole buffer, or a mini-batch: :meth:`subset`)."""

    def __init__(self, affines: list, slopes: tuple, obs_part: th.Tensor, action_dim: int, sizes: tuple[int, ...], n: int):
        self.affines, self.slopes, self.obs_part = affines, slopes, obs_part
        self.w_act = affines[0][0][:, -action_dim:].contiguous()
        self.w_act_t = self.w_act.t()
        self.ws = Workspace(sizes, n, obs_part)
        self.grad, self.inverted = (obs_part.new_empty((action_dim, n)) for _ in range(2))
        w_last, b_last = affines[-1]
        # d mean_n Q / d (last hidden output) = w_last / N for every sample: a broadcast view, made once
        self.dq_dh_last = (w_last[0] / n).unsqueeze(1).expand(w_last.shape[1], n)
        self.w_last, self.b_last = w_last, b_last
        self.weights_t = [weight.t() for weight, _ in affines]  # views, made once
        self.bias_cols = [bias.unsqueeze(1) for _, bias in affines]

    def subset(self, idx: th.Tensor) -> EvalCritic:
        """The same critic on the mini-batch ``idx``."""
        sub = object.__new__(EvalCritic)
        sub.__dict__.update(self.__dict__)
        sub.obs_part = self.obs_part[:, idx]
        return sub

    def action_gradient(self, pi: th.Tensor, want_value: bool) -> tuple[th.Tensor, th.Tensor | None]:
        """d (1/N sum_n Q(s_n, pi_n)) / d pi (A, N), and the mean Q if ``want_value``."""
        affines, slopes, ws, n_layers = self.affines, self.slopes, self.ws, len(self.affines)
        if n_layers == 1:  # linear critic
            value = self.obs_part.mean() + th.dot(self.w_act[0], pi.mean(1)) if want_value else None
            return self.grad.copy_((self.w_act_t / pi.shape[1]).expand_as(pi)), value
        last = n_layers - 2  # the last hidden layer: its activation only matters for the value, its mask for d/dpi
        h = ws.outputs[0]
        if pi.shape[0] == 1:  # a rank-1 update: one pass instead of addmm's two
            th.addcmul(self.obs_part, self.w_act, pi, out=h)
        else:
            th.addmm(self.obs_part, self.w_act, pi, out=h)
        for i in range(last + 1):
            if i > 0:
                h = th.addmm(self.bias_cols[i], affines[i][0], h, out=ws.outputs[i])
            if i < last or want_value:
                _activate_(h, slopes[i])
        value = th.addmv(self.b_last, self.w_last, h.mean(1))[0] if want_value else None
        dz = ws.input_grads[last + 1]
        if slopes[last] is None:
            dz.copy_(self.dq_dh_last)
        else:  # the leaky-ReLU mask from the output (activated) or the pre-activation: the same signs
            leaky_relu_backward(self.dq_dh_last, h, slopes[last], out=dz)
        for i in range(last, 0, -1):
            dh = th.mm(self.weights_t[i], dz, out=ws.input_grads[i])
            dz = _activation_backward_(dh, ws.outputs[i - 1], slopes[i - 1])
        return th.mm(self.w_act_t, dz, out=self.grad), value


def actor_step(
    net,
    ws: Workspace,
    obs,
    fixed: FixedStats | None,
    critic: EvalCritic,
    max_grad_norm,
    inverting: bool,
    want_objective: bool,
    proximal: tuple[float, th.Tensor] | None = None,
):
    """One Adam step ascending 1/N sum_n Q(s_n, pi(s_n)) (Algorithm 1, actor fit; inverting gradients optional).

    ``proximal`` = (lambda, pi_old(s) feature-major): the step descends the proximal loss of
    :mod:`~sb3_denfac.denfac.options` instead, dL/dpi_n = -a_n / sum_m ||a_m|| + 2 lambda (pi_n - pi_old_n) / N with
    a_n = the (inverted) ascent direction d(1/N sum Q)/dpi_n = g_n / N, so a_n / sum ||a|| = g_n / (N S).
    Returns the objective (mean Q, without the penalty) before the step if ``want_objective``, else None.
    """
    folds = step_forward(net, ws, obs, fixed)
    pi = ws.outputs[-1]
    ascent, objective = critic.action_gradient(pi, want_objective)
    if inverting:
        ascent = invert_gradients_unit_box(ascent, pi, out=critic.inverted)
    if proximal is None:
        grad_pi = ascent.neg_()
    else:
        coef, old_pi = proximal
        scale = th.linalg.vector_norm(ascent, dim=0).sum().clamp_(min=1e-12)
        grad_pi = th.sub(pi, old_pi).mul_(2.0 * coef / pi.shape[1]).sub_(ascent.div_(scale))
    backward(net, ws, obs, folds, grad_pi)
    adam_step(net, max_grad_norm)
    return objective
