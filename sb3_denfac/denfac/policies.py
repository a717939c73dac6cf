"""DENFAC networks: an unbounded deterministic actor mu(s) and a Q(s, a) critic, both batch-normalised MLPs.

The defaults are the library's (64-64 networks, no batch norm, PyTorch's initialisation, two Q networks). Paper,
section 4 (:data:`~sb3_denfac.denfac.presets.PAPER`): leaky ReLU, batch normalisation on every layer except the last
two, linear last layer, weights N(0, 0.01), one Q network. Critic hidden layers 50-7; actor hidden layers 5 (Acrobot),
20 (Cartpole), 20-10 (Half-Cheetah). Actions live in SB3's scaled space [-1, 1]; the actor output is unbounded
(inverting gradients keep it in bounds).
"""

from __future__ import annotations

from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BaseModel, BasePolicy
from stable_baselines3.common.preprocessing import get_action_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, CombinedExtractor, FlattenExtractor
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from torch import nn

from sb3_denfac.common.actor import DeterministicActor, parse_net_arch
from sb3_denfac.common.checks import check_bool, check_number
from sb3_denfac.common.networks import create_bn_mlp, create_residual_mlp, reset_parameters_

#: ``net_arch`` of :class:`DENFACPolicy` when it is None (paper: pi=[20], qf=[50, 7]).
DEFAULT_NET_ARCH: dict[str, list[int]] = {"pi": [64, 64], "qf": [64, 64]}


class DENFACActor(DeterministicActor):
    """DENFAC's mu(s): :class:`~sb3_denfac.common.actor.DeterministicActor` with a linear (unbounded) output, the
    truncated Gaussian of ``sigma`` for ``predict(deterministic=False)`` and BN momentum None (cumulative average)."""

    def __init__(self, *args: Any, bn_momentum: float | None = None, sigma: float | None = 0.1, **kwargs: Any):
        super().__init__(*args, bn_momentum=bn_momentum, sigma=sigma, **kwargs)


