"""The zoo's ``ExperimentManager`` with what the zoo cannot guess for this package (:mod:`.cli` lists it): the default
``--conf-file``, a resumable Optuna study, no empty run folder for ``-optimize``, presets expanded and entries checked
(:func:`~.validation.validate_entry`)."""

from __future__ import annotations

import argparse
import json
from collections import OrderedDict
from pathlib import Path
from typing import Any

import optuna
from rl_zoo3.exp_manager import ExperimentManager

from sb3_denfac.zoo import samplers as zoo_samplers
from sb3_denfac.zoo.config import (
    ALGORITHMS,
    ZooConfigError,
    check_env_keys,
    default_config_path,
    expand_preset,
    load_config_file,
    select_entry,
)
from sb3_denfac.zoo.validation import validate_entry


class CheckedExperimentManager(ExperimentManager):
    """rl_zoo3's ExperimentManager with this package's defaults (config file, Optuna storage and study name), the
    entry checked before anything is created, and the entry's ``policy_kwargs`` kept by this package's samplers.

    It reads the command line from the zoo's own parse (``self.args``); only public methods are overridden."""

    def __init__(self, args: argparse.Namespace, algo: str, env_id: str, *rest: Any, **kwargs: Any):
        super().__init__(args, algo, env_id, *rest, **kwargs)
        if args.conf_file is None:
            ours = default_config_path(algo)
            if algo in ALGORITHMS and not ours.is_file():
                raise ZooConfigError(f"No hyperparameter file for {algo!r}: expected {ours}; pass --conf-file")
            if ours.is_file() and (algo in ALGORITHMS or env_id in load_config_file(ours)):
                self.config = args.conf_file = str(ours)
        if self.optimize_hyperparameters:
            from rl_zoo3.hyperparams_opt import HYPERPARAMS_SAMPLER

            if algo not in HYPERPARAMS_SAMPLER:
                raise ZooConfigError(f"No Optuna sampler for {algo!r}; tunable: {', '.join(sorted(HYPERPARAMS_SAMPLER))}")
        if self.optimize_hyperparameters or self.trial_id is not None:  # the study that -optimize writes by default
            if self.storage is None:
                self.storage = args.storage = f"sqlite:///{Path(self.log_folder).resolve() / 'optuna.db'}"
            if self.study_name is None:
                self.study_name = args.study_name = f"{algo}-{env_id.replace('/', '-')}"
        self.entry_policy_kwargs: Any = {}

    def read_hyperparameters(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """The zoo's reading, after a check of the file (YAML syntax, env ids) and before one of the entry."""
        is_yaml = self.config.endswith((".yml", ".yaml"))
        if is_yaml:
            config = load_config_file(self.config)
            check_env_keys(config, self.config)
            entry = {**select_entry(config, self.env_name.gym_id, self.config, self.algo), **(self.custom_hyperparams or {})}
            self.entry_policy_kwargs = entry.get("policy_kwargs", {})
        hyperparams, _ = super().read_hyperparameters()
        # The zoo's entry (and its -params, --trial-id values) over its preset, before anything uses them.
        hyperparams = expand_preset(hyperparams, f" ({self.config})", self.algo)
        saved_hyperparams = OrderedDict((key, hyperparams[key]) for key in sorted(hyperparams))
        if is_yaml:
            name = self.env_name.gym_id if self.env_name.gym_id in config else "default"
            source = f"{self.config}, entry {name!r}"
            try:
                validate_entry(self.algo, hyperparams, source=source, env_id=self.env_name.gym_id)
            except ZooConfigError:
                self._blame_command_line(config, name, source)
                raise
        return hyperparams, saved_hyperparams

    def _blame_command_line(self, config: dict[str, Any], name: str, source: str) -> None:
        """Called when the entry after ``-params`` fails its check: if the YAML entry alone passes, the ``-params``
        values are the cause, and the entry is checked again under that name (raising the error that says so)."""
        if not self.custom_hyperparams:
            return
        yaml_entry = expand_preset(config[name], f" ({source})", self.algo)
        try:
            validate_entry(self.algo, yaml_entry, source=source, env_id=self.env_name.gym_id)
        except ZooConfigError:
            return  # the file's entry fails by itself: its error stands
        given = " ".join(f"{key}:{value!r}" for key, value in self.custom_hyperparams.items())
        hyperparams = expand_preset({**config[name], **self.custom_hyperparams}, f" ({source})", self.algo)
        validate_entry(
            self.algo, hyperparams, source=f"command line -params {given}, over {source}", env_id=self.env_name.gym_id
        )

    def _tuned_policy_kwargs(self) -> dict[str, Any]:
        """The entry's ``policy_kwargs`` for this package's samplers: a plain mapping (recorded in the study)."""
        value = self.entry_policy_kwargs
        try:
            json.dumps(value)
        except TypeError:
            value = None
        if not isinstance(value, dict):
            raise ZooConfigError(
                f"To tune {self.algo!r}, write policy_kwargs as a YAML mapping of plain values (the sampled net_arch is "
                f"merged into it and each trial records it), got {self.entry_policy_kwargs!r}"
            )
        return value

    def objective(self, trial: optuna.Trial) -> float:
        if self.algo in zoo_samplers.SAMPLERS:
            trial.set_user_attr(zoo_samplers.ENTRY_POLICY_KWARGS, self._tuned_policy_kwargs())
        return super().objective(trial)

    def load_trial(self, storage: str, study_name: str, trial_id: int | None = None, convert: bool = True) -> dict:
        hyperparams = super().load_trial(storage, study_name, trial_id, convert)
        if convert and self.algo in zoo_samplers.CONVERTERS:
            return zoo_samplers.with_entry_policy_kwargs(hyperparams, self._tuned_policy_kwargs())
        return hyperparams

    def create_log_folder(self) -> None:
        """The run folder ``<log-folder>/<algo>/<env>_<n>`` of a training run. A tuning run makes none: its trials
        train on envs without logs and keep their results in the study (an empty run folder would be the latest
        run that ``enjoy`` picks)."""
        if not self.optimize_hyperparameters:
            super().create_log_folder()

    def create_envs(self, n_envs: int, eval_env: bool = False, no_log: bool = False) -> Any:
        """The zoo's envs; with ``-optimize`` none is logged, not even the env the zoo makes to read the action space
        before the trials (its Monitor file would make the run folder)."""
        return super().create_envs(n_envs, eval_env=eval_env, no_log=no_log or self.optimize_hyperparameters)

    def hyperparameters_optimization(self) -> None:
        if self.algo in zoo_samplers.SAMPLERS:
            self._tuned_policy_kwargs()  # fails before the first trial
        if self.storage.startswith("sqlite:///"):
            Path(self.storage.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
        self._check_study_budget()
        super().hyperparameters_optimization()

    def _check_study_budget(self) -> None:
        """Trials are comparable only at one budget: the study records its ``n_timesteps`` when it is made, and a run
        that would add trials of another budget to it is refused (the zoo would silently join it)."""
        try:
            study = optuna.load_study(study_name=self.study_name, storage=self.storage)
        except KeyError:  # a new study, made here as the zoo makes it (the zoo then loads it)
            study = optuna.create_study(study_name=self.study_name, storage=self.storage, direction="maximize")
        budget = study.user_attrs.get("n_timesteps")
        if budget is None:
            study.set_user_attr("n_timesteps", int(self.n_timesteps))
        elif int(budget) != int(self.n_timesteps):
            finished = len(study.get_trials(states=(optuna.trial.TrialState.COMPLETE,)))
            raise ZooConfigError(
                f"the Optuna study {self.study_name!r} ({self.storage}) was made with n_timesteps={budget} "
                f"({finished} finished trials); this run asks for {self.n_timesteps}, and trials of two budgets are not "
                "comparable: pass the same -n, or --study-name for a new study"
            )
