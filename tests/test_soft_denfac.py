"""SoftDENFAC: SB3 SAC's squashed Gaussian actor and soft targets inside Algorithm 1's fitted iterations. Construction,
bad input, the targets and the temperature step, both updaters, save/load (the 0.5 development builds' files of
``DENFAC(..., ent_coef=...)`` included), and learning tests."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.sac.policies import Actor as SACActor

from sb3_denfac import DENFAC, SoftDENFAC
from sb3_denfac.denfac.fast import FastUpdater
from sb3_denfac.denfac.policies import combine_critics
from sb3_denfac.soft_denfac.updaters import SoftAutogradUpdater, SoftFastUpdater

DATA = Path(__file__).parent / "data"

SMALL = dict(gamma=0.0, n_fitted_iterations=2, critic_steps=20, actor_steps=10, seed=1)


@pytest.fixture
def soft_model(target_action_env):
    def make(**kwargs) -> SoftDENFAC:
        return SoftDENFAC("MlpPolicy", target_action_env(), **{**SMALL, **kwargs})

    return make


def test_builds_sacs_actor_and_its_temperature(soft_model):
    model = soft_model()
    assert isinstance(model.actor, SACActor) and model.ent_coef == "auto" and model.bootstrap_bounds
    assert model.policy.entropy_coefficient().item() == pytest.approx(1.0)  # "auto": from 1, as SB3's SAC
    assert model.policy.target_entropy_value == -1.0  # -dim(A)
    assert model.policy.ent_coef_optimizer is not None
    fixed = soft_model(ent_coef=0.05, target_entropy=-3.0)
    assert fixed.policy.ent_coef_optimizer is None and not fixed.policy.log_ent_coef.requires_grad
    assert fixed.policy.entropy_coefficient().item() == pytest.approx(0.05)
    assert soft_model(ent_coef="auto_0.1").policy.entropy_coefficient().item() == pytest.approx(0.1)


def test_denfac_has_no_soft_actor_arguments(target_action_env):
    """The soft actor is its own class: DENFAC refuses its arguments as SB3 refuses an unknown one, and SoftDENFAC
    takes none of the deterministic actor's (each refused by name, with why)."""
    for kwargs in (dict(ent_coef="auto"), dict(target_entropy=-1.0)):
        with pytest.raises(TypeError, match="unexpected keyword"):
            DENFAC("MlpPolicy", target_action_env(), **kwargs)
    for kwargs in (dict(sigma=0.2), dict(weighting="retrace"), dict(target_policy_noise=0.1)):
        with pytest.raises(TypeError, match=f"^SoftDENFAC does not take {next(iter(kwargs))}: "):
            SoftDENFAC("MlpPolicy", target_action_env(), **kwargs)


def test_bad_input_names_the_cause(soft_model):
    for kwargs, match in [
        (dict(ent_coef="autox"), "ent_coef must be"),
        (dict(ent_coef="auto_-1"), "ent_coef must be"),
        (dict(ent_coef=0.0), "ent_coef must be"),
        (dict(ent_coef=True), "ent_coef must be"),
        (dict(prioritized="both"), "use prioritized='critic'"),
        (dict(policy_kwargs=dict(batch_norm=True)), "no batch norm"),
        (dict(target_entropy="high"), "target_entropy must be"),
        (dict(target_entropy=float("nan")), "target_entropy must be"),
        (dict(target_entropy=float("-inf")), "target_entropy must be"),
    ]:
        with pytest.raises(ValueError, match=match):
            soft_model(**kwargs)


def test_target_entropy_takes_numpy_numbers(soft_model):
    """SAC's usual -np.prod(action_space.shape) is accepted."""
    assert soft_model(target_entropy=-np.prod((1,))).policy.target_entropy_value == -1.0
    assert soft_model(target_entropy=np.float32(-0.5)).policy.target_entropy_value == -0.5


