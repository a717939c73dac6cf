"""The fast updater of DENFAC's end-of-episode update: the autograd updater's arithmetic in far fewer ops.

The update fits tiny networks (e.g. 5-50-7-1) on a few thousand samples hundreds of times, so per-op dispatch and
memory passes over the activations dominate, not FLOPs. The :class:`FastUpdater`

- keeps each network's parameters in one flat tensor (the module's parameters become views of it, so in-place resets
  write into it), with flat Adam moments and gradients: clipping and Adam are a few ops per step, not a few per
  parameter tensor;
- lays activations out feature-major (features, N): the long sample axis is the matmuls' inner/outer dimension and
  the per-feature batch-norm reductions are contiguous;
- folds batch norm into the following linear layer (``W diag(gamma rstd)``, shifted bias) and writes the backward pass
  by hand (no autograd graph), with the steps of :mod:`~sb3_denfac.denfac.eager_steps`;
- splits the critic's first layer in eval mode into an observation part, computed once per actor fit, and an action
  part for the G actor steps; targets and importance weights use the same eval-mode flat networks.

Running statistics, Adam moments and step counts follow PyTorch's ``BatchNorm1d`` and ``Adam`` (up to float
rounding), so both updaters give the same result for the same seed (tested). Everything stays on the networks'
device and the steps never wait for it: the only reads back are the logged losses at the end of an update and, with
a set ``bn_momentum`` (no reset of the statistics), ``num_batches_tracked`` once per update.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch as th
from torch import nn

from sb3_denfac.denfac import eager_steps
from sb3_denfac.denfac.policies import combine_critics
from sb3_denfac.denfac.updaters import FitSettings, Updater


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
    """Static description of a ``create_bn_mlp`` network for the step functions."""

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
        self.bn_counts: list[int] | None = None  # host copies of num_batches_tracked, read when first needed
        self.optimizer = optimizer
        group = optimizer.param_groups[0]
        self.lr, self.betas, self.eps = float(group["lr"]), tuple(group["betas"]), float(group["eps"])
        self.views = self.spec.unpack(self.flat)
        self.weights_t = [weight.t() for _, _, weight, _ in self.views]
        self.bias_cols = [bias.unsqueeze(1) for _, _, _, bias in self.views]
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

    def reset(self) -> None:
        """Call after the network was re-initialised in place (weights and BN statistics): forget Adam's state."""
        self.exp_avg.zero_()
        self.exp_avg_sq.zero_()
        self.step_count = 0
        self.reset_bn_counts()

    def reset_bn_counts(self) -> None:
        """Call after the running statistics were reset outside (num_batches_tracked back to 0)."""
        self.bn_counts = [0] * len(self.bn_layers)

    def advance(self) -> list[float]:
        """Advance the Adam step and the BN counts (host copies: no device sync); the BN averaging factors."""
        self.step_count += 1
        if self.bn_counts is None:  # a device read, avoided when the statistics were reset (DENFAC's default)
            self.bn_counts = [int(bn.num_batches_tracked) for bn in self.bn_layers]  # type: ignore[arg-type]
        factors = []
        for j, bn in enumerate(self.bn_layers):
            self.bn_counts[j] += 1
            factors.append(bn.momentum if bn.momentum is not None else 1.0 / self.bn_counts[j])
        return factors

    def finish_fit(self, fixed) -> None:
        """After an eager fit: the first BN layer's deferred running update, and the host BN counts written into
        ``num_batches_tracked`` (the eager steps count on the host only)."""
        if fixed is not None:
            fixed.apply(self.bn_layers[0])
        for bn, count in zip(self.bn_layers, self.bn_counts or [], strict=False):
            bn.num_batches_tracked.fill_(count)  # type: ignore[union-attr]

    @th.no_grad()
    def eval_affines(self) -> list[tuple[th.Tensor, th.Tensor]]:
        """Eval-mode (running statistics) weight and bias of every linear layer, BN folded in."""
        out = []
        for layer, (gamma, beta, weight, bias) in zip(self.layers, self.views, strict=True):
            if layer.bn is None:
                out.append((weight, bias))
            else:
                scale = gamma * th.rsqrt(layer.bn.running_var + layer.bn.eps)  # type: ignore[operator]
                out.append((weight * scale, bias + weight @ (beta - layer.bn.running_mean * scale)))  # type: ignore[operator]
        return out

    def eval_forward(self, x: th.Tensor, affines: list[tuple[th.Tensor, th.Tensor]] | None = None) -> th.Tensor:
        """Eval-mode forward on feature-major x (features, N), batch norm folded into the linear layers (``affines``:
        those of :meth:`eval_affines` taken earlier, e.g. a frozen copy; default: the current ones)."""
        h = x
        for (weight, bias), slope in zip(affines or self.eval_affines(), self.spec.slopes, strict=True):
            h = th.addmm(bias.unsqueeze(1), weight, h)
            if slope is not None:
                th.nn.functional.leaky_relu_(h, slope)
        return h

    def write_back(self) -> None:
        """Store the Adam moments in the torch optimizer's state (a later plain update or a save sees them)."""
        for p in self.params:  # this network's entries only: the critic's optimizer also holds the twin Q networks'
            self.optimizer.state.pop(p, None)
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


