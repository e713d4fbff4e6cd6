"""Regression against reference results: ``python -m harness regress`` (docs/studies.md).

In the style of BuildingsPy's ReferenceResults and the Modelica Standard Library's reference results,
checked with the tube (funnel) comparison that BuildingsPy uses (``pyfunnel``): every case (one
scenario with one controller: the built-in scenarios x the three controllers, or a user's scenario
file) runs over its scenario's whole horizon, and every compared signal must lie inside the tube
around its committed reference; a changed experiment or scenario fails the case, a missing
reference fails, and references change only with ``--update``.

One idea per module, each importing only those above it:

==============  =========================================================================
``runs``        the cases, their compared signals, the runs resampled for comparison
``references``  the reference files, the scenario's fingerprint, the tolerances they carry
``comparison``  the tube comparison of a signal and of a case with its reference
``figures``     the PNG of a failing signal (reference, tube, new result, excursion)
``report``      report.md, report.html and JUnit XML
``command``     ``regress`` (run, compare, update, report) and its command line
==============  =========================================================================
"""
from __future__ import annotations

from .command import DEFAULT_REPORT_DIR, Outcome, regress, register
from .comparison import CaseComparison, SignalComparison, compare_case, compare_signal
from .references import (DEFAULT_TOLERANCES, MODEL_EXCHANGE_REFERENCE_DIR, REFERENCE_DIR, Reference, read_reference,
                         reference_paths, scenario_fingerprint, write_reference)
from .report import SLOW_FACTOR, SUMMARY_HEADER, slowness, summary_rows
from .runs import POINTS, SIGNALS, Case, CaseRun, all_cases, case_signals, run_cases

__all__ = ["Case", "CaseRun", "CaseComparison", "SignalComparison", "Reference", "Outcome", "SIGNALS", "POINTS",
           "DEFAULT_TOLERANCES", "REFERENCE_DIR", "MODEL_EXCHANGE_REFERENCE_DIR", "DEFAULT_REPORT_DIR", "SLOW_FACTOR",
           "SUMMARY_HEADER", "all_cases", "case_signals", "reference_paths", "run_cases", "write_reference",
           "read_reference", "compare_signal", "compare_case", "summary_rows", "slowness", "regress",
           "scenario_fingerprint", "register"]