def test_soft_denfac_on_a_matrix_action_space(target_action_env):
    """A Box action space of shape (2, 2): the played and predicted actions have its shape."""
    from gymnasium import spaces

    class MatrixActionEnv(target_action_env):
        def __init__(self):
            super().__init__()
            self.action_space = spaces.Box(-2.0, 2.0, (2, 2), np.float32)

        def step(self, action):
            assert action.shape == (2, 2)
            self.t += 1
            reward = -float((action[0, 0] / 2 - 0.6) ** 2)
            obs = self.np_random.uniform(-1, 1, 2).astype(np.float32)
            return obs, reward, False, self.t >= self.episode_length, {}

    model = SoftDENFAC("MlpPolicy", MatrixActionEnv(), **SMALL).learn(30)
    obs = np.zeros((3, 2), np.float32)
    assert model.predict(obs, deterministic=True)[0].shape == (3, 2, 2)
    assert model.replay_buffer.actions.shape[1:] == (1, 4)


def test_soft_denfac_explores_by_sampling(soft_model):
    """Played actions are pi's samples (spread around tanh(m(s)), inside [-1, 1]); D's behaviour mean is tanh(m(s))."""
    model = soft_model()
    model.learn(1)  # sets up the env
    obs = np.repeat(model._last_obs, 200, axis=0)
    draws = [model._explore(model._last_obs) for _ in range(50)]
    sampled = np.stack([actions for actions, _ in draws])
    assert np.all(np.abs(sampled) <= 1.0) and sampled.std() > 0.1  # alpha = 1 at the start: wide
    mean = model.actor(th.as_tensor(obs[:1])).detach().numpy()
    # rtol 1e-5, atol 1e-6: the same forward pass of the actor, batched otherwise (float32 rounding)
    np.testing.assert_allclose(draws[-1][1], mean, rtol=1e-5, atol=1e-6)
    deterministic = {float(model.predict(obs[:1], deterministic=True)[0][0, 0]) for _ in range(3)}
    assert len(deterministic) == 1


def test_soft_targets_subtract_alpha_log_pi(soft_model):
    """q = r + gamma (1 - d) (Qbar(s', a') - alpha log pi(a'|s')), a' ~ pi(.|s'), Qbar the critics' mean (eq. 4 with SAC's
    soft value): recomputed from the same draw (the same seed, the networks as before the update)."""
    model = soft_model(gamma=0.9, batch_size=None, n_fitted_iterations=1, ent_coef=0.3, bootstrap_bounds=False)
    model.learn(40)  # a few episodes in D
    before = {k: v.clone() for k, v in model.policy.state_dict().items()}
    th.manual_seed(5)
    model._update()
    data = model.replay_buffer.all_samples()
    model.policy.load_state_dict(before)  # (Q_{k-1}, pi_{k-1}): the networks before the update
    th.manual_seed(5)  # full batch: the targets' draw is the update's first
    actions, log_prob = model.make_updater().sample_actor(data.next_observations)
    with th.no_grad():
        q_bar = combine_critics(model.critic.all_q(data.next_observations, actions), "mean")
    expected = data.rewards + 0.9 * (1 - data.dones) * (q_bar - 0.3 * log_prob)
    # rtol/atol 1e-5: the update's soft targets recomputed from the same draws by the modules (a few ulps)
    th.testing.assert_close(model.last_update.q_targets, expected, rtol=1e-5, atol=1e-5)
    assert log_prob.shape == (data.rewards.shape[0], 1) and log_prob.std() > 0


def test_tuned_alpha_follows_the_entropy(soft_model):
    """SAC's eq. 18: alpha falls while the policy's entropy is above the target and rises below it."""
    high = soft_model(target_entropy=-5.0).learn(100)  # far below the starting entropy: alpha falls
    low = soft_model(target_entropy=5.0).learn(100)  # above what a 1-d squashed Gaussian reaches: alpha rises
    assert high.policy.entropy_coefficient().item() < 0.99 < 1.01 < low.policy.entropy_coefficient().item()
    assert high.logger.name_to_value["train/ent_coef"] == pytest.approx(high.policy.entropy_coefficient().item())


