"""The background learner of the asynchronous update (``async_update=True``): one thread that runs one update job
at a time, beside the env steps of the calling thread (:mod:`~sb3_denfac.common.episodic`, "The asynchronous
update")."""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

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
