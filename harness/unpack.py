"""Unpacking FMU and SSP archives: bounded, inside its folder, in a folder any FMU can run from, never left behind.

What an archive may hold is checked from its zip directory before a byte is unpacked
(:func:`check_archive`), each limit of :class:`Limits` a one-line :class:`ArchiveError` naming the
archive, the entry and the limit:

* at most ``entries`` entries, ``entry_bytes`` declared bytes each and ``total_bytes`` in all (an SSP's
  FMUs counted with what they hold in turn);
* an entry of more than ``RATIO_FROM_BYTES`` may expand at most ``ratio`` times its compressed size
  (a zip bomb declares gigabytes that compress to kilobytes);
* no symbolic link, no absolute path, drive, backslash or ``..`` component: nothing lands outside the
  folder it is unpacked into.

The unpacking itself (:func:`extract_archive`) writes no more than each entry declares (zipfile reads an
entry up to its declared size and checks its CRC), and a failed unpacking removes what it wrote.

Where: :func:`unpack_folder` makes a new folder whose ``file:`` URI needs no percent-escape but ``%20``
(ASCII letters, digits, ``-._~``, spaces): pythonfmu 0.7's C++ wrapper turns the resource URI a host gives
back into a path by decoding ``%20`` alone, so an FMU it built crashes its host (segmentation fault) when
unpacked where the path holds ``é``, ``&``, ``%`` or ``<`` (docs/using_fmus.md).  The temporary folder
is used when it is such a folder, else the first of ``AFC_UNPACK_DIR`` and the system's usual
temporary folders that is; :func:`uri_safe` says whether a folder is.

Never left behind: every folder made here is registered with its process and removed when the process
ends (atexit, which SIGTERM reaches in the harness as it does Ctrl-C: harness/termination.py) or when
its owner is done (:func:`remove_folder`); the folders that killed processes of this host left
(their pid in the name) are removed by the next process's first :func:`unpack_folder`.
"""
from __future__ import annotations

import atexit
import contextlib
import os
import shutil
import stat
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

#: the names of the folders made here: afc-<pid>-<label>-<random>
PREFIX = "afc-"
#: below this declared size an entry's compression ratio is not checked (small text compresses well)
RATIO_FROM_BYTES = 1 << 20
MiB = 1 << 20
#: the variable that chooses the unpack folder's parent (when the temporary folder is not URI-safe)
UNPACK_DIR_VARIABLE = "AFC_UNPACK_DIR"
#: the variable that raises (or lowers) the limits on what an archive may unpack to, in MiB
LIMIT_VARIABLE = "AFC_UNPACK_LIMIT_MB"


class ArchiveError(ValueError):
    """An archive that is refused or cannot be unpacked; the message names it and the entry."""


class UnsafeFolder(ArchiveError):
    """An FMU that cannot run from the folder it would be unpacked into (pythonfmu's, see above)."""


@dataclass(frozen=True)
class Limits:
    """What one archive may unpack to (declared sizes, read before unpacking)."""

    total_bytes: int = 2048 * MiB
    entry_bytes: int = 1024 * MiB
    entries: int = 20000
    ratio: float = 200.0  # largest uncompressed / compressed size of an entry of more than RATIO_FROM_BYTES

    @classmethod
    def default(cls) -> "Limits":
        """The limits, with total and per-entry size from $AFC_UNPACK_LIMIT_MB if set."""
        text = os.environ.get(LIMIT_VARIABLE, "").strip()
        if not text:
            return cls()
        try:
            megabytes = float(text)
        except ValueError:
            megabytes = float("nan")
        if not megabytes > 0 or megabytes == float("inf"):
            raise ArchiveError(f"{LIMIT_VARIABLE}={text!r}: give a number of MiB > 0")
        size = int(megabytes * MiB)
        return cls(total_bytes=size, entry_bytes=size)


def _mib(count: float) -> str:
    return f"{count / MiB:.1f} MiB" if count >= 0.1 * MiB else f"{int(count)} bytes"


def _entry_problem(info: zipfile.ZipInfo) -> str | None:
    """Why an entry may not be unpacked (a link, or a path that leaves the folder), or None."""
    name = info.filename
    mode = info.external_attr >> 16
    if stat.S_ISLNK(mode):
        return "is a symbolic link (refused: it could point outside the folder)"
    if "\\" in name:
        return "holds a backslash (zip paths use '/')"
    if name.startswith("/") or (len(name) > 1 and name[1] == ":"):
        return "is an absolute path (refused: it would land outside the folder)"
    if ".." in PurePosixPath(name).parts:
        return "has a '..' component (refused: it would land outside the folder)"
    return None