class DENFACCritic(BaseModel):
    """Q(s, a) on the concatenation of features and scaled action, one linear output per Q network.

    ``qf`` is Q_1, the network the actor ascends (eq. 5); ``n_critics`` > 1 adds ``twin_qfs`` Q_2.. Q_n, each with its
    own initialisation, fitted to the same targets, which take the minimum over all of them (clipped double Q,
    Fujimoto et al. 2018, TD3) or their mean (DENFAC's ``critic_target``; :meth:`target_q`).

    :param observation_space: observation space
    :param action_space: Box action space
    :param net_arch: hidden layer sizes (paper: [50, 7])
    :param features_extractor: network extracting features
    :param features_dim: number of features
    :param activation_fn: hidden activation
    :param batch_norm: batch normalisation before every linear layer but the last
    :param bn_momentum: BatchNorm1d momentum (None: cumulative average)
    :param init: "paper" or "default"
    :param normalize_images: whether to normalise images
    :param n_critics: number of Q networks (paper: 1)
    :param layer_norm: LayerNorm after every hidden layer of each Q network (:func:`~sb3_denfac.common.networks.create_bn_mlp`)
    :param dropout: Dropout rate after every hidden linear layer of each Q network (DroQ; 0: none)
    :param batch_renorm: batch renormalisation before every linear layer but the last of each Q network (CrossQ)
    :param target_subset: REDQ's M (Chen et al. 2021, Algorithm 1): the bootstrap value combines a random subset of M of
        the ``n_critics`` Q networks, drawn anew at every call of :meth:`target_q` (once per fitted iteration, or per
        critic step with joint bootstrapping), and the actor ascends the mean of all of them; None: all of them, and
        the actor ascends Q_1
    :param residual: each Q network is SimBa's residual network (:func:`~sb3_denfac.common.networks.create_residual_mlp`:
        one pre-layer-norm residual block per entry of ``net_arch``) instead of the MLP; ``batch_norm``, ``layer_norm``,
        ``dropout``, ``batch_renorm`` and ``init`` do not apply to it
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: BaseFeaturesExtractor,
        features_dim: int,
        activation_fn: type[nn.Module] = nn.LeakyReLU,
        batch_norm: bool = False,
        bn_momentum: float | None = None,
        init: str = "default",
        normalize_images: bool = True,
        n_critics: int = 2,
        layer_norm: bool = False,
        dropout: float = 0.0,
        batch_renorm: bool = False,
        target_subset: int | None = None,
        residual: bool = False,
    ):
        super().__init__(
            observation_space, action_space, features_extractor=features_extractor, normalize_images=normalize_images
        )
        n_critics = check_number("n_critics", n_critics, minimum=1, integer=True, note=" (1: one critic, as the paper)")
        self.target_subset = check_number(
            "target_subset", target_subset, minimum=1, maximum=n_critics, integer=True, none_ok=True,
            note=" (REDQ's M, at most n_critics; None: all the Q networks)",
        )  # fmt: skip
        action_dim = get_action_dim(self.action_space)

        def q_network() -> nn.Sequential:
            if residual:
                return create_residual_mlp(features_dim + action_dim, 1, net_arch, activation_fn)
            return create_bn_mlp(
                features_dim + action_dim,
                1,
                net_arch,
                batch_norm,
                activation_fn,
                bn_momentum,
                init,  # type: ignore[arg-type]
                layer_norm,
                dropout,
                batch_renorm,
            )

        self.n_critics = n_critics
        self.qf = q_network()  # Q_1 (the only one of files saved before n_critics existed)
        self.twin_qfs = nn.ModuleList(q_network() for _ in range(n_critics - 1))

    @property
    def q_networks(self) -> list[nn.Module]:
        """Q_1, ..., Q_n (SB3's ``ContinuousCritic.q_networks``)."""
        return [self.qf, *self.twin_qfs]

    def q_inputs(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """What every Q network reads: the features of s and the scaled action, concatenated."""
        return th.cat([self.extract_features(obs, self.features_extractor), actions], dim=1)

    def all_q(self, obs: th.Tensor, actions: th.Tensor) -> list[th.Tensor]:
        """Q_1(s, a), ..., Q_n(s, a), each of shape (N, 1)."""
        inputs = self.q_inputs(obs, actions)
        return [q_net(inputs) for q_net in self.q_networks]

    def forward(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """The value the actor ascends (eq. 5), shape (N, 1): Q_1(s, a) (SB3's ``q1_forward``), or with
        ``target_subset`` the mean of Q_1, ..., Q_n (REDQ)."""
        if self.target_subset is None:
            return self.qf(self.q_inputs(obs, actions))
        return th.stack(self.all_q(obs, actions)).mean(dim=0)

    def target_q(self, obs: th.Tensor, actions: th.Tensor, how: str) -> th.Tensor:
        """The bootstrap value of the targets of eq. (4), shape (N, 1): :meth:`combine` of Q_1(s, a), ..., Q_n(s, a)."""
        return self.combine(self.all_q(obs, actions), how)

    def combine(self, values: list[th.Tensor], how: str) -> th.Tensor:
        """``values`` of Q_1, ..., Q_n combined by :func:`combine_critics` (``how`` "min": clipped double Q), over a
        random subset of ``target_subset`` of them if set (REDQ: drawn anew at every call)."""
        if self.target_subset is not None and self.target_subset < len(values):
            chosen = th.randperm(len(values))[: self.target_subset].tolist()
            values = [values[i] for i in chosen]
        return combine_critics(values, how)


#: How several Q networks make the bootstrap value of eq. (4) (DENFAC's ``critic_target``).
CRITIC_TARGETS = ("min", "mean")


def combine_critics(values: list[th.Tensor], how: str) -> th.Tensor:
    """min_j Q_j (``"min"``: clipped double Q, Fujimoto et al. 2018) or 1/n sum_j Q_j (``"mean"``: the ensemble's
    average, without the minimum's pessimism) of same-shaped values; one network: its value."""
    if len(values) == 1:
        return values[0]
    stacked = th.stack(values)
    return stacked.amin(dim=0) if how == "min" else stacked.mean(dim=0)


class DENFACBasePolicy(BasePolicy):
    """An actor and the critic Q(s, a) of DENFAC's family, each with its own Adam optimiser; :meth:`make_actor` builds
    the actor (:class:`DENFACPolicy`: mu(s); SoftDENFAC's policy: SAC's squashed Gaussian).

    :param observation_space: observation space
    :param action_space: Box action space
    :param lr_schedule: SB3 learning-rate schedule (used for both networks unless a rate is given below)
    :param net_arch: ``dict(pi=[...], qf=[...])`` or one list for both (default pi=[64, 64], qf=[64, 64]; paper
        pi=[20], qf=[50, 7])
    :param activation_fn: hidden activation (paper: leaky ReLU, slope 0.01)
    :param batch_norm: batch normalisation before every linear layer but the last (default False; paper True)
    :param bn_momentum: BatchNorm1d momentum; None (default) = cumulative average over the steps since the last
        reset of the running statistics (DENFAC resets them at every fit, so eval mode uses the buffer's statistics)
    :param init: "default" (PyTorch, the default) or "paper" (N(0, 0.01^2)) initialisation
    :param sigma: exploration std of the truncated Gaussian on [-1, 1] (DENFAC passes its own)
    :param actor_learning_rate: initial rate of the actor if not None (else ``lr_schedule(1)``); the algorithm sets
        alpha_a before each update (:mod:`~sb3_denfac.common.learning_rates`), this serves policies used alone
    :param critic_learning_rate: the same for the critic (alpha_c)
    :param features_extractor_class: features extractor (default: flatten)
    :param features_extractor_kwargs: its keyword arguments
    :param normalize_images: whether to normalise images
    :param optimizer_class: optimiser (default Adam)
    :param optimizer_kwargs: optimiser keyword arguments (DENFAC passes ``betas`` and ``eps``)
    :param n_critics: Q networks of the critic (default 2: clipped double Q, see :class:`DENFACCritic`; paper: 1)
    :param layer_norm: LayerNorm after every hidden layer of the critic's Q networks (default False; sbx's SAC
        ``layer_norm``, the critics of DroQ and BRO): keeps the values' regression well scaled over many fitted steps
    :param dropout: Dropout rate after every hidden linear layer of the critic's Q networks (default 0; DroQ, Hiraoka
        et al. 2022: 0.01 with ``layer_norm``, sbx's ``dropout_rate``)
    :param batch_renorm: batch renormalisation (sb3-contrib's ``BatchRenorm1d``) before every linear layer but the
        last of the critic's Q networks (default False; CrossQ's critic, Bhatt et al. 2024, with DENFAC's
        ``frozen_targets=False``)
    :param target_subset: REDQ's M (default None; Chen et al. 2021: M = 2 of ``n_critics`` = 10): the bootstrap value
        takes the minimum (``critic_target``) over a random subset of M Q networks, and the actor ascends the mean of
        all of them (:class:`DENFACCritic`)
    :param residual: the critic's Q networks are SimBa's residual networks (default False; Lee et al. 2025: a linear
        embedding, one pre-layer-norm residual block per entry of ``net_arch["qf"]``, a final layer norm)
    :param checkpoints: keep ``checkpoint_actor``, a copy of the actor that :meth:`save_checkpoint` writes and that
        plays ``predict(deterministic=True)`` (TD7's policy checkpoints; the algorithm's ``checkpoint_episodes``
        decides when; default False)
    """

    actor: nn.Module
    critic: DENFACCritic
    #: the kept actor of ``checkpoints`` (None without)
    checkpoint_actor: nn.Module | None

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        activation_fn: type[nn.Module] = nn.LeakyReLU,
        batch_norm: bool = False,
        bn_momentum: float | None = None,
        init: str = "default",
        sigma: float = 0.1,
        actor_learning_rate: float | Schedule | None = None,
        critic_learning_rate: float | Schedule | None = None,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        n_critics: int = 2,
        layer_norm: bool = False,
        dropout: float = 0.0,
        batch_renorm: bool = False,
        target_subset: int | None = None,
        residual: bool = False,
        checkpoints: bool = False,
    ):
        super().__init__(
            observation_space,
            action_space,
            features_extractor_class,
            features_extractor_kwargs,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
            squash_output=True,
            normalize_images=normalize_images,
        )
        if net_arch is None:
            net_arch = dict(DEFAULT_NET_ARCH)
        archs = parse_net_arch(net_arch, DEFAULT_NET_ARCH)
        self.net_arch = net_arch
        self.activation_fn = activation_fn
        self.batch_norm = batch_norm
        self.bn_momentum = bn_momentum
        self.init = init
        self.sigma = sigma
        self.actor_learning_rate = actor_learning_rate
        self.critic_learning_rate = critic_learning_rate
        common = dict(
            observation_space=self.observation_space,
            action_space=self.action_space,
            activation_fn=activation_fn,
            batch_norm=batch_norm,
            bn_momentum=bn_momentum,
            init=init,
            normalize_images=normalize_images,
        )
        self.actor_kwargs = {**common, "net_arch": archs["pi"], "sigma": sigma}
        self.layer_norm = check_bool("layer_norm", layer_norm)
        self.dropout = check_number("dropout", dropout, minimum=0.0, maximum=0.9, note=" (0: none; DroQ: 0.01)")
        self.batch_renorm = check_bool("batch_renorm", batch_renorm)
        self.residual = check_bool("residual", residual)
        self.checkpoints = check_bool("checkpoints", checkpoints)
        self.critic_kwargs = {
            **common,
            "net_arch": archs["qf"],
            "n_critics": n_critics,
            "layer_norm": self.layer_norm,
            "dropout": self.dropout,
            "batch_renorm": self.batch_renorm,
            "target_subset": target_subset,
            "residual": self.residual,
        }
        self._build(lr_schedule)

    def _build(self, lr_schedule: Schedule) -> None:
        self.actor = self.make_actor()
        self.critic = DENFACCritic(**self._update_features_extractor(self.critic_kwargs))  # type: ignore[arg-type]
        self.actor.optimizer = self.make_optimizer(self.actor, self.actor_learning_rate, lr_schedule)
        self.critic.optimizer = self.make_optimizer(self.critic, self.critic_learning_rate, lr_schedule)
        self.checkpoint_actor = None
        if self.checkpoints:  # a copy, never fitted: no gradients, no optimiser, always in eval mode
            with th.random.fork_rng(devices=[]):  # its initialisation is written over: the seed's draws stay the same
                self.checkpoint_actor = self.make_actor().requires_grad_(False)
            self.register_buffer("checkpoint_return", th.tensor(-th.inf))  # its value, saved with it
            self.save_checkpoint(-th.inf)

    def save_checkpoint(self, value: float) -> None:
        """Copy the actor (weights and running statistics) into ``checkpoint_actor``, whose assessment is ``value``."""
        assert self.checkpoint_actor is not None, "a policy built with checkpoints=True"
        self.checkpoint_actor.load_state_dict(self.actor.state_dict())
        self.checkpoint_actor.set_training_mode(False)
        self.checkpoint_return.fill_(value)

    def load_state_dict(self, state_dict: Any, strict: bool = True, assign: bool = False) -> Any:
        """``nn.Module``'s, for a file saved with or without ``checkpoints`` into a policy built the other way: a
        missing kept actor is the actor, with no value yet; a kept actor the policy does not keep is dropped."""
        state = dict(state_dict)
        kept = [k for k in state if k.startswith("checkpoint_actor.") or k == "checkpoint_return"]
        if self.checkpoint_actor is None:
            for key in kept:
                del state[key]
        elif not kept:
            state.update({"checkpoint_" + k: v for k, v in state_dict.items() if k.startswith("actor.")})
            state["checkpoint_return"] = th.tensor(-th.inf)
        return super().load_state_dict(state, strict=strict, assign=assign)

    def make_actor(self) -> nn.Module:
        """The actor, built from ``actor_kwargs``."""
        raise NotImplementedError

    def make_optimizer(self, net: nn.Module, rate: float | Schedule | None, lr_schedule: Schedule) -> th.optim.Optimizer:
        rate = lr_schedule if rate is None else rate
        lr = rate(1) if callable(rate) else rate
        return self.optimizer_class(net.parameters(), lr=lr, **self.optimizer_kwargs)  # type: ignore[call-arg]

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            dict(
                net_arch=self.net_arch,
                activation_fn=self.activation_fn,
                batch_norm=self.batch_norm,
                bn_momentum=self.bn_momentum,
                init=self.init,
                sigma=self.sigma,
                actor_learning_rate=self.actor_learning_rate,
                critic_learning_rate=self.critic_learning_rate,
                lr_schedule=self._dummy_schedule,
                optimizer_class=self.optimizer_class,
                optimizer_kwargs=self.optimizer_kwargs,
                features_extractor_class=self.features_extractor_class,
                features_extractor_kwargs=self.features_extractor_kwargs,
                n_critics=self.critic.n_critics,  # validated by the critic
                layer_norm=self.layer_norm,
                dropout=self.dropout,
                batch_renorm=self.batch_renorm,
                target_subset=self.critic.target_subset,
                residual=self.residual,
                checkpoints=self.checkpoints,
            )
        )
        return data

    def forward(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self._predict(observation, deterministic=deterministic)

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        """The actor's action at ``observation``; deterministic, the kept actor's (``checkpoints``)."""
        actor = self.checkpoint_actor if deterministic and self.checkpoint_actor is not None else self.actor
        return actor._predict(observation, deterministic=deterministic)

    def set_training_mode(self, mode: bool) -> None:
        """The actor's and the critic's mode (``checkpoint_actor`` stays in eval mode)."""
        self.actor.set_training_mode(mode)
        self.critic.set_training_mode(mode)
        self.training = mode

    def reset_actor(self) -> None:
        """Re-initialise the actor in place (weights and BN statistics) and forget its Adam state."""
        reset_parameters_(self.actor, self.init)
        self.actor.optimizer.state.clear()

    def reset_critic(self) -> None:
        """Re-initialise the critic in place (weights and BN statistics) and forget its Adam state."""
        reset_parameters_(self.critic, self.init)
        self.critic.optimizer.state.clear()


class DENFACPolicy(DENFACBasePolicy):
    """DENFAC's actor mu(s) (:class:`DENFACActor`, eq. 5) and critic Q(s, a) (:class:`DENFACCritic`, eq. 4), each with
    its own Adam optimiser; the parameters are :class:`DENFACBasePolicy`'s."""

    actor: DENFACActor

    def make_actor(self) -> nn.Module:
        return DENFACActor(**self._update_features_extractor(self.actor_kwargs))  # type: ignore[arg-type]


class MultiInputPolicy(DENFACPolicy):
    """:class:`DENFACPolicy` for Dict observations (goal-conditioned envs): SB3's ``CombinedExtractor`` by default, one
    for the actor and one for the critic."""

    def __init__(self, *args: Any, features_extractor_class: type[BaseFeaturesExtractor] = CombinedExtractor, **kwargs: Any):
        super().__init__(*args, features_extractor_class=features_extractor_class, **kwargs)


MlpPolicy = DENFACPolicy
