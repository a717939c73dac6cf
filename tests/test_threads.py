"""``torch_threads``: learn() runs with its own number of torch threads and gives the caller's setting back."""

from __future__ import annotations

import pytest
import torch as th
from stable_baselines3.common.callbacks import BaseCallback

from sb3_denfac.common.threads import torch_threads


class _RecordThreads(BaseCallback):
    """Records torch's threads at every step; raises after ``fail_after`` steps if given."""

    def __init__(self, fail_after: int | None = None) -> None:
        super().__init__()
        self.seen: list[int] = []
        self.fail_after = fail_after

    def _on_step(self) -> bool:
        self.seen.append(th.get_num_threads())
        if self.fail_after is not None and len(self.seen) >= self.fail_after:
            raise RuntimeError("stop here")
        return True


@pytest.fixture
def caller_threads():
    """The caller's setting during the test: 3 threads (the test process runs with 1), restored after."""
    saved = th.get_num_threads()
    th.set_num_threads(3)
    yield 3
    th.set_num_threads(saved)


@pytest.mark.algorithms("all")
def test_learn_uses_one_thread_and_restores_the_callers_setting(name: str, make_model, caller_threads: int) -> None:
    model = make_model(name)
    assert model.torch_threads == 1
    callback = _RecordThreads()
    model.learn(60, callback=callback)
    assert set(callback.seen) == {1}
    assert th.get_num_threads() == caller_threads


@pytest.mark.algorithms("all")
def test_settings_are_restored_when_learn_raises(name: str, make_model, caller_threads: int) -> None:
    model = make_model(name, torch_threads=2)
    callback = _RecordThreads(fail_after=5)
    with pytest.raises(RuntimeError, match="stop here"):
        model.learn(60, callback=callback)
    assert set(callback.seen) == {2}
    assert th.get_num_threads() == caller_threads


@pytest.mark.algorithms("all")
def test_none_leaves_torch_alone_and_the_setting_is_saved(name: str, make_model, algo_class, caller_threads, tmp_path) -> None:
    model = make_model(name, torch_threads=None)
    callback = _RecordThreads()
    model.learn(30, callback=callback)
    assert set(callback.seen) == {caller_threads}
    model.save(tmp_path / "model.zip")
    assert algo_class(name).load(tmp_path / "model.zip").torch_threads is None


@pytest.mark.parametrize("bad", [0, -1, 1.5, "2", True])
@pytest.mark.algorithms("all")
def test_bad_values_are_refused(name: str, make_model, bad) -> None:
    with pytest.raises(ValueError, match="^torch_threads must be an integer >= 1"):
        make_model(name, torch_threads=bad)


def test_context_manager_restores_on_error(caller_threads: int) -> None:
    with pytest.raises(KeyError), torch_threads(1):
        assert th.get_num_threads() == 1
        raise KeyError("x")
    assert th.get_num_threads() == caller_threads
