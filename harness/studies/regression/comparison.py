"""The tube (funnel) comparison of a run with its reference, as BuildingsPy does it with ``pyfunnel``.

Every signal of a new run, resampled like its reference, must lie inside the tube around the
reference: per signal pass/fail, the largest excursion outside the tube and where, and the largest
deviation from the reference.  A case fails on any failing signal, a missing reference (the
message says which ``--update`` command creates it), a failed run, a changed experiment (start,
stop, step) or a changed scenario (its fingerprint; the changed settings are named).
"""
from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...cases import Case
from .references import (DEFAULT_TOLERANCES, Reference, reference_directory, reference_paths, reference_tolerances,
                         relative, scenario_changes, scenario_fingerprint)
from .runs import CaseRun


@dataclass
class SignalComparison:
    signal: str
    passed: bool
    max_error: float  # largest excursion outside the tube (0 inside)
    t_max_error: float | None
    max_deviation: float  # largest |new - reference| on the grid
    t_max_deviation: float | None
    message: str = ""
    plot: Path | None = None
    funnel: dict | None = field(default=None, repr=False)  # lower/upper bound arrays, when kept
    tolerances: dict = field(default_factory=lambda: dict(DEFAULT_TOLERANCES))  # the ones it was compared with


def compare_signal(name, x_ref, y_ref, x_test, y_test, tolerances: dict | None = None,
                   keep_funnel: bool = False) -> SignalComparison:
    """Tube comparison of one signal with pyfunnel (reference and test must span the same x range)."""
    import pyfunnel  # here, not at module level: its import is paid only when signals are compared

    tolerances = {**DEFAULT_TOLERANCES, **(tolerances or {})}
    x_ref, y_ref = np.asarray(x_ref, float), np.asarray(y_ref, float)
    x_test, y_test = np.asarray(x_test, float), np.asarray(y_test, float)
    deviation = np.abs(np.interp(x_ref, x_test, y_test) - y_ref) if len(x_test) else np.array([np.inf])
    worst = int(np.nanargmax(deviation)) if np.isfinite(deviation).any() else 0
    max_deviation = float(deviation[worst]) if np.isfinite(deviation).any() else float("inf")
    if not (np.all(np.isfinite(y_test)) and np.all(np.isfinite(y_ref))):
        bad = np.flatnonzero(~np.isfinite(y_test))
        where = float(x_test[bad[0]]) if bad.size else None
        return SignalComparison(name, False, float("inf"), where, float("inf"), where,
                                "non-finite values (the run stopped or diverged)", tolerances=tolerances)
    directory = tempfile.mkdtemp(prefix="afc_funnel_")
    try:
        log = io.StringIO()
        with contextlib.redirect_stdout(log):
            status = pyfunnel.compareAndReport(x_ref, y_ref, x_test, y_test, outputDirectory=directory, **tolerances)
        if status != 0:
            message = " ".join(log.getvalue().replace("*** Warning:", "").split())
            return SignalComparison(name, False, float("inf"), None, max_deviation, float(x_ref[worst]),
                                    f"pyfunnel failed: {message}", tolerances=tolerances)
        errors = np.loadtxt(os.path.join(directory, "errors.csv"), delimiter=",", skiprows=1, ndmin=2)
        k = int(np.argmax(errors[:, 1]))
        max_error, t_error = float(errors[k, 1]), float(errors[k, 0])
        funnel = None
        if keep_funnel or max_error > 0:
            funnel = {part: np.loadtxt(os.path.join(directory, f"{part}.csv"), delimiter=",", skiprows=1, ndmin=2)
                      for part in ("lowerBound", "upperBound")}
            funnel["errors"] = errors
    finally:
        shutil.rmtree(directory, ignore_errors=True)
    passed = max_error == 0
    message = "" if passed else f"outside the tube by up to {max_error:.3e} at t = {t_error:.6g} s"
    return SignalComparison(name, passed, max_error, t_error if not passed else None, max_deviation,
                            float(x_ref[worst]), message, funnel=funnel, tolerances=tolerances)


