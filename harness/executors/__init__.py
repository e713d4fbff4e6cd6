"""Where a study's tasks run, written once for every study (sweep, tune, tables, the Monte Carlo
study): in this process, on a local pool of worker processes, or on a Dask cluster, behind one
interface (docs/architecture.md, "Executors").

Every executor has ``submit(function, item, key)``, ``next_done()`` (blocks until at least one task is
done and returns their :class:`Done` records, each task exactly once), ``as_completed()``,
``pending()``, ``slots`` (tasks it runs at once), ``describe()`` and ``close(cancel)``; a study
streams its results as they come and keeps its own resumable record of what is done
(:func:`stream_tasks`: its items by key, those already recorded skipped, several per task).  Files the
tasks read (the FMUs) are given once and travel once to each worker; per-worker state
(:func:`worker_state`) keeps extracted or instantiated FMUs from one task to the next.

One idea per module, each importing only those above it:

===============  ======================================================================
``tasks``        a finished task (Done), lost workers and schedulers, per-worker state, shipped files,
                 the worker side of a task
``local_pool``   this process (InlinePool) and a pool of spawned processes (LocalPool), re-running the
                 tasks of a lost worker
``dask_pool``    a dask.distributed scheduler (DaskPool): files scattered once, a lost scheduler
``choose``       the executor of ``--jobs`` / ``--scheduler`` (open_executor)
``stream``       a study's keyed items as tasks: what is done skipped, batches, a bounded window
                 (stream_tasks)
===============  ======================================================================
"""
from __future__ import annotations

from .choose import default_jobs, open_executor
from .dask_pool import DaskPool
from .local_pool import InlinePool, LocalPool
from .stream import stream_tasks
from .tasks import Done, ExecutorError, SchedulerLost, WorkerLost, worker_state

__all__ = ["open_executor", "default_jobs", "DaskPool", "InlinePool", "LocalPool", "Done", "ExecutorError",
           "SchedulerLost", "WorkerLost", "worker_state", "stream_tasks"]