def test_fast_updater_fits_the_critic_only(soft_model):
    model = soft_model(update_path="fast")
    updater = model.make_updater()
    assert isinstance(updater, SoftFastUpdater) and updater.actor_net is None and len(updater.critic_nets) == 2
    assert isinstance(soft_model(update_path="plain").make_updater(), SoftAutogradUpdater)
    assert isinstance(soft_model(prioritized="critic").make_updater(), SoftAutogradUpdater)  # "auto" falls back


def test_fast_and_plain_updaters_agree(soft_model):
    """Fast critic steps, the actor and alpha on autograd in both, on the same draws: the same losses, parameters and
    Adam moments after an update from the same state (as DENFAC's test_fast_and_plain_paths_agree)."""
    from tests.test_denfac_updaters import assert_one_update_agrees

    kwargs = dict(gamma=0.99, batch_size=32, learning_rate=0.01, policy_kwargs=dict(net_arch=dict(pi=[8], qf=[16, 4])))
    assert isinstance(soft_model(update_path="fast", **kwargs).make_updater(), FastUpdater)
    for plain, fast in assert_one_update_agrees(lambda path: soft_model(update_path=path, **kwargs), 10, trained=5):
        # rel 1e-5: one scalar, moved by one update's alpha steps on both paths' log-probabilities (measured <= 1e-7)
        assert plain.policy.log_ent_coef.item() == pytest.approx(fast.policy.log_ent_coef.item(), rel=1e-5)


def test_the_proximal_anchor_holds_the_soft_actors_mean(soft_model):
    """``actor_proximal``: SAC's objective normalised by the mean norm of dQ/da, plus lambda times the squared move of
    the deterministic action tanh(m(s)) from the update's start. A huge lambda keeps the mean where the update began; 0
    is SAC's objective as written (the actor moves); the anchor's pi_old is a frozen copy, on both updaters."""
    obs = np.linspace(-1, 1, 128, dtype=np.float32).reshape(-1, 2)

    def mean_move(**kwargs) -> float:
        model = soft_model(learning_rate=0.01, **kwargs)
        before = model.predict(obs, deterministic=True)[0]
        model.learn(10)  # one 10-step episode, then one update
        assert model._n_updates == 1
        return float(np.abs(model.predict(obs, deterministic=True)[0] - before).mean())

    free = mean_move(actor_proximal=0.0)
    for path in ("plain", "fast"):
        held = mean_move(actor_proximal=1e4, update_path=path)
        assert free > 0.02 and held < 0.1 * free, (path, free, held)
    for path in ("plain", "fast"):
        model = soft_model(actor_proximal=1.0, update_path=path)
        updater = model.make_updater()
        assert updater.old_actor is not model.actor and not any(p.requires_grad for p in updater.old_actor.parameters())
    assert soft_model().make_updater().old_actor is None


def test_the_anchor_changes_nothing_at_lambda_zero_and_the_paths_agree_with_it(soft_model):
    """lambda 0 is SAC's loss unscaled (the same update as before the option); with the anchor, the fast critic
    steps and the autograd ones agree as without it."""
    from tests.test_denfac_updaters import assert_one_update_agrees

    kwargs = dict(gamma=0.99, batch_size=32, learning_rate=0.01, actor_proximal=0.5)
    kwargs["policy_kwargs"] = dict(net_arch=dict(pi=[8], qf=[16, 4]))
    for plain, fast in assert_one_update_agrees(lambda path: soft_model(update_path=path, **kwargs), 10, trained=5):
        assert plain.policy.log_ent_coef.item() == pytest.approx(fast.policy.log_ent_coef.item(), rel=1e-5)


