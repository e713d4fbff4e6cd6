"""How far a long command is, and how long it has left, on stderr.

:class:`Progress` draws tqdm's bar on a terminal; elsewhere (a CI log, ``| tee``, ``| cat``), where no
bar can be drawn, it prints plain lines.  A clock thread, not the work, decides when a line is due, so
the first line comes PROGRESS_LINE_EVERY_S after the start in wall time however long the first item
takes and however loaded the machine is.

The time left comes from the work done, not from the items finished: a :class:`WorkBoard` holds each
item's weight (a co-simulation's communication steps) and the fraction of it done, in memory the pool's
workers share; a worker writes its item's fraction through :func:`step_reporter` about 200 times a run
(the master's progress callback, between blocks of steps, off the per-step path), and
:func:`time_left_s` turns weights, fractions and the elapsed time into seconds left.  The rate is the
work's own: it is measured from the moment the display first sees work done (the work done then and
the time), so the start (spawning, importing, building and extracting the FMUs, instantiating) does not
count as time the work took.
"""
from __future__ import annotations

import heapq
import multiprocessing
import os
import sys
from pathlib import Path
import threading
import time as clock

#: without a terminal: nothing for a command shorter than this, then its first line, whatever has finished;
#: after it at most one line per finished item this often ...
PROGRESS_LINE_EVERY_S = 5.0
#: ... and one this often while nothing finishes, so a long run never looks hung
PROGRESS_HEARTBEAT_S = 30.0
#: how often the clock thread looks (and redraws the bar)
CLOCK_TICK_S = 1.0
#: no time left is shown before this share of the work is done: until then the workers' start
#: (spawning, importing, extracting the FMUs) weighs on the rate more than the work does
ESTIMATE_FROM_SHARE = 0.01


# ------------------------------------------------------------------ the command's clock
_COMMAND_STARTED = None  # perf_counter() time the running command began (command_began), if one runs


def process_started() -> float:
    """The perf_counter() time this process began (Linux: from /proc); now where that cannot be read."""
    now = clock.perf_counter()
    try:
        ticks = int(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[19])
        uptime = float(Path("/proc/uptime").read_text().split()[0])
        return now - max(0.0, uptime - ticks / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError):
        return now


def command_began(at: float | None = None) -> None:
    """The first line's clock counts from ``at`` (a perf_counter() time; default now) until command_ended:
    a command that took long to reach its runs says how far it is PROGRESS_LINE_EVERY_S after it began."""
    global _COMMAND_STARTED
    _COMMAND_STARTED = clock.perf_counter() if at is None else at


def command_ended() -> None:
    """From now on each display's first line counts from the display's own start."""
    global _COMMAND_STARTED
    _COMMAND_STARTED = None


# ------------------------------------------------------------------ the estimate
def time_left_s(weights, fractions, elapsed_s: float, workers: int, done_before: float = 0.0) -> float | None:
    """Seconds left of items of ``weights`` of which ``fractions`` (0 .. 1 each) are done, ``done_before`` of
    that work ``elapsed_s`` ago, on ``workers`` processes; None before any work is done in that time.

    Every busy worker is taken to have worked at the same rate (the work done in ``elapsed_s`` over
    ``elapsed_s`` x busy workers); the work left is then dealt out as the pool deals it: the items under
    way (0 < fraction < 1) first, then the waiting ones in their order, each to the worker that is free
    first.  The time left is when the last worker finishes, so a long item alone at the end counts
    at one worker's rate, not at the whole pool's.
    """
    weights = [float(w) for w in weights]
    fractions = [min(1.0, max(0.0, float(f))) for f in fractions]
    if len(weights) != len(fractions):
        raise ValueError(f"{len(weights)} weights but {len(fractions)} fractions: one of each per item")
    if workers < 1:
        raise ValueError(f"workers = {workers!r}: a whole number >= 1")
    done = sum(w * f for w, f in zip(weights, fractions)) - done_before
    if done <= 0.0 or elapsed_s <= 0.0:
        return None
    busy = min(workers, len(weights))
    rate = done / (elapsed_s * busy)  # work per second of one worker
    under_way = [w * (1.0 - f) for w, f in zip(weights, fractions) if 0.0 < f < 1.0]
    waiting = [w for w, f in zip(weights, fractions) if f == 0.0]
    free_at = [0.0] * busy
    for work in (*under_way, *waiting):
        heapq.heappush(free_at, heapq.heappop(free_at) + work / rate)
    return max(free_at)


