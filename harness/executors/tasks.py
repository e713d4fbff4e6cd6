"""What every executor shares: a task's record when it is done, the errors of a lost worker or a lost
scheduler, the worker side of a task (the files it needs, its worker's state), and the FMU files
shipped once to each worker.

A task is ``function(item)``, or ``function(item, files)`` for an executor given ``files`` ({name:
path of a file the tasks read, e.g. the FMUs}): the worker passes {name: path of that file on this
host}.  On this machine (inline, local pool) those are the paths given.  On a Dask cluster the client
sends each file's bytes once to every worker (:class:`Shipment`); the first task on a worker writes
them into its host's cache, named by their SHA-256 and checked against it, and later tasks use that
copy.

Per-worker state: :func:`worker_state` keeps an object per worker (a process, or a Dask worker's
thread) from one task to the next, made by the task that first needs it: extracted FMUs, instantiated
FMUs reset between runs, a compiled loop.  An object with a ``close()`` is closed when the worker's
process ends.
"""
from __future__ import annotations

import atexit
import hashlib
import os
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

from .. import termination
from ..cli_args import UsageError

CACHE_FOLDER = "afc-shipped-files"  # under the worker host's temporary folder


@dataclass(frozen=True)
class Done:
    """A finished task: ``value`` (what the function returned) or ``error`` (what it raised, or
    WorkerLost); ``key`` is the one given at submission."""

    key: object
    value: object = None
    error: BaseException | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


class WorkerLost(RuntimeError):
    """The worker running a task died (a crash in an FMU, a kill, a host gone) more often than the
    executor re-runs a task: the task is not done, and a resumed study runs it again."""


class ExecutorError(UsageError):
    """The executor asked for cannot be had: no Dask, an unreachable scheduler, workers that cannot run
    the tasks (exit 2, before any task runs)."""


class SchedulerLost(RuntimeError):
    """The Dask scheduler went away (or could not be reached any more): no task finishes from here on."""


# ------------------------------------------------------------------ per-worker state
_STATE = threading.local()
_TO_CLOSE: list = []
_CLOSE_LOCK = threading.Lock()


def worker_state(key, make):
    """The worker's object for ``key``, made by ``make()`` the first time this worker needs it.

    One per worker: a local pool's process, this process for the inline executor, a Dask worker's
    thread (the FMUs' instances are not shared between threads).  Objects with a ``close()`` method
    are closed when the process ends.
    """
    store = getattr(_STATE, "objects", None)
    if store is None:
        store = _STATE.objects = {}
    if key not in store:
        made = make()
        store[key] = made
        if callable(getattr(made, "close", None)):
            with _CLOSE_LOCK:
                if not _TO_CLOSE:
                    atexit.register(_close_all)
                _TO_CLOSE.append(made)
    return store[key]


def _close_all() -> None:
    while _TO_CLOSE:
        try:
            _TO_CLOSE.pop().close()
        except Exception:  # noqa: BLE001 - the process is ending: close what can be closed
            pass


def forget_worker_state() -> None:
    """Drop this worker's objects (closing those with a close()): tests, and the inline executor's close."""
    store = getattr(_STATE, "objects", None) or {}
    for made in store.values():
        if made in _TO_CLOSE:
            _TO_CLOSE.remove(made)
            try:
                made.close()
            except Exception:  # noqa: BLE001 - what cannot be closed is left to the process's end
                pass
    store.clear()


# ------------------------------------------------------------------ shipped files
def sha256_of(path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@dataclass(frozen=True)
class Shipment:
    """The files a cluster's tasks need: {name: (sha256, file name)}; their bytes travel separately
    (scattered once to every worker) as {sha256: bytes}."""

    files: tuple  # ((name, sha256, file name), ...)

    @classmethod
    def of(cls, files: dict) -> tuple:
        """(Shipment, {sha256: bytes}) of {name: path}."""
        entries, blobs = [], {}
        for name, path in files.items():
            data = Path(path).read_bytes()
            digest = hashlib.sha256(data).hexdigest()
            blobs[digest] = data
            entries.append((name, digest, Path(path).name))
        return cls(tuple(entries)), blobs


def cache_dir() -> Path:
    return Path(tempfile.gettempdir()) / CACHE_FOLDER


def cached_file(digest: str, filename: str, blobs: dict) -> Path:
    """The file of SHA-256 ``digest`` in this host's cache, written there from ``blobs`` when missing.

    A file already at that path is used only if its SHA-256 is ``digest`` (a truncated, corrupted or
    foreign file is replaced from the bytes received); bytes whose SHA-256 is not ``digest`` are an error.
    """
    path = cache_dir() / digest[:20] / filename
    if not path.exists() or sha256_of(path) != digest:
        data = blobs[digest]
        if hashlib.sha256(data).hexdigest() != digest:
            raise RuntimeError(f"the bytes received for {filename} do not have the SHA-256 the client sent")
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_name(f".{filename}.{os.getpid()}.{threading.get_ident()}.part")
        partial.write_bytes(data)
        os.replace(partial, path)  # atomic: other workers of this host see all or nothing
    return path


def local_files(shipment: Shipment, blobs: dict) -> dict:
    """{name: path on this host} of a shipment, checked once per worker and then reused."""
    def make():
        return {name: cached_file(digest, filename, blobs) for name, digest, filename in shipment.files}

    return worker_state(("shipped files", shipment), make)


# ------------------------------------------------------------------ the worker side of a task
def run_task(function, item, files=None, shipment: Shipment | None = None):
    """Run one task where it landed: ``function(item)``, or ``function(item, files)`` with the files
    of this host (``files`` as given on this machine, or the ``shipment``'s cached copies, whose
    bytes a Dask worker receives as ``files``).  A worker that SIGTERM reached ends after it."""
    try:
        if shipment is not None:
            return function(item, local_files(shipment, files))
        if files is not None:
            return function(item, files)
        return function(item)
    finally:
        termination.exit_if_stopped()


__all__ = ["Done", "WorkerLost", "SchedulerLost", "ExecutorError", "worker_state", "forget_worker_state", "Shipment", "cached_file",
           "local_files", "cache_dir", "sha256_of", "run_task"]
