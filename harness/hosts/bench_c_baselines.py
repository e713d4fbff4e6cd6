"""``bench --edition native``: our native master against a plain C host and the math floor, side by side.

At each horizon (1 s to 20 s of pendulum_case1/vud by default), in one run and interleaved (every
repeat measures every loop at every horizon in turn, so each figure goes through the same slow and fast
periods of a shared machine), the best of ``repeat`` measurements of the microseconds per communication
step of:

* ours: our master with the native FMI 2.0 FMUs and its compiled loop (harness/master_loop.c), the
  ``us_per_step`` of ``Master.run``, as ``python -m harness run`` reports it;
* ours, cold: the us per step one ``python -m harness run --edition native`` prints, in a process of its own
  (best of ``min(repeat, COLD_REPEAT)``): a first run in a fresh process, as a user makes it;
* the C host: harness/hosts/plain_c_host.c over the same FMUs (harness/hosts/c_baselines.py);
* the floor: the same loop inlined in one C function, no FMI (harness/hosts/math_floor.c);

with the ratios ours / C host (target <= OURS_TO_HOST_TARGET, also for the cold run) and C host / floor
(target <= HOST_TO_FLOOR_TARGET).  ``instructions=True`` adds the instructions per step of the three loops,
counted by callgrind (harness/hosts/instruction_counts.py: repeatable on a loaded machine).
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

from .. import scenario as scenarios
from ..master import Master
from . import c_baselines, instruction_counts

HORIZONS = (1.0, 2.0, 5.0, 10.0, 20.0)  # s
OURS_TO_HOST_TARGET = 1.1
HOST_TO_FLOOR_TARGET = 1.4
COLD_REPEAT = 5  # cold runs per horizon at most: each starts a Python process
LOOPS = ("ours", "host", "floor")
FIGURES = (*LOOPS, "ours_cold", *(f"{loop}_cpu" for loop in LOOPS))
COLD_FIGURE = re.compile(r"steps in [\d.]+ s \(([\d.]+) us/step\)")  # the line `run` prints
SCENARIO, CONTROLLER = c_baselines.SCENARIO, c_baselines.CONTROLLER


def horizons(text: str) -> tuple:
    """``--horizons 1,2,5``: simulated seconds, each a finite number > 0."""
    try:
        values = tuple(float(part) for part in text.split(","))
    except ValueError:
        values = ()
    if not values or not all(0.0 < value < float("inf") for value in values):
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of horizons; give seconds > 0 separated by commas, "
                                         "e.g. 1,2,5,10,20")
    return values


def cold_run_us_per_step(stop: float) -> float:
    """The us per step ``python -m harness run pendulum_case1 --edition native`` prints, run in a new process as a
    user runs it (its progress display on, stderr not a terminal)."""
    command = [sys.executable, "-m", "harness", "run", SCENARIO, "--controller", CONTROLLER, "--edition", "native",
               "--stop", repr(stop)]
    completed = subprocess.run(command, capture_output=True, text=True, env={**os.environ, "AFC_MASTER_LOOP": "c"})
    found = COLD_FIGURE.search(completed.stdout)
    if completed.returncode != 0 or not found:
        last = (completed.stderr.strip().splitlines() or ["no message"])[-1]
        raise RuntimeError(f"the cold run over {stop:g} s failed: {last}")
    return float(found.group(1))


def measure(native: dict, horizons_s=HORIZONS, repeat: int = 3, cold: bool = True) -> list:
    """One row per horizon: {"stop", "steps", "ours_us", "ours_cold_us", "host_us", "floor_us" (wall time),
    "ours_cpu_us", "host_cpu_us", "floor_cpu_us" (the loop thread's CPU time), and the ratios
    "ours_to_host", "ours_cold_to_host", "host_to_floor", "ours_to_host_cpu", "host_to_floor_cpu"}, each
    figure the best of its measurements."""
    configured = {stop: scenarios.configure(SCENARIO, CONTROLLER, None, stop) for stop in horizons_s}
    samples = {(stop, figure): [] for stop in configured for figure in FIGURES}

    def ours(scenario):
        result = Master(scenario, "feedthrough", native, loop="c").run()
        return result.us_per_step, result.cpu_us_per_step

    def host(scenario):
        run = c_baselines.plain_host(scenario, native)
        return run.us_per_step(), run.us_per_step(cpu=True)

    def floor(scenario):
        run = c_baselines.math_floor(scenario)
        return run.us_per_step(), run.us_per_step(cpu=True)

    measurements = {"ours": ours, "host": host, "floor": floor}
    for round_ in range(repeat):
        for stop, scenario in configured.items():
            for loop, function in measurements.items():
                wall, cpu = function(scenario)
                samples[(stop, loop)].append(wall)
                samples[(stop, f"{loop}_cpu")].append(cpu)
            if cold and round_ < COLD_REPEAT:
                samples[(stop, "ours_cold")].append(cold_run_us_per_step(scenario.stop))
    rows = []
    for stop, scenario in configured.items():
        best = {figure: min(samples[(stop, figure)]) if samples[(stop, figure)] else None for figure in FIGURES}
        row = {"stop": scenario.stop, "steps": scenario.steps, **{f"{figure}_us": best[figure] for figure in FIGURES}}
        row.update(ours_to_host=best["ours"] / best["host"], host_to_floor=best["host"] / best["floor"],
                   ours_cold_to_host=best["ours_cold"] / best["host"] if best["ours_cold"] else None,
                   ours_to_host_cpu=best["ours_cpu"] / best["host_cpu"],
                   host_to_floor_cpu=best["host_cpu"] / best["floor_cpu"])
        rows.append(row)
    return rows


def instructions(short: float = 1.0, long: float = 3.0, jobs: int = 2) -> dict:
    """{loop: {category: instructions per step, "total": ...}} of ours, the C host and the floor (callgrind; the
    six counted runs on ``jobs`` processes at a time)."""
    names = {"ours": "master", "host": "host", "floor": "floor"}
    instruction_counts.native_fmus()  # built before any count
    runs = [(names[loop], stop) for loop in LOOPS for stop in (short, long)]
    with ThreadPoolExecutor(jobs) as pool:
        counted = dict(zip(runs, pool.map(lambda run: instruction_counts.count(*run), runs)))
    return {loop: instruction_counts.per_step(names[loop], short, long, counts=lambda name, stop: counted[(name, stop)])
            for loop in LOOPS}


def print_section(rows: list, repeat: int, counts: dict | None = None, stream=None) -> None:
    stream = stream or sys.stdout
    print(f"the native master against a plain C host and the math floor: {SCENARIO}/{CONTROLLER}, FMI 2.0, "
          f"best of {repeat} interleaved (cold runs: of {min(repeat, COLD_REPEAT)})", file=stream)
    print(f"  {'us per step':14s} {'wall time of the loop':>44s} {'CPU time of the loop':>30s}", file=stream)
    print(f"  {'horizon':>8s} {'steps':>5s} {'ours':>6s} {'cold':>6s} {'C host':>6s} {'floor':>6s} "
          f"{'ours/host':>9s} {'cold/host':>9s} {'host/floor':>10s} {'ours':>6s} {'C host':>6s} {'floor':>6s} "
          f"{'ours/host':>9s} {'host/floor':>10s}", file=stream)

    def number(value, width, digits=2):
        return f"{'':>{width}s}" if value is None else f"{value:{width}.{digits}f}"

    for row in rows:
        print(f"  {row['stop']:7g}s {row['steps']:5d} {number(row['ours_us'], 6)} {number(row['ours_cold_us'], 6)} "
              f"{number(row['host_us'], 6)} {number(row['floor_us'], 6)} {number(row['ours_to_host'], 9)} "
              f"{number(row['ours_cold_to_host'], 9)} {number(row['host_to_floor'], 10)} "
              f"{number(row['ours_cpu_us'], 6)} {number(row['host_cpu_us'], 6)} {number(row['floor_cpu_us'], 6)} "
              f"{number(row['ours_to_host_cpu'], 9)} {number(row['host_to_floor_cpu'], 10)}", file=stream)
    worst = {key: max((row[key] for row in rows if row[key] is not None), default=None)
             for key in ("ours_to_host", "ours_cold_to_host", "host_to_floor", "ours_to_host_cpu",
                         "host_to_floor_cpu")}
    said = {key: "n/a" if value is None else f"{value:.2f}" for key, value in worst.items()}
    print(f"  target: ours <= {OURS_TO_HOST_TARGET:g} x the C host at every horizon: worst {said['ours_to_host']} "
          f"wall, {said['ours_to_host_cpu']} CPU, {said['ours_cold_to_host']} for a cold `run`", file=stream)
    print(f"  target: the C host <= {HOST_TO_FLOOR_TARGET:g} x the floor at every horizon: worst "
          f"{said['host_to_floor']} wall, {said['host_to_floor_cpu']} CPU", file=stream)
    if counts:
        print("  instructions per step (callgrind, the difference of a 1 s and a 3 s run: fixed costs removed)",
              file=stream)
        print(f"  {'loop':>8s} {'total':>7s} {'libm':>7s} {'FMUs':>7s} {'loop C':>7s} {'other':>7s}", file=stream)
        for loop in LOOPS:
            figures = counts[loop]
            whole = {key: int(round(value)) for key, value in figures.items()}  # no "-0" for a difference of 0
            print(f"  {loop:>8s} {whole['total']:7d} {whole['libm']:7d} {whole['fmus']:7d} {whole['loop']:7d} "
                  f"{whole['other']:7d}", file=stream)
        print(f"  instructions: ours / C host {counts['ours']['total'] / counts['host']['total']:.3f}, "
              f"C host / floor {counts['host']['total'] / counts['floor']['total']:.3f}", file=stream)


__all__ = ["HORIZONS", "OURS_TO_HOST_TARGET", "HOST_TO_FLOOR_TARGET", "COLD_REPEAT", "horizons", "measure",
           "instructions", "print_section", "cold_run_us_per_step"]
