"""harness/studies/compat.py: the FMUs' compatibility information in the FMI cross-check layout.

``python -m harness compat --out DIR`` runs once for the module: every FMU of both editions (FMI 2.0
co-simulation of the pythonfmu edition; FMI 2.0 and 3.0 of the native edition, with Model Exchange
wherever a model description declares it). The directory must validate clean with fmpy's
``validate_vendor_repo`` (and the same functions on the FMI 3.0 folders it skips), keep the layout's
limits, and every ``_ref.csv`` must come back from ``fmpy simulate`` run on ``_in.csv``. The checks
are also shown to fail: a broken file, a changed reference, a model description declaring ME.
"""
import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from harness.fmu_build import native as build_native
from harness.fmu_build import catalog as fmu_catalog
from harness.cli import main as cli_main
from harness.studies import compat

MODELS = [row.model_identifier for row in fmu_catalog.FMUS]
EDITIONS = compat.EDITIONS if build_native.compiler_available() else ("python",)


@pytest.fixture(scope="module")
def published(tmp_path_factory, fmu_paths):
    out = tmp_path_factory.mktemp("compat") / "compat"
    arguments = ["compat", "--out", str(out)] + ([] if EDITIONS == compat.EDITIONS else ["--edition", "python"])
    status = cli_main(arguments)
    return out, status, json.loads((out / "compat.json").read_text())


def entry_folders(out: Path) -> list:
    """Every fmus/<version>/<type>/<platform>/<tool>/<tool version>/<Model> folder."""
    return sorted(p for p in (out / "fmus").glob("*/*/*/*/*/*") if p.is_dir())


def test_every_fmu_of_both_editions_and_every_declared_interface_is_published(published):
    out, status, summary = published
    assert status == 0
    expected = set()
    for edition in EDITIONS:
        version = "3.0" if edition == "native3" else "2.0"
        built = {"python": fmu_catalog.FMU_DIR, "native": fmu_catalog.NATIVE_DIR,
                 "native3": fmu_catalog.FMI3_DIR}[edition]
        for model in MODELS:
            description = read_model_description(str(built / f"{model}.fmu"))
            declared = ["cs"] * (description.coSimulation is not None) + ["me"] * (description.modelExchange is not None)
            expected |= {f"{version}/{interface}/{compat.TOOLS[edition]}/{model}" for interface in declared}
    assert {entry["entry"] for entry in summary["entries"]} == expected
    assert len(expected) >= 5 * len(EDITIONS)
    platform = compat.platform_folder()
    for folder in entry_folders(out):
        version, interface, where, tool, tool_version, model = folder.relative_to(out / "fmus").parts
        assert where == platform and tool_version == compat.tool_version()
        assert sorted(p.name for p in folder.iterdir()) == sorted(
            [f"{model}.fmu", f"{model}_in.csv", f"{model}_ref.csv", f"{model}_ref.opt", "README.md"])


def test_the_directory_validates_clean_with_fmpys_cross_check_validator(published):
    out, _, summary = published
    validation = compat.validate(out)
    assert validation.problems == [] and summary["validation"]["problems"] == []
    folders = entry_folders(out)
    assert validation.fmus == len(folders) == len(summary["entries"])
    assert validation.results == len(folders)
    assert validation.fmi3_fmus == validation.fmi3_results == sum("/3.0/" in f"/{f.relative_to(out / 'fmus')}"
                                                                   for f in folders)
    if "native3" in EDITIONS:
        assert validation.fmi3_fmus >= 5  # fmpy's validate_repo skips FMI 3.0: checked with its functions here


def test_every_reference_comes_back_from_fmpy_simulate_on_its_inputs(published):
    out, _, summary = published
    for entry in summary["entries"]:
        assert entry["passed"] and entry["problem"] == "", entry
        if "/cs/" in entry["entry"]:
            assert entry["max_relative_deviation"] <= compat.CS_AGREEMENT, entry
    results = sorted(p.parent for p in (out / "results").rglob("passed"))
    assert len(results) == len(summary["entries"]) and not list((out / "results").rglob("failed"))
    for folder in results:
        model = folder.name
        assert (folder / f"{model}_out.csv").is_file()
        assert "fmpy simulate" in (folder / "README.md").read_text()


