"""harness/progress.py: the first line comes from a clock, the time left from the work done; the native
build says what it builds.  Under a pipe on a loaded CPU, the whole `tables` command: tests/test_termination.py."""
from __future__ import annotations

import heapq
import io
import os
import re
import time

import pytest

from harness.fmu_build import native as build_native
from harness.fmu_build.native_stages import ls_ref
from harness import progress as progress_module
from harness.progress import Progress, WorkBoard, time_left_s


# ------------------------------------------------------------------ the estimate on synthetic work
def pool_schedule(weights, workers: int, rate: float, start_s: float, per_item_s: float) -> list:
    """(start, end) of each item as a pool deals them: each to the worker free first, every worker
    ``start_s`` late (spawning) and each item ``per_item_s`` longer than its work (instantiation)."""
    free = [(start_s, k) for k in range(workers)]
    spans = []
    for weight in weights:
        began, worker = heapq.heappop(free)
        end = began + per_item_s + weight / rate
        spans.append((began, end))
        heapq.heappush(free, (end, worker))
    return spans


def fractions_at(t: float, weights, spans, per_item_s: float) -> list:
    return [min(1.0, max(0.0, (t - began - per_item_s) / (end - began - per_item_s)))
            for (began, end) in spans]


#: the shape of the tables pool: the longest runs first, the manipulator's at h/2 twice the h ones, ...
TABLES_LIKE = sorted([800] * 3 + [400] * 3 + [160] * 6 + [100] * 6 + [80] * 6 + [50] * 6, reverse=True)


@pytest.mark.parametrize("start_s, per_item_s", [(0.0, 0.0), (3.0, 0.5), (10.0, 2.0)])
def test_time_left_is_within_a_factor_two_of_the_truth_from_a_fifth_of_the_run_on(start_s, per_item_s):
    rate, workers = 10.0, 2  # work units per second of one worker
    spans = pool_schedule(TABLES_LIKE, workers, rate, start_s, per_item_s)
    total_s = max(end for _, end in spans)
    for share in (0.2, 0.35, 0.5, 0.65, 0.8, 0.9):
        t = share * total_s
        estimate = time_left_s(TABLES_LIKE, fractions_at(t, TABLES_LIKE, spans, per_item_s), t, workers)
        truth = total_s - t
        assert 0.5 <= estimate / truth <= 2.0, (share, estimate, truth)


def test_a_long_item_left_alone_counts_at_one_workers_rate():
    # two workers did 10 + 10 units in 10 s (1 unit/s each); left: one item of 20, half done: 10 s on one worker
    assert time_left_s([20, 10], [0.5, 1.0], 10.0, 2) == pytest.approx(10.0)
    assert time_left_s([10, 10, 10], [1.0, 0.0, 0.0], 10.0, 1) == pytest.approx(20.0)  # one worker: in turn
    assert time_left_s([10, 10], [0.0, 0.0], 5.0, 2) is None  # nothing done yet: no estimate


def test_time_left_refuses_mismatched_input():
    with pytest.raises(ValueError, match="2 weights but 1 fractions"):
        time_left_s([1, 2], [0.5], 1.0, 1)
    with pytest.raises(ValueError, match="workers = 0"):
        time_left_s([1], [0.5], 1.0, 0)


def test_the_lines_show_the_share_of_the_steps_and_the_time_left_from_the_board(monkeypatch):
    monkeypatch.setattr(progress_module, "PROGRESS_LINE_EVERY_S", 0.0)
    board = WorkBoard([300, 100], unit="step")
    stream = io.StringIO()
    with Progress(2, "tables", stream=stream, board=board, workers=2) as bar:
        board.fractions[0] = 0.6  # what a worker writes through step_reporter
        board.finish(1)
        bar.update(label="short")  # the work first seen done: the rate's origin
        time.sleep(0.01)
        board.fractions[0] = 0.7
        bar._line(bar._status())
    first, second = stream.getvalue().splitlines()[:2]
    assert re.fullmatch(r"tables: 1/2 runs done in \d+ s \(70 % of the steps\) \(last: short\)", first), first
    assert re.fullmatch(r"tables: 1/2 runs done in \d+ s \(78 % of the steps\), about \d+ s left \(last: short\)",
                        second), second
    stream = io.StringIO()
    board = WorkBoard([1000, 1000], unit="step")
    with Progress(2, "tables", stream=stream, board=board, workers=2) as bar:
        board.fractions[0] = 0.015  # under ESTIMATE_FROM_SHARE of the work: the start dominates, no estimate
        bar._line(bar._status())
        board.fractions[0] = 0.025
        bar._line(bar._status())
    early, later = stream.getvalue().splitlines()[:2]
    assert early.endswith("(1 % of the steps)") and "left" not in early, early
    assert later.endswith("s left"), later


class FakeClock:
    """perf_counter() under the test's control."""

    def __init__(self):
        self.now = 1000.0

    def perf_counter(self):
        return self.now