# ------------------------------------------------------------------ the shared board
class WorkBoard:
    """Each item's weight and the fraction of it done, the fractions in memory that spawned workers share
    (pass :attr:`fractions` to :func:`attach` in each worker)."""

    def __init__(self, weights, unit: str = ""):
        self.weights = [float(w) for w in weights]
        if any(not w > 0 for w in self.weights):
            raise ValueError("every item's weight must be > 0 (its communication steps, or 1)")
        self.unit = unit  # what a weight counts ("step"); "": items only, no share of the work shown
        self.fractions = multiprocessing.get_context("spawn").RawArray("d", len(self.weights))

    @property
    def total(self) -> float:
        return sum(self.weights)

    def done(self) -> float:
        return sum(w * min(1.0, max(0.0, f)) for w, f in zip(self.weights, self.fractions))

    def finish(self, index: int) -> None:
        self.fractions[index] = 1.0

    def time_left_s(self, elapsed_s: float, workers: int, done_before: float = 0.0) -> float | None:
        return time_left_s(self.weights, list(self.fractions), elapsed_s, workers, done_before)


_FRACTIONS = None  # this process's view of a board's fractions (attach)
_ITEM = None  # the item this process works on (set_item)


def attach(fractions):
    """In a worker (or the parent running items itself): report to these fractions (None: nowhere); returns
    the fractions reported to before."""
    global _FRACTIONS
    before, _FRACTIONS = _FRACTIONS, fractions
    return before


def set_item(index: int | None):
    """The item whose fraction this process reports from now on; returns the one before."""
    global _ITEM
    before, _ITEM = _ITEM, index
    return before


def step_reporter():
    """The master's progress callback for the item under way, ``(done, total) -> None``, writing its fraction
    to the board; None when no board is attached (the master then skips the calls)."""
    fractions, index = _FRACTIONS, _ITEM
    if fractions is None or index is None:
        return None

    def report(done, total):
        fractions[index] = done / total if total > 0 else 1.0

    return report