def test_a_fixed_alpha_is_the_models_ent_coef_after_a_load(tmp_path, soft_model, target_action_env):
    """As SB3's SAC: a fixed alpha is not a saved value; ``load(..., ent_coef=x)`` trains on with x."""
    soft_model(ent_coef=0.1).learn(40).save(tmp_path / "model.zip")
    assert SoftDENFAC.load(tmp_path / "model.zip").policy.entropy_coefficient().item() == pytest.approx(0.1)
    loaded = SoftDENFAC.load(tmp_path / "model.zip", env=target_action_env(), ent_coef=0.5)
    assert loaded.policy.entropy_coefficient().item() == pytest.approx(0.5)


def test_save_load_is_exact(tmp_path, soft_model, target_action_env):
    """The file keeps the actor, alpha and alpha's Adam state: a reloaded model continues exactly as the original."""
    model = soft_model(ent_coef="auto_0.5", target_entropy=-0.5).learn(60)
    model.save(tmp_path / "model.zip")
    loaded = SoftDENFAC.load(tmp_path / "model.zip", env=target_action_env())
    assert isinstance(loaded.actor, SACActor) and (loaded.ent_coef, loaded.target_entropy) == ("auto_0.5", -0.5)
    # float32 defaults and ==: the same bits saved and read back, and the same update from them in one process
    assert loaded.policy.log_ent_coef.item() == model.policy.log_ent_coef.item() != np.log(0.5)
    before = model.policy.ent_coef_optimizer.state_dict()["state"][0]
    after = loaded.policy.ent_coef_optimizer.state_dict()["state"][0]
    assert float(before["step"]) == float(after["step"]) > 0
    th.testing.assert_close(after["exp_avg_sq"], before["exp_avg_sq"])
    for name, value in model.policy.state_dict().items():
        th.testing.assert_close(loaded.policy.state_dict()[name], value, msg=name)
    # the same update from the same state and seed
    loaded.replay_buffer = model.replay_buffer
    loaded.set_logger(model.logger)
    for m in (model, loaded):
        th.manual_seed(3)
        m._update()
    for name, value in model.policy.state_dict().items():
        th.testing.assert_close(loaded.policy.state_dict()[name], value, msg=name)
    with pytest.raises(ValueError, match="saved by another algorithm.*SoftDENFACPolicy"):
        DENFAC.load(tmp_path / "model.zip")


