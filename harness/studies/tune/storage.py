"""The database and the study: Optuna's RDB storage (SQLite by default, write-ahead log), a study
checked against the settings it was made with, the recovery of trials whose process died, the
heartbeat of this process's running trials, and what the study's trials say (outcome, feasible,
best)."""
from __future__ import annotations

import datetime
import json
import math
import os
import re
import socket
import threading
import time as clock
import warnings
from pathlib import Path

from ... import cli_args
from ...fmi import process_alive
from .config import Prepared, shown_url
from .errors import TuneError
from .space import sample_of

HEARTBEAT_S = 10  # a running trial's heartbeat (Optuna's RDB heartbeat)
GRACE_S = 120  # a trial without heartbeat for this long belongs to a dead process: failed and retried
ORPHAN_S = 15  # a RUNNING trial still without owner this long after it started: its process died


def _quiet_optuna():
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    warnings.filterwarnings("ignore", module=r"optuna(\..*)?")
    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)


def _sqlite_pragmas(storage) -> None:
    """Write-ahead log, fsync at checkpoints: cheaper commits than SQLite's default rollback journal
    (docs/tuning.md has the figures), and a committed trial survives a killed process (not a power cut)."""
    from sqlalchemy import event

    @event.listens_for(storage.engine, "connect")
    def _on_connect(connection, _record):
        cursor = connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute("PRAGMA synchronous=NORMAL")
        cursor.close()

    storage.engine.dispose()  # connections opened from here on get the pragmas


#: network file systems, on which SQLite's locks and its write-ahead log's shared memory do not hold
NETWORK_FILE_SYSTEMS = ("nfs", "nfs4", "cifs", "smb3", "smbfs", "ncpfs", "afs", "9p", "fuse.sshfs", "lustre", "gpfs",
                        "ceph", "fuse.ceph", "glusterfs", "fuse.glusterfs", "beegfs", "fuse.s3fs", "davfs")
#: the SQLAlchemy dialect+driver -> (the driver's module, how to install it)
DRIVERS = {"postgresql": ("psycopg2", "use postgresql+psycopg://... with psycopg 3, in the postgres extra: "
                                      "pip install -e '.[postgres]'"),
           "postgresql+psycopg": ("psycopg", "pip install -e '.[postgres]' (psycopg 3)"),
           "postgresql+psycopg2": ("psycopg2", "pip install psycopg2-binary, or use postgresql+psycopg://... with "
                                               "the postgres extra: pip install -e '.[postgres]'"),
           "mysql": ("MySQLdb", "pip install mysqlclient, or use mysql+pymysql://... with pip install pymysql")}


def sqlite_file(url: str) -> Path | None:
    """The file of an SQLite URL (None for another database or an in-memory one)."""
    if not url.startswith("sqlite:///"):
        return None
    path = url[len("sqlite:///"):].split("?", 1)[0]
    return None if path in ("", ":memory:") else Path(path)


def file_system_of(path: Path, mounts: str | None = None) -> str:
    """The type of the file system that holds ``path`` (Linux: /proc/mounts; '' where unknown)."""
    if mounts is None:
        try:
            mounts = Path("/proc/mounts").read_text()
        except OSError:
            return ""
    folder = str(Path(os.path.abspath(path)).parent)
    best, kind = "", ""
    for line in mounts.splitlines():
        fields = line.split()
        if len(fields) < 3:
            continue
        point = fields[1].replace("\\040", " ")
        inside = folder == point or folder.startswith(point.rstrip("/") + "/")
        if inside and len(point) >= len(best):
            best, kind = point, fields[2]
    return kind


