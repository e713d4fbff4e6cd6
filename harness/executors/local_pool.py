"""Tasks on this machine: in this process (:class:`InlinePool`) or on a pool of spawned worker
processes (:class:`LocalPool`).

The pool's workers are clean interpreters (spawned, not forked: loaded FMUs and Ecos's threads never
cross a fork).  Each one leaves Ctrl-C to the command, unwinds on SIGTERM and ends when the command's
process is gone, SIGKILL included (harness/termination.py).  The pool holds at most IN_FLIGHT_PER_WORKER
tasks per worker; the rest wait here, so that a lost worker affects only those.

A lost worker (a crash in an FMU, a kill, the out-of-memory killer) breaks a process pool: every task
it held fails with it.  The pool starts again and runs those tasks one at a time, so that each is seen
alone: one that finishes is delivered (once); one whose worker dies again while it runs alone is the
culprit and comes back as :class:`~harness.executors.tasks.WorkerLost`.  Then the pool runs in
parallel again.
"""
from __future__ import annotations

import collections
import multiprocessing
import os
import signal
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from .. import termination
from ..unpack import remove_dead_folders
from .tasks import Done, WorkerLost, forget_worker_state, run_task

EXIT_WAIT_S = 5.0  # a broken pool's workers, all together, are given this long to be reaped (their exit codes)
IN_FLIGHT_PER_WORKER = 2  # tasks handed to the pool per worker: one running, one ready to start


def _start_worker(parent_pid: int, death_signal: bool, initializer, initargs) -> None:
    termination.worker_signals()
    termination.exit_with_parent(parent_pid, death_signal)
    if initializer is not None:
        initializer(*initargs)


class InlinePool:
    """Tasks run in this process, one at a time, when their results are waited for (``--jobs 1``:
    nothing spawned, the same order as submitted; per-worker state is this process's)."""

    slots = 1

    def __init__(self, files: dict | None = None):
        self.files = files
        self.waiting = collections.deque()

    def describe(self) -> str:
        return "this process"

    def submit(self, function, item, key=None) -> None:
        self.waiting.append((key, function, item))

    def pending(self) -> int:
        return len(self.waiting)

    def next_done(self) -> list:
        if not self.waiting:
            return []
        key, function, item = self.waiting.popleft()
        try:
            return [Done(key, run_task(function, item, self.files))]
        except Exception as error:  # noqa: BLE001 - the task's error is its outcome
            return [Done(key, error=error)]

    def as_completed(self):
        while self.waiting:
            yield from self.next_done()

    def close(self, cancel: bool = False) -> None:
        self.waiting.clear()
        forget_worker_state()

    def __enter__(self):
        return self

    def __exit__(self, kind, value, traceback):
        self.close(cancel=kind is not None)


class _Task:
    __slots__ = ("key", "function", "item", "suspect")

    def __init__(self, key, function, item):
        self.key, self.function, self.item, self.suspect = key, function, item, False


