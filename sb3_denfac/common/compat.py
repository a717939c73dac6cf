"""Compatibility with the model files and arguments of earlier sb3-denfac versions: every shim in one module.

What changed, and what reads the old form (tests: tests/test_saved_models.py, tests/test_conformance_save_load.py,
on the files of tests/data/):

- NFAC and CACLA 0.2 kept their optimizers as ``policy.actor_optimizer`` / ``policy.critic_optimizer`` (now
  ``policy.actor.optimizer`` / ``policy.critic.optimizer``): :class:`LegacyTorchNamesMixin` loads the old torch names,
  :class:`LegacyOptimizerAliasesMixin` keeps the old attributes as read-only aliases.
- DENFAC's ``update_path="compiled"`` was removed in 0.2: refused as an argument, "fast" in a file of 0.1
  (:func:`check_denfac_arguments`, :func:`upgrade_denfac`).
- DENFAC's defaults changed: 0.2 made the networks 64-64 without batch norm, with PyTorch's initialisation (0.1: the
  paper's), 0.3 turned on the proximal actor (``actor_proximal`` 1.0; 0.2: off), 0.4 added a second critic
  (``n_critics`` 2; before: 1). A file gets the value of the version that wrote it for what it did not save:
  :func:`denfac_attributes_of_old_files` (constructor arguments) and :data:`DENFAC_POLICY_KWARGS_OF_OLD_FILES`
  (``policy_kwargs``, applied by :func:`upgrade_denfac`). So that a missing key always means an older file, DENFAC
  writes the policy's own defaults of those keys into ``policy_kwargs`` (:func:`record_policy_defaults`).
- DENFAC files of 0.1 and 0.2 hold ``actor_learning_rate`` / ``critic_learning_rate`` in ``policy_kwargs`` (now the
  algorithm's arguments), and files before the update-to-data ratio say ``gradient_steps=1`` (now always -1, not saved).
"""

from __future__ import annotations

import copy
import inspect
import warnings
from typing import Any, ClassVar

import torch as th
from stable_baselines3.common.save_util import load_from_zip_file

# ----- NFAC and CACLA ------------------------------------------------------------------------------------------------


class LegacyTorchNamesMixin:
    """``set_parameters`` (and so ``load``) also for files saved with the torch names of earlier versions."""

    #: torch save names of earlier versions -> their names now
    _legacy_torch_names: ClassVar[dict[str, str]] = {}

    def set_parameters(self, load_path_or_dict: Any, exact_match: bool = True, device: Any = "auto") -> None:
        params = load_path_or_dict
        if not isinstance(params, dict):
            _, params, _ = load_from_zip_file(params, device=device, load_data=False)
        params = {self._legacy_torch_names.get(name, name): value for name, value in params.items()}
        super().set_parameters(params, exact_match=exact_match, device=device)  # type: ignore[misc]


#: NFAC's and CACLA's torch names of 0.2 (the optimizers were policy attributes).
ON_POLICY_TORCH_NAMES_0_2: dict[str, str] = {
    "policy.actor_optimizer": "policy.actor.optimizer",
    "policy.critic_optimizer": "policy.critic.optimizer",
}


class LegacyOptimizerAliasesMixin:
    """The optimizers' names of 0.2, as read-only aliases of ``actor.optimizer`` and ``critic.optimizer``."""

    actor: Any
    critic: Any

    @property
    def actor_optimizer(self) -> th.optim.Optimizer:
        """Read-only alias of ``actor.optimizer`` (its name in sb3-denfac 0.2)."""
        return self.actor.optimizer

    @property
    def critic_optimizer(self) -> th.optim.Optimizer:
        """Read-only alias of ``critic.optimizer`` (its name in sb3-denfac 0.2)."""
        return self.critic.optimizer


# ----- DENFAC --------------------------------------------------------------------------------------------------------

#: DENFACPolicy's defaults before 0.2 (the paper's networks, one critic): the values of a file whose ``policy_kwargs``
#: lacks the key (0.1 saved none of them; 0.2 and 0.3 no ``n_critics``).
DENFAC_POLICY_KWARGS_OF_OLD_FILES: dict[str, Any] = {
    "net_arch": {"pi": [20], "qf": [50, 7]},
    "batch_norm": True,
    "init": "paper",
    "n_critics": 1,
}


