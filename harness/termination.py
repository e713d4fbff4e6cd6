"""How a command ends on SIGTERM as on Ctrl-C, pool workers and all.

In the command's process SIGTERM becomes :class:`Terminated`, a KeyboardInterrupt, raised in the main
thread, so every place that stops cleanly on Ctrl-C stops the same way on SIGTERM; the exit status
then names the signal (:func:`exit_status`: 128 + its number, 130 for Ctrl-C, 143 for SIGTERM).  A
pool that is stopped ends its workers (:func:`end_workers`): the waiting items are dropped, each
worker gets SIGTERM and, after END_GRACE_S, SIGKILL.  In a worker (:func:`worker_signals`) Ctrl-C is
left to the parent, and SIGTERM raises :class:`WorkerStopped` where the worker is, so what it has
started unwinds (a subprocess it waits for is killed, a temporary folder removed); the worker then
exits (:func:`exit_if_stopped`) instead of taking the next item.
"""
from __future__ import annotations

import contextlib
import os
import signal
import time as clock

from .fmi import release_extractions
from .unpack import remove_dead_folders

#: seconds a stopped worker has to unwind before SIGKILL
END_GRACE_S = 5.0


class Terminated(KeyboardInterrupt):
    """SIGTERM in the command's process: handled wherever Ctrl-C is."""


class WorkerStopped(SystemExit):
    """SIGTERM in a pool worker."""


def exit_status(interrupt: BaseException) -> int:
    """128 + the signal that stopped the command: 143 for SIGTERM, 130 for Ctrl-C."""
    return 128 + (signal.SIGTERM if isinstance(interrupt, Terminated) else signal.SIGINT)


def _raise_terminated(signum, frame):
    raise Terminated()


@contextlib.contextmanager
def sigterm_as_interrupt():
    """Within the block, SIGTERM raises Terminated in the main thread (off it: no change)."""
    try:
        previous = signal.signal(signal.SIGTERM, _raise_terminated)
    except ValueError:  # signals can only be handled in the main thread
        previous = None
    try:
        yield
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


# ------------------------------------------------------------------ in a worker
_STOPPING = False


def _stop_worker(signum, frame):
    global _STOPPING
    _STOPPING = True
    raise WorkerStopped(128 + signum)


def worker_signals() -> None:
    """A pool worker's signals: Ctrl-C is the parent's to handle (it ends the workers); SIGTERM stops the
    worker where it is (WorkerStopped)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _stop_worker)


def exit_if_stopped() -> None:
    """After an item: a worker SIGTERM reached ends now, its extracted FMUs removed, even if the item
    swallowed the exception (the pool would give it the next item otherwise)."""
    if _STOPPING:
        release_extractions()
        os._exit(128 + signal.SIGTERM)


# ------------------------------------------------------------------ in the parent
def end_workers(executor, grace_s: float = END_GRACE_S) -> None:
    """Drop the items a ProcessPoolExecutor has not started and end its workers: SIGTERM, then SIGKILL
    for those still alive after ``grace_s``."""
    processes = list((getattr(executor, "_processes", None) or {}).values())
    executor.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.terminate()
    deadline = clock.monotonic() + grace_s
    for process in processes:
        process.join(max(0.0, deadline - clock.monotonic()))
        if process.is_alive():
            process.kill()
            process.join(1.0)
    remove_dead_folders()  # what a worker killed before it could unwind had unpacked (harness/unpack.py)


__all__ = ["Terminated", "WorkerStopped", "exit_status", "sigterm_as_interrupt", "worker_signals",
           "exit_if_stopped", "end_workers", "END_GRACE_S"]
