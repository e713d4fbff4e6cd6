"""The FMU declarations (harness/fmu_build/catalog.py, plants/registry.py): every FMU has one row, every row's files exist."""
from pathlib import Path

import pytest

from harness.fmu_build import builder as build_fmu
from harness.fmu_build import native as build_native
from harness.fmu_build.native_stages import description
from harness.fmu_build.native_stages import model_exchange as native_model_exchange
from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build import staging as fmu_staging
from plants import registry

ROOT = Path(__file__).resolve().parents[1]
SHARED_C = {"fmi_layer.c", "rk4_plant_slave.c", "plant_integration.c", "sampled_slave.c", "sampled_chain.c"}  # in several FMUs


def test_every_model_folder_is_one_row_and_every_fmu_file_is_in_one():
    """Discovery: each folder of plants/ with an fmu.py is a row (after the controller), named by the
    folder; every FMU script and C model file of fmu_src/ and plants/ belongs to a row."""
    identifiers = [row.model_identifier for row in fmu_catalog.FMUS]
    assert len(set(identifiers)) == len(identifiers)
    folders = sorted(p.parent.name for p in (ROOT / "plants").glob("*/fmu.py"))
    assert [row.name for row in registry.PLANT_FMUS] == folders
    assert [row.model_identifier for row in registry.PLANT_FMUS] == identifiers[1:]  # the controller first
    scripts = sorted([*(ROOT / "fmu_src").glob("*_fmu.py"), *(ROOT / "plants").glob("*/fmu.py")])
    assert sorted(row.script for row in fmu_catalog.FMUS) == scripts
    own_c = sorted(p for p in [*(ROOT / "fmu_src").glob("*.c"), *(ROOT / "plants").rglob("*.c")]
                   if p.name not in SHARED_C)
    assert sorted({p for row in fmu_catalog.FMUS for p in row.c_sources if p.name not in SHARED_C}) == own_c
    assert registry.model_identifier("dc_motor_arm") == "DcMotorArm"


def test_the_c_sources_keep_one_name_each_inside_the_native_fmus():
    """A model folder's model.c is <folder>.c in the archive's sources/; no two files of one FMU share a name."""
    for row in fmu_catalog.FMUS:
        names = [fmu_catalog.archive_name(p) for p in (*row.c_sources, *row.c_headers)]
        assert len(set(names)) == len(names), row.model_identifier
    assert fmu_catalog.archive_name(ROOT / "plants" / "manipulator" / "model.c") == "manipulator.c"


@pytest.mark.parametrize("row", fmu_catalog.FMUS, ids=lambda row: row.model_identifier)
def test_each_rows_files_exist_and_its_class_loads(row):
    for path in (row.script, *row.project_files, *row.c_sources, *row.c_headers):
        assert path.is_file(), path
    assert row.project_files[0] == fmu_catalog.BASE
    assert fmu_catalog.model_class(row.model_identifier).__name__ == row.model_identifier
    assert fmu_catalog.fmu(row.model_identifier) is row


def test_an_unknown_identifier_names_the_valid_ones():
    with pytest.raises(KeyError, match="unknown FMU 'Nope'; valid: .*'InvertedPendulum'"):
        fmu_catalog.fmu("Nope")
    known = " and ".join(row.model_identifier for row in registry.PLANT_FMUS if row.has_oracle)
    assert known.startswith("InvertedPendulum and Manipulator")  # the paper's plants, and any row with an oracle
    with pytest.raises(ValueError, match=f"the oracle knows {known}, not 'DcMotorArm'"):
        registry.oracle_model("DcMotorArm", {})


