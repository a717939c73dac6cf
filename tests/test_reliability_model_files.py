"""Model files and resume: corrupted or foreign model zips and replay buffers are refused with a clear message, and
nothing is lost across a save and resume (SB3's checkpoint callback included)."""

from __future__ import annotations

import pathlib
import zipfile
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import SAC, TD3
from stable_baselines3.common.callbacks import CheckpointCallback


def test_foreign_model_check_mixin(tmp_path: pathlib.Path, checked_td3_class, make_checked_td3, make_env) -> None:
    SAC("MlpPolicy", make_env(), policy_kwargs=dict(net_arch=[4])).save(tmp_path / "sac.zip")
    with pytest.raises(ValueError, match="SACPolicy"):
        checked_td3_class.load(tmp_path / "sac")  # path without .zip, as SB3 allows
    make_checked_td3(make_env()).save(tmp_path / "td3.zip")
    with open(tmp_path / "td3.zip", "rb") as file:
        assert isinstance(checked_td3_class.load(file), checked_td3_class)  # file objects work too
    TD3("MlpPolicy", make_env(), policy_kwargs=dict(net_arch=[4])).save(tmp_path / "sb3_td3.zip")
    assert isinstance(checked_td3_class.load(tmp_path / "sb3_td3.zip"), checked_td3_class)  # same policy family


