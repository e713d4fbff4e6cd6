"""Tasks on an existing dask.distributed scheduler (``--scheduler ADDRESS``): :class:`DaskPool`.

The client (the command) checks that the scheduler answers and that its workers can import this
project, then scatters the files the tasks read (the FMUs) to every worker once; each task carries
only a reference to them.  Results stream back as tasks finish.

A lost worker is the scheduler's to handle: it runs the worker's tasks again on the others (a task
counts once: the client receives one result per task); a task that has killed
``distributed.scheduler.allowed-failures`` + 1 workers (Dask's default: 3 + 1) comes back as
:class:`~harness.executors.tasks.WorkerLost`.  Every worker lost at once takes the files scattered to
them along: the scheduler drops the tasks that need them, and the client sends the files again to the
workers that come (waiting WORKERLESS_S at most) and resubmits those tasks (RESUBMITS times at most).  The scheduler gone is :class:`SchedulerLost`, raised
by :meth:`DaskPool.next_done`: what finished is the caller's, the rest is not done.  So is a
scheduler left without a worker for WORKERLESS_S: the run says so rather than waiting forever.
"""
from __future__ import annotations

import logging
import time as clock

from .tasks import Done, ExecutorError, SchedulerLost, Shipment, WorkerLost, run_task

SCHEDULER_TIMEOUT = "20s"  # how long to try reaching a Dask scheduler
WORKERS_TIMEOUT_S = 20.0  # how long to wait for a first worker on a scheduler that has none
WORKERLESS_S = 60.0  # a cluster without a worker for this long mid-run runs nothing: said, not waited on forever
POLL_S = 0.01  # how often the client looks for finished tasks
CHECK_S = 5.0  # how often it asks the scheduler how many workers it has (and how many threads)
RESUBMITS = 3  # how often a task the scheduler dropped (its files lost with every worker) is submitted again
CLOSE_TIMEOUT_S = 5.0
QUIET_LOGGERS = ("distributed", "distributed.client", "distributed.core", "distributed.comm", "distributed.batched")
CLUSTER_EXTRA = "pip install -e '.[cluster]' (or pip install 'dask[distributed]')"


def _distributed():
    try:
        import distributed  # optional: the cluster extra, and a heavy import
    except ImportError:
        raise ExecutorError(f"--scheduler needs dask.distributed, in the cluster extra: {CLUSTER_EXTRA}") from None
    return distributed


def _quiet():
    """distributed logs a traceback for every reconnection attempt: the command says it in one line."""
    for name in QUIET_LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL)


