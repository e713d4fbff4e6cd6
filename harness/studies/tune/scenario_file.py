"""The tuned scenario file ``<study>.toml``: the scenario with the best trial's values, which
``run`` and ``regress`` take unchanged, with a comment that says where it comes from."""
from __future__ import annotations

import re
from pathlib import Path

from ... import scenario as scenarios
from ...scenario_toml import scenario_toml
from .candidate import with_values
from .config import Prepared
from .storage import outcome_of


def tuned_scenario(prepared: Prepared, values: dict):
    """The configured scenario with the tuned values (and its variant) set, named after the study (the
    file's stem, which regress names its reference files after)."""
    tuned = with_values(prepared.scenario, values)
    tuned.name = file_stem(prepared.study_name)
    tuned.description = (f"{prepared.scenario.description} -- controller {prepared.config.controller} tuned by "
                         f"`python -m harness tune` ({prepared.config.objective})")
    return tuned


def file_stem(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def write_tuned_toml(prepared: Prepared, trial, path: Path) -> Path:
    outcome = outcome_of(trial)
    objective = prepared.config.objective
    scores = outcome["scores"]
    tuned = tuned_scenario(prepared, outcome["parameters"])
    edition = prepared.config.edition
    comments = [f"Tuned by `python -m harness tune` (docs/tuning.md): study {prepared.study_name!r} in "
                f"{prepared.storage_shown}, trial #{trial.number}.",
                f"{objective} = {scores[objective]!r} at step {prepared.scenario.step:g} s with the {edition} "
                f"edition" + (" (worst case over the --robust grid; this file is its base point)"
                              if len(prepared.grid) > 1 else "") + ".",
                f"Reproduce: python -m harness run {path} --controller {prepared.config.controller} --edition "
                f"{edition}",
                f"Regression: python -m harness regress {path} --controller {prepared.config.controller} "
                "[--update]", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    text = scenario_toml(tuned, comments)
    scenarios.parse(scenarios.tomllib.loads(text), path)  # it reads back as a scenario
    path.write_text(text)
    return path
