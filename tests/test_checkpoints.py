"""TD7's policy checkpoints in the episodic base (``checkpoint_episodes``; :mod:`sb3_denfac.common.checkpoints`): which
actor is kept, when updates wait for an assessment, what plays ``predict``, and that it is saved."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.callbacks import BaseCallback

from sb3_denfac import DENFAC, SoftDENFAC
from sb3_denfac.common.checkpoints import Assessment

# a small update: these tests check the bookkeeping, not learning
SMALL = dict(batch_size=64, n_fitted_iterations=2, critic_steps=5, actor_steps=5, seed=0)


class EpisodeEnds(BaseCallback):
    """At each episode end (before the update after it): the return, the policy version, and the actor's weights."""

    def __init__(self) -> None:
        super().__init__()
        self.ends: list[dict[str, Any]] = []

    def _on_step(self) -> bool:
        for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
            if done:
                actor = {k: v.clone() for k, v in self.model.policy.actor.state_dict().items()}
                version = self.model._policy_version
                self.ends.append({"return": float(info["episode"]["r"]), "version": version, "actor": actor})
        return True


def same_weights(a: dict[str, th.Tensor], b: dict[str, th.Tensor]) -> bool:
    return a.keys() == b.keys() and all(th.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("algo", [DENFAC, SoftDENFAC])
def test_one_episode_keeps_the_actor_of_the_best_episode(algo: type[DENFAC]) -> None:
    """n = 1, one env: every episode assesses its actor; the kept actor is the one that played the best episode so far
    (the last of equals), its return the model's ``checkpoint_return``; the deterministic prediction is its action."""
    model = algo("MlpPolicy", "Pendulum-v1", checkpoint_episodes=1, **SMALL)
    ends = EpisodeEnds()
    model.learn(2000, callback=ends)
    returns = [e["return"] for e in ends.ends]
    assert len(returns) == 10
    assert len({e["version"] for e in ends.ends}) == 10  # an update after each episode: nothing waits with n = 1
    best = max(range(len(returns)), key=lambda i: (returns[i], i))
    assert model.checkpoint_return == pytest.approx(returns[best], abs=1e-3)  # Monitor rounds to 6 digits
    assert model.policy.checkpoint_actor is not None
    assert same_weights(model.policy.checkpoint_actor.state_dict(), ends.ends[best]["actor"])
    if best < len(returns) - 1:  # the actor moved on: the prediction is the kept actor's, not the last one's
        assert not same_weights(model.policy.actor.state_dict(), ends.ends[best]["actor"])
    obs = model.env.reset()
    with th.no_grad():
        kept = model.policy.checkpoint_actor(th.as_tensor(obs))
    np.testing.assert_allclose(
        model.policy.scale_action(model.predict(obs, deterministic=True)[0]), th.clamp(kept, -1, 1), atol=1e-6
    )


@pytest.mark.parametrize("algo", [DENFAC, SoftDENFAC])
def test_one_episode_leaves_training_as_it_was(algo: type[DENFAC]) -> None:
    """n = 1 changes what ``predict(deterministic=True)`` plays, not what is trained: from one seed, the same actor and
    critic as without checkpoints (a run with them pairs with one without)."""
    models = [algo("MlpPolicy", "Pendulum-v1", checkpoint_episodes=n, **SMALL).learn(1000) for n in (0, 1)]
    plain, checkpointed = ({k: v for k, v in m.policy.state_dict().items() if not k.startswith("checkpoint_")} for m in models)
    assert same_weights(plain, checkpointed)


def test_several_episodes_assess_an_actor_by_their_minimum() -> None:
    """n = 2: an actor plays two episodes before its update (one, if the first falls below the best so far); the kept
    value is the best minimum over the actors that played both."""
    model = DENFAC("MlpPolicy", "Pendulum-v1", checkpoint_episodes=2, **SMALL)
    ends = EpisodeEnds()
    model.learn(3000, callback=ends)
    by_version: dict[int, list[float]] = {}
    for e in ends.ends:
        by_version.setdefault(e["version"], []).append(e["return"])
    assert all(1 <= len(r) <= 2 for r in by_version.values())
    assert any(len(r) == 2 for r in by_version.values())
    assert model._n_updates == len(ends.ends)  # the waiting updates ran after the assessment, one per episode
    best = -np.inf
    assessments = list(by_version.values())
    for returns in assessments[:-1]:  # the last actor's assessment may be cut by the budget
        if len(returns) == 1:
            assert returns[0] < best  # ended early: below the best so far
        else:
            best = max(best, min(returns))
    if len(assessments[-1]) == 2:
        best = max(best, min(assessments[-1]))
    assert model.checkpoint_return == pytest.approx(best, abs=1e-3)


def test_warm_up_episodes_do_not_assess() -> None:
    """The uniform actions before ``learning_starts`` are not the actor's: the episodes with any are not assessed."""
    model = DENFAC("MlpPolicy", "Pendulum-v1", checkpoint_episodes=1, learning_starts=300, **SMALL)
    ends = EpisodeEnds()
    model.learn(800, callback=ends)  # episodes 0-199, 200-399 (warm-up in both), 400-599, 600-799
    returns = [e["return"] for e in ends.ends]
    assert model.checkpoint_return == pytest.approx(max(returns[2:]), abs=1e-3)


def test_checkpoints_save_and_reload_exactly(tmp_path: Any) -> None:
    model = SoftDENFAC("MlpPolicy", "Pendulum-v1", checkpoint_episodes=1, **SMALL)
    model.learn(1000)
    model.save(tmp_path / "model")
    loaded = SoftDENFAC.load(tmp_path / "model")
    assert loaded.checkpoint_episodes == 1 and loaded.checkpoint_return == model.checkpoint_return
    assert loaded.policy.checkpoint_actor is not None and model.policy.checkpoint_actor is not None
    assert same_weights(loaded.policy.checkpoint_actor.state_dict(), model.policy.checkpoint_actor.state_dict())
    obs = np.random.default_rng(0).uniform(-1, 1, (5, 3)).astype(np.float32)
    np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0])


