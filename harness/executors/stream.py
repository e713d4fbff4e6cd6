"""A study's items as a stream of tasks on any executor (:func:`stream_tasks`), for a study of many
short runs that it records as they finish and resumes from its record (the Monte Carlo study;
docs/architecture.md, "Executors").

* **Each item under its key, once**: ``items`` yields ``(key, item)``; a key the study's record
  already holds (``done``) is skipped, so a rerun submits only what is missing; a key given twice is
  an error.  One :class:`~harness.executors.tasks.Done` comes back per item, in the order the items
  finish, each key exactly once.
* **Several items per task** (``batch``): the executor's own cost per task (docs/performance.md)
  is paid once per batch, not once per run; the worker runs the batch's items one after the other,
  each item's error its own.  A batch whose worker is lost is split and its items run again one per
  task, so that only the item that kills its worker comes back as WorkerLost.
* **A bounded window**: at most ``window`` tasks are submitted at a time (default: twice the
  executor's ``slots``, so that every worker has the next task ready), the items read from
  ``items`` as the work goes: an iterator of draws is never held whole, and a stop leaves little
  submitted.  Leaving the loop early leaves the submitted tasks to the executor's
  ``close(cancel=True)`` (its owner's ``with`` block).
"""
from __future__ import annotations

import collections
import functools

from .. import termination
from .tasks import Done, WorkerLost


def run_batch(function, entries, files=None) -> list:
    """In a worker: ``[(key, value, error)]`` of ``function(item)`` (or ``function(item, files)``) for
    each ``(key, item)`` of ``entries``; an item's exception is its outcome, the batch goes on."""
    outcomes = []
    for key, item in entries:
        try:
            value = function(item) if files is None else function(item, files)
            outcomes.append((key, value, None))
        except Exception as error:  # noqa: BLE001 - an item's error is its outcome, not the batch's
            outcomes.append((key, None, error))
        termination.exit_if_stopped()  # SIGTERM ends the worker between two items of a batch
    return outcomes


def stream_tasks(executor, function, items, done=(), batch: int = 1, window: int | None = None):
    """Yield one Done per ``(key, item)`` of ``items`` whose key is not in ``done``, as their tasks
    finish on ``executor``; ``function`` is a module-level function (it travels to the workers).

    ``batch`` items per task, at most ``window`` tasks submitted at once (default 2 x slots).
    SchedulerLost propagates: what was yielded is the caller's, the rest is not done.
    """
    if batch < 1:
        raise ValueError(f"a batch holds at least one item, not {batch}")
    if window is not None and window < 1:
        raise ValueError(f"a window holds at least one task, not {window}")
    done, seen = set(done), set()
    pending = iter(items)
    retries = collections.deque()  # the items of a batch whose worker was lost, one per task
    task = functools.partial(run_batch, function)
    in_flight = 0

    def next_entries() -> tuple:
        if retries:
            return (retries.popleft(),)
        entries = []
        for key, item in pending:
            if key in seen:
                raise ValueError(f"the key {key!r} is given twice: every item needs a key of its own")
            seen.add(key)
            if key in done:
                continue
            entries.append((key, item))
            if len(entries) == batch:
                break
        return tuple(entries)

    def fill() -> None:
        nonlocal in_flight
        limit = window or 2 * max(1, executor.slots)
        while in_flight < limit:
            entries = next_entries()
            if not entries:
                return
            executor.submit(task, entries, key=entries)
            in_flight += 1

    fill()
    while in_flight:
        outcomes = []
        for finished in executor.next_done():
            in_flight -= 1
            entries = finished.key
            if finished.ok:
                outcomes += [Done(key, value, error) for key, value, error in finished.value]
            elif isinstance(finished.error, WorkerLost) and len(entries) > 1:
                retries.extend(entries)  # each alone: only the one that kills its worker is lost
            else:
                outcomes += [Done(key, error=finished.error) for key, _ in entries]
        fill()  # the workers get their next tasks before the caller handles these
        yield from outcomes


__all__ = ["stream_tasks", "run_batch"]
