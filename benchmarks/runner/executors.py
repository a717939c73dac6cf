"""Where a sweep's runs train: in this process or a local process pool (:func:`run_local`), or on a Ray cluster
(:func:`run_ray`). Each run is ``benchmarks.runner.task.run_one(task)``; its record goes to ``on_result`` as it ends."""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

from benchmarks.runner import task as task_module


def _init_worker() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)


def run_local(tasks: list[dict[str, Any]], workers: int, on_result: Callable[[dict[str, Any]], None]) -> None:
    """Train ``tasks`` in this process (``workers`` 0) or in a pool of ``workers`` fresh processes; ``on_result`` gets
    each run's record as it ends."""
    if workers <= 0:
        for task in tasks:
            on_result(task_module.run_one(task))
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # spawn: fresh interpreters (no inherited torch thread pools), same behaviour on Linux and macOS
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"), initializer=_init_worker) as pool:
        try:
            futures = [pool.submit(task_module.run_one, task) for task in tasks]
            for future in as_completed(futures):
                on_result(future.result())
        except BaseException:  # interrupted (Ctrl-C, SIGTERM): do not leave workers training in the background
            for process in list(getattr(pool, "_processes", {}).values()):
                process.terminate()
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def run_ray(tasks: list[dict[str, Any]], address: str, on_result: Callable[[dict[str, Any]], None]) -> None:
    """Train ``tasks`` on the Ray cluster at ``address`` (``"local"``: one started here); ``on_result`` gets each run's
    record in this driver, which alone writes the runs file."""
    try:
        import ray
    except ImportError as e:
        raise SystemExit(
            "--ray-address needs Ray, which is not installed: pip install 'sb3-denfac[distributed]' (or pip install ray). "
            "Every node of the cluster also needs sb3-denfac installed."
        ) from e
    # Ship the run's code by value so cluster nodes need only the installed package, not this checkout.
    from benchmarks.runner import checkpoints, diagnostics

    for module in (task_module, checkpoints, diagnostics):
        ray.cloudpickle.register_pickle_by_value(module)
    ray.init(address=None if address == "local" else address, ignore_reinit_error=True)
    try:
        # A task whose worker or node dies is retried (max_retries) on the nodes left or on one that joins later.
        remote = ray.remote(num_cpus=1, max_retries=3)(task_module.run_one)
        task_of = {remote.remote(task): task for task in tasks}
        pending = list(task_of)
        while pending:  # results come back to this driver, which alone writes the runs file
            done, pending = ray.wait(pending, num_returns=1)
            try:
                on_result(ray.get(done[0]))
            except ray.exceptions.RayError as error:  # retries exhausted: recorded as failed, redone by a rerun
                task = task_of[done[0]]
                key = task_module.run_key(task)
                on_result({**key, "status": "failed", "error": f"{type(error).__name__}: {error}", "log": ""})
    finally:
        ray.shutdown()  # disconnects from a cluster; stops a "local" one
