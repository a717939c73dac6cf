"""DENFAC: Data Efficient Neural Fitted Actor Critic (paper section 3, Algorithm 1) as an SB3 off-policy algorithm."""

from __future__ import annotations

import time
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import update_learning_rate
from torch.nn.utils import clip_grad_norm_

from sb3_denfac.common.budget import StopAtTotalTimestepsMixin
from sb3_denfac.common.callbacks import ProgressBarMixin
from sb3_denfac.common.checks import InputChecksMixin, check_gamma, check_learning_rate
from sb3_denfac.common.exploration import TruncatedGaussianExplorationMixin, behaviour_log_prob, check_exploration_sigma
from sb3_denfac.common.inverting_gradients import inverting_gradient_actor_backward
from sb3_denfac.common.truncated_normal import clamp_mean, truncated_importance_weights, truncated_normal_log_prob
from sb3_denfac.denfac.buffers import DENFACReplayBuffer
from sb3_denfac.denfac.fast import FastUpdate, supported_networks
from sb3_denfac.denfac.policies import DENFACPolicy, MlpPolicy

SelfDENFAC = TypeVar("SelfDENFAC", bound="DENFAC")

WEIGHTINGS = ("retrace", "retrace_next_state_quirk", "none")
UPDATE_PATHS = ("auto", "fast", "compiled", "plain")