def test_without_checkpoints_the_current_actor_plays() -> None:
    model = DENFAC("MlpPolicy", "Pendulum-v1", **SMALL)
    model.learn(400)
    assert model.policy.checkpoint_actor is None and model.checkpoint_return is None
    obs = np.zeros((1, 3), dtype=np.float32)
    with th.no_grad():
        current = th.clamp(model.policy.actor(th.as_tensor(obs)), -1, 1).numpy()
    np.testing.assert_allclose(model.policy.scale_action(model.predict(obs, deterministic=True)[0]), current, atol=1e-6)


def test_checkpoints_refuse_the_asynchronous_update() -> None:
    with pytest.raises(ValueError, match="async_update"):
        DENFAC("MlpPolicy", "Pendulum-v1", checkpoint_episodes=1, async_update=True)
    with pytest.raises(ValueError, match="checkpoint_episodes"):
        DENFAC("MlpPolicy", "Pendulum-v1", checkpoint_episodes=-1)


def shifted_pendulum(n_envs: int = 1, normalize: bool = False) -> Any:
    """Pendulum-v1 with 20 added to every reward (positive returns: a return added twice would be kept), in Monitors."""
    from gymnasium.wrappers import TransformReward
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    env = make_vec_env(lambda: TransformReward(gym.make("Pendulum-v1"), lambda r: r + 20.0), n_envs, seed=0)
    return VecNormalize(env, norm_obs=False) if normalize else env


def test_a_stopping_callback_and_a_cut_episode_do_not_mix_returns() -> None:
    """Stopped by a callback at an episode's end, then cut by the budget inside one, the run goes on: the kept value is
    one episode's return, never two added together."""
    from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes

    model = DENFAC("MlpPolicy", shifted_pendulum(), checkpoint_episodes=1, **SMALL)
    ends = EpisodeEnds()
    model.learn(10_000, callback=[StopTrainingOnMaxEpisodes(2), ends])
    model.learn(500, reset_num_timesteps=False, callback=ends)  # episodes end at 600 and 800 steps; cut at 900...
    model.learn(300, reset_num_timesteps=False, callback=ends)  # ...it ends at 1000, and one more at 1200
    returns = [e["return"] for e in ends.ends]
    assert len(returns) == 6 and min(returns) > 0
    assert model.checkpoint_return == pytest.approx(max(returns), abs=1e-3)


