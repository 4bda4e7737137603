"""The worker pool: tasks spread over processes, or over a Ray cluster.

A **task** is one piece of work for a module-level ``function(task)`` (picklable by name):
a batch of benchmark episodes driven in lock-step (:func:`clonedrive.bench.driving.drive_batch`),
a group of evaluation runs (:mod:`clonedrive.evaluate.rollout`), one recording of the demo.
:func:`run_tasks` runs a list of tasks on ``workers`` local processes, or as Ray tasks
(``ray="auto"`` or a cluster address; ``"local"`` starts a local Ray instance), and returns
their results in task order. It sits in the bottom layer and imports nothing of clonedrive.

Why results are identical with 1 worker, N workers and Ray: the batches are cut from the
episode list before anything runs (never by which worker is free), every batch runs in a
**fresh process** (``maxtasksperchild=1``; Ray: ``max_calls=1``) with one compute thread, and
every episode is seeded by the suite. A fresh process per task means nothing a task leaves
behind (caches of tracks and scenes, PyTorch's thread count, the renderer's buffers) can reach
the next one, and a network's steering, and so the whole drive, can follow a single pixel.
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable, Sequence
from typing import Any

#: Environment set in every worker before NumPy/PyTorch load: one compute thread each.
_WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def default_workers() -> int:
    """One worker per CPU core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _init_worker() -> None:
    """Before anything loads: one compute thread (PyTorch reads these when it is imported, by
    the model batches only; the expert's batches never import it); and stop with the parent."""
    os.environ.update(_WORKER_ENV)
    _stop_with_parent()


def _stop_with_parent() -> None:
    """Ask the kernel for SIGTERM when the process that started this worker dies, however it
    dies (Linux: ``PR_SET_PDEATHSIG``), so no worker outlives a killed command and goes on
    writing; then exit at once if it died already."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import multiprocessing

    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    parent = multiprocessing.parent_process()
    if parent is not None and os.getppid() != parent.pid:
        os._exit(128 + signal.SIGTERM)


def _run_ray_task(function: Callable[[Any], Any], task: Any) -> Any:
    _init_worker()
    return function(task)


def run_tasks(function: Callable[[Any], Any], tasks: Sequence[Any], *,
              workers: int | None = None, ray: str | None = None,
              on_done: Callable[[int, Any], None] | None = None) -> list[Any]:
    """``[function(task) for task in tasks]``, each call in a fresh worker process; results in
    task order. ``on_done(index, result)`` is called as each task finishes (in task order)."""
    tasks = list(tasks)
    if not tasks:
        return []
    if ray is not None:
        return _run_on_ray(function, tasks, ray, workers, on_done)
    import multiprocessing

    workers = default_workers() if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    context = multiprocessing.get_context("spawn")  # no forked Panda3D or PyTorch state
    results = []
    with context.Pool(processes=min(workers, len(tasks)), initializer=_init_worker,
                      maxtasksperchild=1) as pool:
        for index, result in enumerate(pool.imap(function, tasks)):
            results.append(result)
            if on_done is not None:
                on_done(index, result)
    return results


def _run_on_ray(function: Callable[[Any], Any], tasks: list[Any], address: str,
                workers: int | None, on_done: Callable[[int, Any], None] | None) -> list[Any]:
    try:
        import ray
    except ImportError:
        raise RuntimeError("--ray needs Ray: pip install 'clonedrive[cluster]'") from None
    if not ray.is_initialized():
        if address == "local":
            ray.init(num_cpus=workers or default_workers(), include_dashboard=False,
                     runtime_env={"env_vars": _WORKER_ENV}, log_to_driver=False)
        else:
            ray.init(address=address, runtime_env={"env_vars": _WORKER_ENV},
                     log_to_driver=False)
    remote = ray.remote(num_cpus=1, max_calls=1)(_run_ray_task)
    pending = [remote.remote(function, task) for task in tasks]
    results = []
    for index, ref in enumerate(pending):
        result = ray.get(ref)
        results.append(result)
        if on_done is not None:
            on_done(index, result)
    return results