def refuse_shared_sqlite(url: str, mounts: str | None = None) -> None:
    """An SQLite file on a network file system is refused (one line): its locks and write-ahead log hold
    for the processes of one host only, so tune processes on several hosts would corrupt it."""
    path = sqlite_file(url)
    if path is None:
        return
    kind = file_system_of(path, mounts)
    if kind in NETWORK_FILE_SYSTEMS:
        raise TuneError(f"--storage {url}: {path} is on a network file system ({kind}); SQLite's locks and "
                        "write-ahead log hold only for processes of one host: keep the file on a local disk, or "
                        "share the study through a database server (--storage postgresql+psycopg://...; "
                        "docs/tuning.md)")


def _innermost(error: BaseException) -> BaseException:
    """The driver's own error under SQLAlchemy's and Optuna's wrappers."""
    seen = set()
    while id(error) not in seen:
        seen.add(id(error))
        inner = getattr(error, "orig", None) or error.__cause__
        if inner is None:
            break
        error = inner
    return error


def connection_problem(url: str, error: BaseException) -> str:
    """One line saying why the database at ``url`` cannot be opened, and what to do; the URL's password
    never appears in it."""
    shown = shown_url(url)
    root = _innermost(error)
    dialect = url.split("://", 1)[0]
    if isinstance(root, ModuleNotFoundError) or (isinstance(error, ImportError) and "DB access module" in str(error)):
        module, how = DRIVERS.get(dialect, (getattr(root, "name", None) or dialect, "install its SQLAlchemy driver"))
        return f"--storage {shown}: the database driver {module} is not installed: {how}"
    lines = [line.strip() for line in str(root).splitlines() if line.strip()
             and not line.strip().startswith("(Background on this error")]
    text = "; ".join(re.sub(r"^connection failed: ", "", re.sub(r"FATAL:\s+", "", line)) for line in lines)
    text = text or cli_args.one_line(error)
    if "password authentication failed" in text:
        text += " (the password comes from the URL, PGPASSWORD or the password file ~/.pgpass / PGPASSFILE)"
    elif re.search(r'database ".*" does not exist', text):
        text += " (create it first, e.g. createdb NAME, or name one that exists)"
    password = _password_of(url)
    if password:
        text = text.replace(password, "***")
    return f"--storage {shown}: cannot open the database: {text}"


def _password_of(url: str) -> str | None:
    try:
        from sqlalchemy.engine import make_url

        return make_url(url).password
    except Exception:  # noqa: BLE001 - not a URL: nothing to mask beyond shown_url
        return None


def open_storage(url: str):
    """Optuna's RDB storage at ``url`` with heartbeats; a database that cannot be opened is a TuneError
    (one line, the password masked)."""
    import optuna

    _quiet_optuna()
    refuse_shared_sqlite(url)
    sqlite = url.startswith("sqlite")
    for attempt in range(10):
        try:
            storage = optuna.storages.RDBStorage(
                url, engine_kwargs={"connect_args": {"timeout": 120}} if sqlite else None,
                heartbeat_interval=HEARTBEAT_S, grace_period=GRACE_S,
                heartbeat_stale_trial_callback=optuna.storages.RetryHeartbeatStaleTrialCallback())
            if sqlite:
                _sqlite_pragmas(storage)
            storage.get_all_studies()
            return storage
        except Exception as error:  # noqa: BLE001 - any driver's error: one line, exit 2
            text = cli_args.one_line(error)
            # another process creates the schema now: its tables, its version row (optuna then reports
            # the failed commit of ours), or holds the lock
            racing = ("already exists", "alembic_version", "database is locked", "during the commit")
            if any(word in text for word in racing) and attempt < 9:
                clock.sleep(0.2 * (attempt + 1))
                continue
            raise TuneError(connection_problem(url, error)) from None


class StudyWriteError(RuntimeError):
    """The study's database refused a write mid-run (a full disk, a file size limit, a server gone):
    one line naming the database, exit 1; the trials committed before stay in the study."""


def _chain(error: BaseException) -> list:
    found, seen = [], set()
    while error is not None and id(error) not in seen:
        seen.add(id(error))
        found.append(error)
        error = getattr(error, "orig", None) or error.__cause__ or error.__context__
    return found


