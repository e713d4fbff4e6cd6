"""harness/termination.py: SIGTERM ends a command and its pool's workers as Ctrl-C does (exit 143); SIGKILL of
the command leaves no worker behind (they notice their parent is gone); `tables` under a pipe on a loaded CPU
says how far it is within 10 s of wall time (harness/progress.py)."""
from __future__ import annotations

import os
import selectors
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import psutil
import pytest

from tests.ctrl_c import with_ctrl_c

ROOT = Path(__file__).resolve().parents[1]
FIRST_LINE_WITHIN_S = 10.0


def descendants_until(process: subprocess.Popen, count: int, timeout_s: float, name: str | None = None) -> list:
    """The process's descendants once ``count`` of them (named ``name``) run."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = psutil.Process(process.pid).children(recursive=True)
        if len([p for p in found if name is None or p.name() == name]) >= count:
            return found
        if process.poll() is not None:
            break
        time.sleep(0.1)
    pytest.fail(f"fewer than {count} {name or 'processes'} under the command within {timeout_s} s")


def end_tree(command: subprocess.Popen) -> None:
    """A failing test leaves no process behind: the command and everything under it."""
    try:
        below = psutil.Process(command.pid).children(recursive=True)
    except psutil.NoSuchProcess:
        below = []
    if command.poll() is None:
        command.kill()
    for process in below:
        try:
            process.kill()
        except psutil.NoSuchProcess:
            pass


def alive(processes) -> list:
    left = []
    for process in processes:
        try:
            if process.is_running() and process.status() != psutil.STATUS_ZOMBIE:
                left.append(process)
        except psutil.NoSuchProcess:
            pass
    return left


def gone_within(processes, timeout_s: float) -> list:
    deadline = time.monotonic() + timeout_s
    while alive(processes) and time.monotonic() < deadline:
        time.sleep(0.1)
    return alive(processes)


POOL_SCRIPT = textwrap.dedent("""
    import functools, subprocess, sys
    from harness import termination
    from harness.cases import parallel_map

    try:
        with termination.sigterm_as_interrupt():
            parallel_map(functools.partial(subprocess.run, check=False), [["sleep", "120"]] * 4, jobs=2,
                         progress=False)
    except KeyboardInterrupt as interrupt:
        sys.exit(termination.exit_status(interrupt))
""")


@pytest.mark.parametrize("stop_signal, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_ends_the_pools_workers_and_what_they_started(stop_signal, status):
    command = subprocess.Popen([sys.executable, "-c", POOL_SCRIPT], cwd=ROOT, stdin=subprocess.DEVNULL,
                               preexec_fn=with_ctrl_c)
    below = []
    try:
        below = descendants_until(command, 2, 60.0, name="sleep")  # both workers in their item's subprocess
        command.send_signal(stop_signal)
        assert command.wait(30) == status
        assert gone_within(below, 10.0) == []  # no worker, no worker's subprocess left
    finally:
        end_tree(command)
        for process in alive(below):
            process.kill()


def busy_loop() -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def test_tables_under_a_pipe_on_a_loaded_cpu_says_how_far_within_10_s_and_sigterm_ends_it(fmu_paths, tmp_path):
    import harness.master_loop

    harness.master_loop.library()  # compiled once here, not inside the timed window
    load = busy_loop()
    try:
        began = time.monotonic()
        command = subprocess.Popen([sys.executable, "-m", "harness", "tables", "--stop", "4", "--jobs", "2",
                                    "--out", str(tmp_path / "results")], cwd=ROOT, stdin=subprocess.DEVNULL,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, preexec_fn=with_ctrl_c)
        try:
            selector = selectors.DefaultSelector()
            selector.register(command.stderr, selectors.EVENT_READ)
            first = b""
            while not first.endswith(b"\n") and time.monotonic() - began < FIRST_LINE_WITHIN_S + 5:
                if selector.select(timeout=0.2):
                    chunk = os.read(command.stderr.fileno(), 4096)
                    if not chunk:
                        break
                    first += chunk
            arrived = time.monotonic() - began
            # the first pool: the ladders' runs on the native FMUs (pythonfmu edition, zig installed), else the tables'
            assert first.startswith((b"claims' ladders on the native FMUs", b"Table I/II")), first
            assert arrived <= FIRST_LINE_WITHIN_S, f"first progress line after {arrived:.1f} s: {first!r}"
            workers = descendants_until(command, 2, 30.0)
            command.send_signal(signal.SIGTERM)
            assert command.wait(30) == 143
            assert gone_within(workers, 10.0) == []
            assert b"error: terminated (SIGTERM)" in command.stderr.read()
        finally:
            end_tree(command)
    finally:
        load.kill()
        load.wait()


#: commands whose local pool computes for a while (pythonfmu edition: runs of seconds)
POOL_COMMANDS = {
    "sweep": ["sweep", "pendulum_case2", "--grid", "plant.mp=0.1:2:8", "--stop", "5", "--jobs", "2", "--no-progress",
              "--edition", "python", "--out", "{out}"],
    "tune": ["tune", "pendulum_case1", "--trials", "200", "--jobs", "2", "--stop", "3", "--edition", "python",
             "--quiet", "--held-out", "--out", "{out}"],
    "tables": ["tables", "--jobs", "2", "--edition", "python", "--out", "{out}"],
}


def pool_workers(command: subprocess.Popen, count: int, timeout_s: float) -> list:
    """The command's spawned pool workers once ``count`` of them have computed for a moment."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and command.poll() is None:
        workers = [p for p in psutil.Process(command.pid).children(recursive=True)
                   if "spawn_main" in " ".join(p.cmdline())]
        if len([p for p in workers if sum(p.cpu_times()[:2]) > 0.3]) >= count:
            return workers
        time.sleep(0.1)
    pytest.fail(f"fewer than {count} busy pool workers under the command within {timeout_s} s")


@pytest.mark.parametrize("name", POOL_COMMANDS)
def test_sigkill_of_the_command_leaves_no_pool_worker_behind(fmu_paths, tmp_path, name):
    scratch = tmp_path / "temp"  # what a killed command cannot clean up stays in tmp_path
    scratch.mkdir()
    argv = [part.format(out=tmp_path / "out") for part in POOL_COMMANDS[name]]
    command = subprocess.Popen([sys.executable, "-m", "harness", *argv], cwd=ROOT, stdin=subprocess.DEVNULL,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               env=dict(os.environ, TMPDIR=str(scratch)))
    below = []
    try:
        workers = pool_workers(command, 2, 120.0)
        below = psutil.Process(command.pid).children(recursive=True)  # the workers and the resource tracker
        command.kill()  # the command only: its workers are reparented, as when a user's kill -9 hits it
        command.wait(10)
        assert gone_within(workers, 15.0) == [], f"{name}: workers left computing after the command died"
        assert gone_within(below, 10.0) == []
    finally:
        end_tree(command)
        for process in alive(below):
            process.kill()
