"""Torch threads inside ``learn()``: one setting, ``torch_threads``, shared by the six algorithms.

The package's networks are tiny (tens of units): splitting their matrix products over several intra-op threads only
adds synchronisation, and on a machine whose cores are busy with other work the waiting dominates. Measured on a
2-core machine with another process burning one core, DENFAC's ``learn(2000)`` on Pendulum-v1 took many times longer
with torch's default threads than with one (``research/torch_threads/README.md``). So by default ``learn()`` runs
with one torch thread, and gives the caller's setting back when it returns or raises:

- ``torch_threads=1`` (default): ``torch.set_num_threads(1)`` for the duration of ``learn()`` (rollouts, updates and
  the callbacks called from it), the caller's ``torch.get_num_threads()`` restored afterwards;
- ``torch_threads=n``: the same with n threads (large networks, an otherwise idle many-core machine);
- ``torch_threads=None``: torch's setting is left alone (the caller's ``torch.set_num_threads`` applies).

Interop threads are not touched. The setting is saved with the model; files of earlier versions load with the default.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator
from typing import Any

import torch as th

from sb3_denfac.common.checks import check_number

#: ``torch_threads``'s default: one intra-op thread inside ``learn()``.
DEFAULT_TORCH_THREADS = 1


def check_torch_threads(value: Any) -> int | None:
    """``torch_threads``: an integer >= 1, or None (leave torch's setting alone)."""
    return check_number(
        "torch_threads", value, minimum=1, integer=True, none_ok=True, note=" (None: leave torch's setting alone)"
    )


@contextlib.contextmanager
def torch_threads(n_threads: int | None) -> Iterator[None]:
    """Run the block with ``n_threads`` torch intra-op threads (None: unchanged); the previous number is restored on
    exit, also when the block raises."""
    if n_threads is None:
        yield
        return
    previous = th.get_num_threads()
    if previous != n_threads:
        th.set_num_threads(n_threads)
    try:
        yield
    finally:
        if th.get_num_threads() != previous:
            th.set_num_threads(previous)


def _with_torch_threads(learn: Callable[..., Any]) -> Callable[..., Any]:
    @functools.wraps(learn)
    def wrapped(self: Any, *args: Any, **kwargs: Any) -> Any:
        with torch_threads(getattr(self, "torch_threads", DEFAULT_TORCH_THREADS)):
            return learn(self, *args, **kwargs)

    wrapped.__wrapped_torch_threads__ = True  # type: ignore[attr-defined]
    return wrapped


class TorchThreadsMixin:
    """``learn()`` runs with ``self.torch_threads`` torch threads (:func:`torch_threads`).

    Every ``learn`` defined by a subclass is wrapped as the class is created (CMA-ES's ``learn`` does not call
    ``super().learn``), so the setting applies whatever the class hierarchy; nested wrappers restore in order.
    """

    torch_threads: int | None = DEFAULT_TORCH_THREADS  # class default: files saved before the setting existed

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        learn = cls.__dict__.get("learn")
        if learn is not None and not getattr(learn, "__wrapped_torch_threads__", False):
            cls.learn = _with_torch_threads(learn)  # type: ignore[attr-defined]

    @_with_torch_threads
    def learn(self, *args: Any, **kwargs: Any) -> Any:
        return super().learn(*args, **kwargs)  # type: ignore[misc]
