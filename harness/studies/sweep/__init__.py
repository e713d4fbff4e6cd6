"""Parameter sweeps: ``python -m harness sweep SCENARIO --grid NAME=START:STOP:N ...`` (docs/studies.md).

The cartesian product of the grids (any parameter of any instance, or the
communication ``step`` / the ``stop`` time) times the chosen controllers,
one co-simulation per point, on a local process pool (default: every core)
or on an existing ``dask.distributed`` scheduler (``--scheduler ADDRESS``).

Rows stream to ``DIR/sweep.csv`` as points finish: the controller, the grid
values, every score of docs/model.md section 9 (scores), the wall time of the point, its status
(``ok``, ``diverged``, ``failed``) and the reason.  Run the same command again
after an interruption: points already in the CSV (same controller and grid
values) are skipped.  ``DIR/sweep.json`` holds the settings of the sweep
(scenario, horizon, step, fixed parameters) so a resume with different
settings is refused rather than mixed in.  At the end ``DIR/heatmap_METRIC.png``
shows the metric over the first two grid axes, one panel per controller.

Grid values must be bit-identical wherever the point runs: the parent computes
them, hands them over as Python floats and writes them with ``repr``; workers
run the same FMU files (a Dask worker receives their bytes from the client and
caches them by content hash), so a point gives the same scores on any host.

One idea per module, each importing only those above it:

================  =====================================================================
``grid``          the grid axes (``--grid``), the points' keys, the validated plan (SweepPlan)
``csv_rows``      the resumable ``sweep.csv`` (rows streamed and flushed) and ``sweep.json``
``executors``     one point as a task, and where it runs (a local process pool or Dask)
``heatmap``       the heat map of one metric over the first two axes
``run``           the loop: the points not yet done run, their rows stream (run_sweep)
``command_line``  ``python -m harness sweep``: options, what it prints, ``--apply``
================  =====================================================================
"""
from __future__ import annotations

from .command_line import DOCS_DIR, apply_to_docs, register, sweep_command
from .grid import Grid, SweepPlan, parse_grid, plan_sweep, point_key
from .heatmap import heatmap_arrays, plot_heatmap
from .run import SweepSummary, current_rows, run_sweep

__all__ = ["register", "sweep_command", "apply_to_docs", "DOCS_DIR", "Grid", "SweepPlan", "parse_grid",
           "plan_sweep", "point_key", "heatmap_arrays", "plot_heatmap", "SweepSummary", "current_rows", "run_sweep"]
