"""Which executor a command gets: ``--scheduler ADDRESS`` a Dask cluster, else a local pool of
``--jobs`` processes (default: every core this process may use), or this process itself for one job
where the study asks for it (no process to spawn, the tasks in the order submitted)."""
from __future__ import annotations

import os

from .dask_pool import DaskPool
from .local_pool import InlinePool, LocalPool


def default_jobs() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def open_executor(jobs: int | None = None, scheduler: str | None = None, files: dict | None = None,
                  initializer=None, initargs=(), inline_single: bool = False, tasks: int | None = None):
    """The executor for ``--jobs`` / ``--scheduler``; ``files`` ({name: path}) are read by every task
    (harness/executors/tasks.py); ``initializer(*initargs)`` runs in each local worker as it starts;
    ``tasks``: how many tasks there will be at most (no more local workers than that)."""
    if scheduler:
        return DaskPool(scheduler, files)
    count = jobs or default_jobs()
    if tasks is not None:
        count = min(count, max(1, tasks))
    if count == 1 and inline_single:
        if initializer is not None:
            initializer(*initargs)
        return InlinePool(files)
    return LocalPool(count, files, initializer, initargs)


__all__ = ["open_executor", "default_jobs"]
