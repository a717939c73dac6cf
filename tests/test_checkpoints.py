"""TD7's policy checkpoints in the episodic base (``checkpoint_episodes``; :mod:`sb3_denfac.common.episodic`): which
actor is kept, when updates wait for an assessment, what plays ``predict``, and that it is saved."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch as th
from stable_baselines3.common.callbacks import BaseCallback

from sb3_denfac import DENFAC, SoftDENFAC

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
    plain, checkpointed = (
        {k: v for k, v in m.policy.state_dict().items() if not k.startswith("checkpoint_actor.")} for m in models
    )
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