class DENFAC(
    InputChecksMixin, ProgressBarMixin, StopAtTotalTimestepsMixin, TruncatedGaussianExplorationMixin, OffPolicyAlgorithm
):
    """Data Efficient Neural Fitted Actor Critic (DENFAC).

    Zimmer, Boniface & Dutech, "Off-Policy Neural Fitted Actor-Critic", section 3,
    eqs. (4)-(5) and Algorithm 1; hyper-parameters from section 4 and Figure 5.

    Execution: the deterministic actor mu(s) (linear, unbounded output) is played through a truncated Gaussian
    N(mu(s), sigma^2) on the scaled action bounds [-1, 1]; each transition stores its behaviour mean mu_b(s).
    At the end of every episode one update runs over the whole FIFO replay buffer D (``buffer_size`` transitions):

    for k = 1..K:
        q_t = r_{t+1} + gamma Q_{k-1}(s_{t+1}, pi_{k-1}(s_{t+1}))  (r_{t+1} on terminal states), before any reset
        c_t = min(1, pi_{k-1}(a_t|s_t) / pi_b(a_t|s_t))             (Retrace-style truncated importance weight)
        Q_k <- random critic if reset_critic else Q_{k-1}; ``critic_steps`` Adam steps on 1/N sum c_t (Q_k(s_t,a_t) - q_t)^2
        pi_k <- random actor if reset_actor else pi_{k-1}; G Adam steps ascending 1/N sum Q_k(s_t, pi_k(s_t))
                (with inverting gradients if ``inverting_gradients``)

    Implementation choices (documented differences or precisions):

    - Time limits: truncated episodes bootstrap (``bootstrap_on_timeout=True``, SB3 semantics). The paper-era authors'
      code treated time-limit ends as terminal (fixed by them in 2017): ``bootstrap_on_timeout=False`` reproduces it.
    - Loss scale: 1/N as in Algorithm 1 (the authors' code uses 1/(2N)); Adam is invariant to a constant loss factor
      except through ``adam_eps`` and ``max_grad_norm``.
    - Target actions pi_{k-1}(s') are clipped to [-1, 1] (the executed policy never leaves the bounds).
    - Batch norm: targets and importance weights use eval mode (running statistics); the critic is in eval mode during
      the actor steps (gradients of the fitted function, no update of its statistics). With the default
      ``bn_momentum=None`` the running statistics are reset at every fit and are the cumulative average over its
      full-batch steps, so eval mode uses the statistics of the buffer.
    - Warm-up: ``learning_starts`` > 0 plays uniform actions (as SB3) whose density is the uniform one in the weights.
    - Budget: ``learn(total_timesteps)`` stops at ``total_timesteps``, also inside an episode, and then updates on the
      buffer as it is (the unfinished episode bootstraps); see :mod:`sb3_denfac.common.budget`.
    - Input checks (:class:`~sb3_denfac.common.checks.InputChecksMixin`): NaN/inf observations or rewards raise a
      ValueError, ``load`` refuses corrupted zips and zips or replay buffers of another algorithm, and an action space
      that is not a Box with finite bounds raises an :class:`~sb3_denfac.common.checks.UnsupportedSpaceError` (a
      ValueError that is also SB3's AssertionError).

    :param policy: the policy model ("MlpPolicy" or a :class:`DENFACPolicy` subclass)
    :param env: the environment (a single env: updates are episode-wise)
    :param learning_rate: SB3 learning rate (float or schedule), used for a network whose own rate below is None.
        Default 0.1: Figure 5 lists 0.1 under alpha_a/alpha_c for every env. The update resets the actor and takes only
        G Adam steps from N(0, 0.01) weights, so small rates barely move it: a 2-seed CartPole sweep gave a best-so-far
        return after 60 episodes of about -820 (1e-3), -710 (1e-2), -380 (3e-2), -270 (1e-1).
    :param actor_learning_rate: alpha_a, Adam step size of the actor (takes precedence over ``learning_rate``)
    :param critic_learning_rate: alpha_c, Adam step size of the critic (takes precedence over ``learning_rate``)
    :param buffer_size: D, size of the FIFO replay buffer (paper: 3000-6000)
    :param learning_starts: steps before the first update (uniform actions meanwhile; paper: 0)
    :param batch_size: None (default) = full batch (the whole buffer at every step, paper); an int = one uniformly
        drawn mini-batch of that size per critic/actor step
    :param gamma: discount factor gamma
    :param n_fitted_iterations: K, fitted iterations per update (paper: 10)
    :param critic_steps: Adam steps of the critic per fitted iteration (authors: 10)
    :param actor_steps: G, Adam steps of the actor per fitted iteration (paper: 25)
    :param reset_critic: re-initialise the critic (and its Adam state) at every fitted iteration (paper: Acrobot yes)
    :param reset_actor: re-initialise the actor (and its Adam state) at every fitted iteration (Algorithm 1: yes)
    :param inverting_gradients: bound the unbounded actor with inverting gradients (Hausknecht & Stone 2016)
    :param weighting: "retrace" (c = min(1, pi_{k-1}(a|s)/pi_b(a|s))), "retrace_next_state_quirk" (the authors' code
        evaluates pi_{k-1} at s' instead of s) or "none" (c = 1)
    :param sigma: std of the truncated Gaussian exploration in the scaled action space (paper: 0.05)
    :param adam_betas: Adam (beta1, beta2); default (0.0, 0.999) as the authors' Caffe solver (beta1 = 0)
    :param adam_eps: Adam epsilon (authors: 1e-8)
    :param max_grad_norm: clip each network's global gradient L2 norm (authors: 10); None disables clipping
    :param bootstrap_on_timeout: bootstrap on time-limit truncations (True) or treat them as terminal (paper-era code)
    :param update_path: "auto" (default: "fast" when the policy allows it, else "plain"), "fast" (hand-written
        flat-parameter steps with preallocated buffers and fused Adam, eager: about 5x faster than a straightforward
        autograd update at the paper's Acrobot sizes on one CPU thread, see ``benchmarks/results/update_cost.md``),
        "compiled" (``torch.compile``d steps for the sample count that repeats: the full buffer, or the mini-batch
        size; the first such update of a process pays the compilation, seconds to a minute; on CPU measured no faster
        than "fast") or "plain" (autograd on the
        modules). All compute the same update up to float rounding; see ``fast.py``.
    :param replay_buffer_class: replay buffer class (must subclass :class:`DENFACReplayBuffer`)
    :param replay_buffer_kwargs: keyword arguments of the replay buffer
    :param stats_window_size: episodes averaged in the rollout logs
    :param tensorboard_log: TensorBoard log directory (None: no logging)
    :param policy_kwargs: policy keyword arguments: ``net_arch=dict(pi=[20], qf=[50, 7])``, ``batch_norm``, ``init``
        ("paper" N(0, 0.01^2) or "default"), ``bn_momentum``, ``activation_fn`` (see :class:`DENFACPolicy`)
    :param verbose: verbosity level
    :param seed: random seed
    :param device: torch device
    :param _init_setup_model: whether to build the networks at construction
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"MlpPolicy": MlpPolicy}
    policy: DENFACPolicy
    replay_buffer: DENFACReplayBuffer

    def __init__(
        self,
        policy: str | type[DENFACPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 0.1,
        actor_learning_rate: float | None = None,
        critic_learning_rate: float | None = None,
        buffer_size: int = 6000,
        learning_starts: int = 0,
        batch_size: int | None = None,
        gamma: float = 0.99,
        n_fitted_iterations: int = 10,
        critic_steps: int = 10,
        actor_steps: int = 25,
        reset_critic: bool = False,
        reset_actor: bool = True,
        inverting_gradients: bool = True,
        weighting: str = "retrace",
        sigma: float = 0.05,
        adam_betas: tuple[float, float] = (0.0, 0.999),
        adam_eps: float = 1e-8,
        max_grad_norm: float | None = 10.0,
        bootstrap_on_timeout: bool = True,
        update_path: str = "auto",
        replay_buffer_class: type[ReplayBuffer] | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        _init_setup_model: bool = True,
    ):
        self._check_arguments(n_fitted_iterations, actor_steps, critic_steps, weighting, batch_size, buffer_size)
        check_gamma(gamma)
        for name, rate in (
            ("learning_rate", learning_rate),
            ("actor_learning_rate", actor_learning_rate),
            ("critic_learning_rate", critic_learning_rate),
        ):
            check_learning_rate(name, rate)
        if update_path not in UPDATE_PATHS:
            raise ValueError(f"update_path must be one of {UPDATE_PATHS}, got {update_path!r}")
        super().__init__(
            policy,
            env,
            learning_rate,
            buffer_size,
            learning_starts,
            batch_size,  # type: ignore[arg-type]
            tau=1.0,  # no target networks in DENFAC
            gamma=gamma,
            train_freq=(1, "episode"),
            gradient_steps=1,  # one Algorithm 1 update per episode
            action_noise=None,
            replay_buffer_class=replay_buffer_class,
            replay_buffer_kwargs=replay_buffer_kwargs,
            optimize_memory_usage=False,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=device,
            seed=seed,
            sde_support=False,
            supported_action_spaces=None,  # checked by InputChecksMixin (UnsupportedSpaceError)
            support_multi_env=True,  # checked below with a clear message
        )
        if self.env is not None and self.n_envs != 1:
            raise ValueError(
                f"DENFAC updates at the end of every episode and needs a single environment, got n_envs={self.n_envs}"
            )
        self.sigma = check_exploration_sigma(sigma, allow_none=False)
        self.actor_learning_rate = actor_learning_rate
        self.critic_learning_rate = critic_learning_rate
        self.n_fitted_iterations = n_fitted_iterations
        self.critic_steps = critic_steps
        self.actor_steps = actor_steps
        self.reset_critic = reset_critic
        self.reset_actor = reset_actor
        self.inverting_gradients = inverting_gradients
        self.weighting = weighting
        self.adam_betas = tuple(adam_betas)
        self.adam_eps = adam_eps
        self.max_grad_norm = max_grad_norm
        self.bootstrap_on_timeout = bootstrap_on_timeout
        self.update_path = update_path
        self._check_episode_length()
        if _init_setup_model:
            self._setup_model()

    @staticmethod
    def _check_arguments(
        n_fitted_iterations: int, actor_steps: int, critic_steps: int, weighting: str, batch_size: int | None, buffer_size: int
    ) -> None:
        if int(n_fitted_iterations) < 1:
            raise ValueError(f"n_fitted_iterations (K) must be >= 1, got {n_fitted_iterations}")
        if int(actor_steps) < 0:
            raise ValueError(f"actor_steps (G) must be >= 0, got {actor_steps}")
        if int(critic_steps) < 1:
            raise ValueError(f"critic_steps must be >= 1, got {critic_steps}")
        if weighting not in WEIGHTINGS:
            raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
        if batch_size is not None and int(batch_size) < 2:
            raise ValueError(f"batch_size must be None (full batch) or >= 2 (batch norm), got {batch_size}")
        if int(buffer_size) < 2:
            raise ValueError(f"buffer_size (D) must be >= 2, got {buffer_size}")

    def _check_episode_length(self) -> None:
        """A buffer shorter than one episode would never hold a whole episode: refuse it when the length is known."""
        if self.env is None:
            return
        try:
            spec = self.env.get_attr("spec")[0]
        except (AttributeError, IndexError):
            spec = None
        max_steps = getattr(spec, "max_episode_steps", None)
        if max_steps is not None and self.buffer_size < max_steps:
            raise ValueError(
                f"buffer_size (D={self.buffer_size}) is smaller than the environment's episode length "
                f"(spec.max_episode_steps={max_steps}): the FIFO buffer must hold at least one whole episode"
            )

    def _setup_model(self) -> None:
        if self.replay_buffer_class is None:
            self.replay_buffer_class = DENFACReplayBuffer
        elif not issubclass(self.replay_buffer_class, DENFACReplayBuffer):
            raise ValueError(f"replay_buffer_class must subclass DENFACReplayBuffer, got {self.replay_buffer_class}")
        self.policy_kwargs.update(
            sigma=self.sigma,
            actor_learning_rate=self.actor_learning_rate,
            critic_learning_rate=self.critic_learning_rate,
        )
        optimizer_kwargs = dict(self.policy_kwargs.get("optimizer_kwargs") or {})
        if self.policy_kwargs.get("optimizer_class", th.optim.Adam) in (th.optim.Adam, th.optim.AdamW):
            optimizer_kwargs.setdefault("betas", self.adam_betas)
            optimizer_kwargs.setdefault("eps", self.adam_eps)
        self.policy_kwargs["optimizer_kwargs"] = optimizer_kwargs
        self.policy_kwargs.setdefault("bn_momentum", None)
        super()._setup_model()
        self._create_aliases()

    def _create_aliases(self) -> None:
        self.actor = self.policy.actor
        self.critic = self.policy.critic

    # ----- execution -----------------------------------------------------------------------------------------------
    def _exploration_mean(self, observation: np.ndarray | dict[str, np.ndarray]) -> np.ndarray:
        """Unclipped actor mean mu(s), clamped to [-1 - 3 sigma, 1 + 3 sigma] as stored by the authors."""
        self.policy.set_training_mode(False)
        obs_tensor, _ = self.policy.obs_to_tensor(observation)
        with th.no_grad():
            mean = self.actor(obs_tensor)
        mean_np = mean.cpu().numpy().reshape((-1, *self.action_space.shape)).astype(np.float32)
        return clamp_mean(mean_np, -1.0, 1.0, self.sigma)

    def _sample_action(
        self, learning_starts: int, action_noise: ActionNoise | None = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        if action_noise is not None:
            raise ValueError("DENFAC explores with its truncated Gaussian (sigma); action_noise is not supported")
        return super()._sample_action(learning_starts, None, n_envs)

    def _store_transition(self, replay_buffer: ReplayBuffer, buffer_action: np.ndarray, *args: Any, **kwargs: Any) -> None:
        assert isinstance(replay_buffer, DENFACReplayBuffer)
        replay_buffer.stage_behaviour_means(self._last_behaviour_mean)  # type: ignore[arg-type]
        super()._store_transition(replay_buffer, buffer_action, *args, **kwargs)

    # ----- Algorithm 1 ---------------------------------------------------------------------------------------------
    def _batch_indices(self, n: int) -> th.Tensor | None:
        if self.batch_size is None or self.batch_size >= n:
            return None
        return th.randperm(n, device=self.device)[: self.batch_size]

    def _fit_critic(self, obs: th.Tensor, actions: th.Tensor, q_targets: th.Tensor, weights: th.Tensor) -> th.Tensor:
        critic, optimizer = self.critic, self.critic.optimizer
        critic.set_training_mode(True)
        loss = th.zeros(())
        for _ in range(self.critic_steps):
            idx = self._batch_indices(obs.shape[0])
            o, a, q, c = (
                (obs, actions, q_targets, weights) if idx is None else (obs[idx], actions[idx], q_targets[idx], weights[idx])
            )
            loss = (c * (critic(o, a) - q).pow(2)).mean()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if self.max_grad_norm is not None:
                clip_grad_norm_(critic.parameters(), self.max_grad_norm)
            optimizer.step()
        critic.set_training_mode(False)
        return loss.detach()

    def _fit_actor(self, obs: th.Tensor) -> th.Tensor:
        actor, critic, optimizer = self.actor, self.critic, self.actor.optimizer
        actor.set_training_mode(True)
        critic.set_training_mode(False)  # ascend the fitted Q without touching its running statistics
        critic.requires_grad_(False)
        objective = th.zeros(())
        low, high = th.full((1,), -1.0, device=self.device), th.full((1,), 1.0, device=self.device)
        for _ in range(self.actor_steps):
            idx = self._batch_indices(obs.shape[0])
            o = obs if idx is None else obs[idx]
            optimizer.zero_grad(set_to_none=True)
            pi = actor(o)
            q = critic(o, pi)
            if self.inverting_gradients:
                objective = inverting_gradient_actor_backward(q, pi, low, high)
            else:
                (-q.mean()).backward()
                objective = q.detach().mean()
            if self.max_grad_norm is not None:
                clip_grad_norm_(actor.parameters(), self.max_grad_norm)
            optimizer.step()
        critic.requires_grad_(True)
        actor.set_training_mode(False)
        return objective.detach()

    def _reset_bn_statistics(self, net: th.nn.Module, fast_net=None) -> None:
        if self.policy.bn_momentum is None:  # cumulative average: statistics of this fit only
            for layer in net.modules():
                if isinstance(layer, th.nn.modules.batchnorm._BatchNorm):
                    layer.reset_running_stats()
            if fast_net is not None:
                fast_net.reset_bn_counts()

    def train(self, gradient_steps: int, batch_size: int | None = None) -> None:
        """Algorithm 1 over the whole replay buffer, ``gradient_steps`` times (DENFAC calls it once per episode)."""
        for net, rate in ((self.actor, self.actor_learning_rate), (self.critic, self.critic_learning_rate)):
            if rate is None:  # networks without their own rate follow SB3's learning_rate (schedule)
                update_learning_rate(net.optimizer, self.lr_schedule(self._current_progress_remaining))
        uses_batch_norm = any(isinstance(m, th.nn.modules.batchnorm._BatchNorm) for m in self.policy.modules())
        if uses_batch_norm and self.replay_buffer.size() < 2:
            return  # batch statistics of a single transition are undefined (a first episode of one step): wait
        for _ in range(gradient_steps):
            self._update()

    def _fast_update(self) -> FastUpdate | None:
        if self.update_path == "plain":
            return None
        layers = supported_networks(self.policy)
        if layers is None:
            if self.update_path in ("fast", "compiled"):
                raise ValueError(
                    f"update_path={self.update_path!r} needs vector observations, the default MLP networks and Adam"
                )
            return None
        compiled_size = None
        if self.update_path == "compiled":  # the sample count that repeats: full buffer or mini-batch
            compiled_size = self.replay_buffer.buffer_size if self.batch_size is None else self.batch_size
        return FastUpdate(self.policy, *layers, batch_size=self.batch_size, compiled_size=compiled_size)

    def _update(self) -> None:
        """One end-of-episode update: Algorithm 1 with K fitted iterations over the whole buffer D."""
        start = time.perf_counter()
        data = self.replay_buffer.all_samples(env=self._vec_normalize_env)
        obs, actions, next_obs, rewards = data.observations, data.actions, data.next_observations, data.rewards
        terminal = data.dones if self.bootstrap_on_timeout else th.clamp(data.dones + data.timeouts, max=1.0)
        log_prob_b = behaviour_log_prob(actions, data.behaviour_means, self.sigma)  # type: ignore[arg-type]
        low, high = th.full_like(actions, -1.0), th.full_like(actions, 1.0)
        self.policy.set_training_mode(False)
        fast = self._fast_update()
        # pi(s) and Q(s, a) in eval mode: the modules, or the same networks through the fast path's flat parameters
        actor, critic = (self.actor, self.critic) if fast is None else (fast.actor_eval, fast.critic_eval)
        critic_loss = actor_objective = th.zeros(())
        for _ in range(self.n_fitted_iterations):
            # Targets q_k and weights c from (Q_{k-1}, pi_{k-1}), before any reset (eval mode: running statistics).
            with th.no_grad():
                next_actions = actor(next_obs).clamp(-1.0, 1.0)
                q_targets = rewards + self.gamma * (1.0 - terminal) * critic(next_obs, next_actions)
                if self.weighting == "none":
                    weights = th.ones_like(rewards)
                else:
                    weight_obs = next_obs if self.weighting == "retrace_next_state_quirk" else obs
                    log_prob_target = self._target_log_prob(actions, actor(weight_obs), low, high)
                    weights = truncated_importance_weights(log_prob_target, log_prob_b).unsqueeze(1)
            if self.reset_critic:
                self.policy.reset_critic()
                if fast is not None:
                    fast.critic.reset()
            self._reset_bn_statistics(self.critic, None if fast is None else fast.critic)
            if fast is None:
                critic_loss = self._fit_critic(obs, actions, q_targets, weights)
            else:
                critic_loss = fast.fit_critic(
                    obs, actions, q_targets, weights, self.critic_steps, self.max_grad_norm, self._batch_indices
                )
            if self.reset_actor:
                self.policy.reset_actor()
                if fast is not None:
                    fast.actor.reset()
            self._reset_bn_statistics(self.actor, None if fast is None else fast.actor)
            if self.actor_steps > 0:
                if fast is None:
                    actor_objective = self._fit_actor(obs)
                else:
                    actor_objective = fast.fit_actor(
                        obs, self.actor_steps, self.max_grad_norm, self.inverting_gradients, self._batch_indices
                    )
        if fast is not None:
            fast.write_back()
        self._n_updates += 1
        self._last_update_stats = dict(weights=weights, q_targets=q_targets)
        self.logger.record("train/critic_loss", float(critic_loss))
        self.logger.record("train/actor_objective", float(actor_objective))
        self.logger.record("train/importance_weight_mean", weights.mean().item())
        self.logger.record("train/importance_weight_min", weights.min().item())
        self.logger.record("train/q_mean", q_targets.mean().item())
        self.logger.record("train/update_time", time.perf_counter() - start)
        self.logger.record("train/buffer_size", obs.shape[0])
        self.logger.record("train/n_updates", self._n_updates)

    def _target_log_prob(self, actions: th.Tensor, means: th.Tensor, low: th.Tensor, high: th.Tensor) -> th.Tensor:
        return truncated_normal_log_prob(actions, means, self.sigma, low, high)  # type: ignore[arg-type]

    # ----- SB3 plumbing --------------------------------------------------------------------------------------------
    def learn(
        self: SelfDENFAC,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,  # one update per episode: log every update (SB3's default is 4 episodes)
        tb_log_name: str = "DENFAC",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfDENFAC:
        return super().learn(
            total_timesteps=total_timesteps,
            callback=callback,
            log_interval=log_interval,
            tb_log_name=tb_log_name,
            reset_num_timesteps=reset_num_timesteps,
            progress_bar=progress_bar,
        )

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "actor", "critic", "_last_update_stats"]

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        return ["policy", "actor.optimizer", "critic.optimizer"], []
