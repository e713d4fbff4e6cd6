"""Servers as users run them, started for the tests on 127.0.0.1 and stopped at the end: a throwaway
PostgreSQL cluster (Debian's ``postgresql`` package, initdb into a temporary folder as an unprivileged
user, password authentication) and a Dask cluster of separate processes (``dask scheduler`` and
``dask worker`` started with the commands docs/studies.md prints).

The fixtures of tests/conftest.py (``postgres``, ``dask_cluster``) build on these; a study's tests
(tune, sweep, the Monte Carlo study) take them as they are.  Every process started here is ended by
the helper that started it, by its own id.
"""
from __future__ import annotations

import glob
import os
import pwd
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: the commands of docs/studies.md (on a cluster), with the test's port and folders filled in
SCHEDULER_COMMAND = "dask scheduler --host 127.0.0.1 --port {port} --no-dashboard"
WORKER_COMMAND = "dask worker tcp://127.0.0.1:{port} --nthreads 1 --no-dashboard --host 127.0.0.1"
START_TIMEOUT_S = 90.0
POSTGRES_USER = "afc"  # the cluster's superuser, with a password
SERVICE_ACCOUNT = "postgres"  # the system user Debian's package creates: initdb refuses to run as root


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _end_group(process: subprocess.Popen, grace_s: float = 10.0) -> None:
    """SIGTERM to the process's group (it was started in a session of its own), then SIGKILL."""
    if process.poll() is not None:
        return
    try:
        os.killpg(process.pid, signal.SIGTERM)
        process.wait(grace_s)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait(10)
    except ProcessLookupError:
        pass


# ------------------------------------------------------------------ PostgreSQL
def postgres_bin() -> Path | None:
    """The newest ``/usr/lib/postgresql/<version>/bin`` with initdb and pg_ctl (Debian's layout), or the
    folder of an initdb on PATH; None when PostgreSQL is not installed."""
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"), key=lambda p: int(Path(p).parts[-3]))
    if found:
        return Path(found[-1]).parent
    initdb = shutil.which("initdb")
    return Path(initdb).parent if initdb else None


class PostgresServer:
    """A PostgreSQL cluster in a temporary folder, listening on 127.0.0.1 only, password required."""

    def __init__(self, bin_dir: Path):
        self.bin = Path(bin_dir)
        self.port = free_port()
        self.user = POSTGRES_USER
        self.password = "pw-" + secrets.token_hex(12)  # a token the tests grep every output for
        self.folder = Path(tempfile.mkdtemp(prefix="afc-postgres-"))
        self.data = self.folder / "data"
        self.log = self.folder / "server.log"
        self.as_service = os.geteuid() == 0  # root (CI): run the server as the package's system user
        self.started = False

    def _command(self, *argv) -> list:
        command = [str(self.bin / argv[0]), *map(str, argv[1:])]
        if self.as_service:
            return ["runuser", "-u", SERVICE_ACCOUNT, "--", *command]
        return command

    def _run(self, *argv, env=None) -> subprocess.CompletedProcess:
        return subprocess.run(self._command(*argv), cwd=self.folder, capture_output=True, text=True, env=env,
                              timeout=START_TIMEOUT_S, check=False)

    def start(self) -> "PostgresServer":
        password_file = self.folder / "password"
        password_file.write_text(self.password + "\n")
        if self.as_service:
            account = pwd.getpwnam(SERVICE_ACCOUNT)
            for path in (self.folder, password_file):
                os.chown(path, account.pw_uid, account.pw_gid)
        made = self._run("initdb", "-D", self.data, "-U", self.user, "--auth=scram-sha-256",
                         f"--pwfile={password_file}", "-E", "UTF8", "--no-instructions")
        password_file.unlink()
        if made.returncode:
            raise RuntimeError(f"initdb failed: {made.stderr.strip() or made.stdout.strip()}")
        options = f"-c listen_addresses=127.0.0.1 -p {self.port} -k {self.folder} -c fsync=off"
        started = self._run("pg_ctl", "-D", self.data, "-o", options, "-l", self.log, "-w", "-t", "60", "start")
        if started.returncode:
            raise RuntimeError(f"pg_ctl start failed: {started.stderr.strip()} {self.log_text()}")
        self.started = True
        return self

    def log_text(self) -> str:
        try:
            return self.log.read_text()[-2000:]
        except OSError:
            return ""

    def url(self, database: str, password: bool = True, driver: str = "psycopg", port: int | None = None) -> str:
        secret = f":{self.password}" if password else ""
        return f"postgresql+{driver}://{self.user}{secret}@127.0.0.1:{port or self.port}/{database}"

    def create_database(self, name: str) -> str:
        """A new empty database; returns its name."""
        env = dict(os.environ, PGPASSWORD=self.password)
        made = subprocess.run([str(self.bin / "createdb"), "-h", "127.0.0.1", "-p", str(self.port), "-U", self.user,
                               name], capture_output=True, text=True, env=env, timeout=60, check=False)
        if made.returncode:
            raise RuntimeError(f"createdb {name} failed: {made.stderr.strip()}")
        return name

    def stop(self) -> None:
        if self.started:
            self._run("pg_ctl", "-D", self.data, "-m", "immediate", "-w", "stop")
            self.started = False
        shutil.rmtree(self.folder, ignore_errors=True)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


