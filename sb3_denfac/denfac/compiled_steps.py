"""DENFAC's critic and actor steps for ``update_path="compiled"``: pure functions of tensors for ``torch.compile``.

Each step (train-mode forward, hand-written backward, BN running statistics, clip_grad_norm_ and Adam) is one
function of the flat parameters, Adam moments and data, compiled with static shapes, so inductor fuses the
element-wise passes around the matmuls and the per-op dispatch of eager mode disappears. Written for fusion:
``mm + bias`` instead of ``addmm``, the critic's action input as broadcasts, and the actor's critic gradient through
the first hidden layer as one (A*K, H) @ (H, N) matmul on the activation derivative.

The arithmetic is the eager steps' (``eager_steps.py``) up to float rounding: see ``fast.py``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch as th

from sb3_denfac.common.inverting_gradients import invert_gradients

if TYPE_CHECKING:
    from sb3_denfac.denfac.fast import _Spec


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


def _linear(weight: th.Tensor, bias: th.Tensor, h: th.Tensor) -> th.Tensor:
    """weight @ h + bias[:, None] as mm + add, so that the add fuses into the next element-wise kernel."""
    return th.mm(weight, h) + bias.unsqueeze(1)


def _train_forward(spec: _Spec, flat: th.Tensor, x: th.Tensor, stats0: tuple[th.Tensor, th.Tensor] | None):
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
        z = _linear(w_eff, b_eff, h)
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


def _make_critic_step(spec: _Spec, betas: tuple[float, float], eps: float, max_grad_norm: float | None):
    def critic_step(flat, exp_avg, exp_avg_sq, scalars, running, x, stats0, q, c):
        out, cache, stats = _train_forward(spec, flat, x, stats0)
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
):
    def actor_step(flat, exp_avg, exp_avg_sq, scalars, running, obs, obs_part, w_act, critic_affines):
        pi, cache, stats = _train_forward(spec, flat, obs, None)
        _update_running_(running, stats, scalars, obs.shape[1])
        # Critic in eval mode on (s, pi(s)) (BN folded with running statistics), then d mean(Q) / d pi by hand.
        z = obs_part  # obs_part + w_act @ pi as broadcasts: one fused pass with the activation (few actions)
        for a in range(pi.shape[0]):
            z = z + w_act[:, a : a + 1] * pi[a : a + 1]
        outs = []
        for i, (weight, bias) in enumerate(critic_affines):
            if i > 0:
                z = _linear(weight, bias, outs[-1])
            outs.append(th.nn.functional.leaky_relu(z, critic_slopes[i]) if critic_slopes[i] is not None else z)
        objective = outs[-1].mean()
        dz = th.full_like(outs[-1], 1.0 / pi.shape[1])
        n_layers = len(critic_affines)
        last = 1 if n_layers > 1 else 0
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


def compiled_step(kind: str, n: int, *key):
    """The ``torch.compile``d critic or actor step for a static key and sample count ``n``, cached per process.

    Static shapes (one N) generate much faster code than dynamic ones, so the compiled steps serve only the sample
    count that repeats, the full buffer or the mini-batch size (see ``FastUpdate``); the compilation is paid once.
    """
    cache_key = (kind, n, key)
    if cache_key not in _STEP_FUNCTIONS:
        factory = _make_critic_step if kind == "critic" else _make_actor_step
        _STEP_FUNCTIONS[cache_key] = th.compile(factory(*key), dynamic=False)
    return _STEP_FUNCTIONS[cache_key]
