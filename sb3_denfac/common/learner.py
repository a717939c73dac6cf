"""The background learner of the asynchronous update (``async_update=True``): one thread that runs one update job
at a time, beside the env steps of the calling thread (:mod:`~sb3_denfac.common.episodic`, "The asynchronous
update"), and hands the caller a snapshot of the job's progress (:meth:`BackgroundLearner.offer`) before its end; the
caller may ask a running job to end early (:meth:`BackgroundLearner.request_end`), which the job reads between its
steps (:meth:`BackgroundLearner.end_requested`)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

#: the learner thread's name (prefix), e.g. to find it in ``threading.enumerate()``
THREAD_NAME = "denfac-learner"


class BackgroundLearner:
    """One learner thread running one job at a time (:mod:`concurrent.futures`); an exception in the job is raised in
    the caller by :meth:`result`. While a job runs it may :meth:`offer` snapshots of its progress, which the caller
    takes with :meth:`take_offer` (the newest only; :meth:`result` drops the one not taken). The caller may ask the
    running job to end early (:meth:`request_end`); the job decides where it can stop (:meth:`end_requested`)."""

    def __init__(self) -> None:
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix=THREAD_NAME)
        self._job: Future[Any] | None = None
        self._lock = threading.Lock()
        self._offered: Any = None
        self._inside = threading.local()  # inside_job: set in the learner thread while a job runs
        self._end = threading.Event()  # request_end: set by the caller, cleared at each submit

    @property
    def busy(self) -> bool:
        """A job was submitted and its result not yet taken."""
        return self._job is not None

    def ready(self) -> bool:
        """A job was submitted and has ended (its result can be taken without waiting)."""
        return self._job is not None and self._job.done()

    def inside_job(self) -> bool:
        """Whether the calling thread is the learner thread, running a job."""
        return getattr(self._inside, "job", False)

    def submit(self, job: Callable[..., Any], *args: Any) -> None:
        if self._job is not None:
            raise RuntimeError("the learner is still busy: take the result of its job first")
        self._take()
        self._end.clear()

        def run() -> Any:
            self._inside.job = True
            try:
                return job(*args)
            finally:
                self._inside.job = False

        self._job = self._executor.submit(run)

    def request_end(self) -> None:
        """From the caller: the running job should end at its next point where it can (its result stays whole)."""
        self._end.set()

    def end_requested(self) -> bool:
        """From the running job: whether the caller asked it to end early."""
        return self._end.is_set()

    def offer(self, snapshot: Any) -> None:
        """From the running job: ``snapshot`` replaces the one offered before, if the caller has not taken it."""
        with self._lock:
            self._offered = snapshot

    def take_offer(self) -> Any:
        """The newest snapshot the running job offered and nobody took yet (None: none)."""
        return self._take()

    def _take(self) -> Any:
        with self._lock:
            snapshot, self._offered = self._offered, None
        return snapshot

    def result(self) -> Any:
        """The job's result, waiting for it to end; the learner is then free (a snapshot not taken is dropped)."""
        assert self._job is not None, "no job submitted"
        job, self._job = self._job, None
        try:
            return job.result()
        finally:
            self._take()

    def close(self) -> None:
        """Wait for the running job, if any (its result is dropped), and end the thread."""
        self._executor.shutdown(wait=True)
        self._job = None
        self._take()
