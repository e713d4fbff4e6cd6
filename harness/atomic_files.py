"""Every file the project writes is written whole or not at all.

A file is written to a temporary file beside its target (``.<name>.<random>.partial``, same folder and
so the same file system), flushed to the disk, given the mode of an ordinary new file and renamed over
the target in one step (``os.replace``).  A reader never sees a half-written file; when writing fails
(a full disk, a file-size limit, a folder that cannot be written, an exception of the code that writes)
the temporary file is removed, the previous file is left as it was, and the error is one
:class:`OutputError` naming the file: "cannot write results/run.csv: No space left on device; the
previous file is unchanged".

* :func:`replacing`: a stream to write to, in text or binary mode (``np.savetxt``, ``csv``, ``zipfile``,
  ``ElementTree`` and matplotlib's ``savefig`` write to it);
* :func:`write_text`, :func:`write_bytes`: a whole text (UTF-8) or byte string;
* :func:`write_files`: several files that belong together, renamed only once all are written;
* :func:`save_figure`: a matplotlib figure in the format of the target's suffix;
* :func:`ordinary_file_mode`: what a file made by ``mkstemp`` (0600) gets before it replaces the target.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

PARTIAL_SUFFIX = ".partial"


class OutputError(RuntimeError):
    """A file that could not be written; the previous one (if any) is unchanged."""

    def __init__(self, path, error: BaseException):
        self.path, self.error = Path(path), error
        reason = getattr(error, "strerror", None) or str(error) or type(error).__name__
        state = "the previous file is unchanged" if self.path.is_file() else "no file was written"
        super().__init__(f"cannot write {path}: {reason}; {state}")


def ordinary_file_mode(path) -> None:
    """Give a file made by mkstemp (private, 0600) the mode of an ordinary new file (0666 less the umask)."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


@contextlib.contextmanager
def replacing(path, mode: str = "w", encoding: str | None = "utf-8", newline: str | None = None):
    """A stream (``mode`` "w" or "wb") whose content replaces the file at ``path`` when the block ends
    without an exception; the folder is made if it is missing.  An OSError of the writing is an
    OutputError naming the file; any exception leaves the previous file as it was."""
    if mode not in ("w", "wb"):
        raise ValueError(f"mode {mode!r}: 'w' (text) or 'wb' (binary)")
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=PARTIAL_SUFFIX)
    except OSError as error:
        raise OutputError(path, error) from None
    try:
        options = {} if mode == "wb" else {"encoding": encoding, "newline": newline}
        with os.fdopen(handle, mode, **options) as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())
        ordinary_file_mode(temporary)
        os.replace(temporary, path)
    except BaseException as error:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        if isinstance(error, OSError):
            raise OutputError(path, error) from None
        raise


def write_text(path, text: str) -> Path:
    """``text`` (UTF-8) as the whole content of ``path``."""
    with replacing(path, "w") as stream:
        stream.write(text)
    return Path(path)


def write_bytes(path, data: bytes) -> Path:
    """``data`` as the whole content of ``path``."""
    with replacing(path, "wb") as stream:
        stream.write(data)
    return Path(path)


def write_files(contents: dict) -> list:
    """Several files that belong together ({path: text or bytes}): every temporary file is written first and
    only then are they renamed over their targets, so a failure while writing leaves every previous file."""
    stack = contextlib.ExitStack()
    with stack:
        for path, content in contents.items():
            stream = stack.enter_context(replacing(path, "wb"))
            stream.write(content.encode() if isinstance(content, str) else content)
    return [Path(path) for path in contents]


def save_figure(figure, path, **options) -> Path:
    """A matplotlib figure saved to ``path`` in the format its suffix names (``.png``, ``.svg``, ...)."""
    path = Path(path)
    with replacing(path, "wb") as stream:
        figure.savefig(stream, format=path.suffix.lstrip(".") or "png", **options)
    return path


__all__ = ["OutputError", "replacing", "write_text", "write_bytes", "write_files", "save_figure", "ordinary_file_mode",
           "PARTIAL_SUFFIX"]
