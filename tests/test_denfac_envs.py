"""DENFAC with several envs (``n_envs > 1``) and the asynchronous update (``async_update=True``)."""

from __future__ import annotations

import copy
import threading
import time
import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

from sb3_denfac import DENFAC, SoftDENFAC
from sb3_denfac.common.callbacks import UpdateStatsCallback
from sb3_denfac.common.learner import THREAD_NAME, BackgroundLearner

#: K_e = ceil(rho n / critic_steps) = n, the episode's length: the updates say which episodes they were for
PER_STEP = dict(
    update_to_data_ratio=1.0,
    n_fitted_iterations=(1, None),
    critic_steps=1,
    actor_steps=1,
    batch_size=8,
    policy_kwargs=dict(net_arch=dict(pi=[4], qf=[4])),
)


def _two_lengths(first: int = 10, second: int = 15) -> DummyVecEnv:
    return DummyVecEnv([lambda n=n: gym.make("Pendulum-v1", max_episode_steps=n) for n in (first, second)])


def _learner_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith(THREAD_NAME)]


@pytest.mark.parametrize("async_update", [False, True])
def test_each_finished_episode_of_each_env_gets_its_own_update(async_update: bool) -> None:
    """Envs of 10- and 15-step episodes, 30 VecEnv steps: episodes end at steps 10, 15, 20 and 30 (both); with
    learning_starts=25 (num_timesteps counts both envs) the one at step 10 gets none, as with one env."""
    seen: list[int] = []
    model = DENFAC("MlpPolicy", _two_lengths(), learning_starts=25, seed=0, async_update=async_update, **PER_STEP)
    model.learn(60, callback=UpdateStatsCallback(lambda stats: seen.append(stats.fitted_iterations)))
    assert seen == [15, 10, 10, 15]  # one update each, K_e from its own episode's length; the two at step 30 back to back
    assert model._n_updates == 4 and [stats.n_updates for stats in model.last_updates] == [1, 2, 3, 4]  # 2 n_envs kept
    assert model.num_timesteps == 60 and model.replay_buffer.size() == 30  # 30 steps of each env
    assert not _learner_threads()


def test_a_budget_inside_episodes_updates_on_their_steps_so_far_and_continues_them() -> None:
    seen: list[int] = []
    callback = UpdateStatsCallback(lambda stats: seen.append(stats.fitted_iterations))
    model = DENFAC("MlpPolicy", _two_lengths(), seed=0, **PER_STEP).learn(14, callback=callback)  # 7 steps of each
    assert seen == [7, 7]
    # 5 more steps each: env 0's episode ends at its 10th step (3 since the budget), then the budget again (2 and 5)
    model.learn(10, callback=callback, reset_num_timesteps=False)
    assert seen == [7, 7, 3, 2, 5]


def test_subprocess_envs_train_save_and_load(tmp_path) -> None:
    env = make_vec_env("Pendulum-v1", n_envs=2, seed=0, vec_env_cls=SubprocVecEnv, env_kwargs=dict(max_episode_steps=20))
    try:
        model = DENFAC("MlpPolicy", env, seed=0, **PER_STEP).learn(80)
        assert model._n_updates == 4 and model.replay_buffer.size() == 40
        model.save(tmp_path / "model.zip")
        loaded = DENFAC.load(tmp_path / "model.zip", env=env)
        obs = env.reset()
        # exact: the same bits saved and read back, evaluated by the same kernels in one process
        np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])
        loaded.learn(40, reset_num_timesteps=False)  # goes on from the file with the same envs
        assert loaded._n_updates == 6
    finally:
        env.close()


