"""The FMI-LS-REF layered standard in every FMU: ``extra/org.fmi-standard.fmi-ls-ref/``.

It holds the manifest ``fmi-ls-manifest.xml`` (one experiment: start, stop, step, tolerance, the
stimuli and the references), the stimuli ``<Model>_in.csv`` and the reference result
``<Model>_ref.csv`` (time, then the outputs). The experiment is the one of the compatibility
information (``python -m harness compat``): the FMU's connected inputs as our master set them in a
closed loop, stored once in ``harness/fmu_build/native_stages/ls_ref_experiments/`` by ``python -m harness compat
--ls-ref-experiments``. The reference is the FMU itself simulated by fmpy in co-simulation on those
inputs, as an importer replays them; ``tolerance`` is the largest deviation of an output from the
reference allowed, relative to the output's range in the reference (the cross-check's measure).
"""
from __future__ import annotations

import contextlib
import io
import json
import tempfile
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
from fmpy import platform as FMPY_PLATFORM
from fmpy import platform_tuple as FMPY_PLATFORM_TUPLE
from fmpy import simulate_fmu
from fmpy.util import read_csv

from harness import atomic_files
from harness.fmu_build.native_stages import ROOT
from harness.fmu_build.native_stages.description import pretty_xml

FOLDER = "extra/org.fmi-standard.fmi-ls-ref"
MANIFEST = f"{FOLDER}/fmi-ls-manifest.xml"
EXPERIMENTS = Path(__file__).parent / "ls_ref_experiments"
EXPERIMENTS_FILE = EXPERIMENTS / "experiments.json"
LS_NAMESPACE = "http://fmi-standard.org/fmi-ls-manifest"
LS_VERSION = "1.0.0-rc.1"
LS_DESCRIPTION = "Layered Standard providing reference stimuli and results for an FMU."
#: the same binary, inputs and calls give the same numbers: room for nothing but printing
TOLERANCE = 1e-12


@dataclass(frozen=True)
class Experiment:
    """One FMU's experiment as stored: the grid, the signals, the stimuli file's text."""

    model: str
    scenario: str
    instance: str
    start: float
    step: float
    steps: int
    inputs: tuple
    outputs: tuple
    stimuli: bytes  # <Model>_in.csv

    @property
    def stop(self) -> float:
        return self.start + self.steps * self.step

    def as_json(self) -> dict:
        return {"scenario": self.scenario, "instance": self.instance, "start": self.start, "step": self.step,
                "steps": self.steps, "inputs": list(self.inputs), "outputs": list(self.outputs)}


def csv_text(names, table) -> bytes:
    """A cross-check CSV: quoted names, time first, numbers as the shortest text that reads back exactly."""
    lines = [",".join(f'"{name}"' for name in names)]
    lines += [",".join(repr(float(value)) for value in row) for row in table]
    return ("\n".join(lines) + "\n").encode()


def stimuli_name(model: str) -> str:
    return f"{model}_in.csv"


def reference_name(model: str) -> str:
    return f"{model}_ref.csv"


def stored_models() -> list[str]:
    return sorted(json.loads(EXPERIMENTS_FILE.read_text())) if EXPERIMENTS_FILE.exists() else []


def load(model: str) -> Experiment:
    """The stored experiment of ``model``; a missing one is one clear error."""
    stored = json.loads(EXPERIMENTS_FILE.read_text()) if EXPERIMENTS_FILE.exists() else {}
    if model not in stored:
        raise KeyError(f"no FMI-LS-REF experiment of {model} in {EXPERIMENTS_FILE.relative_to(ROOT)} "
                       f"(has: {', '.join(sorted(stored)) or 'none'}); write them with "
                       "python -m harness compat --ls-ref-experiments")
    entry = stored[model]
    return Experiment(model, entry["scenario"], entry["instance"], entry["start"], entry["step"], entry["steps"],
                      tuple(entry["inputs"]), tuple(entry["outputs"]),
                      (EXPERIMENTS / stimuli_name(model)).read_bytes())


def write(experiments: list[Experiment]) -> None:
    """Store the experiments (experiments.json and each stimuli file)."""
    EXPERIMENTS.mkdir(parents=True, exist_ok=True)
    for experiment in experiments:
        atomic_files.write_bytes(EXPERIMENTS / stimuli_name(experiment.model), experiment.stimuli)
    atomic_files.write_text(EXPERIMENTS_FILE, json.dumps({e.model: e.as_json() for e in sorted(experiments,
                                                                                               key=lambda e: e.model)},
                                                         indent=2) + "\n")