def dict_keys_of(policy) -> list[str] | None:
    """The keys of a Dict observation in the order SB3's ``CombinedExtractor`` concatenates them, where its features
    are that concatenation (every key a 1-D ``Box``, flattened as it is: ``MultiInputPolicy``'s default on goal
    envs); None for any other policy."""
    from gymnasium import spaces
    from stable_baselines3.common.torch_layers import CombinedExtractor

    space = policy.observation_space
    if not isinstance(space, spaces.Dict):
        return None
    keys = []
    for net in (policy.actor, policy.critic):
        extractor = getattr(net, "features_extractor", None)
        if not isinstance(extractor, CombinedExtractor):
            return None
        if not all(isinstance(module, nn.Flatten) for module in extractor.extractors.values()):
            return None
        keys.append(list(extractor.extractors))
    if keys[0] != keys[1] or sorted(keys[0]) != sorted(space.spaces):
        return None
    if not all(isinstance(space[key], spaces.Box) and len(space[key].shape) == 1 for key in keys[0]):
        return None
    return keys[0]


def flat_observations(obs: th.Tensor | dict[str, th.Tensor], keys: list[str] | None) -> th.Tensor:
    """The networks' input: vector observations as they are, Dict ones concatenated in ``keys``' order (what
    ``CombinedExtractor`` computes for 1-D Boxes, :func:`dict_keys_of`)."""
    if keys is None:
        return obs  # type: ignore[return-value]
    return th.cat([obs[key].float() for key in keys], dim=1)  # type: ignore[index]


def supported_networks(policy, flat_actor: bool = True) -> tuple[list[_Layer] | None, list[list[_Layer]]] | None:
    """Parsed layers of the actor and of each Q network of the critic if the fast path supports this policy (vector
    observations, or Dict ones of 1-D Boxes with SB3's ``CombinedExtractor``; Adam), else None; the actor's are None
    without ``flat_actor`` (an actor fitted by autograd, as SoftDENFAC's)."""
    from gymnasium import spaces
    from stable_baselines3.common.torch_layers import FlattenExtractor

    vector = isinstance(policy.observation_space, spaces.Box) and len(policy.observation_space.shape) == 1
    if not vector and dict_keys_of(policy) is None:
        return None
    for net in (policy.actor, policy.critic):
        if vector and not isinstance(getattr(net, "features_extractor", None), FlattenExtractor):
            return None
        opt = net.optimizer
        group = opt.param_groups[0]
        if type(opt) is not th.optim.Adam or len(opt.param_groups) != 1:
            return None
        if group.get("weight_decay", 0) != 0 or group.get("amsgrad") or group.get("maximize"):
            return None
        if group.get("capturable") or group.get("fused"):  # their step counts live on the device; ours on the host
            return None
    critic_layers = [parse_bn_mlp(q) for q in policy.critic.q_networks]
    if any(layers is None for layers in critic_layers):
        return None
    if not flat_actor:  # the actor stays on autograd; the critic's steps are fast
        return None, critic_layers  # type: ignore[return-value]
    actor_layers = parse_bn_mlp(policy.actor.mu)
    if actor_layers is None:
        return None
    return actor_layers, critic_layers  # type: ignore[return-value]


