"""The warnings of a host that prints the FMUs' log messages instead of handing them to a logger
callback: the process's stdout and stderr captured, and the lines that say warning kept."""
from __future__ import annotations

import contextlib
import ctypes
import os
import re
import sys
import tempfile


@contextlib.contextmanager
def captured_console():
    """Capture the process's stdout and stderr (file descriptors 1, 2: C hosts print there too)."""
    lines: list = []
    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 1)
        os.dup2(sink.fileno(), 2)
        try:
            yield lines
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            libc.fflush(None)
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            sink.seek(0)
            lines.extend(sink.read().decode("utf-8", "replace").splitlines())


def console_warnings(lines: list) -> list:
    return [line.strip() for line in lines if re.search(r"warn", line, re.IGNORECASE)]
