"""CMA-ES policy search (Hansen 2006) over the actor's weights, as an SB3 algorithm (the paper's actor-only baseline)."""

from __future__ import annotations

import copy
import sys
import time
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback
from stable_baselines3.common.utils import safe_mean
from torch.nn.utils import parameters_to_vector, vector_to_parameters

from sb3_denfac.cmaes.policies import CMAESPolicy, MlpPolicy
from sb3_denfac.common.budget import budget_reached
from sb3_denfac.common.callbacks import ProgressBarMixin
from sb3_denfac.common.checks import InputChecksMixin, check_choice, check_number, check_positive, check_sigma
from sb3_denfac.common.device import warn_about_device
from sb3_denfac.common.threads import TorchThreadsMixin, check_torch_threads
from sb3_denfac.common.truncated_normal import sample_truncated_normal

if TYPE_CHECKING:  # cma imports scipy.stats and matplotlib: loaded when a search is created (or a model loaded)
    import cma

SelfCMAES = TypeVar("SelfCMAES", bound="CMAES")

INCUMBENTS = ("mean", "best")


class _Randn:
    """Picklable normal sampler for cma's ``randn`` option: a private generator that is saved with the search."""

    def __init__(self, seed: int):
        self.rng = np.random.default_rng(seed)

    def __call__(self, *shape: int) -> np.ndarray:
        return self.rng.standard_normal(shape)