def test_updates_held_by_an_assessment_are_not_lost_when_a_callback_stops() -> None:
    from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes

    model = DENFAC("MlpPolicy", "Pendulum-v1", checkpoint_episodes=3, **SMALL)
    model.learn(10_000, callback=StopTrainingOnMaxEpisodes(2))  # two episodes of one actor's assessment: held
    assert model._n_updates == 0
    # a new learn: the first episode's held update runs with the next episode's (the callback stopped at the second
    # episode's last step, which, as in SB3, is not stored, and gets no update)
    model.learn(200)
    assert model._n_updates == 2


def test_several_envs_assess_the_first_whole_episode_on_the_env_scale() -> None:
    """Two envs whose episodes end together, rewards normalised by ``VecNormalize``: each actor is assessed once, on
    env 0's episode (the first to end), with the env's own rewards."""
    model = DENFAC("MlpPolicy", shifted_pendulum(2, normalize=True), checkpoint_episodes=1, **SMALL)
    ends = EpisodeEnds()
    model.learn(2000, callback=ends)
    first_env = [e["return"] for e in ends.ends[::2]]  # both envs end at the same steps, env 0 first
    assert model.checkpoint_return == pytest.approx(max(first_env), abs=1e-3)


def test_set_parameters_brings_the_kept_actor_and_its_value() -> None:
    """The kept actor's value is saved with it: another model's parameters bring both, and start a new actor."""
    a, b = (DENFAC("MlpPolicy", "Pendulum-v1", checkpoint_episodes=1, **{**SMALL, "seed": s}).learn(600) for s in (0, 1))
    version = a._policy_version
    a.set_parameters(b.get_parameters())
    assert a.checkpoint_return == b.checkpoint_return and a._policy_version > version
    assert a.policy.checkpoint_actor is not None and b.policy.checkpoint_actor is not None
    assert same_weights(a.policy.checkpoint_actor.state_dict(), b.policy.checkpoint_actor.state_dict())


def test_load_may_turn_checkpoints_on_or_off(tmp_path: Any) -> None:
    plain = DENFAC("MlpPolicy", "Pendulum-v1", **SMALL).learn(400)
    plain.save(tmp_path / "plain")
    on = DENFAC.load(tmp_path / "plain", checkpoint_episodes=1)  # the kept actor starts as the actor, with no value
    assert on.checkpoint_return is None and on.policy.checkpoint_actor is not None
    assert same_weights(on.policy.checkpoint_actor.state_dict(), on.policy.actor.state_dict())
    with_checkpoints = DENFAC("MlpPolicy", "Pendulum-v1", checkpoint_episodes=1, **SMALL).learn(400)
    with_checkpoints.save(tmp_path / "kept")
    off = DENFAC.load(tmp_path / "kept", checkpoint_episodes=0)
    assert off.policy.checkpoint_actor is None and off.checkpoint_return is None
    with pytest.raises(ValueError, match="async_update"):
        DENFAC.load(tmp_path / "kept", async_update=True)


def test_an_episode_with_an_update_inside_assesses_nothing() -> None:
    """Two envs whose episodes (200 and 150 steps) end at different steps: up to step 500 every episode but env 1's
    first has another env's end, and so an update, inside it; it alone is one actor's, and assesses it."""
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv

    env = DummyVecEnv(
        [lambda: Monitor(gym.make("Pendulum-v1")), lambda: Monitor(gym.make("Pendulum-v1", max_episode_steps=150))]
    )
    model = DENFAC("MlpPolicy", env, checkpoint_episodes=1, **SMALL)
    assessed: list[float] = []

    class Recording(Assessment):
        def _take(self, episode_return: float, *args: Any) -> float | None:
            assessed.append(episode_return)
            return super()._take(episode_return, *args)

    model._assessment = Recording(1)
    model.learn(1000)  # 500 steps of each env: 5 episode ends, then the budget's 2 cut episodes, one update each
    assert model._n_updates == 7
    assert assessed == [pytest.approx(model.ep_info_buffer[0]["r"], abs=1e-3)]  # env 1's first episode, steps 0-150
    # to step 800: both end at 600 with the budget's update (at 500) inside; env 1's episode 600-750 is one actor's
    model.learn(600, reset_num_timesteps=False)
    assert len(assessed) == 2


