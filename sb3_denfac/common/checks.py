"""Input checks shared by the package's algorithms, built on SB3's own tooling.

Add :class:`InputChecksMixin` as the FIRST base of an algorithm class (``class DENFAC(InputChecksMixin, ...,
EpisodicOffPolicyAlgorithm)``). It checks:

- every environment an algorithm is given (constructor, ``set_env``, ``load(env=...)``): a NaN or inf in an
  observation (at reset or step), a reward or an action raises a ``ValueError`` naming which (``found nan in
  rewards``, ``found inf in observations``...) instead of silently turning the networks' weights into NaN. In-process
  envs get a gym-level :class:`FiniteCheckWrapper` per sub-env, other VecEnvs SB3's
  :class:`~stable_baselines3.common.vec_env.VecCheckNan` with ``raise_exception=True`` (see :func:`wrap_check_finite`).
  The same hook refuses an action space that is not a Box with finite bounds with an :class:`UnsupportedSpaceError`
  (a ``ValueError`` that is also an ``AssertionError``, SB3's type for unsupported spaces);
- ``predict``: a NaN/inf observation is refused with the same message, unless ``model.allow_non_finite_predict = True``;
- ``load``: a truncated, corrupted or missing model file, or one another algorithm saved, is refused with an error
  naming the problem (:func:`~.model_files.check_loadable`);
- ``learn`` without an environment, or with a replay buffer of another algorithm or environment
  (``load_replay_buffer``): a ``ValueError`` saying so;
- ``"MultiInputPolicy"`` for an algorithm without Dict observations: the cause, named;
- the constructor: a preset of another algorithm is refused by name (:func:`check_preset_keywords`).
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any, Protocol, SupportsFloat, runtime_checkable

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.env_util import is_wrapped
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.preprocessing import get_action_dim, get_obs_shape
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.vec_env import DummyVecEnv, VecCheckNan, VecEnv, VecEnvWrapper

from sb3_denfac.common.model_files import check_loadable


def _non_finite(name: str, value: Any) -> list[str]:
    """``["nan in <name>", ...]`` for the non-finite entries of a (possibly dict / tuple) numeric value."""
    if isinstance(value, dict):
        return [issue for key, item in value.items() for issue in _non_finite(f"{name}.{key}", item)]
    if isinstance(value, tuple):
        return [issue for index, item in enumerate(value) for issue in _non_finite(f"{name}.{index}", item)]
    array = np.asarray(value)
    if array.dtype.kind not in "fc":  # integers and booleans are always finite
        return []
    return [f"{kind} in {name}" for kind, test in (("inf", np.isinf), ("nan", np.isnan)) if test(array).any()]


class FiniteCheckWrapper(gym.Wrapper):
    """Raise a ``ValueError`` when the wrapped env returns a NaN/inf observation or reward, or is given a NaN/inf action.

    The message reads as SB3's ``VecCheckNan`` ("found nan in rewards, ...") and says where the value came from.
    """

    def reset(self, **kwargs: Any) -> tuple[Any, dict]:
        observation, info = self.env.reset(**kwargs)
        self._raise_if_any(_non_finite("observations", observation), "the environment observation (at reset)")
        return observation, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict]:
        self._raise_if_any(_non_finite("actions", action), "the RL model (the action it gave the environment)")
        observation, reward, terminated, truncated, info = self.env.step(action)
        issues = _non_finite("observations", observation) + _non_finite("rewards", reward)
        self._raise_if_any(issues, f"the environment, after the action {action}")
        return observation, reward, terminated, truncated, info

    @staticmethod
    def _raise_if_any(issues: list[str], origin: str) -> None:
        if issues:
            raise ValueError(f"found {', found '.join(issues)}. Originated from {origin}")


def _base_vec_env(env: VecEnv) -> VecEnv:
    while isinstance(env, VecEnvWrapper):
        env = env.venv
    return env


def has_finite_check(env: VecEnv) -> bool:
    """True if every sub-env carries a :class:`FiniteCheckWrapper` or a raising ``VecCheckNan`` wraps the VecEnv."""
    node = env
    while isinstance(node, VecEnvWrapper):
        if isinstance(node, VecCheckNan) and node.raise_exception:
            return True
        node = node.venv
    return isinstance(node, DummyVecEnv) and all(is_wrapped(sub_env, FiniteCheckWrapper) for sub_env in node.envs)


def wrap_check_finite(env: VecEnv) -> VecEnv:
    """Make NaN/inf observations, rewards and actions of ``env`` raise a ``ValueError``; returns the env to use.

    In-process envs (a :class:`DummyVecEnv`, possibly under ``VecNormalize`` etc.) get a :class:`FiniteCheckWrapper`
    around each sub-env, in place: the VecEnv keeps its type (SB3's ``EvalCallback`` warns when the training and eval
    envs differ in type) and the raw values are checked, before any normalisation. Other VecEnvs (``SubprocVecEnv``...)
    are wrapped in SB3's ``VecCheckNan(raise_exception=True)``. Nothing is added twice.
    """
    if has_finite_check(env):
        return env
    base = _base_vec_env(env)
    if isinstance(base, DummyVecEnv):
        base.envs = [
            sub_env if is_wrapped(sub_env, FiniteCheckWrapper) else FiniteCheckWrapper(sub_env) for sub_env in base.envs
        ]
        return env
    if isinstance(env.action_space, spaces.Dict):  # not supported by VecCheckNan
        return env
    return VecCheckNan(env, raise_exception=True, warn_once=False, check_inf=True)


class UnsupportedSpaceError(ValueError, AssertionError):
    """An action space the algorithm cannot use. A ``ValueError`` naming the space and what is needed; also an
    ``AssertionError``, which SB3 raises for unsupported spaces, so code written for SB3 (``except AssertionError``,
    ``pytest.raises(AssertionError)``) keeps working."""


def check_action_space(algorithm: str, space: spaces.Space) -> None:
    """Raise an :class:`UnsupportedSpaceError` unless ``space`` is a Box with finite bounds (all of the package's
    algorithms scale actions to [-1, 1])."""
    if not isinstance(space, spaces.Box):
        raise UnsupportedSpaceError(f"{algorithm} needs a continuous (gymnasium.spaces.Box) action space, got {space}")
    if not (np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high))):
        raise UnsupportedSpaceError(f"{algorithm} needs finite action bounds (actions are scaled to [-1, 1]), got {space}")


#: SB3's policy name for Dict observations, which DENFAC and SoftDENFAC implement.
MULTI_INPUT_POLICY = "MultiInputPolicy"


def _no_dict_observations(algorithm: str, what: str) -> UnsupportedSpaceError:
    return UnsupportedSpaceError(
        f"{algorithm} has no {MULTI_INPUT_POLICY}: {what}. Its policies take Box, Discrete, MultiDiscrete or MultiBinary "
        "observations; flatten a Dict observation into one vector with gymnasium.wrappers.FlattenObservation(env) "
        "and use 'MlpPolicy', or use DENFAC or SoftDENFAC, which take it with 'MultiInputPolicy' (and HerReplayBuffer)"
    )


def check_observation_space(algorithm: str, space: spaces.Space, multi_input: bool = False) -> None:
    """Raise an :class:`UnsupportedSpaceError` for a Dict (or Tuple) observation space, naming the way around it; a
    Dict is taken by an algorithm with a ``MultiInputPolicy`` (``multi_input``)."""
    if multi_input and isinstance(space, spaces.Dict):
        return
    if isinstance(space, spaces.Dict | spaces.Tuple):
        keys = f" with keys {list(space.spaces)}" if isinstance(space, spaces.Dict) else ""
        raise _no_dict_observations(algorithm, f"the env's observation space is a {type(space).__name__}{keys}")


def check_replay_buffer(model: Any) -> None:
    """Raise a ``ValueError`` if an off-policy ``model``'s replay buffer does not fit it (e.g. a buffer loaded with
    ``load_replay_buffer`` from another algorithm, env or number of envs); no-op without a replay buffer."""
    buffer = getattr(model, "replay_buffer", None)
    if buffer is None:
        return
    name = type(model).__name__
    expected = getattr(model, "replay_buffer_class", None)
    if isinstance(expected, type) and not isinstance(buffer, expected):
        raise ValueError(
            f"{name}'s replay buffer is a {type(buffer).__name__}, it needs a {expected.__name__}: "
            "was it saved by another algorithm?"
        )
    fits = (
        getattr(buffer, "obs_shape", None) == get_obs_shape(model.observation_space)
        and getattr(buffer, "action_dim", None) == get_action_dim(model.action_space)
        and (model.env is None or getattr(buffer, "n_envs", None) == model.n_envs)
    )
    if not fits:
        raise ValueError(
            f"{name}'s replay buffer (observation shape {getattr(buffer, 'obs_shape', None)}, action dim "
            f"{getattr(buffer, 'action_dim', None)}, n_envs {getattr(buffer, 'n_envs', None)}) does not fit the model "
            f"(observation shape {get_obs_shape(model.observation_space)}, action dim {get_action_dim(model.action_space)}"
            f", n_envs {model.n_envs}): was it saved for another environment?"
        )


def check_preset_keywords(cls: type, keywords: dict[str, Any], parameters: Mapping[str, inspect.Parameter]) -> None:
    """Refuse a preset of another algorithm given to ``cls``'s constructor (``SoftDENFAC(..., **presets.PAPER)``) with a
    ``TypeError`` (Python's type for an unexpected keyword argument) that names the preset, its algorithm and the keys
    ``cls`` does not take (:func:`~sb3_denfac.denfac.presets.foreign_preset_message`). Other unexpected keywords are
    left to Python's own TypeError. ``parameters``: ``cls.__init__``'s."""
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return
    not_taken = [key for key in keywords if key not in parameters]
    if not_taken:
        from sb3_denfac.denfac.presets import foreign_preset_message

        message = foreign_preset_message(cls.__name__, keywords, not_taken)
        if message is not None:
            raise TypeError(message)


@runtime_checkable
class InputChecksHost(Protocol):
    """What :class:`InputChecksMixin` needs from the algorithm it is mixed into (an SB3 ``BaseAlgorithm``)."""

    policy_aliases: dict[str, type[BasePolicy]]
    env: VecEnv | None

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = False) -> Any: ...

    def _setup_learn(self, *args: Any, **kwargs: Any) -> Any: ...


class InputChecksMixin:
    """All checks of this module (module docstring); put it first in an algorithm's bases.

    Overrides BaseAlgorithm's static ``_wrap_env`` with a classmethod (``self._wrap_env`` and ``cls._wrap_env`` both
    still work), so the check of the env covers the constructor, ``set_env`` and ``load``.
    """

    policy_aliases: dict[str, type[BasePolicy]]
    env: VecEnv | None
    #: True lets ``predict`` take observations holding NaN or inf (the actions are then what the networks make of
    #: them, often NaN); ``learn`` refuses them regardless. Set it on the model: ``model.allow_non_finite_predict = True``.
    allow_non_finite_predict: bool = False

    def __new__(cls, *args: Any, **kwargs: Any) -> Any:
        parameters = inspect.signature(cls.__init__).parameters  # type: ignore[misc]
        check_preset_keywords(cls, kwargs, parameters)  # before Python binds the arguments (its TypeError would name one)
        model = super().__new__(cls)
        # the constructor arguments the caller gave (positional ones by name), which settings chosen from the env leave
        # alone (DENFAC's goal settings, :func:`~sb3_denfac.denfac.her.take_goal_settings`)
        positional = [name for name in parameters if name != "self"][: len(args)]
        model._given_arguments = frozenset(positional) | frozenset(kwargs)
        return model

    def _get_policy_from_name(self, policy_name: str) -> type[BasePolicy]:
        # SB3 answers "MultiInputPolicy" with "Policy MultiInputPolicy unknown": this names the cause instead
        if policy_name == MULTI_INPUT_POLICY and policy_name not in self.policy_aliases:
            raise _no_dict_observations(type(self).__name__, "Dict observation spaces are not supported yet")
        return super()._get_policy_from_name(policy_name)  # type: ignore[misc]

    def predict(
        self,
        observation: Any,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        if not self.allow_non_finite_predict:
            issues = _non_finite("observations", observation)
            if issues:
                name = type(self).__name__
                raise ValueError(
                    f"found {', found '.join(issues)}. Originated from the observation given to {name}.predict() "
                    f"(to let non-finite observations through predict, set model.allow_non_finite_predict = True)"
                )
        return super().predict(observation, state, episode_start, deterministic)  # type: ignore[misc]

    @classmethod
    def _wrap_env(cls, env: GymEnv, verbose: int = 0, monitor_wrapper: bool = True) -> VecEnv:
        wrapped = super()._wrap_env(env, verbose, monitor_wrapper)  # type: ignore[misc]
        check_action_space(cls.__name__, wrapped.action_space)  # before SB3's own assert (one error type for all)
        multi_input = MULTI_INPUT_POLICY in getattr(cls, "policy_aliases", {})
        check_observation_space(cls.__name__, wrapped.observation_space, multi_input)  # before SB3's "use MultiInputPolicy"
        return wrap_check_finite(wrapped)

    @classmethod
    def load(cls, path: Any, *args: Any, **kwargs: Any) -> Any:
        check_loadable(cls, path, kwargs.get("custom_objects"))
        return super().load(path, *args, **kwargs)  # type: ignore[misc]

    def _setup_learn(self, *args: Any, **kwargs: Any) -> Any:
        if self.env is None:  # instead of SB3's bare assert, e.g. after load(path) without env=
            name = type(self).__name__
            raise ValueError(f"{name}.learn() needs an environment: pass env= to {name}.load(...) or call set_env(env) first")
        check_replay_buffer(self)
        return super()._setup_learn(*args, **kwargs)  # type: ignore[misc]


# ---------------------------------------------------------------------------------------------- hyperparameter checks
# The one set of constructor-argument validators of the six algorithms: each raises a ValueError whose message starts
# with the parameter's name and returns the value as the algorithm stores it (Python int/float: SB3's schedules and
# JSON saving want Python scalars, not the numpy scalars YAML or Optuna may give).


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def check_number(
    name: str,
    value: Any,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    exclusive_minimum: bool = False,
    integer: bool = False,
    none_ok: bool = False,
    note: str = "",
) -> Any:
    """``value`` as a Python int (``integer``) or float if it is a finite number in the bounds, else a ValueError naming
    ``name``; ``None`` is returned as is when ``none_ok``. ``note`` is appended to the message (why the bound)."""
    if value is None and none_ok:
        return None
    valid = _is_number(value) and bool(np.isfinite(value)) and (not integer or float(value).is_integer())
    if valid and minimum is not None:
        valid = value > minimum if exclusive_minimum else value >= minimum
    if valid and maximum is not None:
        valid = value <= maximum
    if not valid:
        bounds = []
        if minimum is not None:
            bounds.append(f"{'>' if exclusive_minimum else '>='} {minimum:g}")
        if maximum is not None:
            bounds.append(f"<= {maximum:g}")
        requirement = " ".join(["an integer" if integer else "a number", " and ".join(bounds)]).strip()
        alternatives = " (or None)" if none_ok else ""
        raise ValueError(f"{name} must be {requirement}{alternatives}{note}, got {value!r}")
    return int(value) if integer else float(value)


def check_positive(name: str, value: Any, integer: bool = False, none_ok: bool = False) -> Any:
    """A number > 0 (an integer >= 1 if ``integer``); see :func:`check_number`."""
    if integer:
        return check_number(name, value, minimum=1, integer=True, none_ok=none_ok)
    return check_number(name, value, minimum=0, exclusive_minimum=True, none_ok=none_ok)


def check_learning_rate(name: str, value: Any) -> Any:
    """A learning rate: a positive number (returned as a float), a schedule of the remaining progress (a callable,
    returned as is) or None (= follow ``learning_rate``)."""
    return value if callable(value) else check_positive(name, value, none_ok=True)


def check_gamma(gamma: Any) -> float:
    """The discount factor gamma, in [0, 1]."""
    return check_number("gamma (discount factor)", gamma, minimum=0, maximum=1)


def check_sigma(sigma: Any, none_ok: bool = False, zero_ok: bool = False, name: str = "sigma") -> Any:
    """The standard deviation of the truncated-Gaussian exploration, > 0 (>= 0 if ``zero_ok``; None if ``none_ok``)."""
    note = " (exploration std of the truncated Gaussian)"
    return check_number(name, sigma, minimum=0, exclusive_minimum=not zero_ok, none_ok=none_ok, note=note)


def check_choice(name: str, value: Any, choices: tuple[Any, ...]) -> Any:
    """One of ``choices``."""
    if value not in choices:
        raise ValueError(f"{name} must be one of {choices}, got {value!r}")
    return value


def check_bool(name: str, value: Any) -> bool:
    """True or False (a numpy bool too), not a number or a string that would read as one."""
    if not isinstance(value, bool | np.bool_):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)