def storage_write_problem(prepared: Prepared, error: BaseException) -> str | None:
    """One line for an error of the study's database during the run (None for any other error): the
    database's file (or masked URL) and the driver's own words, e.g. "database or disk is full"."""
    import optuna
    from sqlalchemy import exc as sqlalchemy_errors

    chain = _chain(error)
    if not any(isinstance(e, (optuna.exceptions.StorageInternalError, sqlalchemy_errors.SQLAlchemyError))
               for e in chain):
        return None
    root = chain[-1]
    lines = [line.strip() for line in str(root).splitlines() if line.strip()
             and not line.strip().startswith("(Background on this error")]
    text = "; ".join(lines) or type(root).__name__
    password = _password_of(prepared.storage_url)
    if password:
        text = text.replace(password, "***")
    where = sqlite_file(prepared.storage_url) or prepared.storage_shown
    return (f"the study database {where} could not be written: {type(root).__name__}: {text}; the trials "
            "told before are kept: free space (or mend the database) and run the same command to resume")


def _signature_difference(stored: dict, wanted: dict) -> list:
    names = {"scenario_digest": "the scenario's components, connections or bounds (digest)"}
    return [f"{names.get(key, key)} = {json.dumps(stored.get(key))} (now {json.dumps(wanted.get(key))})"
            for key in wanted if stored.get(key) != wanted.get(key)]


def open_study(prepared: Prepared, storage):
    """Create the study (with the starting parameters as its first trial) or load it; a study of the
    same name made with other settings is a TuneError (nothing written)."""
    import optuna

    name = prepared.study_name
    try:
        storage.get_study_id_from_name(name)
        exists = True
    except KeyError:
        exists = False
    if not exists:
        try:
            study = optuna.create_study(storage=storage, study_name=name, direction="minimize")
        except optuna.exceptions.DuplicatedStudyError:  # another process created it meanwhile
            exists = True
        else:
            study.set_user_attr("signature", prepared.signature)
            study.set_user_attr("seed", prepared.config.seed)
            start = sample_of(prepared.dimensions, prepared.fixed)
            study.enqueue_trial(start, user_attrs={"start": True}, skip_if_exists=False)
            return study
    study = optuna.load_study(study_name=name, storage=storage)
    check_signature(study, prepared)
    return study


def check_signature(study, prepared: Prepared) -> None:
    """A TuneError unless the existing ``study`` was made with ``prepared``'s settings (reads only)."""
    name = prepared.study_name
    for _ in range(100):  # a study another process is creating gets its signature within moments
        stored = study.user_attrs.get("signature")
        if stored is not None:
            break
        clock.sleep(0.1)
    else:
        raise TuneError(f"study {name!r} in {prepared.storage_shown} was not made by tune (no signature); "
                        "name another study with --study NAME")
    differences = _signature_difference(stored, prepared.signature)
    if differences:
        raise TuneError(f"study {name!r} in {prepared.storage_shown} was made with other settings: "
                        f"{'; '.join(differences)}; resume it with its settings or name another study with "
                        "--study NAME")


def seed_note(study, prepared: Prepared) -> str | None:
    """A line when this process samples the study with another seed than the one it was made with (a
    study shared on purpose: ``--study NAME`` given to several processes, each with its own seed)."""
    made_with = study.user_attrs.get("seed")
    if made_with is None or made_with == prepared.config.seed:
        return None
    return (f"note: study {prepared.study_name!r} was made with --seed {made_with}; this process samples its "
            f"trials with --seed {prepared.config.seed} (processes sharing a study should differ in seed)")


def check_existing(prepared: Prepared) -> None:
    """Before a run of several studies: an existing study of the same name must have the same settings
    (an SQLite file that is not there yet is not created here)."""
    import optuna

    url = prepared.storage_url
    if url.startswith("sqlite:///"):
        path = url[len("sqlite:///"):]
        if path != ":memory:" and not Path(path).exists():
            return
    storage = open_storage(url)
    try:
        storage.get_study_id_from_name(prepared.study_name)
    except KeyError:
        return
    check_signature(optuna.load_study(study_name=prepared.study_name, storage=storage), prepared)