def test_assessment_books() -> None:
    """:class:`Assessment` alone (n = 2): an actor's whole episodes, the minimum kept if at least the best, an early
    end below the best, one value per actor, warm-up and episodes begun under another version."""
    done, going = np.array([True, True]), np.array([False, False])
    books = Assessment(2)
    assert books.step(np.array([1.0, 2.0]), going, True, 0, None) is None  # warm-up spoils both running episodes
    assert books.step(np.array([1.0, 2.0]), done, False, 0, None) is None and not books.going_on(0)
    books.step(np.array([5.0, 3.0]), going, False, 1, None)
    assert books.step(np.array([1.0, 1.0]), done, False, 1, None) == 4.0  # both envs end: min(6, 4)
    assert not books.going_on(1)
    books.step(np.array([9.0, 9.0]), done, False, 1, 4.0)  # actor 1's assessment has ended: not read again
    assert books._version == 1 and books._assessed is None
    assert books.step(np.array([5.0, 0.0]), np.array([True, False]), False, 2, 4.0) is None and books.going_on(2)
    assert books.step(np.array([0.0, 3.0]), np.array([False, True]), False, 2, 4.0) is None  # 3 < 4: ends early
    assert not books.going_on(2)
    books.new_episodes()  # the envs reset: the running episodes are dropped, versions start anew
    books.step(np.array([7.0, 0.0]), np.array([True, False]), False, 3, 4.0)
    assert books.going_on(3)
    assert books.step(np.array([0.0, 8.0]), np.array([False, True]), False, 3, 4.0) == 7.0


@pytest.mark.parametrize(("algo", "name"), [(DENFAC, "denfac"), (SoftDENFAC, "soft_denfac")])
def test_the_kept_return_is_logged(algo: type[DENFAC], name: str) -> None:
    """With checkpoints the algorithm writes ``train/best_return`` (the kept actor's value) beside its usual keys."""
    from stable_baselines3.common.logger import KVWriter, Logger

    from sb3_denfac.common.logging_keys import WITH_AN_OPTION, WRITTEN_BY

    class Values(KVWriter):
        def __init__(self) -> None:
            self.dumps: list[dict[str, Any]] = []

        def write(self, key_values: dict, key_excluded: dict, step: int = 0) -> None:
            self.dumps.append(dict(key_values))

    values = Values()
    model = algo("MlpPolicy", "Pendulum-v1", checkpoint_episodes=1, **SMALL)
    model.set_logger(Logger(folder=None, output_formats=[values]))
    model.learn(1000, log_interval=1)
    written = {key for dump in values.dumps for key in dump if key.startswith("train/")}
    assert WITH_AN_OPTION["train/best_return"][0] == "checkpoint_episodes"
    assert written == {*WRITTEN_BY[name], "train/best_return"}
    assert values.dumps[-1]["train/best_return"] == pytest.approx(model.checkpoint_return)
    logged = [dump["train/best_return"] for dump in values.dumps if "train/best_return" in dump]
    assert len(logged) >= 4 and logged == sorted(logged)  # at each episode's end, the best so far


def test_updates_held_by_an_assessment_are_each_reported() -> None:
    """n = 3: an assessment's held updates run back to back; ``last_updates`` keeps them all, so the statistics callback
    and the benchmark's count of critic gradient steps see every one."""
    from benchmarks.runner.task import GradientSteps
    from sb3_denfac.common.callbacks import UpdateStatsCallback
    from sb3_denfac.denfac.options import fitted_iterations

    model = DENFAC("MlpPolicy", "Pendulum-v1", checkpoint_episodes=3, update_to_data_ratio=0.1, **SMALL)
    seen: list[Any] = []
    steps = GradientSteps()
    groups: list[int] = []  # updates run since the last rollout, at each rollout's start

    class Groups(BaseCallback):
        def _on_rollout_start(self) -> None:
            groups.append(self.model._n_updates - sum(groups))

        def _on_step(self) -> bool:
            return True

    model.learn(3000, callback=[UpdateStatsCallback(seen.append), steps, Groups()])
    assert max(groups) == 3  # an assessment held two episodes' updates: three ran back to back
    assert model._n_updates == 15 and [s.n_updates for s in seen] == list(range(1, 16))
    k = fitted_iterations(model.n_fitted_iterations, model.critic_steps, model.update_to_data_ratio, 200)
    assert steps.total() == 15 * k * model.critic_steps
