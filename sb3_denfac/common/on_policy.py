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
with their running statistics; those are refreshed from recent states by
:func:`~sb3_denfac.common.actor_value_policy.refresh_bn_statistics` (NFAC: the states of the episode(s) D before each
update; CACLA: a window of the last steps before each per-step update). A batch of one is then well defined, and the
function that is fitted is exactly the one that computes targets and acts.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.type_aliases import GymEnv, Schedule
from stable_baselines3.common.utils import obs_as_tensor
from stable_baselines3.common.vec_env import VecEnv

from sb3_denfac.common.actor_value_policy import DeterministicActorValuePolicy
from sb3_denfac.common.callbacks import ProgressBarMixin
from sb3_denfac.common.checks import InputChecksMixin, check_gamma, check_learning_rate, check_positive, check_sigma
from sb3_denfac.common.compat import ON_POLICY_TORCH_NAMES_0_2, LegacyTorchNamesMixin
from sb3_denfac.common.device import warn_about_device
from sb3_denfac.common.learning_rates import ActorCriticRatesMixin
from sb3_denfac.common.threads import TorchThreadsMixin, check_torch_threads


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


class DeterministicOnPolicyAlgorithm(
    InputChecksMixin, TorchThreadsMixin, ProgressBarMixin, LegacyTorchNamesMixin, ActorCriticRatesMixin, OnPolicyAlgorithm
):
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
    :param gamma: discount factor.
    :param max_grad_norm: clip of the global gradient L2 norm of each step (authors' code: 10); None disables it.
    :param stats_window_size: episodes averaged in the rollout/ logs.
    :param tensorboard_log: TensorBoard log directory (None: no logging).
    :param policy_kwargs: extra arguments of the policy (net_arch, batch_norm, bn_momentum, init, optimizer_kwargs...).
    :param verbose: 0 silent, 1 info, 2 debug.
    :param seed: random seed.
    :param device: torch device.
    :param torch_threads: torch threads inside ``learn()`` (default 1; None: leave torch's setting alone), restored
        after it (:mod:`~sb3_denfac.common.threads`).
    :param _init_setup_model: build the networks at construction.
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
        torch_threads: int | None = 1,
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
        self.torch_threads = check_torch_threads(torch_threads)
        if _init_setup_model:
            self._setup_model()
            warn_about_device(type(self).__name__, device, self.device, self.policy)

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

    _legacy_torch_names: ClassVar[dict[str, str]] = ON_POLICY_TORCH_NAMES_0_2  # sb3_denfac.common.compat

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
            actions = self.policy.sample(means)  # scaled to [-1, 1]
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
