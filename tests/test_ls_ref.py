"""Every FMU carries FMI-LS-REF (``extra/org.fmi-standard.fmi-ls-ref/``): a manifest, the stimuli and
the reference result of one experiment, the experiment of the compatibility information.

Each FMU is re-simulated by fmpy from its own embedded files (the manifest's start, stop and step, its
stimuli) and must match its reference within the tolerance its manifest states; the stored experiments
are compat's (``harness.studies.compat.closed_loop_experiments``), not a second definition.
"""
from __future__ import annotations

import zipfile
from xml.etree import ElementTree as ET

import pytest

from harness.fmu_build import builder as build_fmu
from harness.fmu_build import native as build_native
from harness.fmu_build import catalog as fmu_catalog
from harness.studies import compat
from harness.fmu_build.native_stages import ls_ref

MODELS = [row.model_identifier for row in fmu_catalog.FMUS]
NATIVE = [m.model_identifier for m in build_native.models()]

needs_zig = pytest.mark.skipif(not build_native.compiler_available(),
                               reason="zig's C compiler is not installed (pip install -e '.[native]')")


@pytest.fixture(scope="module")
def native():
    return build_native.ensure_built()


@pytest.fixture(scope="module")
def python_fmus():
    return build_fmu.ensure_built(edition="python")


def embedded(fmu) -> dict[str, bytes]:
    with zipfile.ZipFile(fmu) as archive:
        return {name: archive.read(name) for name in archive.namelist() if name.startswith(ls_ref.FOLDER + "/")}


def resimulated_deviation(fmu, tmp_path) -> tuple[dict, float]:
    """({output: deviation / range}, tolerance) of fmpy's run of ``fmu`` on its own LS-REF files."""
    files = embedded(fmu)
    experiment = ls_ref.read_manifest(files[ls_ref.MANIFEST])
    stimuli = None
    if experiment["stimuli"]:
        stimuli = tmp_path / experiment["stimuli"]
        stimuli.write_bytes(files[f"{ls_ref.FOLDER}/{experiment['stimuli']}"])
    reference = ls_ref.read_table(files[f"{ls_ref.FOLDER}/{experiment['references']}"])
    outputs = reference.dtype.names[1:]
    result = ls_ref.simulate(fmu, experiment["startTime"], experiment["stopTime"], experiment["stepSize"],
                             stimuli, outputs)
    assert len(result) == len(reference)
    assert (result["time"] == reference["time"]).all()
    return ls_ref.deviation(reference, result, outputs), experiment["tolerance"]


@needs_zig
@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("model", NATIVE)
def test_native_fmu_reproduces_its_embedded_reference(model, version, native, tmp_path):
    found, tolerance = resimulated_deviation(native[model][version], tmp_path)
    assert max(found.values()) <= tolerance, found


@pytest.mark.parametrize("model", MODELS)
def test_python_fmu_reproduces_its_embedded_reference(model, python_fmus, tmp_path):
    found, tolerance = resimulated_deviation(python_fmus[model], tmp_path)
    assert max(found.values()) <= tolerance, found


@needs_zig
@pytest.mark.parametrize("model", NATIVE)
def test_manifest_names_the_layered_standard_and_its_files(model, native):
    for version in (2, 3):
        files = embedded(native[model][version])
        root = ET.fromstring(files[ls_ref.MANIFEST])
        assert root.tag == "fmiReferences"
        assert root.get(f"{{{ls_ref.LS_NAMESPACE}}}fmi-ls-name") == "org.fmi-standard.fmi-ls-ref"
        assert root.get(f"{{{ls_ref.LS_NAMESPACE}}}fmi-ls-version") == ls_ref.LS_VERSION
        experiment = ls_ref.read_manifest(files[ls_ref.MANIFEST])
        for source in (experiment["stimuli"], experiment["references"]):
            assert f"{ls_ref.FOLDER}/{source}" in files


def test_stored_experiments_are_compats(python_fmus):
    """harness/fmu_build/native_stages/ls_ref_experiments/ is what compat's closed loops give now (else: python -m harness
    compat --ls-ref-experiments)."""
    experiments = compat.closed_loop_experiments(MODELS, python_fmus)
    assert ls_ref.stored_models() == sorted(MODELS)
    for model in MODELS:
        assert ls_ref.load(model) == compat.ls_ref_experiment(experiments[model]), \
            f"{model}: stored FMI-LS-REF experiment is stale; run python -m harness compat --ls-ref-experiments"


def test_a_missing_experiment_is_one_clear_error():
    with pytest.raises(KeyError, match="no FMI-LS-REF experiment of Nope .*--ls-ref-experiments"):
        ls_ref.load("Nope")


def test_a_new_fmus_first_build_leaves_fmi_ls_ref_out_and_says_so(monkeypatch, capsys):
    """Before its experiment is stored (the recipe's first build of a new FMU), the builds leave FMI-LS-REF
    out with a note naming the command that writes it; once stored, they embed it."""
    monkeypatch.setattr(ls_ref, "stored_models", lambda: ["InvertedPendulum"])
    assert build_fmu.ls_ref_model("Sensor") is None
    note = capsys.readouterr().err
    assert note.startswith("note: Sensor: no FMI-LS-REF experiment stored yet") and "--fmu Sensor" in note
    assert build_fmu.ls_ref_model("InvertedPendulum") == "InvertedPendulum" and not capsys.readouterr().err