# ------------------------------------------------------------------ Dask
class DaskCluster:
    """``dask scheduler`` and ``workers`` ``dask worker`` processes on 127.0.0.1, one thread each, each
    command in a session of its own (a worker is its nanny and the worker process under it).

    The workers' temporary folder (where they cache the FMUs the client ships) is ``folder/tmp``.
    """

    def __init__(self, workers: int = 2, folder: Path | None = None):
        self.count = workers
        self.folder = Path(folder or tempfile.mkdtemp(prefix="afc-dask-"))
        self.own_folder = folder is None
        self.port = free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.scheduler = None
        self.workers = []
        self.temp = self.folder / "tmp"

    def _env(self) -> dict:
        bin_dir = str(Path(sys.executable).parent)  # the dask command of this interpreter's environment
        return dict(os.environ, TMPDIR=str(self.temp), PATH=bin_dir + os.pathsep + os.environ.get("PATH", ""),
                    DASK_TEMPORARY_DIRECTORY=str(self.temp))

    def _start(self, command: str, log_name: str) -> subprocess.Popen:
        log = open(self.folder / log_name, "ab")
        try:
            return subprocess.Popen(command.split(), cwd=self.folder, stdin=subprocess.DEVNULL, stdout=log,
                                    stderr=subprocess.STDOUT, env=self._env(), start_new_session=True)
        finally:
            log.close()

    def start(self) -> "DaskCluster":
        self.temp.mkdir(parents=True, exist_ok=True)
        self.scheduler = self._start(SCHEDULER_COMMAND.format(port=self.port), "scheduler.log")
        for index in range(self.count):
            self.start_worker(index)
        self.wait_for_workers(self.count)
        return self

    def start_worker(self, index: int) -> subprocess.Popen:
        worker = self._start(WORKER_COMMAND.format(port=self.port)
                             + f" --local-directory {self.folder / f'worker{index}'}", f"worker{index}.log")
        if index < len(self.workers):
            self.workers[index] = worker
        else:
            self.workers.append(worker)
        return worker

    def wait_for_workers(self, count: int, timeout_s: float = START_TIMEOUT_S) -> None:
        from distributed import Client

        deadline = time.monotonic() + timeout_s
        with Client(self.address, timeout=f"{int(timeout_s)}s", set_as_default=False) as client:
            while len(client.scheduler_info(n_workers=-1)["workers"]) < count:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"{count} Dask workers did not join within {timeout_s:g} s: {self.logs()}")
                time.sleep(0.2)

    def logs(self) -> str:
        return " | ".join(f"{path.name}: {path.read_text(errors='replace')[-600:]}"
                          for path in sorted(self.folder.glob("*.log")))

    def worker_address(self, index: int) -> str:
        """The address worker ``index`` registered with (its log's last start)."""
        text = (self.folder / f"worker{index}.log").read_text(errors="replace")
        return re.findall(r"Start worker at:\s+(\S+)", text)[-1]

    def busy_worker(self, timeout_s: float = START_TIMEOUT_S, alive=lambda: True) -> int | None:
        """The index of a live worker that holds a task now (waits for one): a kill that loses work; None
        once ``alive()`` is false (the client whose tasks they would be has ended)."""
        from distributed import Client

        deadline = time.monotonic() + timeout_s
        with Client(self.address, timeout=f"{int(timeout_s)}s", set_as_default=False) as client:
            while time.monotonic() < deadline:
                if not alive():
                    return None
                processing = client.processing()
                for index, process in enumerate(self.workers):
                    if process.poll() is None and processing.get(self.worker_address(index)):
                        return index
                time.sleep(0.01)
        raise RuntimeError(f"no Dask worker held a task within {timeout_s:g} s: {self.logs()}")

    def kill_worker(self, index: int) -> None:
        """SIGKILL to a worker command and everything under it, as when its host is lost."""
        os.killpg(self.workers[index].pid, signal.SIGKILL)
        self.workers[index].wait(10)

    def kill_scheduler(self) -> None:
        os.killpg(self.scheduler.pid, signal.SIGKILL)
        self.scheduler.wait(10)

    def stop(self) -> None:
        for process in [*self.workers, self.scheduler]:
            if process is not None:
                _end_group(process)
        if self.own_folder:
            shutil.rmtree(self.folder, ignore_errors=True)

    def __enter__(self):
        try:
            return self.start()
        except BaseException:
            self.stop()
            raise

    def __exit__(self, *exc):
        self.stop()
