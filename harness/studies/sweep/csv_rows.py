"""The resumable CSV of a sweep: one row per point, streamed and flushed as points finish.

``DIR/sweep.csv`` holds the controller, the grid values, every score of docs/model.md
section 9 (scores), the wall time of the point, its status and the reason; a row cut short
by a kill is dropped on resume.  ``DIR/sweep.json`` holds the settings of the sweep
so that a resume with other settings is refused rather than mixed in.
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path

from ...cases import STATUSES
from ...scenario import ScenarioError
from ...scores import SCORE_KEYS
from ...variants import CONTROLLER_VARIANTS

CSV_NAME = "sweep.csv"
SETTINGS_NAME = "sweep.json"
TRAILING_COLUMNS = (*SCORE_KEYS, "wall_s", "status", "reason")


def csv_columns(names) -> list:
    return ["controller", *names, *TRAILING_COLUMNS]


def _format(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return repr(float(value))


def row_cells(row: dict) -> list:
    return [row["controller"], *(_format(v) for v in row["values"]),
            *(_format(row["scores"].get(k)) for k in SCORE_KEYS),
            f"{row['wall_s']:.4f}", row["status"], row["reason"]]


def parse_cells(cells: list, names) -> dict | None:
    """A row from its CSV cells; None if the row is incomplete (e.g. cut by a kill)."""
    if len(cells) != len(csv_columns(names)):
        return None
    n = len(names)
    try:
        controller = cells[0]
        values = [float(v) for v in cells[1:1 + n]]
        scores = {k: (float(v) if v != "" else math.nan) for k, v in zip(SCORE_KEYS, cells[1 + n:1 + n + len(SCORE_KEYS)])}
        wall, status, reason = cells[1 + n + len(SCORE_KEYS):]
        wall_s = float(wall)
    except ValueError:
        return None
    if controller not in CONTROLLER_VARIANTS or status not in STATUSES:
        return None
    return {"controller": controller, "values": values, "scores": scores, "wall_s": wall_s,
            "status": status, "reason": reason}


def read_rows(path, names) -> list:
    """Every complete row of a sweep CSV (a last line cut short by a kill is left out)."""
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return []
    with open(path, newline="") as stream:
        text = stream.read()
    lines = list(csv.reader(io.StringIO(text)))
    if not lines:
        return []
    header = lines[0]
    if header != csv_columns(names):
        theirs = header[1:header.index("ts")] if "ts" in header else header
        raise ScenarioError(f"{path} holds a sweep over {', '.join(theirs) or 'nothing'}, not over "
                            f"{', '.join(names)}: use another --out, or remove it to start over")
    complete_text = text if text.endswith("\n") else text[:text.rfind("\n") + 1]
    complete = list(csv.reader(io.StringIO(complete_text)))[1:]
    return [row for row in (parse_cells(cells, names) for cells in complete) if row is not None]


class CsvSink:
    """Append rows one at a time, flushed, so a killed sweep loses at most the row being written."""

    def __init__(self, path: Path, names, kept_rows: list):
        self.path = Path(path)
        self.names = list(names)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # rewrite the file with its complete rows only: a row cut short by a kill is dropped here
        partial = self.path.with_name(self.path.name + ".part")
        with open(partial, "w", newline="") as stream:
            writer = csv.writer(stream, lineterminator="\n")
            writer.writerow(csv_columns(self.names))
            for row in kept_rows:
                writer.writerow(row_cells(row))
        os.replace(partial, self.path)
        self.stream = open(self.path, "a", newline="")

    def write(self, row: dict):
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\n").writerow(row_cells(row))
        self.stream.write(buffer.getvalue())
        self.stream.flush()
        os.fsync(self.stream.fileno())

    def close(self):
        self.stream.close()


def check_settings(path: Path, settings: dict):
    if not path.exists():
        return
    try:
        previous = json.loads(path.read_text())
    except (OSError, ValueError):
        return
    differing = [key for key in settings if key in previous and previous[key] != settings[key]]
    if differing:
        what = "; ".join(f"{key}: {previous[key]!r} then, {settings[key]!r} now" for key in differing)
        raise ScenarioError(f"{path.parent} holds a sweep with other settings ({what}); "
                            "use another --out, or remove the directory to start over")
