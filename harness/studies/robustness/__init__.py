"""A Monte Carlo robustness study: ``python -m harness robustness SCENARIO --samples N --param ...``
(docs/studies.md).

The uncertain plant parameters are drawn from their distributions (uniform, normal, log-uniform,
truncated normal) on a ``scipy.stats.qmc`` design (scrambled Sobol' or a Latin hypercube, seeded),
the sensor's noise seed per sample where the scenario has one, and every controller runs on the same
draws (common random numbers).  The runs go through the executor layer's stream (harness/executors/:
a local pool or a Dask scheduler), each worker keeping its FMUs extracted and instantiated (reset
between samples); rows stream to ``DIR/robustness.csv`` as they finish and a rerun adds only the
missing ones.  The summary (shares with Wilson intervals, quantiles and paired differences with
bootstrap intervals, the probability of meeting ``--spec``, the parameters ranked by SALib's RBD-FAST)
is computed from the file's rows, written to ``DIR/summary.json`` and drawn.

One idea per module, each importing only those above it:

=================  ==================================================================
``distributions``  the distributions of the uncertain parameters (``--param``, ``--distributions``)
``draws``          the design on the unit cube (scipy.stats.qmc) and the noise seeds
``plan``           the validated plan: scenario, controllers, distributions, design, settings
``kept_instances`` a master whose FMU instances are reset between runs, not made anew
``sample_run``     one (sample, controller) as a task, with the worker's kept state
``rows``           the streamed, resumable ``robustness.csv`` and the settings file
``spec``           ``--spec "ITAE<0.6,umax<50"``
``statistics``     shares (Wilson), quantiles and paired differences (bootstrap)
``influence``      the parameters ranked by influence (SALib RBD-FAST)
``figure``         the ECDF of the objective, the objective over the most influential parameter
``run``            the loop: the missing items stream, rows written, the summary (run_study)
``command_line``   ``python -m harness robustness``: options, what it prints
=================  ==================================================================
"""
from __future__ import annotations

from .command_line import register, robustness_command, summary_lines
from .distributions import Distribution, load_file, parse_param
from .plan import StudyPlan, plan_study
from .rows import read_rows
from .run import StudyOutcome, run_study, summarise
from .spec import parse_spec

__all__ = ["register", "robustness_command", "summary_lines", "Distribution", "load_file", "parse_param", "StudyPlan",
           "plan_study", "read_rows", "StudyOutcome", "run_study", "summarise", "parse_spec"]