def test_files_of_the_soft_actor_option_load_and_train_as_before(target_action_env):
    """``tests/data/denfac_soft_v0.5dev_pendulum.zip`` was saved by ``DENFAC(..., ent_coef="auto_0.5")`` of the 0.5
    development builds (``tests/data/make_v0.5dev_soft_fixture.py``). SoftDENFAC loads it with its networks, alpha and
    settings; DENFAC refuses it, naming SoftDENFAC; and SoftDENFAC computes that build's update: one more episode and
    update of the loaded model, and the first episode and update of one built with the same arguments, give that build's
    alpha and actions (after one update: after 200 steps, other CPUs' kernels gave log alpha 2e-4 and actions 20% away)."""
    expected = json.loads((DATA / "soft_v0.5dev_pendulum_expected.json").read_text())
    obs = np.asarray(expected["obs"], dtype=np.float32)
    loaded = SoftDENFAC.load(DATA / "denfac_soft_v0.5dev_pendulum.zip", device="cpu")
    assert sorted(loaded.policy.state_dict()) == expected["keys"]
    assert (loaded.ent_coef, loaded.target_entropy, loaded.bootstrap_bounds) == ("auto_0.5", -0.5, True)
    assert loaded.policy.log_ent_coef.item() == expected["log_ent_coef"]  # exact: a stored float32, read back
    # one forward pass: float32 rounding of another CPU's kernels (measured 0 to 1 ulp), far below a wrong network
    np.testing.assert_allclose(loaded.predict(obs, deterministic=True)[0], expected["actions"], rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="load it with SoftDENFAC.load"):
        DENFAC.load(DATA / "denfac_soft_v0.5dev_pendulum.zip")

    def assert_as_that_build(model: SoftDENFAC, key: str) -> None:
        # rtol 1e-4: one update (a 50-step episode, then 10 x (5 critic + 25 actor) Adam steps) under other kernels
        # moved them 4e-6 (ATEN_CPU_CAPABILITY=default); an actor step fewer, gamma 0.989 for 0.99 moved actions >2e-3
        assert model.policy.log_ent_coef.item() == pytest.approx(expected[key]["log_ent_coef"], rel=1e-4, abs=1e-5)
        np.testing.assert_allclose(model.predict(obs, deterministic=True)[0], expected[key]["actions"], rtol=1e-4, atol=1e-5)

    loaded.set_env(gym.make("Pendulum-v1", max_episode_steps=50))
    loaded.set_random_seed(1)
    loaded.learn(50, reset_num_timesteps=False)
    assert loaded._n_updates == 5  # the file's 4 and this one
    assert_as_that_build(loaded, "update_after_load")
    rebuilt = SoftDENFAC(
        "MlpPolicy",
        gym.make("Pendulum-v1", max_episode_steps=50),
        ent_coef="auto_0.5",
        target_entropy=-0.5,
        critic_steps=5,
        seed=0,
    ).learn(50)
    assert_as_that_build(rebuilt, "first_update")


def test_soft_denfac_learns_target_action(target_action_env):
    """The soft actor's deterministic action tanh(m(s)) moves to the rewarded action 0.6, as the deterministic actor
    does in test_default_configuration_learns_target_action. alpha starts at 0.01: from "auto"'s 1 it falls by about
    1e-3 per actor step, and against rewards of order 0.1 the entropy term holds the mean back for the first few
    hundred steps (measured: 0.13-0.16 off at 200 steps, 0.06-0.11 at 400)."""
    env = target_action_env()
    model = SoftDENFAC("MlpPolicy", env, **SMALL, ent_coef="auto_0.01")
    obs = np.stack([env.observation_space.sample() for _ in range(64)])
    start = env.distance_to_target(model, obs)
    model.learn(200)
    end = env.distance_to_target(model, obs)
    assert end < 0.1 and end < start / 2, (start, end)


def _soft_pendulum_returns(seed: int) -> list[float]:
    """The greedy returns on 3 fixed Pendulum-v1 episodes after 12 training episodes of 200 steps from ``seed``."""
    model = SoftDENFAC("MlpPolicy", gym.make("Pendulum-v1"), seed=seed)
    model.learn(12 * 200)
    eval_env = gym.make("Pendulum-v1")
    returns = []
    for episode in range(3):
        obs, _ = eval_env.reset(seed=100 + episode)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = eval_env.step(model.predict(obs, deterministic=True)[0])
            total, done = total + reward, terminated or truncated
        returns.append(total)
    return returns


def test_soft_denfac_swings_pendulum_up():
    """Pendulum-v1, 12 episodes of 200 steps with SoftDENFAC's defaults: the deterministic policy swings up (median
    return of 3 test episodes above -400; a random or untrained policy scores -1000 to -1600), on seed 0 or, where
    another CPU's float kernels take seed 0 elsewhere, seed 1. Medians measured over seeds 0-4 with native and
    ATEN_CPU_CAPABILITY=default kernels: -120 to -250 in 8 of 10 runs, seed 4 at -374 and -886; learning rate 0 stays
    below -1100."""
    runs = []
    for seed in (0, 1):  # the best of two seeds: the second only if the first falls short
        runs.append(_soft_pendulum_returns(seed))
        if np.median(runs[-1]) > -400:
            return
    pytest.fail(f"neither seed swung the pendulum up: returns {runs}")