class LocalPool:
    """``jobs`` spawned worker processes on this machine.  ``initializer(*initargs)`` runs in each
    worker as it starts (after the signals and the watch on the parent are set up)."""

    def __init__(self, jobs: int, files: dict | None = None, initializer=None, initargs=()):
        if jobs < 1:
            raise ValueError(f"a pool needs at least one worker, not {jobs}")
        self.slots = self.jobs = jobs
        self.files = files
        self.initializer, self.initargs = initializer, tuple(initargs)
        # the kernel's parent-death signal follows the thread that starts a worker: only from the main thread
        self.death_signal = threading.current_thread() is threading.main_thread()
        self.waiting = collections.deque()  # not handed to the pool yet
        self.suspects = collections.deque()  # held by a pool that broke: each runs again, alone
        self.running = {}  # future -> _Task
        self.processes = {}  # pid -> the pool's worker processes (their exit codes name a lost worker's end)
        self.lost_workers = 0
        self.executor = self._start()

    def _start(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(max_workers=self.jobs, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_start_worker,
                                   initargs=(os.getpid(), self.death_signal, self.initializer, self.initargs))

    def describe(self) -> str:
        return f"local pool, {self.jobs} process{'es' if self.jobs != 1 else ''}"

    def submit(self, function, item, key=None) -> None:
        self.waiting.append(_Task(key, function, item))
        self._hand_over()

    def pending(self) -> int:
        return len(self.waiting) + len(self.suspects) + len(self.running)

    def _hand_over(self) -> None:
        """Fill the pool: suspects one at a time and alone, else up to IN_FLIGHT_PER_WORKER per worker."""
        if self.suspects:
            if not self.running:
                task = self.suspects.popleft()
                self.running[self.executor.submit(run_task, task.function, task.item, self.files)] = task
        else:
            while self.waiting and len(self.running) < IN_FLIGHT_PER_WORKER * self.jobs:
                task = self.waiting.popleft()
                self.running[self.executor.submit(run_task, task.function, task.item, self.files)] = task
        self._note_processes()

    def _note_processes(self) -> None:
        """Keep the pool's worker processes: a broken pool forgets them before their exit codes are read."""
        self.processes.update(getattr(self.executor, "_processes", None) or {})

    def _exit_codes(self) -> list:
        codes, deadline = [], time.monotonic() + EXIT_WAIT_S
        for process in list(self.processes.values()):
            process.join(max(0.0, deadline - time.monotonic()))
            if process.exitcode not in (None, 0):
                codes.append(process.exitcode)
        self.processes.clear()
        return codes

    def _restart(self) -> str:
        """After a break: the old pool's remaining tasks are collected, a new pool started; returns what
        ended the dead worker."""
        codes = self._exit_codes()
        wait(list(self.running))  # a broken pool fails all it holds at once
        self.executor.shutdown(wait=False, cancel_futures=True)
        self.executor = self._start()
        self.lost_workers += 1
        remove_dead_folders()  # what the dead worker had unpacked (harness/unpack.py)
        if not codes:
            return "ended abruptly"
        # a broken pool terminates its other workers (SIGTERM): the dead one is the one that did not get that
        code = next((c for c in codes if c != -signal.SIGTERM), codes[0])
        if code < 0:
            try:
                return f"killed by {signal.Signals(-code).name}"
            except ValueError:
                return f"killed by signal {-code}"
        return f"exited with status {code}"

    def next_done(self) -> list:
        """Block until at least one task is done; [] when nothing is pending."""
        while True:
            if not self.running:
                self._hand_over()
                if not self.running:
                    return []
            finished, _ = wait(list(self.running), return_when=FIRST_COMPLETED)
            results, broken, why = [], [], ""
            if any(isinstance(future.exception(), BrokenProcessPool) for future in finished):
                why = self._restart()
                finished = list(self.running)  # every task the broken pool held
            for future in finished:
                task = self.running.pop(future)
                error = future.exception()
                if error is None:
                    results.append(Done(task.key, future.result()))
                elif isinstance(error, BrokenProcessPool):
                    broken.append(task)
                else:
                    results.append(Done(task.key, error=error))
            for task in broken:
                if task.suspect:  # its worker died while it ran alone: the culprit
                    results.append(Done(task.key, error=WorkerLost(
                        f"the worker process running it died twice, the second time running it alone ({why})")))
                else:
                    task.suspect = True
                    self.suspects.append(task)
            self._hand_over()
            if results:
                return results

    def as_completed(self):
        while self.pending():
            yield from self.next_done()

    def close(self, cancel: bool = False) -> None:
        """Wait for the workers to end; ``cancel``: drop what is pending and end the workers now
        (SIGTERM, then SIGKILL after termination.END_GRACE_S)."""
        if cancel:
            self.waiting.clear()
            self.suspects.clear()
            self.running.clear()
            termination.end_workers(self.executor)
        else:
            self.executor.shutdown(wait=True)

    def __enter__(self):
        return self

    def __exit__(self, kind, value, traceback):
        self.close(cancel=kind is not None)


__all__ = ["InlinePool", "LocalPool", "IN_FLIGHT_PER_WORKER"]