class DaskPool:
    """Tasks go to the scheduler at ``address``; ``files`` ({name: path}) travel once to every worker."""

    def __init__(self, address: str, files: dict | None = None, timeout: str | None = None):
        distributed = _distributed()
        _quiet()
        self.address = address
        try:
            self.client = distributed.Client(address, timeout=timeout or SCHEDULER_TIMEOUT,
                                             set_as_default=False)
        except (OSError, TimeoutError, ValueError) as error:
            raise ExecutorError(f"cannot reach the Dask scheduler at {address!r}: {error}") from None
        try:
            self._check_workers()
            self.shipment, self.blobs, self.data = None, files, None
            if files is not None:
                self.shipment, self.data = Shipment.of(files)
                self.blobs = self.client.scatter(self.data, broadcast=True)  # one future: {sha256: bytes}
        except BaseException:
            self._close_client()
            raise
        self.keys = {}  # future -> the caller's key
        self.tasks = {}  # future -> (function, item, how often it was resubmitted)
        self._threads, self._asked = 1, -CHECK_S  # the workers' threads, and when the scheduler was last asked
        self._workerless_since = None
        self.completed = distributed.as_completed(loop=self.client.loop, with_results=True, raise_errors=False)
        self.killed_worker = distributed.KilledWorker

    def _check_workers(self) -> None:
        def worker_can_run():  # defined here so cloudpickle ships it by value, with its import
            import importlib.util

            return all(importlib.util.find_spec(module) is not None for module in ("harness", "fmpy", "numpy"))

        deadline = clock.monotonic() + WORKERS_TIMEOUT_S
        checks = self.client.run(worker_can_run)
        while not checks and clock.monotonic() < deadline:
            clock.sleep(0.5)
            checks = self.client.run(worker_can_run)
        if not checks:
            raise ExecutorError(f"the Dask scheduler at {self.address!r} has no workers (waited "
                                f"{WORKERS_TIMEOUT_S:g} s): start some with dask worker {self.address} --nthreads 1")
        missing = [worker for worker, ok in checks.items() if not ok]
        if missing:
            raise ExecutorError(f"Dask workers {', '.join(missing)} cannot import harness, fmpy and numpy: "
                                "install this project on every worker host (pip install '.[cluster]')")

    @property
    def workers(self) -> int:
        return len(self.client.scheduler_info().get("workers", {}))

    def _threads_now(self) -> int:
        """The workers' threads, asked of the scheduler at most every CHECK_S."""
        if clock.monotonic() - self._asked >= CHECK_S:
            self._asked = clock.monotonic()
            try:
                self._threads = sum(self.client.nthreads().values())
            except Exception:  # noqa: BLE001 - a scheduler gone: next_done says so
                pass
        return self._threads

    @property
    def slots(self) -> int:
        """Tasks the cluster runs at once: its workers' threads (at least 1)."""
        return max(1, self._threads_now())

    def describe(self) -> str:
        count = self.workers
        return f"Dask scheduler {self.address}, {count} worker{'s' if count != 1 else ''}"

    def submit(self, function, item, key=None) -> None:
        if self.client.status != "running":
            raise SchedulerLost(f"lost the Dask scheduler at {self.address} (client {self.client.status})")
        self._send(key, function, item, 0)

    def _send(self, key, function, item, resubmitted: int) -> None:
        future = self.client.submit(run_task, function, item, self.blobs, self.shipment, pure=False)
        self.keys[future] = key
        self.tasks[future] = (function, item, resubmitted)
        self.completed.add(future)

    def pending(self) -> int:
        return len(self.keys)

    def next_done(self) -> list:
        """Block until at least one task is done; [] when nothing is pending; SchedulerLost when the
        scheduler went away."""
        if not self.keys:
            return []
        while True:
            results, dropped = [], []
            for future, value in self._next_batch():
                if future.status == "cancelled" and (self.client.status != "running" or
                                                     getattr(value, "reason", "") == "scheduler-connection-lost"):
                    raise SchedulerLost(f"lost the Dask scheduler at {self.address} ({self._why(value)})")
                key = self.keys.pop(future, None)
                function, item, resubmitted = self.tasks.pop(future)
                if future.status == "finished":
                    results.append(Done(key, value))
                elif future.status == "error":
                    if isinstance(value, tuple):  # as_completed gives an error as (type, exception, traceback)
                        value = next((part for part in value if isinstance(part, BaseException)), value)
                    if isinstance(value, self.killed_worker):
                        value = WorkerLost(f"the scheduler gave up on it: {value}")
                    results.append(Done(key, error=value))
                elif resubmitted >= RESUBMITS:  # dropped by the scheduler again and again
                    results.append(Done(key, error=WorkerLost(
                        f"the scheduler dropped it {resubmitted + 1} times ({self._why(value)})")))
                else:  # dropped by the scheduler: its files were lost with every worker
                    dropped.append((key, function, item, resubmitted + 1))
            if dropped:
                self._send_files_again()
                for entry in dropped:
                    self._send(*entry)
            if results:
                return results

    def _send_files_again(self) -> None:
        """After every worker was lost: wait for one (WORKERLESS_S at most) and scatter the files again."""
        deadline = clock.monotonic() + WORKERLESS_S
        self._asked = -CHECK_S
        while self._threads_now() == 0:
            if clock.monotonic() > deadline:
                raise SchedulerLost(f"the Dask scheduler at {self.address} has had no worker for {WORKERLESS_S:g} s "
                                    f"({len(self.keys)} task(s) waiting)")
            clock.sleep(CHECK_S / 10)
            self._asked = -CHECK_S
        if self.data is not None:
            self.blobs = self.client.scatter(self.data, broadcast=True)

    def _next_batch(self) -> list:
        """The tasks finished since the last call, at least one; SchedulerLost after WORKERLESS_S without
        a worker."""
        while True:
            batch = self.completed.next_batch(block=False)
            if batch:
                self._workerless_since = None
                return batch
            if self._threads_now() == 0 and self.client.status == "running":
                self._workerless_since = self._workerless_since or clock.monotonic()
                if clock.monotonic() - self._workerless_since >= WORKERLESS_S:
                    raise SchedulerLost(f"the Dask scheduler at {self.address} has had no worker for "
                                        f"{WORKERLESS_S:g} s ({len(self.keys)} task(s) waiting)")
            else:
                self._workerless_since = None
            clock.sleep(POLL_S)

    def _why(self, cancelled) -> str:
        reason = getattr(cancelled, "reason", None) or str(cancelled) or "its tasks were cancelled"
        return str(reason).replace("-", " ")

    def as_completed(self):
        while self.keys:
            yield from self.next_done()

    def _close_client(self) -> None:
        try:
            self.client.close(timeout=CLOSE_TIMEOUT_S)
        except Exception:  # noqa: BLE001 - a scheduler gone cannot be told goodbye
            pass

    def close(self, cancel: bool = False) -> None:
        """Release the tasks (``cancel``: stop those not done) and disconnect."""
        if cancel and self.keys and self.client.status == "running":
            try:
                self.client.cancel(list(self.keys))
            except Exception:  # noqa: BLE001 - as above
                pass
        self.keys.clear()
        self.tasks.clear()
        self._close_client()

    def __enter__(self):
        return self

    def __exit__(self, kind, value, traceback):
        self.close(cancel=kind is not None)


__all__ = ["DaskPool", "SCHEDULER_TIMEOUT", "WORKERS_TIMEOUT_S"]
