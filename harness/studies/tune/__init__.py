"""Tuning the controller for a plant: ``python -m harness tune SCENARIO`` (docs/tuning.md).

The paper picks lambda_ce and kappa "by trial and error" and the rest by hand; this study searches
the controller's design parameters with an optimiser instead, on any scenario that wires our
controller (``AdaptiveFuzzyController``) to a plant.

Search space
    From the FMU's own variable table (``fmu_src/adaptive_fuzzy_controller_fmu.py``, the single
    source): every parameter that declares a :class:`Tuning` range and acts in the chosen variant
    at the controller's order.  ``log`` ranges are searched in log(value), ``log1m`` (lambda_ce)
    in log(1 - value), ``hurwitz`` (k3, k4) as a fraction of the Routh bound given the lower gains.
    The paper's conditions hold by construction or are checked before any run
    (:func:`paper_conditions`): every value inside its valid range (0 < lambda_ce < 1, gamma > 0,
    ...), k Hurwitz so that P of (30) is positive definite (the FMU's own test), |theta0| <= M_theta.

Optimiser and database
    Optuna (TPE by default, CMA-ES with ``--sampler cmaes``) with its RDB storage: SQLite by
    default (``sqlite:///results/tune/<scenario>.db``, write-ahead log), any SQLAlchemy URL with
    ``--storage`` (PostgreSQL: ``postgresql+psycopg://``, the postgres extra; its password masked in
    every output).  ``--jobs N`` keeps N trials in flight on a local pool, ``--scheduler ADDRESS`` as
    many as a Dask cluster's workers run (harness/executors/): a finished one is told and the next
    one asked while the others run.  Several ``tune`` processes may drive one study (same
    ``--storage`` and ``--study``; the seed is in the default name); ``--trials N`` is the number of
    finished trials the study should hold, so a repeated or resumed command adds only the missing
    ones.  A killed run leaves its running trials RUNNING: the next run on the same host fails them
    and enqueues them again with the same parameters (a dead process on another host: after the
    heartbeat's grace period).
    The sampler is seeded per trial from ``--seed`` and the number of trials already in the study,
    so the same seed gives the same trials under sequential sampling: ``--jobs 1``, one process,
    the study run from empty without interruption.  In parallel the trials depend on the order in
    which runs finish; a resumed run retries the killed trials as new ones, so its later trials
    differ from an uninterrupted run's.

Pruned, not lost
    A candidate whose run diverges (the master's divergence stop, or an FMU that reports its
    state or adaptation diverged), fails, or makes u chatter (the controller FMU's own monitor,
    a warning in its log) is told as PRUNED with the reason; so is one that beats the best so far
    and whose objective moves by more than ``--verify-tolerance`` (1 %) when the run is repeated
    at half the step (a numerical artefact, not the controller).  The best trial is therefore
    always one re-run at half the step: its Richardson estimate 2 f(h/2) - f(h) and the error
    estimate |f(h) - (2 f(h/2) - f(h))| of every score are reported.

Outputs (``--out``, default results/tune/)
    ``<study>.toml``: the scenario with the best parameters, which ``run`` and ``regress`` take
    unchanged; ``<study>.json`` and ``<study>_*.png``; ``report.md``: every study of the folder
    (best-so-far curve, Pareto fronts ITAE vs Ec and vs TV(u), parameter importances, the tuned
    controller against the starting one on held-out scenarios) and the equal-effort comparison
    of the three controllers (``--compare``).

One idea per module, each importing only those above it:

=================  =====================================================================
``errors``         TuneError, the command's usage error
``space``          the search space from the FMU's table, the Hurwitz fraction, the paper's conditions
``objective``      the score minimised, the constraints, the plant grid of ``--robust``
``candidate``      running a candidate: every grid point, the worst case, the half-step re-run
``config``         TuneConfig, and every input checked before the database opens (prepare)
``storage``        the database, the study and its signature, dead trials recovered, heartbeats
``loop``           ask, run, tell until the study holds its budget (run_study)
``scenario_file``  the tuned scenario ``<study>.toml``
``summary``        one study as plain data (``<study>.json``)
``report``         ``report.md`` and the figures
``comparison``     the equal-effort comparison's rows and verdicts
``study``          one study from configuration to outputs (tune)
``command_line``   ``python -m harness tune``: options, ``--bench``, ``--compare``
=================  =====================================================================
"""
from __future__ import annotations

from .candidate import evaluate
from .command_line import register
from .config import TuneConfig
from .space import hurwitz_bound, paper_conditions, parameter_values, sample_of, search_space
from .study import tune
from .summary import pareto_front

__all__ = ["TuneConfig", "tune", "search_space", "hurwitz_bound", "parameter_values", "sample_of",
           "paper_conditions", "evaluate", "pareto_front", "register"]
