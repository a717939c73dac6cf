"""Pieces shared by the on-policy baselines NFAC and CACLA (paper, section 2): a deterministic actor mu(s) with a state-value
critic V(s), truncated-Gaussian exploration and the common rollout loop.

Both algorithms act with a truncated Gaussian of standard deviation sigma around the actor output, in the action space
scaled to [-1, 1] (paper, section 4), and both learn from transitions (s, a, mu_b(s), r, s', terminal) where ``a`` is the
executed (scaled) action and ``mu_b(s)`` the behaviour mean (the authors' ``pure_a``).

Time limits: unlike SB3's ``collect_rollouts`` (which adds gamma * V(terminal obs) to the reward at collection time), the
true last observation of a truncated episode is stored as s' with ``terminal = False``, so the TD target
r + gamma * V(s') bootstraps from it with the critic of the moment the target is computed. Only true terminations
(``terminated`` in Gymnasium, the authors' ``goal_reached``) stop the bootstrap.

Batch norm ("NFAC+", "CACLA+"): the policy stays in eval mode, also during the gradient steps, so BN layers normalise
with their running statistics; those are refreshed from recent states by :func:`refresh_bn_statistics` (NFAC: the states
of the episode(s) D before each update; CACLA: a window of the last steps before each per-step update). A batch of one
is then well defined, and the function that is fitted is exactly the one that computes targets and acts.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.preprocessing import get_action_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, FlattenExtractor
from stable_baselines3.common.type_aliases import GymEnv, PyTorchObs, Schedule
from stable_baselines3.common.utils import obs_as_tensor
from stable_baselines3.common.vec_env import VecEnv
from torch import nn

from sb3_denfac.common.callbacks import ProgressBarMixin
from sb3_denfac.common.checks import InputChecksMixin, check_gamma, check_learning_rate, check_positive, check_sigma
from sb3_denfac.common.learning_rates import ActorCriticRatesMixin
from sb3_denfac.common.networks import create_bn_mlp, reset_parameters_, set_bn_training_mode
from sb3_denfac.common.truncated_normal import sample_truncated_normal


class DeterministicActorValuePolicy(BasePolicy):
    """Deterministic actor mu(s) (linear output in the [-1, 1]-scaled action space) and state-value critic V(s).

    Both networks are :func:`~sb3_denfac.common.networks.create_bn_mlp` MLPs (leaky ReLU, batch norm before every linear
    layer but the last, i.e. "except on the last two layers"). ``predict(deterministic=True)`` returns mu(s) clipped to
    the action bounds; ``deterministic=False`` samples the truncated Gaussian exploration policy.

    :param observation_space: observation space (Box, Discrete, MultiDiscrete or MultiBinary: SB3's preprocessing).
    :param action_space: Box action space with finite bounds.
    :param lr_schedule: actor learning rate alpha_a (schedule of the remaining progress).
    :param critic_lr_schedule: critic learning rate alpha_c; defaults to ``lr_schedule``.
    :param sigma: standard deviation of the truncated Gaussian exploration in the scaled space (paper: 0.05).
    :param net_arch: hidden sizes, a list for both networks or ``dict(pi=[...], vf=[...])``
        (default: actor [20] as the paper's Cartpole actor, critic [50, 7] as the paper's critics).
    :param batch_norm: batch normalisation ("NFAC+", "CACLA+"); False gives plain MLPs.
    :param activation_fn: hidden activation (paper: leaky ReLU).
    :param bn_momentum: momentum of the batch-norm running statistics.
    :param init: "paper" (N(0, 0.01^2) weights, zero biases) or "default" (PyTorch).
    :param features_extractor_class: features extractor (default: flatten).
    :param features_extractor_kwargs: its keyword arguments.
    :param normalize_images: SB3 image normalisation flag.
    :param optimizer_class: optimiser of both networks (default Adam).
    :param optimizer_kwargs: its keyword arguments, except the learning rate.
    :param share_features_extractor: one features extractor for actor and critic (trained by both optimisers, as SB3's
        ActorCriticPolicy), else one each (``features_extractor`` is the actor's, ``vf_features_extractor`` the critic's).
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        critic_lr_schedule: Schedule | None = None,
        sigma: float = 0.05,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        batch_norm: bool = True,
        activation_fn: type[nn.Module] = nn.LeakyReLU,
        bn_momentum: float = 0.1,
        init: str = "paper",
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        share_features_extractor: bool = True,
    ):
        super().__init__(
            observation_space,
            action_space,
            features_extractor_class,
            features_extractor_kwargs,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
            normalize_images=normalize_images,
            squash_output=True,  # the actor works in [-1, 1]: predict() un-scales to the env bounds
        )
        if net_arch is None:
            net_arch = dict(pi=[20], vf=[50, 7])
        if isinstance(net_arch, dict):
            pi_arch, vf_arch = list(net_arch.get("pi", [20])), list(net_arch.get("vf", [50, 7]))
        else:
            pi_arch, vf_arch = list(net_arch), list(net_arch)
        self.net_arch = net_arch
        self.sigma = sigma
        self.batch_norm = batch_norm
        self.activation_fn = activation_fn
        self.bn_momentum = bn_momentum
        self.init = init

        # As SB3's ActorCriticPolicy: a shared extractor is trained by both optimisers, else each network has its own.
        self.share_features_extractor = share_features_extractor
        self.features_extractor = self.make_features_extractor()
        self.vf_features_extractor = self.features_extractor if share_features_extractor else self.make_features_extractor()
        features_dim = self.features_extractor.features_dim
        mlp_kwargs = dict(batch_norm=batch_norm, activation_fn=activation_fn, bn_momentum=bn_momentum, init=init)
        self.actor = create_bn_mlp(features_dim, get_action_dim(action_space), pi_arch, **mlp_kwargs)
        self.critic = create_bn_mlp(features_dim, 1, vf_arch, **mlp_kwargs)

        self.lr_schedule = lr_schedule
        self.critic_lr_schedule = critic_lr_schedule or lr_schedule
        # As SB3's TD3/SAC: each network carries its optimizer (the features extractor with it, see actor_modules).
        self.actor.optimizer = self._make_optimizer(self.actor_modules(), lr_schedule)
        self.critic.optimizer = self._make_optimizer(self.critic_modules(), self.critic_lr_schedule)

    @property
    def actor_optimizer(self) -> th.optim.Optimizer:
        """Read-only alias of ``actor.optimizer`` (its name in sb3-denfac 0.2)."""
        return self.actor.optimizer

    @property
    def critic_optimizer(self) -> th.optim.Optimizer:
        """Read-only alias of ``critic.optimizer`` (its name in sb3-denfac 0.2)."""
        return self.critic.optimizer

    def actor_modules(self) -> list[nn.Module]:
        """mu(s) as trained by the actor optimiser: its features extractor and MLP."""
        return [self.features_extractor, self.actor]

    def critic_modules(self) -> list[nn.Module]:
        """V(s) as trained by the critic optimiser: its features extractor and MLP."""
        return [self.vf_features_extractor, self.critic]

    def _make_optimizer(self, modules: list[nn.Module], schedule: Schedule) -> th.optim.Optimizer:
        params = [p for module in modules for p in module.parameters()]
        return self.optimizer_class(params, lr=schedule(1), **self.optimizer_kwargs)  # type: ignore[call-arg]

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            dict(
                lr_schedule=self._dummy_schedule,
                critic_lr_schedule=self._dummy_schedule,
                sigma=self.sigma,
                net_arch=self.net_arch,
                batch_norm=self.batch_norm,
                activation_fn=self.activation_fn,
                bn_momentum=self.bn_momentum,
                init=self.init,
                features_extractor_class=self.features_extractor_class,
                features_extractor_kwargs=self.features_extractor_kwargs,
                optimizer_class=self.optimizer_class,
                optimizer_kwargs=self.optimizer_kwargs,
                share_features_extractor=self.share_features_extractor,
            )
        )
        return data

    def reset_critic(self) -> None:
        """Re-initialise V's MLP (weights and batch-norm statistics) and the critic optimiser state (NFAC's
        ``reset_critic``); a custom features extractor keeps its weights."""
        lr = self.critic.optimizer.param_groups[0]["lr"]
        reset_parameters_(self.critic, self.init)
        self.critic.optimizer = self._make_optimizer(self.critic_modules(), lambda _: lr)

    def actor_mean(self, obs: PyTorchObs) -> th.Tensor:
        """mu(s): unbounded actor output in the scaled action space (the behaviour mean of the exploration)."""
        return self.actor(self.extract_features(obs, self.features_extractor))

    def predict_values(self, obs: PyTorchObs) -> th.Tensor:
        """V(s), shape (batch, 1)."""
        return self.critic(self.extract_features(obs, self.vf_features_extractor))

    @th.no_grad()
    def refresh_bn_statistics(self, obs: PyTorchObs, exact_when_fresh: bool = False, critic_only: bool = False) -> None:
        """Move the running statistics of the BN layers (features extractors included) toward those of ``obs`` by one
        gradient-free train-mode forward; see :func:`refresh_bn_statistics`. Needs at least two observations."""
        modules = self.critic_modules() if critic_only else [*self.actor_modules(), *self.critic_modules()]
        modules = list(dict.fromkeys(modules))  # a shared extractor once

        def forward() -> None:
            self.predict_values(obs)
            if not critic_only:
                self.actor_mean(obs)

        refresh_bn_statistics(modules, forward, len(obs), exact_when_fresh)  # type: ignore[arg-type]

    def forward(self, obs: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self._predict(obs, deterministic=deterministic)

    def explore(self, mean: np.ndarray) -> np.ndarray:
        """Sample the truncated Gaussian N(mean, sigma^2) on [-1, 1] (scaled space)."""
        return sample_truncated_normal(mean, self.sigma, np.float32(-1.0), np.float32(1.0))

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        mean = self.actor_mean(observation)
        if deterministic:
            return th.clamp(mean, -1.0, 1.0)
        return th.as_tensor(self.explore(mean.cpu().numpy()), device=mean.device)


@th.no_grad()
def refresh_bn_statistics(
    modules: list[nn.Module], forward: Callable[[], Any], n_inputs: int, exact_when_fresh: bool = False
) -> None:
    """Update the running statistics of the BN layers of ``modules`` with ``forward()`` run once in BN train mode.

    The statistics move toward those of the forwarded batch with each layer's momentum; with ``exact_when_fresh``, a
    layer that has never seen a batch (new or re-initialised network) takes them as they are. Needs ``n_inputs`` >= 2.
    """
    if n_inputs < 2:
        return
    fresh = [
        m
        for module in modules
        for m in module.modules()
        if exact_when_fresh and isinstance(m, nn.modules.batchnorm._BatchNorm) and m.num_batches_tracked == 0
    ]
    momenta = [m.momentum for m in fresh]
    for layer in fresh:
        layer.momentum = 1.0
    for module in modules:
        set_bn_training_mode(module, True)
    try:
        forward()
    finally:
        for module in modules:
            set_bn_training_mode(module, False)
        for layer, momentum in zip(fresh, momenta, strict=True):
            layer.momentum = momentum


def td_targets(rewards: th.Tensor, next_values: th.Tensor, terminals: th.Tensor, gamma: float) -> th.Tensor:
    """y = r + gamma * V(s'), without bootstrap on true terminal transitions (time-limit ends do bootstrap)."""
    return rewards + gamma * (1.0 - terminals) * next_values


class Transitions(NamedTuple):
    observations: th.Tensor
    actions: th.Tensor  # executed action a, scaled to [-1, 1]
    behaviour_means: th.Tensor  # mu_b(s), the actor output that generated a (authors' pure_a)
    rewards: th.Tensor
    next_observations: th.Tensor
    terminals: th.Tensor  # 1.0 on true terminations only


class TransitionBuffer:
    """Growing list of the transitions of the current rollout (NFAC: the last episode(s)); cleared by ``reset()``."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self._data: list[tuple[np.ndarray, ...]] = []

    def __len__(self) -> int:
        return sum(len(step[0]) for step in self._data)

    def add(self, obs, actions, means, rewards, next_obs, terminals) -> None:
        """Add one vectorised step (leading dimension n_envs)."""
        self._data.append(tuple(np.array(x, copy=True) for x in (obs, actions, means, rewards, next_obs, terminals)))

    def get(self, device: th.device) -> Transitions:
        obs, actions, means, rewards, next_obs, terminals = (np.concatenate(x) for x in zip(*self._data, strict=True))
        return Transitions(
            observations=obs_as_tensor(obs, device),
            actions=th.as_tensor(actions, dtype=th.float32, device=device),
            behaviour_means=th.as_tensor(means, dtype=th.float32, device=device),
            rewards=th.as_tensor(rewards, dtype=th.float32, device=device),
            next_observations=obs_as_tensor(next_obs, device),
            terminals=th.as_tensor(terminals, dtype=th.float32, device=device),
        )


class DeterministicOnPolicyAlgorithm(InputChecksMixin, ProgressBarMixin, ActorCriticRatesMixin, OnPolicyAlgorithm):
    """Base of NFAC and CACLA: an :class:`OnPolicyAlgorithm` whose rollouts explore with a truncated Gaussian around
    mu(s) and store (s, a, mu_b(s), r, s', terminal). Subclasses choose when a rollout ends (``_rollout_done``), may
    learn online in ``_on_step_transition`` and learn from the collected rollout in ``train``. NaN/inf inputs and
    corrupted or foreign model files raise a ValueError (:class:`~sb3_denfac.common.checks.InputChecksMixin`), and an
    action space that is not a Box with finite bounds raises an :class:`~sb3_denfac.common.checks.UnsupportedSpaceError`
    (a ValueError that is also SB3's AssertionError).

    Arguments not listed in :class:`~stable_baselines3.common.on_policy_algorithm.OnPolicyAlgorithm`:

    :param learning_rate: the rate (float or schedule) of each network whose own rate below is None
        (:mod:`~sb3_denfac.common.learning_rates`).
    :param actor_learning_rate: alpha_a, the actor's Adam step size (float or schedule); None means ``learning_rate``.
    :param critic_learning_rate: alpha_c, the critic's Adam step size (float or schedule); None means ``learning_rate``.
    :param sigma: exploration standard deviation in the [-1, 1]-scaled action space (paper: 0.05).
    :param max_grad_norm: clip of the global gradient L2 norm of each step (authors' code: 10); None disables it.
    """

    policy: DeterministicActorValuePolicy  # type: ignore[assignment]
    rollout_buffer: TransitionBuffer  # type: ignore[assignment]
    #: True if ``_on_step_transition`` learns (CACLA); NFAC only learns from the rollout in ``train``.
    _learns_online: ClassVar[bool] = False

    def __init__(
        self,
        policy: str | type[DeterministicActorValuePolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule,
        actor_learning_rate: float | Schedule | None,
        critic_learning_rate: float | Schedule | None,
        n_steps: int,
        gamma: float,
        sigma: float,
        max_grad_norm: float | None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        _init_setup_model: bool = True,
    ):
        sigma = check_sigma(sigma)
        gamma = check_gamma(gamma)
        max_grad_norm = check_positive("max_grad_norm", max_grad_norm, none_ok=True)
        learning_rate = check_learning_rate("learning_rate", learning_rate)
        if learning_rate is None:
            raise ValueError("learning_rate must be a positive number or a schedule, got None")
        super().__init__(
            policy,
            env,
            learning_rate=learning_rate,
            n_steps=n_steps,
            gamma=gamma,
            gae_lambda=1.0,  # unused
            ent_coef=0.0,  # unused
            vf_coef=1.0,  # unused
            max_grad_norm=max_grad_norm,  # type: ignore[arg-type]
            use_sde=False,
            sde_sample_freq=-1,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            policy_kwargs=policy_kwargs,
            verbose=verbose,
            seed=seed,
            device=device,
            _init_setup_model=False,
            supported_action_spaces=None,  # checked by InputChecksMixin (UnsupportedSpaceError)
        )
        self.actor_learning_rate = check_learning_rate("actor_learning_rate", actor_learning_rate)
        self.critic_learning_rate = check_learning_rate("critic_learning_rate", critic_learning_rate)
        self.sigma = sigma
        if _init_setup_model:
            self._setup_model()

    def _setup_model(self) -> None:
        self._setup_lr_schedule()
        self.set_random_seed(self.seed)
        self.rollout_buffer = TransitionBuffer()
        self.policy = self.policy_class(  # type: ignore[assignment]
            self.observation_space, self.action_space, self.lr_schedule, sigma=self.sigma, **self.policy_kwargs
        )
        self.policy = self.policy.to(self.device)
        self._setup_actor_critic_schedules()  # alpha_a and alpha_c, see ActorCriticRatesMixin
        self.policy.set_training_mode(False)  # BN layers normalise with their running statistics, see refresh_bn_statistics

    #: sb3-denfac 0.2 saved the optimizers as policy attributes
    _legacy_torch_names: ClassVar[dict[str, str]] = {
        "policy.actor_optimizer": "policy.actor.optimizer",
        "policy.critic_optimizer": "policy.critic.optimizer",
    }

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        return ["policy", "policy.actor.optimizer", "policy.critic.optimizer"], []

    def _gradient_step(self, loss: th.Tensor, optimizer: th.optim.Optimizer) -> None:
        """One step of ``optimizer`` (actor or critic, features extractor included) on ``loss``, norm-clipped."""
        optimizer.zero_grad()
        loss.backward()
        if self.max_grad_norm is not None:
            th.nn.utils.clip_grad_norm_([p for group in optimizer.param_groups for p in group["params"]], self.max_grad_norm)
        optimizer.step()

    def _rollout_done(self, n_steps: int, n_episodes: int, n_rollout_steps: int) -> bool:
        raise NotImplementedError

    def _on_step_transition(self, transitions: Transitions) -> None:
        """Hook called after every vectorised environment step (online learning)."""

    def collect_rollouts(
        self,
        env: VecEnv,
        callback: BaseCallback,
        rollout_buffer: TransitionBuffer,  # type: ignore[override]
        n_rollout_steps: int,
    ) -> bool:
        """Act with the truncated Gaussian around mu(s) and store (s, a, mu_b(s), r, s', terminal) into a cleared buffer.

        :return: False if a callback asked to stop training.
        """
        assert self._last_obs is not None, "No previous observation was provided"
        self.policy.set_training_mode(False)
        rollout_buffer.reset()
        callback.on_rollout_start()
        n_steps, n_episodes = 0, 0
        while not self._rollout_done(n_steps, n_episodes, n_rollout_steps):
            with th.no_grad():
                means = self.policy.actor_mean(obs_as_tensor(self._last_obs, self.device)).cpu().numpy()  # type: ignore[arg-type]
            actions = self.policy.explore(means)  # scaled to [-1, 1]
            env_actions = self.policy.unscale_action(actions.reshape((-1, *self.action_space.shape)))  # flat -> Box shape
            new_obs, rewards, dones, infos = env.step(env_actions)
            self.num_timesteps += env.num_envs

            callback.update_locals(locals())
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            n_steps += 1
            n_episodes += int(np.sum(dones))

            # s' of a finished episode is its real last observation; only true terminations stop the bootstrap.
            next_obs = np.array(new_obs, copy=True)
            terminals = np.zeros(env.num_envs, dtype=np.float32)
            for idx, done in enumerate(dones):
                if done:
                    next_obs[idx] = infos[idx]["terminal_observation"]
                    terminals[idx] = 0.0 if infos[idx].get("TimeLimit.truncated", False) else 1.0
            rollout_buffer.add(self._last_obs, actions, means, rewards, next_obs, terminals)
            if self._learns_online:
                self._on_step_transition(
                    Transitions(
                        observations=obs_as_tensor(self._last_obs, self.device),  # type: ignore[arg-type]
                        actions=th.as_tensor(actions, dtype=th.float32, device=self.device),
                        behaviour_means=th.as_tensor(means, dtype=th.float32, device=self.device),
                        rewards=th.as_tensor(rewards, dtype=th.float32, device=self.device),
                        next_observations=obs_as_tensor(next_obs, self.device),
                        terminals=th.as_tensor(terminals, device=self.device),
                    )
                )
            self._last_obs = new_obs  # type: ignore[assignment]
            self._last_episode_starts = dones

        callback.update_locals(locals())
        callback.on_rollout_end()
        return True