# ----- corrupted and foreign model files -------------------------------------------------------------------------------
def _corrupted_copies(model_zip: pathlib.Path) -> dict[str, pathlib.Path]:
    """Truncated, random-bytes, 'data'-less and bit-flipped copies of a model zip."""
    content = model_zip.read_bytes()
    paths = {kind: model_zip.with_name(f"{kind}.zip") for kind in ("truncated", "noise", "no_data", "bit_flip")}
    paths["truncated"].write_bytes(content[: len(content) // 2])
    paths["noise"].write_bytes(np.random.default_rng(0).bytes(1000))
    with zipfile.ZipFile(model_zip) as source, zipfile.ZipFile(paths["no_data"], "w") as target:
        for item in source.namelist():
            if item != "data":
                target.writestr(item, source.read(item))
    with zipfile.ZipFile(model_zip) as source:
        info = source.getinfo("data")
        offset = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra) + 2  # inside the entry's bytes
    flipped = bytearray(content)
    flipped[offset] ^= 0xFF
    paths["bit_flip"].write_bytes(bytes(flipped))
    return paths


CORRUPTIONS = ["truncated", "noise", "no_data", "bit_flip"]


@pytest.mark.parametrize("kind", CORRUPTIONS)
def test_model_file_check_mixin(tmp_path: pathlib.Path, kind: str, checked_td3_class, make_checked_td3, make_env) -> None:
    make_checked_td3(make_env()).save(tmp_path / "model.zip")
    path = _corrupted_copies(tmp_path / "model.zip")[kind]
    with pytest.raises(ValueError, match="truncated|corrupted|not a zip"):
        checked_td3_class.load(path)


@pytest.mark.algorithms("all")
def test_corrupted_zip(tmp_path: pathlib.Path, name: str, algo_class, make_model) -> None:
    """Truncated, random or damaged model files: a ValueError that says so (the truncated and 'data'-less cases need
    InputChecksMixin: SB3 itself only asserts "No data found in the saved file")."""
    cls = algo_class(name)
    make_model(name).save(tmp_path / "model.zip")
    for kind, path in _corrupted_copies(tmp_path / "model.zip").items():
        with pytest.raises(ValueError, match="truncated|corrupted|not a zip"):
            cls.load(path)
            pytest.fail(f"{kind} file loaded")


#: A zip of another algorithm with another policy class (NFAC and CACLA share theirs: their zips are interchangeable).
FOREIGN = {
    "denfac": "ddpg",
    "denfac_plain": "nfac",
    "soft_denfac": "denfac",  # a DENFACPolicy is not SoftDENFAC's, though SoftDENFAC is a DENFAC
    "ddpg": "nfac",
    "ddpg_ig": "cacla",
    "nfac": "denfac",
    "cacla": "cmaes",
    "cmaes": "cacla",
}


@pytest.mark.algorithms("all")
def test_foreign_zip(tmp_path: pathlib.Path, name: str, algo_class, make_env, make_model) -> None:
    """A zip saved by another algorithm is refused with a message naming its policy (needs InputChecksMixin)."""
    cls = algo_class(name)
    TD3("MlpPolicy", make_env(), policy_kwargs=dict(net_arch=[4])).save(tmp_path / "td3.zip")
    with pytest.raises(ValueError, match="TD3Policy"):
        cls.load(tmp_path / "td3.zip", env=make_env())
    other = FOREIGN[name]
    other_model = make_model(other)
    other_model.save(tmp_path / "other.zip")
    with pytest.raises(ValueError, match=type(other_model.policy).__name__):
        cls.load(tmp_path / "other.zip", env=make_env())


@pytest.mark.algorithms("off_policy")
def test_foreign_replay_buffer(tmp_path: pathlib.Path, name: str, episode_steps, make_model) -> None:
    """A replay buffer of another env (or, for DENFAC, of an algorithm without behaviour means) is refused clearly."""
    cartpole = gym.make("sb3_denfac/ContinuousCartPole-v0", max_episode_steps=episode_steps, episode_length=episode_steps)
    other = make_model(name, env=cartpole)
    other.learn(episode_steps)
    other.save_replay_buffer(tmp_path / "cartpole.pkl")
    model = make_model(name)
    model.load_replay_buffer(tmp_path / "cartpole.pkl")
    with pytest.raises(ValueError, match="does not fit"):
        model.learn(episode_steps)
    if "denfac" in name:
        ddpg = make_model("ddpg")
        ddpg.learn(episode_steps)
        ddpg.save_replay_buffer(tmp_path / "ddpg.pkl")
        model.load_replay_buffer(tmp_path / "ddpg.pkl")
        with pytest.raises(ValueError, match="needs a DENFACReplayBuffer"):
            model.learn(episode_steps)


# ----- nothing lost: save and resume ----------------------------------------------------------------------------------
def _saved_and_loaded(model: Any, folder: pathlib.Path, env: gym.Env, with_replay_buffer: bool) -> Any:
    """``model`` saved to ``folder`` (and its replay buffer) and loaded back on ``env``."""
    model.save(folder / "model.zip")
    if with_replay_buffer:
        model.save_replay_buffer(folder / "buffer.pkl")
    loaded = type(model).load(folder / "model.zip", env=env)
    if with_replay_buffer:
        loaded.load_replay_buffer(folder / "buffer.pkl")
    return loaded


@pytest.mark.algorithms("all")
def test_save_and_resume_loses_nothing(
    tmp_path: pathlib.Path, name: str, episode_steps, off_policy_names, make_env, make_model
) -> None:
    """learn; save (+ replay buffer); load; learn(reset_num_timesteps=False) ends where an uninterrupted run ends,
    with the same number of updates and episodes and, off-policy, the same buffer content up to the interruption."""
    half, total = 2 * episode_steps, 4 * episode_steps
    off_policy = name in off_policy_names
    uninterrupted = make_model(name, seed=1)
    uninterrupted.learn(total)

    interrupted = make_model(name, seed=1)
    interrupted.learn(half)
    resumed = _saved_and_loaded(interrupted, tmp_path, make_env(), with_replay_buffer=off_policy)
    resumed.learn(total - half, reset_num_timesteps=False)

    assert resumed.num_timesteps == uninterrupted.num_timesteps == total
    assert resumed._n_updates == uninterrupted._n_updates
    assert resumed._episode_num == uninterrupted._episode_num
    if off_policy:
        assert resumed.replay_buffer.size() == uninterrupted.replay_buffer.size() == total
        for key in ("observations", "actions", "rewards", "dones"):
            # exact: the same seed, code and kernels in one process repeat a run bit for bit
            np.testing.assert_array_equal(
                getattr(resumed.replay_buffer, key)[:half], getattr(uninterrupted.replay_buffer, key)[:half], err_msg=key
            )


@pytest.mark.algorithms("all")
def test_checkpoint_callback_resume(
    tmp_path: pathlib.Path, name: str, episode_steps, off_policy_names, algo_class, make_env, make_model
) -> None:
    """Resuming from a CheckpointCallback checkpoint reaches the uninterrupted run's number of timesteps.

    SB3 calls callbacks before storing the step's transition and before the end-of-rollout update, so such a checkpoint
    lacks the last transition (off-policy) or the last episode's update (episode-wise): only the count is compared.
    """
    total = 4 * episode_steps
    off_policy = name in off_policy_names
    checkpoint = CheckpointCallback(save_freq=2 * episode_steps, save_path=str(tmp_path), save_replay_buffer=off_policy)
    uninterrupted = make_model(name, seed=1)
    uninterrupted.learn(total, callback=checkpoint)

    resumed = algo_class(name).load(tmp_path / f"rl_model_{2 * episode_steps}_steps.zip", env=make_env())
    assert resumed.num_timesteps == 2 * episode_steps
    if off_policy:
        resumed.load_replay_buffer(tmp_path / f"rl_model_replay_buffer_{2 * episode_steps}_steps.pkl")
        assert resumed.replay_buffer.size() >= 2 * episode_steps - 1
    resumed.learn(total - resumed.num_timesteps, reset_num_timesteps=False)
    assert resumed.num_timesteps == uninterrupted.num_timesteps == total


@pytest.mark.algorithms("all")
def test_resume_is_exact(
    tmp_path: pathlib.Path,
    name: str,
    episode_steps,
    off_policy_names,
    assert_same_parameters,
    make_env,
    make_model,
) -> None:
    """Everything that training depends on is saved: from the same seed and a fresh env, a loaded copy (and its replay
    buffer) continues exactly as the original model (weights, optimizer states, batch-norm statistics, search state)."""
    off_policy = name in off_policy_names
    model = make_model(name, seed=2)
    model.learn(2 * episode_steps)
    loaded = _saved_and_loaded(model, tmp_path, make_env(), with_replay_buffer=off_policy)
    model.set_env(make_env(), force_reset=True)
    for copy in (model, loaded):
        copy.set_random_seed(7)
        copy.learn(2 * episode_steps, reset_num_timesteps=False)
    assert loaded.num_timesteps == model.num_timesteps == 4 * episode_steps
    # exact: the same seed, code and kernels in one process repeat a run bit for bit (the loaded copy too)
    assert_same_parameters(model.get_parameters(), loaded.get_parameters())