class CMAES(InputChecksMixin, TorchThreadsMixin, ProgressBarMixin, BaseAlgorithm):
    """CMA-ES over the weights of the actor network, the actor-only baseline of the DENFAC paper.

    Paper: "Data-efficient Neural Fitted Actor-Critic" (Zimmer, Boniface, Dutech), sections 2 and 4: CMA-ES (Hansen
    2006) searches the parameters theta of the same actor mu_theta(s) as the actor-critic algorithms (leaky ReLU,
    linear output), without batch normalization "as it does not rely on the gradient". Each generation samples
    ``population_size`` candidates theta_i ~ N(m, sigma_cma^2 C) (the ``cma`` package), runs each for
    ``n_eval_episodes`` episodes, and tells cma the mean episode returns (cma minimises -return).

    The evaluation episodes are the training data: every environment step counts in ``num_timesteps`` and calls the
    callbacks (EvalCallback, progress bar, best-so-far callbacks work), Monitor episodes fill ``rollout/ep_rew_mean``.
    ``learn(n)`` stops after n steps, also inside an episode (an env without time limit does not hang): the unfinished
    candidate evaluation and generation are kept and resumed by the next ``learn(reset_num_timesteps=False)``, which
    continues the same episode, so a candidate is always scored on whole episodes. When the env is reset in between
    (``reset_num_timesteps=True``, ``load``, a callback that stopped training), the interrupted episode is restarted.
    cma's termination criteria are ignored: the budget is ``total_timesteps``.

    Exploration: candidates act deterministically by default (``sigma=0``, the usual CMA-ES policy search, which
    explores in parameter space). ``sigma > 0`` adds the paper's truncated Gaussian action noise N(mu(s), sigma^2) on
    [-1, 1] during evaluation episodes (the authors' code uses sigma = 0.05 for every algorithm).

    ``predict`` uses the incumbent policy: the CMA-ES mean m (``incumbent="mean"``, cma's recommendation for noisy
    objectives) or the best evaluated candidate (``"best"``), updated after every generation; it is loaded into
    ``self.policy`` and saved with the model. Before the first generation it is the initial actor (the search start).

    Saved with the model (``save``/``load``): the policy weights (torch), the pickled ``cma.CMAEvolutionStrategy``
    (mean, step size, covariance, evolution paths and its private random generator), the unfinished generation,
    the best candidate and its return, and the generation count.

    Input checks (:class:`~sb3_denfac.common.checks.InputChecksMixin`): NaN/inf observations, rewards or actions raise
    a ValueError, ``load`` refuses corrupted zips and zips saved by another algorithm, and an action space that is not
    a Box with finite bounds raises an :class:`~sb3_denfac.common.checks.UnsupportedSpaceError` (a ValueError that is
    also SB3's AssertionError).

    :param policy: policy class or "MlpPolicy" (:class:`sb3_denfac.cmaes.policies.CMAESPolicy`; policy_kwargs:
        ``net_arch``, ``batch_norm`` (default False), ``init``, ``activation_fn``)
    :param env: environment (Box action space, one env) or its registered id
    :param population_size: CMA-ES population size lambda (popsize, >= 2); None = cma's default 4 + 3 ln(n_params)
    :param sigma0: initial CMA-ES step size sigma_cma in parameter space
    :param n_eval_episodes: episodes per candidate; its fitness is their mean return
    :param sigma: std of the truncated Gaussian action noise during evaluation episodes (0 = deterministic candidates)
    :param incumbent: "mean" or "best": which parameters ``predict`` uses (see above)
    :param cma_options: extra options for ``cma.CMAEvolutionStrategy`` (e.g. ``{"CMA_diagonal": True}``)
    :param stats_window_size: episodes averaged in ``rollout/ep_rew_mean``
    :param tensorboard_log: TensorBoard log directory (the ``train/`` keys of :mod:`sb3_denfac.common.logging_keys`:
        train/cma_sigma, train/best_return, train/generation_mean_return...; train/n_updates counts generations)
    :param policy_kwargs: keyword arguments of the policy
    :param verbose: verbosity level
    :param seed: random seed (also seeds CMA-ES's private generator)
    :param device: torch device
    :param torch_threads: torch threads inside ``learn()`` (default 1; None: leave torch's setting alone), restored
        after it (:mod:`~sb3_denfac.common.threads`)
    :param _init_setup_model: build the policy and the search at construction
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"MlpPolicy": MlpPolicy}
    policy: CMAESPolicy

    def __init__(
        self,
        policy: str | type[CMAESPolicy],
        env: GymEnv | str,
        population_size: int | None = None,
        sigma0: float = 0.5,
        n_eval_episodes: int = 1,
        sigma: float = 0.0,
        incumbent: str = "mean",
        cma_options: dict[str, Any] | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        torch_threads: int | None = 1,
        _init_setup_model: bool = True,
    ):
        super().__init__(
            policy,
            env,
            learning_rate=0.0,  # unused: no gradient
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=device,
            support_multi_env=False,
            seed=seed,
            supported_action_spaces=(spaces.Box,),
        )
        self.population_size = check_number("population_size", population_size, minimum=2, integer=True, none_ok=True)
        self.sigma0 = check_positive("sigma0 (initial CMA-ES step size)", sigma0)
        self.n_eval_episodes = check_positive("n_eval_episodes", n_eval_episodes, integer=True)
        self.sigma = check_sigma(sigma, zero_ok=True)  # 0 = deterministic candidates
        self.torch_threads = check_torch_threads(torch_threads)
        self.incumbent = check_choice("incumbent", incumbent, INCUMBENTS)
        self.cma_options = dict(cma_options or {})
        # Search state (saved): the CMA-ES object, the unfinished generation, the best candidate so far.
        self.es: cma.CMAEvolutionStrategy | None = None
        self.generation = 0
        self.best_return = -np.inf
        self.best_params: np.ndarray | None = None
        self._candidates: list[np.ndarray] | None = None
        self._candidate_returns: list[float] = []
        self._episode_returns: list[float] = []  # finished evaluation episodes of the current candidate
        self._episode_return = 0.0  # return so far of the episode being evaluated
        self._episode_num = 0
        if _init_setup_model:
            self._setup_model()
            warn_about_device(type(self).__name__, device, self.device, self.policy)

    def _setup_model(self) -> None:
        self.set_random_seed(self.seed)
        self.policy = self.policy_class(self.observation_space, self.action_space, **self.policy_kwargs)
        self.policy = self.policy.to(self.device)
        # Candidates are evaluated in a copy, so callbacks (EvalCallback...) always see the incumbent policy.
        self._candidate_policy = copy.deepcopy(self.policy)
        if self.es is None:  # fresh model (a loaded one already has its search state)
            options = {
                "seed": np.nan,  # cma must not reseed numpy's global generator
                "randn": _Randn(int(np.random.randint(0, 2**31 - 1))),
                "verbose": -9,
                "verb_log": 0,
                "verb_disp": 0,
                **({} if self.population_size is None else {"popsize": self.population_size}),
                **self.cma_options,
            }
            import cma

            x0 = parameters_to_vector(self.policy.parameters()).detach().cpu().double().numpy()
            self.es = cma.CMAEvolutionStrategy(x0, self.sigma0, options)
            self.population_size = int(self.es.popsize)

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_candidate_policy"]

    def _load_parameters(self, policy: CMAESPolicy, flat: np.ndarray) -> None:
        vector_to_parameters(th.as_tensor(flat, dtype=th.float32, device=self.device), policy.parameters())

    def _act(self, observation: np.ndarray) -> np.ndarray:
        """Action of the candidate being evaluated, in the env's bounds (noise in the scaled space if sigma > 0)."""
        obs_tensor, _ = self._candidate_policy.obs_to_tensor(observation)
        with th.no_grad():
            mean = self._candidate_policy(obs_tensor).cpu().numpy().reshape((-1, *self.action_space.shape))
        if self.sigma > 0:
            scaled = sample_truncated_normal(mean, self.sigma, -1.0, 1.0)
        else:
            scaled = np.clip(mean, -1.0, 1.0)
        return self.policy.unscale_action(scaled)

    def _evaluate_candidate(self, flat: np.ndarray, callback: BaseCallback) -> float | None:
        """Run candidate ``flat``'s remaining evaluation episodes; its mean return, or None if training stops first
        (a callback, or ``total_timesteps`` reached: the evaluation is then resumed by the next ``learn``)."""
        assert self.env is not None
        self._load_parameters(self._candidate_policy, flat)
        callback.on_rollout_start()
        while len(self._episode_returns) < self.n_eval_episodes:
            done = False
            while not done:
                if budget_reached(self):
                    return None
                actions = self._act(self._last_obs)  # type: ignore[arg-type]
                new_obs, rewards, dones, infos = self.env.step(actions)
                if self._vec_normalize_env is not None:
                    rewards = self._vec_normalize_env.get_original_reward()
                self.num_timesteps += 1
                self._episode_return += float(rewards[0])
                done = bool(dones[0])
                self._update_info_buffer(infos, dones)
                self._last_obs = new_obs  # after a done, VecEnv has already reset: the next episode's first obs
                callback.update_locals(locals())
                if not callback.on_step():
                    if not done:
                        self._last_obs = None  # type: ignore[assignment]  # the next learn() resets the env
                    else:
                        self._end_episode()
                    return None
            self._end_episode()
        callback.on_rollout_end()
        mean_return = float(np.mean(self._episode_returns))
        self._episode_returns = []
        return mean_return

    def _end_episode(self) -> None:
        self._episode_num += 1
        self._episode_returns.append(self._episode_return)
        self._episode_return = 0.0

    def _end_generation(self) -> None:
        """Tell cma the returns of the finished generation, update the best candidate and the incumbent policy."""
        assert self.es is not None and self._candidates is not None
        returns = np.asarray(self._candidate_returns)
        self.es.tell(self._candidates, list(-returns))  # cma minimises
        self.generation += 1
        best = int(np.argmax(returns))
        if returns[best] > self.best_return:
            self.best_return = float(returns[best])
            self.best_params = np.array(self._candidates[best], dtype=np.float64)
        incumbent = self.es.mean if self.incumbent == "mean" else self.best_params
        self._load_parameters(self.policy, np.asarray(incumbent))
        self.logger.record("train/n_updates", self.generation, exclude="tensorboard")  # one search update per generation
        self.logger.record("train/cma_sigma", float(self.es.sigma))
        self.logger.record("train/best_return", self.best_return)
        self.logger.record("train/generation_mean_return", float(returns.mean()))
        self.logger.record("train/generation_best_return", float(returns[best]))
        self.logger.record("train/population_size", len(returns))
        self._candidates, self._candidate_returns = None, []

    def _dump_logs(self) -> None:
        time_elapsed = max((time.time_ns() - self.start_time) / 1e9, sys.float_info.epsilon)
        fps = int((self.num_timesteps - self._num_timesteps_at_start) / time_elapsed)
        if self.ep_info_buffer:
            self.logger.record("rollout/ep_rew_mean", safe_mean([ep["r"] for ep in self.ep_info_buffer]))
            self.logger.record("rollout/ep_len_mean", safe_mean([ep["l"] for ep in self.ep_info_buffer]))
        self.logger.record("time/episodes", self._episode_num, exclude="tensorboard")
        self.logger.record("time/fps", fps)
        self.logger.record("time/time_elapsed", int(time_elapsed), exclude="tensorboard")
        self.logger.record("time/total_timesteps", self.num_timesteps, exclude="tensorboard")
        self.logger.dump(step=self.num_timesteps)

    def learn(
        self: SelfCMAES,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 1,
        tb_log_name: str = "CMAES",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfCMAES:
        """Run CMA-ES generations until ``total_timesteps`` environment steps; logs every ``log_interval`` generations."""
        if reset_num_timesteps or self._last_obs is None:
            self._episode_return = 0.0  # the env is reset: an interrupted episode restarts
        total_timesteps, callback = self._setup_learn(
            total_timesteps, callback, reset_num_timesteps, tb_log_name, progress_bar
        )
        callback.on_training_start(locals(), globals())
        assert self.es is not None
        while self.num_timesteps < total_timesteps:
            if self._candidates is None:
                self._candidates = [np.asarray(x) for x in self.es.ask()]
                self._candidate_returns = []
            candidate_return = self._evaluate_candidate(self._candidates[len(self._candidate_returns)], callback)
            if candidate_return is None:
                break
            self._candidate_returns.append(candidate_return)
            self._update_current_progress_remaining(self.num_timesteps, total_timesteps)
            if len(self._candidate_returns) == len(self._candidates):
                self._end_generation()
                if log_interval is not None and self.generation % log_interval == 0:
                    self._dump_logs()
        callback.on_training_end()
        return self
