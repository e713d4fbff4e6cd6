"""One study from its configuration to its outputs: prepare, open the study, run the loop, write
``<study>.toml``, ``<study>.json`` and the figures, and the folder's ``report.md`` again."""
from __future__ import annotations

import json
from pathlib import Path

from ... import cli_args
from ...fmi import release_extractions
from .config import Prepared, TuneConfig, prepare
from .loop import run_study
from .report import REPORT_NAME, figure_pareto, figure_progress, write_report
from .scenario_file import file_stem, write_tuned_toml
from .storage import best_trial, open_storage, open_study, outcome_of
from .summary import held_out_runs, summarize


def tune(config: TuneConfig, log=None, outputs: bool = True) -> dict:
    """Prepare, open the study, run it, write the outputs; returns the study's summary (plain data)."""
    prepared = prepare(config)
    if outputs:  # before the database and the first trial: a folder it cannot write is one line, not lost trials
        cli_args.check_writable(study_outputs(prepared))
    out = Path(config.out)
    if config.storage is None:
        out.mkdir(parents=True, exist_ok=True)
    storage = open_storage(prepared.storage_url)
    study = open_study(prepared, storage)
    log = log or (lambda line: None)
    log(f"study {prepared.study_name!r} in {prepared.storage_url}: {len(prepared.dimensions)} parameters "
        f"({', '.join(d.name for d in prepared.dimensions)}), {config.edition} edition, {config.jobs} process(es)")
    try:
        run_info = run_study(prepared, study, log)
        run_info["jobs"] = config.jobs
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