def _check_entries(infos, where: str, limits: Limits) -> int:
    """The declared bytes of ``infos`` after checking every entry against ``limits``."""
    if len(infos) > limits.entries:
        raise ArchiveError(f"{where}: {len(infos)} entries; the limit is {limits.entries}")
    total = 0
    for info in infos:
        problem = _entry_problem(info)
        if problem:
            raise ArchiveError(f"{where}: entry {info.filename!r} {problem}")
        if info.file_size > limits.entry_bytes:
            raise ArchiveError(f"{where}: entry {info.filename!r} declares {_mib(info.file_size)} unpacked; the "
                               f"limit is {_mib(limits.entry_bytes)} per entry (${LIMIT_VARIABLE} raises it)")
        if info.file_size > RATIO_FROM_BYTES and info.file_size > limits.ratio * max(info.compress_size, 1):
            raise ArchiveError(f"{where}: entry {info.filename!r} expands {info.file_size / max(info.compress_size, 1):.0f} "
                               f"times ({_mib(info.compress_size)} to {_mib(info.file_size)}); the limit is "
                               f"{limits.ratio:g} times for an entry of more than {_mib(RATIO_FROM_BYTES)} "
                               "(a zip bomb?)")
        total += info.file_size
    return total


def check_archive(path, limits: Limits | None = None, nested: tuple = ()) -> int:
    """Check the zip directory of the archive at ``path`` (and of its entries whose name ends with one of
    ``nested``, e.g. the FMUs of an SSP); return the declared bytes it unpacks to, nested ones included."""
    limits = limits or Limits.default()
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as archive:
            infos = archive.infolist()
            total = _check_entries(infos, str(path), limits)
            for info in infos:
                if nested and info.filename.endswith(tuple(nested)) and not info.is_dir():
                    where = f"{path}: {info.filename}"
                    try:
                        with archive.open(info) as stream, zipfile.ZipFile(stream) as inner:
                            total += _check_entries(inner.infolist(), where, limits)
                    except zipfile.BadZipFile as error:
                        raise ArchiveError(f"{where} is not a zip archive ({error})") from None
    except zipfile.BadZipFile as error:
        raise ArchiveError(f"{path} is not a zip archive ({error})") from None
    except OSError as error:
        raise ArchiveError(f"{path} cannot be read: {error.strerror or error}") from None
    if total > limits.total_bytes:
        raise ArchiveError(f"{path} declares {_mib(total)} unpacked in all; the limit is "
                           f"{_mib(limits.total_bytes)} (${LIMIT_VARIABLE} raises it)")
    return total


def extract_archive(path, folder, limits: Limits | None = None) -> Path:
    """Unpack the archive at ``path`` into the existing, empty folder ``folder`` after :func:`check_archive`; on
    any failure what was unpacked is removed (the folder is left empty) and the error names the archive."""
    check_archive(path, limits)
    folder = Path(folder)
    root = folder.resolve()
    try:
        with zipfile.ZipFile(path) as archive:
            for info in archive.infolist():
                target = folder / info.filename
                if not target.resolve().is_relative_to(root):  # checked above; once more where it is written
                    raise ArchiveError(f"{path}: entry {info.filename!r} would land outside {folder}")
                if info.is_dir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                with archive.open(info) as source, open(target, "wb") as sink:
                    shutil.copyfileobj(source, sink, 1 << 20)
    except BaseException as error:
        for child in list(folder.iterdir()) if folder.is_dir() else ():
            if child.is_dir() and not child.is_symlink():
                shutil.rmtree(child, ignore_errors=True)
            else:
                child.unlink(missing_ok=True)
        if isinstance(error, (zipfile.BadZipFile, OSError, EOFError)):
            reason = getattr(error, "strerror", None) or str(error)
            raise ArchiveError(f"{path} could not be unpacked into {folder}: {reason}") from None
        raise
    return folder


# ------------------------------------------------------------------ where
def uri_safe(folder) -> bool:
    """Whether the ``file:`` URI of ``folder`` needs no percent-escape but ``%20`` (which every FMU decodes)."""
    uri = Path(os.path.abspath(folder)).as_uri()
    return "%" not in uri.replace("%20", "")


def _candidate_parents() -> list:
    """Where unpack folders may go, in order of preference."""
    chosen = os.environ.get(UNPACK_DIR_VARIABLE)
    if chosen:
        return [chosen]
    candidates = [tempfile.gettempdir()]
    if sys.platform.startswith("win"):
        candidates += [os.environ[name] for name in ("PUBLIC", "ProgramData") if os.environ.get(name)]
    else:
        candidates += ["/tmp", "/var/tmp", "/dev/shm"]
    return candidates


_OWNED: dict = {}  # folder -> pid of the process that made it
_AT_EXIT: list = []  # one atexit registration (and one sweep of dead processes' folders) per process