class FastUpdater(Updater):
    """The :class:`~sb3_denfac.denfac.updaters.Updater` on flat parameters with the eager steps of ``eager_steps.py``.

    Needs the policy shapes :func:`supported_networks` accepts; the flat state is written back by :meth:`finish`. A
    subclass with ``flat_actor = False`` (SoftDENFAC's) gets ``actor_layers`` None: only the critic is flat, and the
    critic module's parameters are views of the flat ones, so an actor fitted by autograd ascends the critic as fitted
    so far.
    """

    #: whether the actor is fitted on flat parameters too (False: :func:`supported_networks` parses the critic only)
    flat_actor: bool = True

    def __init__(self, policy, settings: FitSettings, actor_layers: list[_Layer] | None, critic_layers: list[list[_Layer]]):
        super().__init__(policy, settings)
        self.actor_net = None if actor_layers is None else _FlatNet(policy.actor.mu, actor_layers, policy.actor.optimizer)
        self.critic_nets = [
            _FlatNet(q_net, layers, policy.critic.optimizer)
            for q_net, layers in zip(policy.critic.q_networks, critic_layers, strict=True)
        ]
        self.critic_net = self.critic_nets[0]  # Q_1, the one the actor ascends
        self.dict_keys = dict_keys_of(policy)  # Dict observations: concatenated as the features extractor does
        # actor_proximal: pi_old = the actor at the start of the update (eval mode), as frozen folded affines
        self.old_actor_affines = None
        if settings.actor_proximal > 0 and self.actor_net is not None:
            self.old_actor_affines = [(w.clone(), b.clone()) for w, b in self.actor_net.eval_affines()]

    def reset_critic(self) -> None:
        super().reset_critic()
        for net in self.critic_nets:
            net.reset()

    def reset_actor(self) -> None:
        super().reset_actor()
        if self.actor_net is not None:
            self.actor_net.reset()

    def finish(self) -> None:
        for net in (self.actor_net, *self.critic_nets):
            if net is not None:
                net.write_back()

    @th.no_grad()
    def actor(self, obs: th.Tensor) -> th.Tensor:
        """pi(s) in eval mode (running statistics), (N, A) like ``policy.actor(obs)``, from the flat parameters."""
        if self.actor_net is None:  # an actor fitted by autograd: its mean action, from the module
            self.policy.actor.set_training_mode(False)
            return self.policy.actor(obs)
        # contiguous as the module's output: noise drawn like it (TD3's target smoothing, randn_like) fills the same
        # elements with the same draws as on the autograd path
        return self.actor_net.eval_forward(flat_observations(obs, self.dict_keys).float().t()).t().contiguous()

    @th.no_grad()
    def critic(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """Q_1..Q_n combined (``critic_target``) in eval mode, (N, 1) like ``policy.critic.target_q(obs, actions, how)``."""
        inputs = th.cat([flat_observations(obs, self.dict_keys).float(), actions], dim=1).t()
        return combine_critics([net.eval_forward(inputs) for net in self.critic_nets], self.settings.critic_target).t()

    @th.no_grad()
    def fit_critic(
        self, obs: th.Tensor, actions: th.Tensor, q_targets: th.Tensor, weights: th.Tensor, batches: th.Tensor | None = None
    ) -> th.Tensor:
        nets, steps = self.critic_nets, self.settings.critic_steps
        if self.fresh_bn_statistics(self.policy.critic):
            for net in nets:
                net.reset_bn_counts()
        obs = flat_observations(obs, self.dict_keys)
        inputs = th.cat([obs.float(), actions], dim=1).t().contiguous()  # feature-major (obs + act, N)
        q_t, c_t = q_targets.reshape(1, -1), weights.reshape(1, -1)
        n_full = inputs.shape[1]
        n = batches.shape[1] if batches is not None else self.sample_count(n_full)
        whole = batches is None and n == n_full  # every step reads all the rows given, in their order
        # Full batch: the first layer's input is the same at every step, normalised once (FixedStats).
        workspaces = [eager_steps.Workspace(net.spec.sizes, n, inputs) for net in nets]
        fixed = [
            eager_steps.FixedStats(inputs, ws.centred, net.spec.eps[0]) if net.spec.bn[0] and whole else None
            for net, ws in zip(nets, workspaces, strict=True)
        ]
        scaled_full = c_t * (2.0 / n_full)
        losses = []
        for step in range(steps):
            # one mini-batch for every Q network, as the autograd updater
            idx = batches[step] if batches is not None else self.batch_indices(n_full)
            if idx is None:
                x, q, c2 = inputs, q_t, scaled_full
            else:
                x, q, c2 = inputs[:, idx], q_t[:, idx], c_t[:, idx] * (2.0 / n)
            losses = [
                eager_steps.critic_step(net, ws, x, fix, q, c2, self.settings.max_grad_norm, want_loss=step == steps - 1)
                for net, ws, fix in zip(nets, workspaces, fixed, strict=True)
            ]
        for net, fix in zip(nets, fixed, strict=True):
            net.finish_fit(fix)
        return losses[0]  # type: ignore[return-value]

    @th.no_grad()
    def fit_actor(self, obs: th.Tensor, batches: th.Tensor | None = None) -> th.Tensor:
        net, steps = self.actor_net, self.settings.actor_steps
        assert net is not None, "flat_actor=False: the subclass fits the actor"
        if steps == 0:
            return th.zeros(())
        if self.fresh_bn_statistics(self.policy.actor):
            net.reset_bn_counts()
        obs_t = flat_observations(obs, self.dict_keys).float().t().contiguous()
        action_dim = net.spec.sizes[-1]
        critic_affines = self.critic_net.eval_affines()
        w_first, b_first = critic_affines[0]
        obs_part_full = th.addmm(b_first.unsqueeze(1), w_first[:, :-action_dim], obs_t)  # fixed over the G steps
        n_full = obs_t.shape[1]
        n = batches.shape[1] if batches is not None else self.sample_count(n_full)
        whole = batches is None and n == n_full  # every step reads all the rows given, in their order
        ws = eager_steps.Workspace(net.spec.sizes, n, obs_t)
        fixed = eager_steps.FixedStats(obs_t, ws.centred, net.spec.eps[0]) if net.spec.bn[0] and whole else None
        critic_full = eager_steps.EvalCritic(
            critic_affines, self.critic_net.spec.slopes, obs_part_full, action_dim, self.critic_net.spec.sizes, n
        )
        old_affines, coef = self.old_actor_affines, self.settings.actor_proximal
        old_pi_full = None  # pi_old on the whole buffer: once per fit when every step takes it all
        if old_affines is not None and whole:
            old_pi_full = net.eval_forward(obs_t, old_affines)
        objective = proximal = None
        for step in range(steps):
            idx = batches[step] if batches is not None else self.batch_indices(n_full)
            o, critic = (obs_t, critic_full) if idx is None else (obs_t[:, idx], critic_full.subset(idx))
            if old_affines is not None:
                proximal = (coef, old_pi_full if idx is None else net.eval_forward(o, old_affines))
            objective = eager_steps.actor_step(
                net,
                ws,
                o,
                fixed,
                critic,
                self.settings.max_grad_norm,
                self.settings.inverting_gradients,
                want_objective=step == steps - 1,
                proximal=proximal,
            )
        net.finish_fit(fixed)
        return objective  # type: ignore[return-value]