def test_every_plant_row_declares_its_model_exchange_interface(monkeypatch, capsys):
    """Every model folder's fmu.py declares model_exchange(): an RK4 plant's states are its RK4 states, the
    reference has none, a sampled FMU announces its samples as time events (the actuator's state is its
    rate limiter's); a script without one stops the native build with one line naming the file, not an
    AttributeError."""
    expected = {"reference": (), "sampled": {"Sensor": (), "Actuator": ("slew_state",)}}
    for row in registry.PLANT_FMUS:
        me = native_model_exchange.model_exchange(row.model_identifier)
        if row.integrated:  # y, dy, ... of an RK4 plant
            assert len(me.states) == len(fmu_catalog.model_class(row.model_identifier).STATE_ATTRIBUTES)
        elif row.kind == "sampled":
            assert me.states == expected["sampled"][row.model_identifier] and me.time_events, row.model_identifier
        else:
            assert me.states == expected[row.kind] and not me.time_events, row.model_identifier
    monkeypatch.delattr(fmu_catalog.declaration("Manipulator"), "model_exchange")
    with pytest.raises(build_native.NativeBuildError, match="Manipulator declares no model_exchange"):
        description.model_guid("Manipulator")  # where a build of the native FMU first asks for it
    # the build command says so in one line (the build itself is not run: its first step, the GUID, fails)
    monkeypatch.setattr(build_native, "compiler_available", lambda: True)
    monkeypatch.setattr(build_fmu, "ensure_built", lambda **_: description.model_guid("Manipulator"))
    assert build_fmu.main(["--edition", "native"]) == 1
    error = capsys.readouterr().err
    assert error.startswith("error: plants/manipulator/fmu.py: Manipulator declares no model_exchange()")
    assert "Traceback" not in error and len(error.strip().splitlines()) == 1


def test_the_oracle_models_are_the_plants_own_functions():
    pendulum = registry.oracle_model("InvertedPendulum", {"gv": 9.8, "mc": 1.0, "mp": 0.1, "lp": 0.5,
                                                          "dist_gain": 1.0})
    from plants.inverted_pendulum import model

    assert pendulum.derivative is model.pendulum_derivative
    assert pendulum.params == model.pendulum_params(9.8, 1.0, 0.1, 0.5, 1.0)
    assert pendulum.extra(0.7, 0.0, 0.0) == {"plant.d": model.pendulum_disturbance(0.7, 1.0)}


def test_each_fmu_file_loads_under_one_module_name():
    """The FMU sources load as modules of their packages only: no folder of theirs on sys.path, no
    second copy under a top-level name (harness/fmu_build/staging.py gives them those names inside the FMUs only)."""
    import sys

    staged = {fmu_staging.staged_module(p) for row in fmu_catalog.FMUS for p in row.sources}
    for row in fmu_catalog.FMUS:
        fmu_catalog.model_class(row.model_identifier)
    # an FMU loaded in this process has its own copies under these names, from its resources folder
    twice = [name for name in staged & set(sys.modules)
             if Path(getattr(sys.modules[name], "__file__", "") or "").resolve().is_relative_to(ROOT)]
    assert not twice, twice
    assert not {str(ROOT / "fmu_src"), str(ROOT / "plants")} & set(sys.path)


def test_staging_rewrites_the_imports_to_the_names_inside_the_fmu(tmp_path):
    row = fmu_catalog.fmu("InvertedPendulum")
    written = fmu_staging.stage(row.sources, tmp_path)
    assert [p.name for p in written] == ["inverted_pendulum_fmu.py", "afc_slave_base.py", "afc_declaration.py",
                                         "inverted_pendulum_model.py", "plant_integration.py", "rk4_plant_slave.py"]
    script = written[0].read_text()
    assert "import inverted_pendulum_model as model\n" in script
    assert "from rk4_plant_slave import RK4PlantSlave as Fmi2Slave\n" in script
    assert "from fmu_src" not in script and "from plants" not in script
    assert "from afc_slave_base import TableSlave\nimport plant_integration\n" in written[-1].read_text()
    with pytest.raises(ValueError, match=r"inverted_pendulum/fmu\.py:\d+: imports plants\.\S+, which is not among the FMU.s files"):
        fmu_staging.stage((row.script, fmu_catalog.BASE), tmp_path / "missing")