def test_model_exchange_entries_agree_with_the_reference_where_the_model_is_smooth(published):
    """ME re-simulated by CVode against the co-simulation result: the smooth models to 1e-5 of the range
    (measured: TrackingReference 0, DcMotorArm 1.6e-8, InvertedPendulum 3.2e-7). Inputs interpolated
    instead of held, or outputs read with the previous inputs, give 6e-3 (e) and 2.3 (the open-loop
    pendulum): this is what the held input file and the reference's read-out are for."""
    _, _, summary = published
    by_label = {entry["entry"]: entry for entry in summary["entries"]}
    me = [label for label in by_label if "/me/" in label]
    if not me:
        pytest.skip("no FMU declares Model Exchange")
    for label in me:
        if label.endswith(("/TrackingReference", "/DcMotorArm", "/InvertedPendulum")):
            assert by_label[label]["max_relative_deviation"] <= 1e-5, by_label[label]


def test_the_files_keep_the_layouts_limits_and_name_only_the_fmus_variables(published):
    out, _, _ = published
    for folder in entry_folders(out):
        model = folder.name
        description = read_model_description(str(folder / f"{model}.fmu"))
        variables = {v.name: v for v in description.modelVariables}
        header = [n.strip('"') for n in (folder / f"{model}_in.csv").open().readline().strip().split(",")]
        assert header[0] == "time" and all(variables[name].causality == "input" for name in header[1:])
        header = [n.strip('"') for n in (folder / f"{model}_ref.csv").open().readline().strip().split(",")]
        assert header[0] == "time" and 1 <= len(header) - 1 <= compat.MAX_SIGNALS
        assert all(variables[name].causality == "output" for name in header[1:])
        for name in (f"{model}_in.csv", f"{model}_ref.csv"):
            assert (folder / name).stat().st_size < 1_000_000
        reference = np.genfromtxt(folder / f"{model}_ref.csv", delimiter=",", skip_header=1)
        options = dict(line.split(", ") for line in (folder / f"{model}_ref.opt").read_text().splitlines())
        assert reference[0, 0] == float(options["StartTime"]) and reference[-1, 0] == float(options["StopTime"])
        assert np.all(np.isfinite(reference)) and np.ptp(reference[:, 1:], axis=0).max() > 0  # something moves
        readme = (folder / "README.md").read_text()
        assert "## The experiment" in readme and "fmpy simulate" in readme


def copy_entry(out: Path, target: Path, version: str) -> Path:
    """One published FMU folder (and its result) copied into a new vendor directory."""
    source = next(f for f in entry_folders(out) if f.relative_to(out / "fmus").parts[0] == version)
    relative = source.relative_to(out)
    shutil.copytree(source, target / relative)
    return target / relative


@pytest.mark.parametrize("version", ["2.0", "3.0"])
def test_the_validation_sees_a_broken_file(published, tmp_path, version):
    out, _, _ = published
    if version == "3.0" and "native3" not in EDITIONS:
        pytest.skip("the native edition needs zig's C compiler")
    folder = copy_entry(out, tmp_path, version)
    assert compat.validate(tmp_path).problems == []
    reference = folder / f"{folder.name}_ref.csv"
    lines = reference.read_text().splitlines()
    reference.write_text("\n".join([lines[0].replace('"time",', '"time","no_such_variable",'),
                                    *(line.replace(",", ",0,", 1) for line in lines[1:])]) + "\n")
    problems = compat.validate(tmp_path).problems
    assert len(problems) == 1 and "no_such_variable" in problems[0]


