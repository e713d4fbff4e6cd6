"""harness/progress.py through harness/cases.py: progress of long commands where no bar can be drawn.

`tables` printed nothing for 4 minutes under `| cat` or in a CI log: tqdm's bar is drawn only on a
terminal.  Elsewhere a long command now prints lines to stderr: none if it is done within
PROGRESS_LINE_EVERY_S, then per finished item (at most that often), while nothing finishes (every
PROGRESS_HEARTBEAT_S), and at the end.
The whole `tables` command under a pipe: tests/test_tables.py.
"""
from __future__ import annotations

import io
import re
import time

from harness import cases
from harness import progress as progress_module


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_without_a_terminal_progress_is_lines_per_item_and_at_the_end(monkeypatch):
    monkeypatch.setattr(progress_module, "PROGRESS_LINE_EVERY_S", 0.0)
    stream = io.StringIO()
    with progress_module.Progress(3, "Table I/II", stream=stream) as progress:
        for name in ("pendulum_case1_vud", "manipulator_fae", "motor_arm_fixed"):
            progress.update(label=name)
    lines = stream.getvalue().splitlines()  # the first finished run is the rate's origin: no estimate yet
    assert re.fullmatch(r"Table I/II: 1/3 runs done in \d+ s \(last: pendulum_case1_vud\)", lines[0])
    assert re.fullmatch(r"Table I/II: 2/3 runs done in \d+ s, about \d+ s left \(last: manipulator_fae\)", lines[1])
    assert re.fullmatch(r"Table I/II: 3/3 runs done in \d+ s", lines[2]) and len(lines) == 3


def test_lines_are_rate_limited_and_a_heartbeat_says_a_long_wait_is_not_a_hang(monkeypatch):
    monkeypatch.setattr(progress_module, "PROGRESS_LINE_EVERY_S", 3600.0)
    stream = io.StringIO()
    with progress_module.Progress(1000, "sweep", unit="pt", stream=stream) as progress:
        for _ in range(999):
            progress.update()
    assert stream.getvalue() == ""  # a command done within PROGRESS_LINE_EVERY_S stays quiet: no flood, no noise
    monkeypatch.setattr(progress_module, "PROGRESS_HEARTBEAT_S", 0.2)
    stream = io.StringIO()
    with progress_module.Progress(2, "hosts", stream=stream):
        time.sleep(1.5)
    beats = [line for line in stream.getvalue().splitlines() if line.endswith(", still running")]
    assert beats and beats[0].startswith("hosts: 0/2 runs done in "), stream.getvalue()


def test_on_a_terminal_the_bar_and_when_disabled_nothing():
    terminal = Terminal()
    with progress_module.Progress(2, "run", stream=terminal) as progress:
        progress.update(2)
    assert progress.mode == "bar" and "2/2" in terminal.getvalue() and "runs done" not in terminal.getvalue()
    quiet = io.StringIO()
    with progress_module.Progress(2, "run", stream=quiet, enabled=False) as progress:
        progress.update(2)
    assert quiet.getvalue() == ""


def test_parallel_map_reports_progress_by_item_when_stderr_is_not_a_terminal(monkeypatch, capsys):
    monkeypatch.setattr(progress_module, "PROGRESS_LINE_EVERY_S", 0.0)
    assert cases.parallel_map(abs, [-1, -2, -3], jobs=1, description="demo", progress=None,
                              label=lambda item: f"item {item}") == [1, 2, 3]
    err = capsys.readouterr().err
    assert "demo: 1/3 runs done in " in err and "(last: item -2)" in err
    assert re.search(r"demo: 3/3 runs done in \d+ s$", err.strip())
    assert cases.parallel_map(abs, [-1], jobs=1, progress=False) == [1]
    assert capsys.readouterr().err == ""