def manifest(experiment: Experiment, tolerance: float = TOLERANCE) -> bytes:
    ET.register_namespace("fmi-ls", LS_NAMESPACE)
    attribute = lambda name: f"{{{LS_NAMESPACE}}}{name}"  # noqa: E731
    root = ET.Element("fmiReferences", {attribute("fmi-ls-name"): "org.fmi-standard.fmi-ls-ref",
                                        attribute("fmi-ls-version"): LS_VERSION,
                                        attribute("fmi-ls-description"): LS_DESCRIPTION})
    element = ET.SubElement(root, "Experiment", name=f"{experiment.scenario}_{experiment.instance}",
                            description=f"the FMU's inputs in the first {experiment.stop - experiment.start:g} s of "
                                        f"the closed loop {experiment.scenario} (instance {experiment.instance}), "
                                        "parameters at their defaults, co-simulation",
                            startTime=repr(experiment.start), stopTime=repr(experiment.stop),
                            stepSize=repr(experiment.step), tolerance=repr(tolerance))
    if experiment.inputs:
        ET.SubElement(element, "Stimuli", source=stimuli_name(experiment.model), type="text/csv")
    ET.SubElement(element, "References", source=reference_name(experiment.model), type="text/csv")
    return pretty_xml(root)


def read_manifest(text: bytes) -> dict:
    """{startTime, stopTime, stepSize, tolerance, stimuli, references} of the manifest's one experiment."""
    experiment = ET.fromstring(text).find("Experiment")
    stimuli, references = experiment.find("Stimuli"), experiment.find("References")
    return {**{key: float(experiment.get(key)) for key in ("startTime", "stopTime", "stepSize", "tolerance")},
            "stimuli": stimuli.get("source") if stimuli is not None else None,
            "references": references.get("source")}


def simulate(fmu, start: float, stop: float, step: float, stimuli: Path | None, outputs) -> np.ndarray:
    """fmpy's co-simulation of ``fmu`` (an FMU file or unpacked folder) on a stimuli file."""
    with contextlib.redirect_stdout(io.StringIO()):  # fmpy prints a line per input left at its start value
        return simulate_fmu(str(fmu), start_time=start, stop_time=stop, output_interval=step, step_size=step,
                            input=read_csv(str(stimuli)) if stimuli is not None else None, output=list(outputs),
                            fmi_type="CoSimulation", validate=False)


def runs_here(files: dict[str, bytes], fmi_version: int) -> bool:
    """Whether the archive holds a binary for this machine's platform (the reference needs one)."""
    folder = f"binaries/{FMPY_PLATFORM if fmi_version == 2 else FMPY_PLATFORM_TUPLE}/"
    return any(name.startswith(folder) for name in files)


def ls_ref_files(experiment: Experiment, files: dict[str, bytes]) -> dict[str, bytes]:
    """{archive path: bytes}: the manifest, the stimuli and the reference of the FMU made of ``files``
    (simulated from a scratch folder removed afterwards)."""
    with tempfile.TemporaryDirectory(prefix="afc_ls_ref_") as scratch:
        folder = Path(scratch)
        for name, data in files.items():
            (folder / name).parent.mkdir(parents=True, exist_ok=True)
            (folder / name).write_bytes(data)
        stimuli = folder / stimuli_name(experiment.model)
        stimuli.write_bytes(experiment.stimuli)
        result = simulate(folder, experiment.start, experiment.stop, experiment.step,
                          stimuli if experiment.inputs else None, experiment.outputs)
    table = np.column_stack([result[name] for name in ("time", *experiment.outputs)])
    return {MANIFEST: manifest(experiment),
            **({f"{FOLDER}/{stimuli_name(experiment.model)}": experiment.stimuli} if experiment.inputs else {}),
            f"{FOLDER}/{reference_name(experiment.model)}": csv_text(("time", *experiment.outputs), table)}


def deviation(reference: np.ndarray, result: np.ndarray, outputs) -> dict[str, float]:
    """{output: max |result - reference| / range of the reference} on the reference's grid."""
    found = {}
    for name in outputs:
        scale = float(np.ptp(reference[name])) or max(float(np.max(np.abs(reference[name]))), 1.0)
        found[name] = float(np.max(np.abs(result[name] - reference[name]))) / scale
    return found


def read_table(data: bytes) -> np.ndarray:
    """A CSV of the archive as fmpy reads it (a structured array)."""
    with tempfile.TemporaryDirectory(prefix="afc_ls_ref_") as scratch:
        path = Path(scratch) / "table.csv"
        path.write_bytes(data)
        return read_csv(str(path))