def test_a_reference_that_fmpy_does_not_reproduce_is_marked_failed(published, tmp_path, fmu_paths):
    out, _, _ = published
    experiments = compat.closed_loop_experiments(["TrackingReference"], fmu_paths)
    entry = compat.Entry("TrackingReference", "python", "2.0", "cs", fmu_paths["TrackingReference"],
                         experiments["TrackingReference"])
    compat.write_entry(entry, tmp_path)
    assert compat.resimulate(entry, tmp_path).passed
    reference = entry.folder / "TrackingReference_ref.csv"
    table = np.genfromtxt(reference, delimiter=",", skip_header=1)
    table[2000:, 1] *= 1.001  # ym 0.1 % off in the second half: inside fmpy's band, not an exact replay
    compat.write_csv(reference, ["time", *entry.experiment.outputs], table)
    again = compat.resimulate(entry, tmp_path)
    assert not again.passed and "differs from the reference" in again.problem
    assert (again.result_folder / "failed").exists() and not (again.result_folder / "passed").exists()


def test_the_interfaces_come_from_the_model_description(fmu_paths, tmp_path):
    """A model description that declares ModelExchange gets an "me" entry (the native FMUs'
    branch declare it); here one declaring both is made from a co-simulation FMU's description."""
    source = fmu_paths["TrackingReference"]
    assert compat.interfaces(source) == ["cs"]
    both = tmp_path / "Both.fmu"
    with zipfile.ZipFile(source) as original, zipfile.ZipFile(both, "w") as copy:
        for item in original.infolist():
            data = original.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                identifier = read_model_description(str(source)).coSimulation.modelIdentifier
                text = text.replace("<CoSimulation", f'<ModelExchange modelIdentifier="{identifier}"/>\n<CoSimulation', 1)
                data = text.encode()
            copy.writestr(item, data)
    assert compat.interfaces(both) == ["cs", "me"]


def test_compat_refuses_a_folder_it_did_not_write(tmp_path, capsys):
    (tmp_path / "mine.txt").write_text("keep me")
    assert cli_main(["compat", "--out", str(tmp_path), "--fmu", "TrackingReference", "--edition", "python"]) == 2
    assert "is a folder with other files" in capsys.readouterr().err
    assert (tmp_path / "mine.txt").read_text() == "keep me"
    assert cli_main(["compat", "--out", "docs", "--edition", "python"]) == 2
    assert "would overwrite committed files" in capsys.readouterr().err


def test_model_exchange_inputs_are_held_over_each_step_and_read_back_as_the_rows_of_each_step():
    table = np.array([[0.0, 1.0, 10.0], [0.5, 2.0, 20.0], [1.0, 3.0, 30.0]])
    held = compat.held(table)
    assert held.tolist() == [[0.0, 1.0, 10.0], [0.5, 1.0, 10.0], [0.5, 2.0, 20.0], [1.0, 2.0, 20.0],
                             [1.0, 3.0, 30.0]]
    assert held[::2].tolist() == table.tolist()  # how write_entry reads the rows of each step back


def test_a_replay_reads_outputs_with_the_previous_or_the_current_inputs(fmu_paths):
    """TrackingReference: e = ym - y with y an input (direct feedthrough): the co-simulation replay reads e
    at t_k+1 with y of t_k, the Model Exchange reference with y of t_k+1."""
    experiment = compat.Experiment("TrackingReference", "test", "reference", 0.0, 0.5, 2, 1, ("y",), ("ym", "e"),
                                   np.array([[0.0, 0.0], [0.5, 1.0], [1.0, 2.0]]))
    previous = compat.replay(fmu_paths["TrackingReference"], experiment)
    current = compat.replay(fmu_paths["TrackingReference"], experiment, outputs_with="current")
    ym = previous[:, 1]
    assert previous[:, 2] == pytest.approx(ym - [0.0, 0.0, 1.0], abs=1e-15)
    assert current[:, 2] == pytest.approx(ym - [0.0, 1.0, 2.0], abs=1e-15)
