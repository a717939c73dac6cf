"""DENFAC's update on a real replay buffer computes no subnormal float (they cost many times the normal arithmetic).

The buffer is filled by real Acrobot episodes of uniform warm-up actions: most of them lie far from the actor's mean,
so their density ratios are far below float32's normal range, which is where subnormals used to enter the update.
"""

from __future__ import annotations

import gymnasium as gym
import pytest
import torch as th
from stable_baselines3.common.logger import configure
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_flatten

from sb3_denfac import DENFAC
from sb3_denfac.denfac.presets import paper

TINY = float(th.finfo(th.float32).tiny)


class SubnormalCounter(TorchDispatchMode):
    """Counts the ops that read or compute float32 subnormal numbers: any tensor among an op's arguments (read, or
    written in place) or results, checked after the op. Views and ``empty`` allocations are no arithmetic (their
    memory may hold anything until written) and are skipped."""

    def __init__(self):
        super().__init__()
        self.ops: dict[str, int] = {}

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        out = func(*args, **kwargs)
        if func.is_view or "empty" in func.__name__:
            return out
        for tensor in tree_flatten((args, kwargs, out))[0]:
            if isinstance(tensor, th.Tensor) and tensor.dtype == th.float32 and tensor.numel():
                magnitude = tensor.detach().abs()
                if bool(((magnitude > 0) & (magnitude < TINY)).any()):
                    self.ops[str(func)] = self.ops.get(str(func), 0) + 1
        return out


@pytest.fixture(scope="module")
def warm_up_model(tmp_path_factory):
    model = DENFAC(
        "MlpPolicy",
        gym.make("sb3_denfac/ContinuousAcrobot-v0"),
        learning_starts=10**9,  # uniform actions: the behaviour density is 1/2, the target's is tiny for most
        seed=0,
        **paper(buffer_size=1000, gamma=0.9, reset_critic=True, policy_kwargs=dict(net_arch=dict(pi=[5], qf=[50, 7]))),
    )
    model.learn(1000)
    path = tmp_path_factory.mktemp("denormals")
    model.save(path / "model")
    model.save_replay_buffer(path / "buffer")
    return path


@pytest.mark.parametrize("update_path", ["fast", "plain"])
def test_update_on_real_buffer_computes_no_subnormal(warm_up_model, update_path):
    model = DENFAC.load(warm_up_model / "model", update_path=update_path)
    model.load_replay_buffer(warm_up_model / "buffer")
    model.set_logger(configure(None, []))
    model.n_fitted_iterations, model.critic_steps, model.actor_steps = 2, 3, 3
    model._update()  # a first update moves the actor away from its zero-ish initial output
    weights = model.last_update.weights
    assert float((weights < 1e-6).float().mean()) > 0.5, "the buffer should hold many far-off-policy samples"
    counter = SubnormalCounter()
    with counter:
        model._update()
    assert counter.ops == {}
