"""The worker pool: tasks spread over processes, or over a Ray cluster.

A **task** is one piece of work for a module-level ``function(task)`` (picklable by name):
a batch of benchmark episodes driven in lock-step (:func:`clonedrive.bench.driving.drive_batch`),
a group of evaluation runs (:mod:`clonedrive.evaluate.rollout`), one recording of the demo.
:func:`run_tasks` runs a list of tasks on ``workers`` local processes, or as Ray tasks
(``ray="auto"`` or a cluster address; ``"local"`` starts a local Ray instance), and returns
their results in task order. It sits in the bottom layer and imports only
:mod:`clonedrive.base.interrupts` and :mod:`clonedrive.base.allocator`.

Why results are identical with 1 worker, N workers and Ray: the batches are cut from the
episode list before anything runs (never by which worker is free), every batch runs in a
**fresh process** (``maxtasksperchild=1``; Ray: ``max_calls=1``) with one compute thread, and
every episode is seeded by the suite. A fresh process per task means nothing a task leaves
behind (caches of tracks and scenes, PyTorch's thread count, the renderer's buffers) can reach
the next one, and a network's steering, and so the whole drive, can follow a single pixel.

Local tasks travel to their workers as files: each task is pickled into a private temporary
folder and the pool's pipe carries only its path. A task holds a model's traces and its tracks'
arrays, far more than a pipe's 64 KB buffer. Sent through the pipe, a SIGTERM arriving while
one was half written could leave ``Pool.terminate`` waiting forever for its task thread, which
was blocked writing to workers that were gone.
"""

from __future__ import annotations

import os
import pickle
import signal
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from clonedrive.base.allocator import keep_freed_memory
from clonedrive.base.interrupts import deferred_termination

#: Environment set in every worker before NumPy/PyTorch load: one compute thread each.
_WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
#: How often a worker checks that its parent process is still there [s].
_PARENT_CHECK_S = 0.5


def default_workers() -> int:
    """One worker per CPU core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _init_worker(parent: int) -> None:
    """Before anything loads: one compute thread (PyTorch reads these when it is imported, by
    the model batches only; the expert's batches never import it); and stop with ``parent``,
    the process that runs the pool."""
    os.environ.update(_WORKER_ENV)
    keep_freed_memory()
    _stop_with_parent(parent)


def _stop_with_parent(parent: int) -> None:
    """Exit when the process that started this worker is gone, however it died (SIGKILL
    included), so no worker outlives a killed command and goes on writing: a daemon thread
    watches the parent's PID every :data:`_PARENT_CHECK_S` seconds. (The kernel's
    ``PR_SET_PDEATHSIG`` would fire when the *thread* that forked the worker ends, and the pool
    forks its replacement workers from a thread that ends at the pool's shutdown.)"""
    import threading
    import time

    if os.getppid() != parent:  # it died while this worker started
        os._exit(128 + signal.SIGTERM)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(_PARENT_CHECK_S)
        os._exit(128 + signal.SIGTERM)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


@dataclass(frozen=True)
class _TaskFile:
    """What the pool's pipe carries for one task: the function and the pickled task's path."""

    function: Callable[[Any], Any]
    path: str


def _run_task_file(handle: _TaskFile) -> Any:
    """In a worker: load the task from its file and run it."""
    with open(handle.path, "rb") as file:
        task = pickle.load(file)
    return handle.function(task)


def _write_task_files(function: Callable[[Any], Any], tasks: Sequence[Any],
                      folder: Path) -> list[_TaskFile]:
    handles = []
    for index, task in enumerate(tasks):
        path = folder / f"task-{index}.pickle"
        with open(path, "wb") as file:
            pickle.dump(task, file, protocol=pickle.HIGHEST_PROTOCOL)
        handles.append(_TaskFile(function, str(path)))
    return handles


def _run_ray_task(function: Callable[[Any], Any], task: Any) -> Any:
    os.environ.update(_WORKER_ENV)  # Ray stops its own workers
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
    workers = default_workers() if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    with tempfile.TemporaryDirectory(prefix="clonedrive-tasks-") as folder:
        handles = _write_task_files(function, tasks, Path(folder))
        return _run_in_pool(handles, min(workers, len(tasks)), on_done)


def _run_in_pool(handles: list[_TaskFile], processes: int,
                 on_done: Callable[[int, Any], None] | None) -> list[Any]:
    import multiprocessing

    context = multiprocessing.get_context("spawn")  # no forked Panda3D or PyTorch state
    results = []
    pool = None
    try:
        # A SIGTERM while the pool starts its workers waits until they are started: a worker
        # whose start-up data were cut off would print a traceback after the command ended.
        with deferred_termination():
            pool = context.Pool(processes=processes, initializer=_init_worker,
                                initargs=(os.getpid(),), maxtasksperchild=1)
        for index, result in enumerate(pool.imap(_run_task_file, handles)):
            results.append(result)
            if on_done is not None:
                on_done(index, result)
    finally:
        if pool is not None:
            pool.terminate()  # as the pool's context manager does: every worker stops
            pool.join()
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
