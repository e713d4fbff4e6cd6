"""The rows of a Monte Carlo study, streamed to ``DIR/robustness.csv`` as samples finish, and its
settings in ``DIR/robustness.json``.

One row per (sample, controller): the sample's index, the controller, the drawn values (and the
noise seed), every score of docs/model.md section 9 (scores), whether the controller's chatter
monitor warned, the status (``ok``, ``diverged``, ``failed``) and its reason, the run's wall time
and its loop's, the run's CPU time in its worker and its loop's.  Each row is flushed as it is written (a killed command loses only the samples in
flight; the operating system has every flushed row), and synced to disk at most every SYNC_S; a
last line cut short by a kill is dropped when the file is read back.  A rerun with other settings
is refused (one line), rather than mixed in.
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import time as clock
from pathlib import Path

from ...cases import STATUSES
from ...scenario import ScenarioError
from ...scores import SCORE_KEYS
from ...variants import CONTROLLER_VARIANTS

CSV_NAME = "robustness.csv"
SETTINGS_NAME = "robustness.json"
SYNC_S = 1.0  # rows reach the disk (fsync) at least this often; every row reaches the OS at once (flush)
TRAILING_COLUMNS = (*SCORE_KEYS, "chatter", "status", "reason", "wall_s", "loop_s", "cpu_s", "loop_cpu_s")


def columns(names) -> list:
    return ["sample", "controller", *names, *TRAILING_COLUMNS]


def _number(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return repr(float(value)) if not isinstance(value, int) else str(value)


def cells(key, values, row: dict) -> list:
    sample, controller = key
    return [str(sample), controller, *(_number(v) for v in values),
            *(_number(row["scores"].get(k)) for k in SCORE_KEYS), str(int(row["chatter"])), row["status"],
            row["reason"], f"{row['wall_s']:.6f}", _number(row["loop_s"]), f"{row['cpu_s']:.6f}",
            _number(row["loop_cpu_s"])]


def parse(line: list, names) -> dict | None:
    """A row from its cells; None when incomplete or malformed (a line cut short by a kill)."""
    if len(line) != len(columns(names)):
        return None
    n = len(names)
    try:
        sample, controller = int(line[0]), line[1]
        values = [float(v) for v in line[2:2 + n]]
        first = 2 + n
        scores = {k: (float(v) if v != "" else math.nan) for k, v in zip(SCORE_KEYS, line[first:first + len(SCORE_KEYS)])}
        chatter, status, reason, wall, loop, cpu, loop_cpu = line[first + len(SCORE_KEYS):]
        row = {"sample": sample, "controller": controller, "values": values, "scores": scores,
               "chatter": int(chatter), "status": status, "reason": reason, "wall_s": float(wall),
               "loop_s": float(loop) if loop else math.nan, "cpu_s": float(cpu),
               "loop_cpu_s": float(loop_cpu) if loop_cpu else math.nan}
    except ValueError:
        return None
    if controller not in CONTROLLER_VARIANTS or status not in STATUSES:
        return None
    return row


def read_rows(path, names) -> list:
    """Every complete row of the file (a last line cut short left out)."""
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return []
    text = path.read_text()
    lines = list(csv.reader(io.StringIO(text)))
    if lines and lines[0] != columns(names):
        raise ScenarioError(f"{path} holds a study of other columns ({', '.join(lines[0][2:2 + len(names)])}), "
                            f"not of {', '.join(names)}: use another --out, or remove it to start over")
    complete = text if text.endswith("\n") else text[:text.rfind("\n") + 1]
    return [row for row in (parse(line, names) for line in list(csv.reader(io.StringIO(complete)))[1:])
            if row is not None]


class RowSink:
    """The CSV rewritten with its complete rows (a line cut short dropped), then rows appended one at
    a time, each flushed."""

    def __init__(self, path, names, kept: list):
        self.path, self.names = Path(path), list(names)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        partial = self.path.with_name(self.path.name + ".part")
        with open(partial, "w", newline="") as stream:
            writer = csv.writer(stream, lineterminator="\n")
            writer.writerow(columns(self.names))
            for row in kept:
                writer.writerow(cells((row["sample"], row["controller"]), row["values"], row))
        os.replace(partial, self.path)
        self.stream = open(self.path, "a", newline="")
        self.synced = clock.monotonic()

    def write(self, key, values, row: dict) -> None:
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\n").writerow(cells(key, values, row))
        self.stream.write(buffer.getvalue())
        self.stream.flush()
        if clock.monotonic() - self.synced >= SYNC_S:
            os.fsync(self.stream.fileno())
            self.synced = clock.monotonic()

    def close(self) -> None:
        self.stream.flush()
        os.fsync(self.stream.fileno())
        self.stream.close()


def check_settings(path, settings: dict) -> None:
    """Refuse, in one line, a study whose settings differ from those recorded at ``path``."""
    path = Path(path)
    if not path.exists():
        return
    settings = json.loads(json.dumps(settings))  # as it reads back (tuples as lists)
    try:
        previous = json.loads(path.read_text())
    except (OSError, ValueError):
        raise ScenarioError(f"{path} is not the settings file of a study: use another --out, or remove it") from None
    keys = sorted(set(previous) | set(settings))
    differing = [key for key in keys if previous.get(key) != settings.get(key)]
    if differing:
        what = "; ".join(f"{key}: {_short(previous.get(key))} then, {_short(settings.get(key))} now" for key in differing)
        raise ScenarioError(f"{path.parent} holds a study with other settings ({what}); use another --out, "
                            "or remove the directory to start over")


def _short(value) -> str:
    text = json.dumps(value, sort_keys=True)
    return text if len(text) <= 120 else text[:117] + "..."


def write_settings(path, settings: dict) -> None:
    partial = Path(path).with_name(Path(path).name + ".part")
    partial.write_text(json.dumps(settings, indent=2, sort_keys=True))
    os.replace(partial, path)


__all__ = ["CSV_NAME", "SETTINGS_NAME", "columns", "read_rows", "RowSink", "check_settings", "write_settings"]
