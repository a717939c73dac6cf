"""DENFAC's settings are checked in one place (``sb3_denfac.denfac.settings``), in step with the signature."""

from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import gymnasium as gym
import pytest

import sb3_denfac
from sb3_denfac import DENFAC, SoftDENFAC
from sb3_denfac.denfac import settings as settings_module
from sb3_denfac.denfac.settings import SETTINGS

#: Constructor arguments that are SB3's plumbing, not settings of the algorithm (checked by SB3 or where they are used).
PLUMBING = {
    "self",
    "policy",
    "env",
    "learning_starts",
    "replay_buffer_class",
    "replay_buffer_kwargs",
    "stats_window_size",
    "tensorboard_log",
    "policy_kwargs",
    "verbose",
    "seed",
    "device",
    "_init_setup_model",
}


def test_every_argument_is_a_checked_setting_or_sb3_plumbing():
    parameters = set(inspect.signature(DENFAC.__init__).parameters)
    assert parameters - PLUMBING == set(SETTINGS)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(reset_critic=1), "reset_critic must be True or False"),
        (dict(reset_actor="yes"), "reset_actor must be True or False"),
        (dict(inverting_gradients=None), "inverting_gradients must be True or False"),
        (dict(bootstrap_on_timeout=0), "bootstrap_on_timeout must be True or False"),
        (dict(max_grad_norm=-1.0), "max_grad_norm must be a number > 0 \\(or None\\)"),
        (dict(weighting="importance"), "weighting must be one of"),
        (dict(critic_target="max"), "critic_target must be one of"),
    ],
)
def test_settings_unchecked_before_are_refused_with_their_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DENFAC("MlpPolicy", gym.make("Pendulum-v1"), **kwargs)


def test_checked_values_are_stored_normalised():
    model = DENFAC("MlpPolicy", gym.make("Pendulum-v1"), prioritized="critic", max_grad_norm=None, critic_steps=5.0)
    assert (model.prioritized, model.priority_alpha, model.priority_beta, model.priority_eps) == ("critic", 0.6, 0.4, 1e-3)
    assert model.max_grad_norm is None
    assert model.critic_steps == 5 and isinstance(model.critic_steps, int)
    assert SoftDENFAC("MlpPolicy", gym.make("Pendulum-v1"), critic_steps=7.0).critic_steps == 7


def test_settings_the_others_make_meaningless_are_named_in_a_warning():
    """A value other than the default for a setting the others switch off is ignored: the constructor says so."""
    env = gym.make("Pendulum-v1")
    with pytest.warns(UserWarning, match=r"ignores critic_target='min': critic_target needs n_critics > 1"):
        DENFAC("MlpPolicy", env, critic_target="min", policy_kwargs=dict(n_critics=1))
    with pytest.warns(UserWarning, match=r"ignores target_noise_clip=0.3"):
        DENFAC("MlpPolicy", env, target_policy_noise=0.0, target_noise_clip=0.3)
    import warnings

    from sb3_denfac import presets

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for kwargs in ({}, presets.PAPER, presets.DENFAC_DATA_EFFICIENT, dict(prioritized=dict(on="critic", alpha=0.7))):
            DENFAC("MlpPolicy", env, **kwargs)
        SoftDENFAC("MlpPolicy", env, critic_target="min")
        SoftDENFAC("MlpPolicy", env, **presets.DATA_EFFICIENT)


def test_adam_settings_live_in_optimizer_kwargs():
    """Adam's betas and eps are SB3's ``policy_kwargs=dict(optimizer_kwargs=...)``, not DENFAC arguments; the paper's
    preset sets the authors' beta1 = 0 there, and files that saved them as DENFAC's ``adam_betas`` keep their values."""
    from pathlib import Path

    from sb3_denfac import presets

    env = gym.make("Pendulum-v1")
    with pytest.raises(TypeError, match="adam_betas"):
        DENFAC("MlpPolicy", env, adam_betas=(0.0, 0.999))
    for kwargs, betas in (({}, (0.9, 0.999)), (presets.PAPER, (0.0, 0.999))):
        model = DENFAC("MlpPolicy", env, **kwargs)
        assert all(net.optimizer.param_groups[0]["betas"] == betas for net in (model.actor, model.critic))
    old = DENFAC.load(Path(__file__).parent / "data" / "denfac_v0.1_pendulum.zip", device="cpu")  # saved adam_betas
    assert old.actor.optimizer.param_groups[0]["betas"] == (0.0, 0.999) and "adam_betas" not in vars(old)


