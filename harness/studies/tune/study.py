"""One study from its configuration to its outputs: prepare, open the study, run the loop, write
``<study>.toml``, ``<study>.json`` and the figures, and the folder's ``report.md`` again."""
from __future__ import annotations

import json
from pathlib import Path

from ... import cli_args
from ...executors import SchedulerLost, open_executor
from ...fmi import release_extractions
from .config import Prepared, TuneConfig, prepare
from .loop import candidate_files, run_study
from .report import REPORT_NAME, figure_pareto, figure_progress, write_report
from .scenario_file import file_stem, write_tuned_toml
from .storage import (StudyWriteError, best_trial, open_storage, open_study, outcome_of, seed_note, sqlite_file,
                      storage_write_problem)
from .summary import held_out_runs, summarize


def tune(config: TuneConfig, log=None, outputs: bool = True) -> dict:
    """Prepare, open the study, run it, write the outputs; returns the study's summary (plain data).

    Everything that can be refused is refused before the first trial (one line each): the inputs, the
    output folder, the database, the executor (a Dask scheduler that cannot be reached).
    """
    prepared = prepare(config)
    if outputs:  # before the database and the first trial: a folder it cannot write is one line, not lost trials
        cli_args.check_writable(study_outputs(prepared))
    out = Path(config.out)
    if config.storage is None:
        out.mkdir(parents=True, exist_ok=True)
    storage = open_storage(prepared.storage_url)
    study = open_study(prepared, storage)
    log = log or (lambda line: None)
    note = seed_note(study, prepared)
    if note:
        log(note)
    executor = open_executor(config.jobs, config.scheduler, files=candidate_files(prepared), inline_single=True)
    where = executor.describe()
    log(f"study {prepared.study_name!r} in {prepared.storage_shown}: {len(prepared.dimensions)} parameters "
        f"({', '.join(d.name for d in prepared.dimensions)}), {config.edition} edition, trials on {where}")
    database = sqlite_file(prepared.storage_url)
    if config.scheduler and database is not None:
        log(f"note: the study stays in the SQLite file {database} on this host: the Dask workers run the "
            "candidates and only this process writes the study; tune processes on other hosts cannot share it "
            "(use --storage postgresql+psycopg://... for that)")
    try:
        try:
            run_info = run_study(prepared, study, log, executor)
        except SchedulerLost as error:
            raise SchedulerLost(f"{error}: the study keeps its finished trials and queues the running ones again; "
                                "run the same command to resume") from None
        except Exception as error:
            problem = storage_write_problem(prepared, error)
            if problem is None:
                raise
            raise StudyWriteError(problem) from None
        run_info["jobs"] = config.jobs if config.scheduler is None else executor.slots
        if not outputs:
            summary = summarize(prepared, study, run_info)
            summary["study_file"] = None
            return summary
        summary = write_study_outputs(prepared, study, run_info, jobs=config.jobs)
    finally:
        release_extractions()  # those of --jobs 1 (the workers remove theirs when they exit)
    write_report(out)
    return summary


def study_outputs(prepared: Prepared) -> list:
    """The files one study writes into its output folder: <study>.toml, .json, the two figures, report.md."""
    out = Path(prepared.config.out)
    base = file_stem(prepared.study_name)
    return [out / f"{base}.toml", out / f"{base}.json", out / f"{base}_progress.png", out / f"{base}_pareto.png",
            out / REPORT_NAME]


def write_study_outputs(prepared: Prepared, study, run_info: dict | None, held_out: bool = True,
                        jobs: int = 1) -> dict:
    """<study>.toml (when there is a best), <study>.json, the two figures; returns the summary."""
    toml, data, progress, pareto, _ = study_outputs(prepared)
    toml.parent.mkdir(parents=True, exist_ok=True)
    summary = summarize(prepared, study, run_info)
    summary["study_file"] = None
    best = best_trial(study.get_trials(deepcopy=False))
    if best is not None:
        path = write_tuned_toml(prepared, best, toml)
        summary["study_file"] = str(path)
        if held_out and prepared.held_out:
            summary["held_out"] = held_out_runs(prepared, outcome_of(best)["parameters"], jobs)
    figure_progress(summary, progress)
    figure_pareto(summary, pareto)
    data.write_text(json.dumps(summary, indent=1, default=str))
    return summary