@dataclass
class CaseComparison:
    case: Case
    signals: list
    message: str = ""  # a failure that is not one signal's (missing reference, failed run, changed scenario)
    wall_s: float = 0.0
    reference_wall_s: float | None = None  # the wall time of the reference's run
    notes: list = field(default_factory=list)  # what the report says that is no failure
    run_tolerances: dict = field(default_factory=lambda: dict(DEFAULT_TOLERANCES))  # the report's (no metadata)

    @property
    def passed(self) -> bool:
        return not self.message and all(s.passed for s in self.signals)

    @property
    def slowdown(self) -> float | None:
        """The run's wall time over its reference's (None without a recorded reference time)."""
        return self.wall_s / self.reference_wall_s if self.reference_wall_s else None


def code_span(text: str) -> str:
    """``text`` as one Markdown code span, whatever backticks it holds (a longer fence: CommonMark's rule)."""
    fence = "`" * (max((len(run) for run in re.findall(r"`+", text)), default=0) + 1)
    pad = " " if text.startswith("`") or text.endswith("`") else ""
    return f"{fence}{pad}{text}{pad}{fence}"


def update_command(case: Case, reference_dir: Path) -> str:
    """The command that creates the case's reference, each argument quoted for a POSIX shell."""
    me = " --algorithm me --edition native" if case.algorithm == "me" else ""
    command = (f"python -m harness regress {shlex.quote(str(case.scenario))} --controller {case.controller}{me} "
               "--update")
    if Path(reference_dir).resolve() != reference_directory(case.algorithm).resolve():
        command += f" --references {shlex.quote(str(reference_dir))}"
    return command


def compare_case(run: CaseRun, reference: Reference | None, tolerances: dict | None = None,
                 reference_dir: Path | None = None) -> CaseComparison:
    """Compare one run with its reference; ``tolerances``: those given on the command line, which override
    the reference's own (per case and per signal) and the defaults."""
    case = run.case
    reference_dir = reference_directory(case.algorithm) if reference_dir is None else Path(reference_dir)
    given = dict(tolerances or {})
    run_tolerances = {**DEFAULT_TOLERANCES, **given}
    if reference is None:
        missing = reference_paths(case, reference_dir)[0]
        return CaseComparison(case, [], f"no reference {relative(missing)}: run "
                                        f"{code_span(update_command(case, reference_dir))} to create it", run.wall_s,
                              run_tolerances=run_tolerances)
    messages, notes = [], []
    meta = reference.meta
    for key, value in (("start", run.start), ("stop", run.stop), ("step", run.step)):
        if key in meta and not np.isclose(meta[key], value, rtol=1e-12, atol=0):
            messages.append(f"experiment changed: reference {key} = {meta[key]:g}, now {value:g} "
                            "(run --update if intended)")
    digest, settings = scenario_fingerprint(case)
    if "scenario_hash" not in meta:
        notes.append("the reference records no scenario hash (run --update to add it)")
    elif meta["scenario_hash"] != digest:
        changes = scenario_changes(meta.get("scenario_settings", {}), settings)
        messages.append(f"scenario changed since the reference ({changes or 'hash differs'}); "
                        "run --update if intended")
    if run.error:
        messages.append(f"the run failed: {run.error.splitlines()[0]}")
    case_level, per_signal = reference_tolerances(reference, list(run.signals))
    signals = []
    for name in run.signals:
        own = {**DEFAULT_TOLERANCES, **case_level, **per_signal.get(name, {}), **given}
        if name not in reference.signals:
            signals.append(SignalComparison(name, False, float("inf"), None, float("inf"), None,
                                            "missing from the reference (run --update)", tolerances=own))
            continue
        signals.append(compare_signal(name, reference.time, reference.signals[name], run.time, run.signals[name],
                                      own))
    wall = meta.get("wall_s")
    reference_wall = float(wall) if isinstance(wall, (int, float)) and wall > 0 else None
    return CaseComparison(case, signals, "; ".join(messages), run.wall_s, reference_wall, notes, run_tolerances)
