"""DENFAC's asynchronous update (``async_update=True``): Algorithm 1's end-of-episode update beside the next episode.

On a robot or a slow simulator, the update at the end of an episode stalls the control loop. With ``async_update``:

1. at an episode end, DENFAC snapshots D (``all_samples``, a copy) and the policy (``copy.deepcopy``: networks,
   optimizers, running statistics) and hands them to one learner thread, which runs the update (or, with several envs,
   one update per episode finished, back to back) on the copies;
2. meanwhile the env steps with the last published policy, ``model.policy``, which no thread writes;
3. the first env step after the update ends publishes it: the copy becomes ``model.policy`` and the update's logging
   keys and ``last_update`` are recorded, all in the calling thread.

What changes against ``async_update=False``: the first steps of an episode are played by the previous policy; an
episode end waits for the update still running, if any (so at most one is in flight, and every finished episode
still gets its update); the learner's random draws interleave with the env's, so runs are not reproducible from the
seed. ``learn`` returns after the last update is published; on an exception (``KeyboardInterrupt`` included) it waits
for the running update, publishes it, and shuts the thread down before the exception propagates. ``save`` during
``learn`` writes the last published policy.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

from sb3_denfac.common.budget import budget_reached

#: the learner thread's name (prefix), e.g. to find it in ``threading.enumerate()``
THREAD_NAME = "denfac-learner"


class BackgroundLearner:
    """One learner thread running one job at a time (:mod:`concurrent.futures`); an exception in the job is raised in
    the caller by :meth:`result`."""

    def __init__(self) -> None:
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix=THREAD_NAME)
        self._job: Future[Any] | None = None

    @property
    def busy(self) -> bool:
        """A job was submitted and its result not yet taken."""
        return self._job is not None

    def ready(self) -> bool:
        """A job was submitted and has ended (its result can be taken without waiting)."""
        return self._job is not None and self._job.done()

    def submit(self, job: Callable[..., Any], *args: Any) -> None:
        if self._job is not None:
            raise RuntimeError("the learner is still busy: take the result of its job first")
        self._job = self._executor.submit(job, *args)

    def result(self) -> Any:
        """The job's result, waiting for it to end; the learner is then free."""
        assert self._job is not None, "no job submitted"
        job, self._job = self._job, None
        return job.result()

    def close(self) -> None:
        """Wait for the running job, if any (its result is dropped), and end the thread."""
        self._executor.shutdown(wait=True)
        self._job = None


class AsyncUpdateMixin:
    """The update's two modes for DENFAC (put it before SB3's ``OffPolicyAlgorithm``): :meth:`_run_updates` runs the
    updates of the episodes just finished in the calling thread, or, with ``async_update`` inside ``learn``, on the
    learner thread (module docstring). The host provides ``_fit(updater, data, n_iterations)`` (one update on copies it
    is given, returning what :meth:`_record` needs), ``_record(fits)``, ``make_updater(policy)`` and ``_create_aliases``.
    """

    async_update: bool
    _learner: BackgroundLearner | None = None

    def _run_updates(self, iterations: list[int], reset: bool = False) -> None:
        """One update per finished episode, ``iterations[i]`` fitted iterations each, back to back; with ``reset``, the
        actor and the critic are re-initialised first (``reset_every``)."""
        if self._learner is None:
            data = self.replay_buffer.all_samples(env=self._vec_normalize_env)  # type: ignore[attr-defined]
            self._record(self._fit_all(self.policy, data, iterations, reset))  # type: ignore[attr-defined]
            return
        self._publish(wait=True)  # the update still running, if any: at most one in flight
        policy = copy.deepcopy(self.policy)  # type: ignore[attr-defined]
        data = self.replay_buffer.all_samples(env=self._vec_normalize_env)  # type: ignore[attr-defined]
        self._learner.submit(self._fit_in_background, policy, data, iterations, reset)
        if budget_reached(self):  # the last update of this learn(): published before learn() returns
            self._publish(wait=True)

    def _fit_all(self, policy: Any, data: Any, iterations: list[int], reset: bool = False) -> list[Any]:
        """The updates of ``policy`` on D's content ``data``, back to back: a new updater for each, made after the
        previous one finished; with ``reset``, ``policy``'s actor and critic re-initialised first."""
        if reset:
            policy.reset_actor()
            policy.reset_critic()
        return [self._fit(self.make_updater(policy), data, n) for n in iterations]  # type: ignore[attr-defined]

    def _fit_in_background(self, policy: Any, data: Any, iterations: list[int], reset: bool) -> tuple[Any, list[Any]]:
        return policy, self._fit_all(policy, data, iterations, reset)

    def _publish(self, wait: bool) -> None:
        """Make the learner's finished update (``wait``: or the running one, once it ends) the model's policy, and
        record it; nothing if there is none."""
        learner = self._learner
        if learner is None or not (learner.ready() or (wait and learner.busy)):
            return
        policy, fits = learner.result()
        self.policy = policy
        self._create_aliases()  # type: ignore[attr-defined]
        self._record(fits)  # type: ignore[attr-defined]

    def _on_step(self) -> None:
        super()._on_step()  # type: ignore[misc]
        self._publish(wait=False)

    def learn(self, *args: Any, **kwargs: Any) -> Any:
        if not self.async_update:
            return super().learn(*args, **kwargs)  # type: ignore[misc]
        self._learner = BackgroundLearner()
        try:
            return super().learn(*args, **kwargs)  # type: ignore[misc]
        finally:  # also on an exception (KeyboardInterrupt too): the running update is kept, no thread is left
            try:
                self._publish(wait=True)
            finally:
                self._learner.close()
                self._learner = None

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_learner"]  # type: ignore[misc]