def test_the_time_left_counts_the_loops_own_rate_not_the_start(monkeypatch):
    """`harness run` said "30/6000 steps done in 19 s, about 3805 s left" and finished a second later: the 19 s
    of building and instantiating the FMUs were counted as time the steps took."""
    fake = FakeClock()
    monkeypatch.setattr(progress_module, "clock", fake)
    monkeypatch.setattr(progress_module, "PROGRESS_LINE_EVERY_S", 3600.0)
    stream = io.StringIO()
    with Progress(6000, "my_loop/vud", unit="step", stream=stream, bar=False) as bar:
        fake.now += 19.0  # the start: no step yet
        bar.update(30)  # the master's first report
        assert bar.time_left_s() is None  # one report: no rate yet
        fake.now += 0.1  # 30 more steps in 0.1 s
        bar.update(30)
        left = bar.time_left_s()
        assert left == pytest.approx(5940 / 300, rel=1e-6)  # 19.8 s, not the start's 1890 s
        assert "about 20 s left" in bar._status()


def test_step_reporter_writes_the_items_fraction_and_is_none_without_a_board():
    assert progress_module.step_reporter() is None
    board = WorkBoard([10, 10], unit="step")
    before = progress_module.attach(board.fractions), progress_module.set_item(1)
    try:
        progress_module.step_reporter()(5, 20)
    finally:
        progress_module.attach(before[0])
        progress_module.set_item(before[1])
    assert list(board.fractions) == [0.0, 0.25] and board.done() == 2.5


# ------------------------------------------------------------------ the first line in wall time
def test_the_first_line_comes_from_the_clock_while_nothing_finishes(monkeypatch):
    monkeypatch.setattr(progress_module, "PROGRESS_LINE_EVERY_S", 0.3)
    monkeypatch.setattr(progress_module, "PROGRESS_HEARTBEAT_S", 3600.0)
    stream = io.StringIO()
    with Progress(5, "hosts", stream=stream):
        time.sleep(1.0)  # no item finishes
        lines = stream.getvalue().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hosts: 0/5 runs done in "), lines


def test_on_a_terminal_the_clock_redraws_the_bar_with_the_work_done(monkeypatch):
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.setattr(progress_module, "CLOCK_TICK_S", 0.1)
    board = WorkBoard([100, 100], unit="step")
    terminal = Terminal()
    with Progress(2, "tables", stream=terminal, board=board, workers=2):
        board.fractions[0] = 0.4
        time.sleep(0.3)  # no update: the clock draws it (and takes the rate's origin)
        board.fractions[0] = 0.5
        time.sleep(0.4)
        drawn = terminal.getvalue()
    assert " 25%|" in drawn and "0/2 runs done" in drawn and "s left" in drawn, drawn


# ------------------------------------------------------------------ the native build says what it builds
def test_the_native_build_says_each_binary_as_it_is_there(monkeypatch, tmp_path, capsys):
    work = tmp_path / "work"
    monkeypatch.setattr(build_native, "WORK_DIR", work)
    monkeypatch.setattr(build_native, "ROOT", tmp_path)  # the "built ..." line names the FMUs from there
    model = build_native.models()[0]
    name = model.model_identifier
    monkeypatch.setattr(build_native, "fmu_paths", lambda: {name: {2: tmp_path / "2" / f"{name}.fmu",
                                                                     3: tmp_path / "3" / f"{name}.fmu"}})
    compiled = []

    def fake_compile(model, header_dir, fmi_version, target, zig_version):  # no zig: a file per binary
        path = work / "obj" / f"{fmi_version}-{target.zig}{target.extension}"
        if fmi_version == 3:  # the FMI 3.0 binary from the cache: made before the build began
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(b"cached")
            old = time.time() - 3600
            os.utime(path, (old, old))
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(b"binary")
        compiled.append((fmi_version, target.zig))
        return path

    monkeypatch.setattr(build_native, "compile_binary", fake_compile)
    monkeypatch.setattr(ls_ref, "runs_here", lambda files, version: False)  # the fake binaries cannot run
    build_native.build_model(model, platforms=("linux64",), jobs=1, zig_version="0", verbose=True)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == f"native: {name}: 2 binaries (FMI 2.0 and 3.0 for x86_64-linux-gnu.2.17), 1 at a time", err
    assert re.fullmatch(rf"native: {name} FMI 2\.0 x86_64-linux-gnu\.2\.17: compiled in \d+\.\d s", err[1]), err
    assert err[2] == f"native: {name} FMI 3.0 x86_64-linux-gnu.2.17: from the cache", err
    assert len(compiled) == 2
    build_native.build_model(model, platforms=("linux64",), jobs=1, zig_version="0", verbose=False)
    assert capsys.readouterr().err == ""  # quiet unless asked (the harness's own builds)


def test_a_command_slow_to_reach_its_runs_says_how_far_at_the_first_tick(monkeypatch):
    monkeypatch.setattr(progress_module, "CLOCK_TICK_S", 0.1)
    stream = io.StringIO()
    with Progress(5, "tables", stream=stream):  # a display of its own: its first line after 5 s
        time.sleep(0.5)
    assert stream.getvalue() == ""
    progress_module.command_began(time.perf_counter() - progress_module.PROGRESS_LINE_EVERY_S)  # imports, builds...
    try:
        with Progress(5, "tables", stream=stream):
            time.sleep(0.5)
            lines = stream.getvalue().splitlines()
    finally:
        progress_module.command_ended()
    assert len(lines) == 1 and lines[0].startswith("tables: 0/5 runs done in 0 s"), lines


def test_the_process_began_before_now():
    assert 0.0 <= time.perf_counter() - progress_module.process_started() < 3600