def test_async_update_plays_the_last_published_policy_and_leaves_no_thread() -> None:
    played: dict[int, list] = {}  # policy object -> its parameters at every step it played

    class Watch(BaseCallback):
        def _on_step(self) -> bool:
            policy = self.model.policy
            played.setdefault(id(policy), [policy]).append(th.cat([p.detach().flatten().clone() for p in policy.parameters()]))
            return True

    model = DENFAC("MlpPolicy", gym.make("Pendulum-v1", max_episode_steps=20), seed=0, async_update=True, **PER_STEP)
    first = model.policy
    model.learn(100, callback=Watch())
    assert model._n_updates == 5 and model.last_update is not None and model.last_update.fitted_iterations == 20
    assert model.policy is not first and id(first) in played  # each update's copy became the model's policy
    assert len(played) >= 2  # (fits slower than an episode are published at the next episode end, then played)
    for _, *parameters in played.values():  # a policy that plays is never written: the learner fits a copy
        # exact: a published policy must never be written
        assert all(th.equal(parameters[0], p) for p in parameters[1:])
    assert not _learner_threads()
    assert model.async_update is True


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_async_update_keeps_the_running_update_on_an_exception(error: type[BaseException]) -> None:
    class Stop(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps == 21:  # the step after the first episode's end: its update is running
                raise error("stop")
            return True

    model = DENFAC("MlpPolicy", gym.make("Pendulum-v1", max_episode_steps=20), seed=0, async_update=True, **PER_STEP)
    with pytest.raises(error):
        model.learn(200, callback=Stop())
    assert model._n_updates == 1  # the update in flight was waited for and kept
    assert not _learner_threads()


def test_async_update_save_during_learn_loads(tmp_path) -> None:
    env = gym.make("Pendulum-v1", max_episode_steps=20)
    model = DENFAC("MlpPolicy", env, seed=0, async_update=True, **PER_STEP)
    model.learn(85, callback=CheckpointCallback(save_freq=21, save_path=str(tmp_path)))  # a step after each episode end
    files = sorted(tmp_path.glob("*.zip"))
    assert len(files) == 4
    loaded = DENFAC.load(files[-1], env=env)
    assert loaded.async_update is True
    loaded.learn(20)
    assert not _learner_threads()


def test_async_update_plays_its_snapshots_between_fitted_iterations() -> None:
    """An update that outlasts its episode publishes its progress: after each fitted iteration the learner offers a
    copy of the policy fitted so far, and the next env step plays it (model.policy changes without a recorded update).
    Before the snapshots, the policy from before the running update played until it ended."""
    changes: list[tuple[int, int]] = []  # (updates recorded before, after) at each step whose policy is new

    class Slow(BaseCallback):  # 5 ms per env step while an update runs: the update (20 iterations) spans many steps
        last: tuple[int, int] | None = None

        def _on_step(self) -> bool:
            learner = self.model._learner
            if learner is not None and learner.busy:
                time.sleep(0.005)
            now = (id(self.model.policy), self.model._n_updates)
            if self.last is not None and now[0] != self.last[0]:
                changes.append((self.last[1], now[1]))
            self.last = now
            return True

    model = DENFAC("MlpPolicy", gym.make("Pendulum-v1", max_episode_steps=20), seed=0, async_update=True, **PER_STEP)
    model.learn(100, callback=Slow())
    assert model._n_updates == 5  # every episode still gets its update, counted once, when it ends
    snapshots = [change for change in changes if change[0] == change[1]]
    assert snapshots, f"no snapshot played between fitted iterations: {changes}"
    assert not _learner_threads()


def test_async_job_ends_at_the_fitted_iteration_after_the_next_episodes_end() -> None:
    """A job of 3 updates of 5 fitted iterations on the learner thread (what 3 envs whose episodes end together hand it).
    The end is requested during the second update's second iteration: that update ends there and the third is dropped
    (common/episodic.py); the first update always runs whole. Requested from inside the job, so that the timing does not
    depend on the machine; without a request the job runs whole."""
    env = DummyVecEnv([lambda: gym.make("Pendulum-v1", max_episode_steps=5) for _ in range(3)])
    model = DENFAC("MlpPolicy", env, seed=0, **PER_STEP)
    model.learn(15)  # D: 3 episodes, in place
    data = model.replay_buffer.all_samples()

    def job_iterations(end_at: int | None) -> list[int]:
        learner, offers = BackgroundLearner(), []
        offer = model._offer_snapshot

        def offer_and_maybe_request_end(policy, flush=None):  # type: ignore[no-untyped-def]
            offers.append(1)
            if len(offers) == end_at:
                learner.request_end()  # what _run_updates does when the next episodes end
            offer(policy, flush)

        model._learner, model._offer_snapshot = learner, offer_and_maybe_request_end  # type: ignore[method-assign]
        try:
            learner.submit(model._fit_all, copy.deepcopy(model.policy), data, [5, 5, 5], False)
            return [fit.fitted_iterations for fit in learner.result()]
        finally:
            learner.close()
            model._learner, model._offer_snapshot = None, offer  # type: ignore[method-assign]

    assert job_iterations(end_at=7) == [5, 2]
    assert job_iterations(end_at=2) == [5]  # requested inside the first update: it runs whole, the rest is dropped
    assert job_iterations(end_at=None) == [5, 5, 5]


def test_async_episode_end_asks_the_running_job_to_end() -> None:
    """_run_updates asks a busy learner's job to end before waiting for it; an idle learner gets no request."""

    class Learner:
        def __init__(self, busy: bool) -> None:
            self.busy, self.calls = busy, []

        def request_end(self) -> None:
            self.calls.append("request_end")

        def ready(self) -> bool:
            return False

        def submit(self, *args) -> None:  # type: ignore[no-untyped-def]
            self.calls.append("submit")

        def take_offer(self) -> None:
            return None

    model = DENFAC("MlpPolicy", gym.make("Pendulum-v1", max_episode_steps=5), seed=0, **PER_STEP)
    model.learn(5)
    model._budget = 10**6
    for busy, calls in ((True, ["request_end", "submit"]), (False, ["submit"])):
        learner = Learner(busy)
        model._learner = learner  # type: ignore[assignment]
        model._publish = lambda wait: None  # type: ignore[method-assign]
        model._run_updates([1], False)
        assert learner.calls == calls
    model._learner = None


def test_async_update_with_more_than_two_envs_warns_once_and_says_why() -> None:
    """With 4 envs on Reacher-v5 the asynchronous update lost 1 seed of 3 even with its bound (research/several_envs)."""
    env = DummyVecEnv([lambda: gym.make("Pendulum-v1", max_episode_steps=5) for _ in range(3)])
    model = DENFAC("MlpPolicy", env, seed=0, async_update=True, **PER_STEP)
    with pytest.warns(UserWarning, match=r"async_update=True with 3 envs.*in one job.*action bounds"):
        model.learn(15)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.learn(15)  # once per model
        DENFAC("MlpPolicy", _two_lengths(), seed=0, async_update=True, **PER_STEP).learn(30)  # 2 envs: held
    assert not _learner_threads()


def test_background_learner_passes_an_end_request_to_the_running_job_only() -> None:
    learner = BackgroundLearner()
    try:
        started, release = threading.Event(), threading.Event()
        seen: list[bool] = []

        def job() -> None:
            started.set()
            release.wait(5)
            seen.append(learner.end_requested())

        learner.submit(job)
        started.wait(5)
        learner.request_end()
        release.set()
        learner.result()
        learner.submit(lambda: seen.append(learner.end_requested()))  # a new job starts without the request
        learner.result()
        assert seen == [True, False]
    finally:
        learner.close()


def test_offer_snapshot_outside_an_asynchronous_update_does_nothing() -> None:
    """The update in place (the synchronous path) offers nothing and calls no flush: its arithmetic is unchanged."""
    model = DENFAC("MlpPolicy", gym.make("Pendulum-v1", max_episode_steps=20), seed=0, **PER_STEP)
    flushed: list[int] = []
    model._offer_snapshot(model.policy, lambda: flushed.append(1))
    assert flushed == [] and model._learner is None


def test_background_learner_hands_over_the_newest_snapshot_and_drops_it_with_the_result() -> None:
    learner = BackgroundLearner()
    try:
        started, release = threading.Event(), threading.Event()
        inside: list[bool] = []

        def job() -> str:
            inside.append(learner.inside_job())
            learner.offer("first")
            learner.offer("second")  # replaces the one not taken
            started.set()
            release.wait(5)
            learner.offer("third")
            return "done"

        learner.submit(job)
        assert started.wait(5) and not learner.inside_job()  # the caller is not the learner thread
        assert learner.take_offer() == "second" and learner.take_offer() is None
        release.set()
        assert learner.result() == "done" and learner.take_offer() is None  # the result supersedes "third"
        assert inside == [True]
    finally:
        learner.close()


def _async_pendulum_run(algo, seed: int, episodes: int) -> tuple[float, float]:
    """The greedy return on 5 fixed episodes before and after ``episodes`` episodes of Pendulum-v1 on 4 envs in
    subprocesses, with an asynchronous update after each env's episode. The episodes last 200, 197, 194 and 191 steps,
    so that they seldom end at the same step: every episode gets its update whatever the machine's speed (episodes
    that end together may lose their updates past the first to the next episodes' end, which the test above checks)."""
    lengths = (200, 197, 194, 191)
    env = SubprocVecEnv([lambda n=n: gym.make("Pendulum-v1", max_episode_steps=n) for n in lengths])  # seeded by DENFAC
    try:
        model = algo("MlpPolicy", env, seed=seed, async_update=True)
        before, _ = evaluate_policy(model, make_vec_env("Pendulum-v1", n_envs=1, seed=100), n_eval_episodes=5)
        model.learn(episodes * 200)
        after, _ = evaluate_policy(model, make_vec_env("Pendulum-v1", n_envs=1, seed=100), n_eval_episodes=5)
    finally:
        env.close()
    assert model._n_updates >= episodes  # every episode its update (the budget ends the unfinished ones)
    return before, after


@pytest.mark.parametrize("algo, episodes", [(DENFAC, 32), (SoftDENFAC, 24)])
def test_several_envs_with_async_update_learn_pendulum(algo, episodes) -> None:
    """4 envs in subprocesses, an asynchronous update after each env's episode: 32 (SoftDENFAC: 24) episodes of
    Pendulum-v1 lift the greedy return far above the untrained policy's (about -1200), on seed 0 or, where another
    CPU's float kernels or the learner thread's timing take seed 0 elsewhere, on seed 1.

    Measured over seeds 0-9 with native and ATEN_CPU_CAPABILITY=default kernels, DENFAC: after 24 episodes 5 of 20 runs
    stayed below -600 (-970 to -1430), after 32 episodes 2 of 20 (seed 5: -900, -1050), the others -150 to -490;
    seeds 0 and 1 at -150 to -200 in all. SoftDENFAC over seeds 0-4: -140 to -195 after 24 episodes in 10 of 10.
    A learning rate of 0 keeps the untrained policy's return."""
    runs = []
    for seed in (0, 1):  # the best of two seeds: the second only if the first falls short
        before, after = _async_pendulum_run(algo, seed, episodes)
        runs.append((before, after))
        if after > -600 and after > before + 400:
            return
    pytest.fail(f"neither seed lifted the greedy return above -600: (before, after) = {runs}")
