"""How a command ends on SIGTERM as on Ctrl-C, pool workers and all.

In the command's process SIGTERM becomes :class:`Terminated`, a KeyboardInterrupt, raised in the main
thread, so every place that stops cleanly on Ctrl-C stops the same way on SIGTERM; the exit status
then names the signal (:func:`exit_status`: 128 + its number, 130 for Ctrl-C, 143 for SIGTERM).  A
pool that is stopped ends its workers (:func:`end_workers`): the waiting items are dropped, each
worker gets SIGTERM and, after END_GRACE_S, SIGKILL.  In a worker (:func:`worker_signals`) Ctrl-C is
left to the parent, and SIGTERM raises :class:`WorkerStopped` where the worker is, so what it has
started unwinds (a subprocess it waits for is killed, a temporary folder removed); the worker then
exits (:func:`exit_if_stopped`) instead of taking the next item.

A worker also ends when its parent is gone, killed with SIGKILL included, so that no pool outlives its
command (:func:`exit_with_parent`): on Linux the kernel sends it SIGTERM when the parent dies
(``prctl(PR_SET_PDEATHSIG)``), and on every platform a watchdog thread waits on the parent's sentinel
(the pipe or process handle that multiprocessing gives a spawned child; a poll of the parent's pid
where there is none), sends SIGTERM to its own process and, if the worker is still there after
END_GRACE_S (a long call into an FMU's C code delays Python's signal handler), removes its extracted
FMUs and exits.
"""
from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import threading
import time as clock

from .fmi import release_extractions
from .unpack import remove_dead_folders

#: seconds a stopped worker has to unwind before SIGKILL
END_GRACE_S = 5.0
#: how often the watchdog polls the parent's pid where no sentinel is available
PARENT_POLL_S = 0.5
PR_SET_PDEATHSIG = 1  # linux/prctl.h


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
    """The first SIGTERM unwinds the worker where it is; a later one (the clean-up under way) is let be."""
    global _STOPPING
    if _STOPPING:
        return
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


def _parent_death_signal() -> bool:
    """Linux: the kernel sends this process SIGTERM when the thread that started it ends (its parent
    process's, for a pool started from the main thread).  False elsewhere or if prctl is refused."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _parent_gone(parent_pid: int) -> bool:
    return os.getppid() != parent_pid


def _wait_for_parent(parent_pid: int) -> None:
    """Return once the parent process is gone: its sentinel (a pipe's end or a process handle) becomes
    ready when it ends; without one, a poll of the parent's pid."""
    parent = multiprocessing.parent_process()
    sentinel = getattr(parent, "sentinel", None) if parent is not None and parent.pid == parent_pid else None
    if sentinel is not None:
        multiprocessing.connection.wait([sentinel])
        return
    while not _parent_gone(parent_pid):
        clock.sleep(PARENT_POLL_S)


def _watch_parent(parent_pid: int, grace_s: float) -> None:
    _wait_for_parent(parent_pid)
    try:
        os.kill(os.getpid(), signal.SIGTERM)  # the worker unwinds where it is (worker_signals)
    except OSError:
        pass
    clock.sleep(grace_s)
    release_extractions()
    os._exit(128 + signal.SIGTERM)


def exit_with_parent(parent_pid: int, death_signal: bool = True, grace_s: float = END_GRACE_S) -> None:
    """In a pool worker: end when the process ``parent_pid`` (the command) is gone, however it ended.

    ``death_signal``: also ask Linux for SIGTERM at the parent's death (PR_SET_PDEATHSIG); only for a
    pool started from the parent's main thread, since the kernel sends it when that *thread* ends.
    A parent already gone when this runs ends the worker at once.
    """
    if death_signal:
        _parent_death_signal()
    if _parent_gone(parent_pid):  # the parent died before the worker got here
        release_extractions()
        os._exit(128 + signal.SIGTERM)
    threading.Thread(target=_watch_parent, args=(parent_pid, grace_s), daemon=True,
                     name="afc-parent-watch").start()


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
           "exit_if_stopped", "exit_with_parent", "end_workers", "END_GRACE_S"]