def check_denfac_arguments(update_path: str) -> None:
    if update_path == "compiled":
        raise ValueError(
            "update_path='compiled' was removed in sb3-denfac 0.2 (measured no faster than 'fast' on CPU): use 'fast'"
        )


def denfac_attributes_of_old_files(model: Any) -> None:
    """Before SB3's ``load`` writes a file's attributes over the constructor's: what files of earlier versions did not
    save takes the value those versions ran with (0.2 and earlier: no proximal actor)."""
    model.actor_proximal = 0.0
    model.target_policy_noise, model.target_noise_clip = 0.0, 0.5  # 0.4 and earlier: deterministic next actions
    model.critic_target = "min"  # 0.4 (n_critics 2) took the minimum
    model.bootstrap_bounds = False  # 0.5 and earlier: no bound


def record_policy_defaults(policy_kwargs: dict[str, Any], policy_class: type, default_net_arch: dict[str, Any]) -> None:
    """Write ``policy_class``'s own defaults of the keys of :data:`DENFAC_POLICY_KWARGS_OF_OLD_FILES` into
    ``policy_kwargs`` where it does not set them (``net_arch`` None: ``default_net_arch``), so that a saved file says
    which networks it has and a missing key means an older file."""
    parameters = _init_parameters(policy_class)
    for key in DENFAC_POLICY_KWARGS_OF_OLD_FILES:
        if key in policy_kwargs or key not in parameters:
            continue
        value = parameters[key].default
        policy_kwargs[key] = copy.deepcopy(default_net_arch if key == "net_arch" and value is None else value)


def _init_parameters(policy_class: type) -> dict[str, inspect.Parameter]:
    """The keyword parameters of ``policy_class``'s constructor, those its bases take through ``**kwargs`` included."""
    parameters: dict[str, inspect.Parameter] = {}
    for klass in reversed(policy_class.__mro__):
        if "__init__" in vars(klass):
            parameters.update(inspect.signature(klass.__init__).parameters)
    return parameters


def upgrade_denfac(model: Any) -> None:
    """At the start of ``_setup_model``: a model built now is left as it is; one loaded from an older file gets the
    settings that file was trained with (module docstring)."""
    if model.update_path == "compiled":  # a model saved by sb3-denfac 0.1
        warnings.warn("update_path='compiled' was removed in sb3-denfac 0.2: this model now updates with 'fast'")
        model.update_path = "fast"
    model.gradient_steps = -1  # files saved before update_to_data_ratio say 1 (one update per episode, as now)
    if model.policy_kwargs.get("soft_actor"):  # SoftDENFAC takes these files over before this point
        raise ValueError(
            f"this model was saved by a 0.5 development build with DENFAC's soft actor (ent_coef="
            f"{getattr(model, 'ent_coef', None)!r}), which is now its own algorithm: load it with SoftDENFAC.load(path)"
        )
    if "adam_betas" in model.__dict__:  # 0.5 development builds and earlier: Adam's settings were DENFAC's arguments
        betas, eps = model.__dict__.pop("adam_betas"), model.__dict__.pop("adam_eps", 1e-8)
        if model.policy_kwargs.get("optimizer_class", th.optim.Adam) in (th.optim.Adam, th.optim.AdamW):
            optimizer_kwargs = dict(model.policy_kwargs.get("optimizer_kwargs") or {})
            optimizer_kwargs.setdefault("betas", tuple(betas))
            optimizer_kwargs.setdefault("eps", eps)
            model.policy_kwargs["optimizer_kwargs"] = optimizer_kwargs
    if "ent_coef" in model.__dict__ and model.ent_coef is None:  # the 0.5 development builds' deterministic actor
        del model.ent_coef, model.target_entropy
    for key in ("actor_learning_rate", "critic_learning_rate"):  # written by 0.1 and 0.2, now the algorithm's
        model.policy_kwargs.pop(key, None)
    accepted = _init_parameters(model.policy_class)
    for key, value in DENFAC_POLICY_KWARGS_OF_OLD_FILES.items():
        if key in accepted:
            model.policy_kwargs.setdefault(key, copy.deepcopy(value))
