"""Where the points of a sweep run: a local process pool or a dask.distributed scheduler.

Each point is one :class:`~harness.cases.Case` run by the shared runner
(:func:`~harness.cases.run_case`) and turned into a CSV row.  A Dask worker
receives the FMUs' bytes from the client once and caches them by content hash,
so a point gives the same scores on any host.
"""
from __future__ import annotations

import dataclasses
import hashlib
import multiprocessing
import os
import signal
import tempfile
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from ...cases import Case, run_case
from ...scenario import ScenarioError
from ...scores import SCORE_KEYS
from .grid import SweepPlan

SCHEDULER_TIMEOUT = "20s"  # how long to try reaching a Dask scheduler


def run_point(task: dict, fmu_blobs: dict | None = None) -> dict:
    """Run one point; never raises for a failing simulation (the row says why).

    ``task``: the point's case (grid values, controller and FMU file per instance
    already set) and its grid values.  ``fmu_blobs`` (Dask): {sha256: bytes} of the
    FMUs, written once per host into a cache and used from there.
    """
    case = task["case"]
    if fmu_blobs is not None:
        case = _with_cached_fmus(case, task["fmu_hashes"], fmu_blobs)
    try:
        outcome = run_case(case)
    except SystemExit as stop:  # SIGTERM of a cancelled local pool: the FMUs were freed on the way out
        os._exit(stop.code if isinstance(stop.code, int) else 1)
    scores = {key: outcome[key] for key in SCORE_KEYS} if outcome["status"] == "ok" else {}
    return {"controller": case.controller, "values": list(task["values"]), "scores": scores,
            "wall_s": outcome["wall_s"], "status": outcome["status"],
            "reason": outcome["reason"] or "; ".join(outcome["notes"])}  # e.g. a stop moved to whole steps


def _fmu_cache_dir() -> Path:
    return Path(tempfile.gettempdir()) / "afc-sweep-fmus"


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _with_cached_fmus(case: Case, hashes: dict, blobs: dict) -> Case:
    """Write the FMUs received from the client to this host's cache; point the case at them.

    A file already in the cache is used only if its SHA-256 is the one the client sent
    (a truncated, corrupted or foreign file at that path is replaced from the bytes received).
    """
    files = []
    for instance, (digest, filename) in hashes.items():
        path = _fmu_cache_dir() / digest[:20] / filename
        if not path.exists() or sha256_of(path) != digest:
            data = blobs[digest]
            if hashlib.sha256(data).hexdigest() != digest:
                raise RuntimeError(f"the bytes received for {filename} do not have the SHA-256 the client sent")
            path.parent.mkdir(parents=True, exist_ok=True)
            partial = path.with_name(f".{filename}.{os.getpid()}.part")
            partial.write_bytes(data)
            os.replace(partial, path)  # atomic: other worker processes see all or nothing
        files.append((instance, str(path)))
    return dataclasses.replace(case, fmu_files=tuple(files))


def point_task(plan: SweepPlan, controller: str, values) -> dict:
    """What a worker needs to run one point."""
    case = Case(plan.scenario, controller, algorithm=plan.algorithm, overrides=tuple(zip(plan.names, values)),
                fmu_files=tuple((instance, str(path)) for instance, path in plan.fmu_files.items()))
    return {"case": case, "controller": controller, "values": tuple(values)}


def _ignore_sigint():
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and cancels
    signal.signal(signal.SIGTERM, _stop_worker)  # a cancelled point still frees its FMUs (and their extractions)


def _stop_worker(signum, frame):
    raise SystemExit(128 + signum)


def _outcome(future) -> tuple:
    """(row, None), or (None, error) when the worker itself was lost (the point is not recorded)."""
    try:
        return future.result(), None
    except Exception as error:  # noqa: BLE001 - a crashed or killed worker, a pickling error...
        return None, error


class LocalPool:
    """A process pool on this machine (spawned workers: no state inherited from the parent)."""

    def __init__(self, jobs: int, function=None):
        self.jobs = jobs
        self.function = function or run_point  # tests swap in a module-level wrapper
        self.executor = ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                                            initializer=_ignore_sigint)

    def describe(self) -> str:
        return f"local pool, {self.jobs} process{'es' if self.jobs != 1 else ''}"

    def run(self, tasks):
        futures = [self.executor.submit(self.function, task) for task in tasks]
        for future in as_completed(futures):
            yield _outcome(future)

    def close(self, cancel: bool = False):
        if cancel:  # stop the points under way too: they are not recorded and rerun on resume
            for process in list((getattr(self.executor, "_processes", None) or {}).values()):
                process.terminate()
        self.executor.shutdown(wait=True, cancel_futures=cancel)


class DaskPool:
    """Points go to an existing dask.distributed scheduler; the FMUs travel with them, once per worker."""

    def __init__(self, address: str, plan: SweepPlan):
        try:
            from distributed import Client  # optional: the cluster extra, and a heavy import
        except ImportError:
            raise ScenarioError("--scheduler needs dask.distributed, in the cluster extra: pip install -e '.[cluster]' "
                                "(or pip install 'dask[distributed]')") from None
        try:
            self.client = Client(address, timeout=SCHEDULER_TIMEOUT)
        except (OSError, TimeoutError) as error:
            raise ScenarioError(f"cannot reach the Dask scheduler at {address!r}: {error}") from None
        self.address = address

        def worker_can_run():  # defined here so cloudpickle ships it by value, with its import
            import importlib.util

            return all(importlib.util.find_spec(module) is not None for module in ("harness", "fmpy", "numpy"))

        checks = self.client.run(worker_can_run)
        if not checks:
            self.client.close()
            raise ScenarioError(f"the Dask scheduler at {address!r} has no workers")
        missing = [worker for worker, ok in checks.items() if not ok]
        if missing:
            self.client.close()
            raise ScenarioError(f"Dask workers {', '.join(missing)} cannot import harness, fmpy and numpy: "
                                "install this project on every worker host (pip install '.[cluster]')")
        self.workers = len(checks)
        blobs, self.hashes = {}, {}
        for instance, path in plan.fmu_files.items():
            data = Path(path).read_bytes()
            digest = hashlib.sha256(data).hexdigest()
            blobs[digest] = data
            self.hashes[instance] = (digest, Path(path).name)
        self.blobs = self.client.scatter(blobs, broadcast=True)  # one future: a dict {sha256: bytes}

    def describe(self) -> str:
        return f"Dask scheduler {self.address}, {self.workers} worker{'s' if self.workers != 1 else ''}"

    def run(self, tasks):
        from distributed import as_completed as dask_as_completed  # optional, as above

        self.futures = []
        for task in tasks:
            task = dict(task, fmu_hashes=self.hashes)
            self.futures.append(self.client.submit(run_point, task, self.blobs, pure=False))
        for future in dask_as_completed(self.futures):
            yield _outcome(future)

    def close(self, cancel: bool = False):
        if cancel and getattr(self, "futures", None):
            self.client.cancel(self.futures)
        self.client.close()