def _age_s(trial) -> float:
    """Seconds since the trial started (Optuna stores local naive times)."""
    started = trial.datetime_start
    return (datetime.datetime.now() - started).total_seconds() if started else math.inf


def recover_dead_trials(study, mine=()) -> tuple:
    """RUNNING trials of a dead ``tune`` process: failed, and enqueued again with the same parameters
    (Optuna's retry: system attribute failed_trial).  Returns (their numbers, how many trials have no
    owner yet but are younger than ORPHAN_S: a process claims its trial right after asking it).

    A trial's owner (host, pid) is written right after it is asked; one of this host whose process is
    gone is recovered at once, one without an owner once it is ORPHAN_S old (its process died between
    the two writes), one of another host by the heartbeat's grace period (fail_stale_trials).
    """
    import optuna
    from optuna.trial import TrialState

    host, me = socket.gethostname(), os.getpid()
    retry = optuna.storages.RetryHeartbeatStaleTrialCallback()
    recovered, waiting = [], 0
    for trial in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        if trial.number in mine:
            continue
        owner = trial.user_attrs.get("owner")
        if owner is None:
            if _age_s(trial) < ORPHAN_S:
                waiting += 1
                continue
            reason = "its process ended between asking for the trial and claiming it"
        else:
            if owner.get("host") != host or (owner.get("pid") != me and process_alive(owner.get("pid"))):
                continue
            reason = f"its process (pid {owner.get('pid')}) ended before the trial did"
        try:
            study._storage.set_trial_user_attr(trial._trial_id, "outcome", {
                "status": "lost", "reason": f"{reason}; run again as a new trial"})
            if not study._storage.set_trial_state_values(trial._trial_id, state=TrialState.FAIL):
                continue
        except optuna.exceptions.UpdateFinishedTrialError:
            continue
        retry(study, study._storage.get_trial(trial._trial_id))
        recovered.append(trial.number)
    return recovered, waiting


class Heartbeat:
    """Records Optuna heartbeats for this process's running trials (ask-and-tell has no thread of its own)."""

    def __init__(self, storage):
        from optuna.storages._heartbeat import is_heartbeat_enabled

        self.storage, self.ids, self.lock = storage, set(), threading.Lock()
        self.enabled = is_heartbeat_enabled(storage)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True, name="tune-heartbeat")
        if self.enabled:
            self.thread.start()

    def add(self, trial_id: int):
        if self.enabled:
            self.storage.record_heartbeat(trial_id)
            with self.lock:
                self.ids.add(trial_id)

    def remove(self, trial_id: int):
        with self.lock:
            self.ids.discard(trial_id)

    def _run(self):
        while not self.stop.wait(self.storage.get_heartbeat_interval()):
            with self.lock:
                ids = list(self.ids)
            for trial_id in ids:
                try:
                    self.storage.record_heartbeat(trial_id)
                except Exception:  # noqa: BLE001 - a missed beat is retried at the next interval
                    pass

    def close(self):
        self.stop.set()
        if self.enabled:
            self.thread.join(timeout=5)


def outcome_of(trial) -> dict:
    return trial.user_attrs.get("outcome") or {}


def is_feasible(trial) -> bool:
    """Every constraint met (Optuna: every constraint value <= 0)."""
    constraints = trial.constraints or {}
    return all(value <= 0.0 for value in (constraints.values() if isinstance(constraints, dict) else constraints))


def best_trial(trials):
    """The best COMPLETE, feasible trial that was re-run at half the step; None if there is none."""
    from optuna.trial import TrialState

    candidates = [t for t in trials if t.state == TrialState.COMPLETE and is_feasible(t)
                  and outcome_of(t).get("half_step")]
    return min(candidates, key=lambda t: (t.value, t.number)) if candidates else None