def unpack_folder(label: str) -> Path:
    """A new empty folder ``afc-<pid>-<label>-*`` to unpack into, in a parent whose URI is safe (see above;
    the temporary folder when it is), removed at exit if its owner has not removed it (:func:`remove_folder`).

    An unsafe ``$AFC_UNPACK_DIR`` is refused; with none of the candidates safe and writable, the
    temporary folder is used (native FMUs run from any folder; :func:`uri_safe` tells the caller)."""
    if not _AT_EXIT or _AT_EXIT[0] != os.getpid():
        _AT_EXIT[:] = [os.getpid()]
        atexit.register(remove_owned)
        remove_dead_folders()
    chosen = os.environ.get(UNPACK_DIR_VARIABLE)
    if chosen and not uri_safe(chosen):
        raise UnsafeFolder(f"{UNPACK_DIR_VARIABLE}={chosen}: its file: URI needs percent-escapes; give a folder "
                           "whose path holds ASCII letters, digits, '-', '_', '.', '~' and spaces only")
    prefix = f"{PREFIX}{os.getpid()}-{label}-"
    folder = None
    for parent in _candidate_parents():
        if not uri_safe(parent):
            continue
        try:
            folder = tempfile.mkdtemp(prefix=prefix, dir=parent)
            break
        except OSError:
            if chosen:
                raise
    if folder is None:  # no safe parent: the temporary folder all the same
        folder = tempfile.mkdtemp(prefix=prefix)
    _OWNED[folder] = os.getpid()
    return Path(folder)


def remove_folder(folder) -> None:
    """Remove a folder of :func:`unpack_folder` (and forget it)."""
    _OWNED.pop(str(folder), None)
    shutil.rmtree(folder, ignore_errors=True)


def remove_owned() -> None:
    """Remove every folder this process made and has not removed yet."""
    for folder, pid in list(_OWNED.items()):
        if pid == os.getpid():
            remove_folder(folder)


@contextlib.contextmanager
def private_temporary_folder(label: str):
    """Within the block, the temporary folder (Python's ``tempfile`` and ``$TMPDIR``, which fmpy, Ecos and
    OMSimulator unpack into) is a new folder of :func:`unpack_folder`; afterwards both are restored and the
    folder is removed with whatever a third-party engine left in it, whether the block succeeded or not."""
    folder = unpack_folder(label)
    previous, previous_variable = tempfile.tempdir, os.environ.get("TMPDIR")
    tempfile.tempdir = str(folder)
    os.environ["TMPDIR"] = str(folder)
    try:
        yield folder
    finally:
        tempfile.tempdir = previous
        if previous_variable is None:
            os.environ.pop("TMPDIR", None)
        else:
            os.environ["TMPDIR"] = previous_variable
        remove_folder(folder)


def process_alive(pid) -> bool:
    """Whether process ``pid`` of this host is running (one that cannot be asked counts as running)."""
    try:
        pid = int(pid)
    except (TypeError, ValueError):
        return True
    if sys.platform.startswith("win"):  # os.kill(pid, 0) would send CTRL_C_EVENT there: ask the kernel instead
        return _windows_process_alive(pid)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True
    return True


def _windows_process_alive(pid: int) -> bool:
    import ctypes  # here, not at module level: Windows only

    kernel32 = ctypes.WinDLL("kernel32", use_last_error=True)
    handle = kernel32.OpenProcess(0x1000, False, pid)  # PROCESS_QUERY_LIMITED_INFORMATION
    if not handle:
        return ctypes.get_last_error() != 87  # ERROR_INVALID_PARAMETER: no such process; denied: running
    try:
        code = ctypes.c_ulong()
        if not kernel32.GetExitCodeProcess(handle, ctypes.byref(code)):
            return True
        return code.value == 259  # STILL_ACTIVE
    finally:
        kernel32.CloseHandle(handle)


def remove_dead_folders() -> None:
    """The unpack folders that killed processes of this host left in the candidate parents."""
    for parent in dict.fromkeys(_candidate_parents()):
        try:
            folders = list(Path(parent).glob(f"{PREFIX}*-*"))
        except OSError:
            continue
        for folder in folders:
            pid = folder.name[len(PREFIX):].split("-", 1)[0]
            if pid.isdigit() and int(pid) != os.getpid() and not process_alive(int(pid)) and folder.is_dir():
                shutil.rmtree(folder, ignore_errors=True)


__all__ = ["ArchiveError", "UnsafeFolder", "Limits", "process_alive", "check_archive", "extract_archive", "uri_safe", "unpack_folder",
           "remove_folder", "remove_owned", "private_temporary_folder", "remove_dead_folders", "PREFIX", "RATIO_FROM_BYTES",
           "UNPACK_DIR_VARIABLE", "LIMIT_VARIABLE"]