# ------------------------------------------------------------------ the display
class Progress:
    """How a long command says how far it is, on stderr: tqdm's bar on a terminal, redrawn every
    CLOCK_TICK_S; elsewhere plain lines: none for a command done within PROGRESS_LINE_EVERY_S (a short
    run stays quiet, its error alone on stderr), then one at PROGRESS_LINE_EVERY_S of wall time after the
    command began (command_began; else after this display began), one per
    finished item at most every PROGRESS_LINE_EVERY_S, one every PROGRESS_HEARTBEAT_S while nothing
    finishes, and one at the end.  ``board``: a :class:`WorkBoard` of the items (their share of the work
    done and the time left come from it); ``workers``: the processes working on them.
    ``enabled=False``: silent.  ``bar``: force the bar (True) or the lines (False)."""

    def __init__(self, total: int, description: str, unit: str = "run", enabled: bool = True, initial: int = 0,
                 stream=None, bar: bool | None = None, board: WorkBoard | None = None, workers: int = 1,
                 **tqdm_options):
        self.stream = stream or sys.stderr
        self.total, self.description, self.unit = total, description, unit
        self.board, self.workers = board, max(1, workers)
        self.done, self.label, self.printed = initial, "", False
        self.started = self.last_line = clock.perf_counter()
        began = _COMMAND_STARTED
        self.first_line_from = began if began is not None and began <= self.started else self.started
        self.finished_since_line = False
        self._rate_from = None  # (perf_counter time, work done) when work was first seen done: the rate's origin
        terminal = self.stream.isatty() if bar is None else bar
        self.mode = "off" if not enabled else "bar" if terminal else "lines"
        self._lock = threading.RLock()
        self._stopped = threading.Event()
        self._bar = self._clock = None
        if self.mode == "bar":
            from tqdm import tqdm  # here, not at module level: an import a CLI start without a study skips

            if board is not None and board.unit:  # the bar fills with the work done; the runs in the text
                self._bar = tqdm(total=board.total, desc=description, file=self.stream,
                                 bar_format="{desc}: {percentage:3.0f}%|{bar}| {postfix}")
                self._bar.set_postfix_str(self._status(), refresh=False)
            else:
                self._bar = tqdm(total=total, initial=initial, desc=description, unit=unit, file=self.stream,
                                 **tqdm_options)
        if self.mode != "off":
            self._clock = threading.Thread(target=self._tick, daemon=True)
            self._clock.start()

    def update(self, count: int = 1, label: str = "") -> None:
        """``count`` more items finished (the last one: ``label``)."""
        with self._lock:
            self.done += count
            self.label = label or self.label
            self.finished_since_line = True
            self._observe()
            if self._bar is not None:
                if self.board is not None and self.board.unit:
                    self._redraw()
                else:
                    self._bar.update(count)
            elif self.mode == "lines" and self.done < self.total and \
                    clock.perf_counter() - self.last_line >= PROGRESS_LINE_EVERY_S:
                self._line(self._status())

    def set_postfix(self, **values) -> None:
        with self._lock:
            if self._bar is not None and not (self.board is not None and self.board.unit):
                self._bar.set_postfix(**values)
            else:
                self.label = ", ".join(f"{key} {value}" for key, value in values.items())

    def close(self) -> None:
        """Stop (and say where it ended, if it said anything); closing twice is harmless."""
        if self._stopped.is_set():
            return
        self._stopped.set()
        if self._clock is not None:
            self._clock.join()
        with self._lock:
            if self._bar is not None:
                if self.board is not None and self.board.unit:
                    self._bar.set_postfix_str(self._status(final=True), refresh=False)
                    self._bar.n = self._bar.total if self.done >= self.total else self.board.done()
                self._bar.close()
            elif self.mode == "lines" and self.printed:
                self._line(self._status(final=True))

    def _work_done(self) -> float:
        return self.board.done() if self.board is not None and self.board.unit else float(self.done)

    def _observe(self) -> None:
        """Take the rate's origin the first time work is seen done (an update, or a clock tick)."""
        if self._rate_from is None:
            done = self._work_done()
            if done > 0:
                self._rate_from = (clock.perf_counter(), done)

    def time_left_s(self) -> float | None:
        """The estimate the lines and the bar show (time_left_s), from the rate since work was first seen
        done: None until then and until more is done."""
        self._observe()
        if self._rate_from is None:
            return None
        began, done_before = self._rate_from
        elapsed = clock.perf_counter() - began
        if self.board is not None and self.board.unit:
            if self.board.done() < ESTIMATE_FROM_SHARE * self.board.total:
                return None
            return self.board.time_left_s(elapsed, self.workers, done_before)
        return time_left_s([1.0] * self.total, [1.0] * min(self.done, self.total) +
                           [0.0] * max(0, self.total - self.done), elapsed, self.workers, done_before)

    def _status(self, final: bool = False) -> str:
        elapsed = clock.perf_counter() - self.started
        text = f"{self.done}/{self.total} {self.unit}s done in {elapsed:.0f} s"
        if self.board is not None and self.board.unit and not final and self.done < self.total:
            text += f" ({100 * self.board.done() / self.board.total:.0f} % of the {self.board.unit}s)"
        left = None if final or self.done >= self.total else self.time_left_s()
        if left is not None:
            text += f", about {left:.0f} s left"
        return text + (f" (last: {self.label})" if self.label and not final else "")

    def _tick(self):
        tick = max(0.05, min(CLOCK_TICK_S, PROGRESS_LINE_EVERY_S or CLOCK_TICK_S, PROGRESS_HEARTBEAT_S))
        while not self._stopped.wait(tick):
            try:
                with self._lock:
                    self._observe()
                    if self._bar is not None:
                        self._redraw()
                        continue
                    since_start = clock.perf_counter() - self.first_line_from
                    since_line = clock.perf_counter() - self.last_line
                    if not self.printed and since_start >= PROGRESS_LINE_EVERY_S:
                        self._line(self._status())
                    elif since_line >= PROGRESS_HEARTBEAT_S:
                        self._line(self._status() + ("" if self.finished_since_line else ", still running"))
            except (ValueError, OSError):  # the stream was closed under us: nothing more to say
                return

    def _redraw(self):
        if self.board is not None and self.board.unit:
            self._bar.n = self.board.done()
            self._bar.set_postfix_str(self._status(), refresh=False)
        self._bar.refresh()

    def _line(self, text: str):
        print(f"{self.description}: {text}", file=self.stream, flush=True)
        self.last_line, self.printed, self.finished_since_line = clock.perf_counter(), True, False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


__all__ = ["Progress", "WorkBoard", "time_left_s", "attach", "set_item", "step_reporter", "PROGRESS_LINE_EVERY_S",
           "PROGRESS_HEARTBEAT_S", "CLOCK_TICK_S", "ESTIMATE_FROM_SHARE", "command_began", "command_ended",
           "process_started"]