def _imports(module: str, seen: set[str]) -> set[str]:
    """The package's modules that ``module``'s import statements reach, transitively (packages' ``__init__`` left
    out: ``sb3_denfac.denfac``'s imports the whole algorithm)."""
    path = Path(sb3_denfac.__file__).parent.joinpath(*module.split(".")[1:]).with_suffix(".py")
    for node in ast.walk(ast.parse(path.read_text())):
        names = [node.module] if isinstance(node, ast.ImportFrom) and node.module else []
        names += [alias.name for alias in node.names] if isinstance(node, ast.Import) else []
        for name in names:
            if (
                name.startswith("sb3_denfac.")
                and name not in seen
                and Path(sb3_denfac.__file__).parent.joinpath(*name.split(".")[1:]).with_suffix(".py").exists()
            ):
                seen.add(name)
                _imports(name, seen)
    return seen


def test_settings_module_does_not_import_the_update_kernels():
    """Checking a setting needs no updater: ``settings`` reaches neither ``update_paths`` nor the kernels."""
    reached = _imports("sb3_denfac.denfac.settings", set())
    kernels = {f"sb3_denfac.denfac.{name}" for name in ("update_paths", "fast", "eager_steps", "updaters")}
    assert not reached & kernels, sorted(reached)
    assert "sb3_denfac.denfac.options" in reached  # the walk follows the imports


def test_every_setting_is_stored_by_one_explicit_assignment():
    """A reader follows a setting from the signature to one line of settings.py (``m.<name> = check...``)."""
    source = inspect.getsource(settings_module.store_settings)
    stored = set(re.findall(r"\bm\.(\w+)\b(?=[\w., m]*=)", source))
    assert set(SETTINGS) - {"learning_rate", "buffer_size", "batch_size", "gamma", "prioritized"} <= stored
    for name in SETTINGS:
        if name not in ("learning_rate", "buffer_size", "batch_size", "gamma"):
            assert hasattr(DENFAC("MlpPolicy", gym.make("Pendulum-v1")), name)
            break


def test_soft_denfac_names_its_own_arguments_and_forwards_denfacs():
    """SoftDENFAC's signature is DENFAC's without the deterministic actor's settings it pins, plus its own; a pinned
    setting is refused by name with the reason, an unknown one with Python's TypeError naming SoftDENFAC."""
    denfac, soft = (set(inspect.signature(c.__init__).parameters) for c in (DENFAC, SoftDENFAC))
    assert soft == (denfac - set(SoftDENFAC.PINNED)) | {"ent_coef", "target_entropy"}
    assert inspect.signature(SoftDENFAC.__init__).parameters["bootstrap_bounds"].default is True  # its own default
    env = gym.make("Pendulum-v1")
    for name, value in (("sigma", 0.1), ("weighting", "retrace"), ("target_noise_clip", 0.3)):
        with pytest.raises(TypeError, match=f"^SoftDENFAC does not take {name}: "):
            SoftDENFAC("MlpPolicy", env, **{name: value})
    with pytest.raises(TypeError, match=r"SoftDENFAC.__init__\(\) got an unexpected keyword argument 'critic_step'"):
        SoftDENFAC("MlpPolicy", env, critic_step=3)
    model = SoftDENFAC("MlpPolicy", env, critic_steps=3, gamma=0.9, reset_every=500)
    assert (model.critic_steps, model.gamma, model.reset_every, model.weighting) == (3, 0.9, 500, "none")
