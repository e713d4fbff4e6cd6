"""The FMU declarations (fmu_catalog.py, plants/registry.py): every FMU has one row, every row's files exist."""
from pathlib import Path

import pytest

import build_fmu
import build_native
from native_build import description
from native_build import model_exchange as native_model_exchange
import fmu_catalog
from plants import registry

ROOT = Path(__file__).resolve().parents[1]
SHARED_C = {"fmi_layer.c", "rk4_plant_slave.c", "plant_integration.c"}  # compiled into several FMUs


def test_every_fmu_script_and_c_model_has_exactly_one_row():
    identifiers = [row.model_identifier for row in fmu_catalog.FMUS]
    assert len(set(identifiers)) == len(identifiers)
    scripts = sorted(p.name for folder in ("fmu_src", "plants") for p in (ROOT / folder).glob("*_fmu.py"))
    assert sorted(row.script.name for row in fmu_catalog.FMUS) == scripts
    own_c = sorted(p.name for folder in ("fmu_src", "plants") for p in (ROOT / folder).glob("*.c")
                   if p.name not in SHARED_C)
    assert sorted({p.name for row in fmu_catalog.FMUS for p in row.c_sources} - SHARED_C) == own_c
    assert [row.model_identifier for row in registry.PLANT_FMUS] == identifiers[1:]  # the controller first


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
    known = " and ".join(row.model_identifier for row in registry.PLANT_FMUS if row.oracle is not None)
    assert known.startswith("InvertedPendulum and Manipulator")  # the paper's plants, and any row with an oracle
    with pytest.raises(ValueError, match=f"the oracle knows {known}, not 'DcMotorArm'"):
        registry.oracle_model("DcMotorArm", {})


def test_every_plant_row_declares_its_model_exchange_interface(monkeypatch, capsys):
    """The native build's Model Exchange table (native_build/model_exchange.py: MODEL_EXCHANGE) has an entry per registry row;
    a row without one stops the build with one line naming the table, not a KeyError."""
    for row in registry.PLANT_FMUS:
        me = native_model_exchange.model_exchange(row.model_identifier)
        assert len(me.states) == (row.order or 0), row.model_identifier  # y, dy, ... of an RK4 plant; none else
    monkeypatch.delitem(native_model_exchange.MODEL_EXCHANGE, "Manipulator")
    with pytest.raises(build_native.NativeBuildError, match="MODEL_EXCHANGE has no entry for 'Manipulator'"):
        description.model_guid("Manipulator")  # where a build of the native FMU first asks for it
    # the build command says so in one line (the build itself is not run: its first step, the GUID, fails)
    monkeypatch.setattr(build_native, "compiler_available", lambda: True)
    monkeypatch.setattr(build_fmu, "ensure_built", lambda **_: description.model_guid("Manipulator"))
    assert build_fmu.main(["--edition", "native"]) == 1
    error = capsys.readouterr().err
    assert error.startswith("error: native_build/model_exchange.py: MODEL_EXCHANGE has no entry for 'Manipulator'")
    assert "Traceback" not in error and len(error.strip().splitlines()) == 1


def test_the_oracle_models_are_the_plants_own_functions():
    pendulum = registry.oracle_model("InvertedPendulum", {"gv": 9.8, "mc": 1.0, "mp": 0.1, "lp": 0.5,
                                                          "dist_gain": 1.0})
    from plants import inverted_pendulum_model as model

    assert pendulum.derivative is model.pendulum_derivative
    assert pendulum.params == model.pendulum_params(9.8, 1.0, 0.1, 0.5, 1.0)
    assert pendulum.extra(0.7, 0.0, 0.0) == {"plant.d": model.pendulum_disturbance(0.7, 1.0)}
