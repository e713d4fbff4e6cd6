"""Scenario-file and command-line mistakes give one clear error line (exit 2), never a traceback.

Name mistakes already in tests/test_master.py are not repeated here."""
from __future__ import annotations

import zipfile

import pytest

from harness.fmu_build import builder as build_fmu

from harness import scenario as scenarios
from harness.cli import main as cli_main


# ------------------------------------------------------------ scenario mistakes
def edited_scenario(tmp_path, edit):
    text = (scenarios.SCENARIO_DIR / "pendulum_case1.toml").read_text()
    edited = edit(text)
    assert edited != text, "the edit did not apply"
    path = tmp_path / "edited.toml"
    path.write_text(edited)
    return path


MISTAKES = [  # (what, edit, expected text); name mistakes already in test_master.py are not repeated
    ("unknown instance in a connection target", lambda t: t.replace('to = "plant.u"', 'to = "plnt.u"'),
     "[[connections]] 7: to = 'plnt.u': unknown instance 'plnt' (did you mean 'plant'?); valid: plant, reference, controller"),
    ("unknown instance in the record", lambda t: t.replace('"reference.ym", "reference.dym"',
                                                             '"ref.ym", "reference.dym"'),
     "[record] variables: 'ref.ym': unknown instance 'ref'"),
    ("an input recorded as an output", lambda t: t.replace('variables = ["plant.y",', 'variables = ["plant.u", "plant.y",'),
     "[record] variables: 'plant.u' is an input, not an output; valid outputs of plant: y, dy, d"),
    ("an input set as a parameter", lambda t: t.replace("parameters = { mp = 0.1,", "parameters = { u = 1.0, mp = 0.1,"),
     "InvertedPendulum has no parameter 'u'"),
    ("an input connected twice", lambda t: t.replace('to = "reference.dy"', 'to = "reference.y"'),
     "input 'reference.y' is connected twice"),
    ("a scored signal that is not recorded", lambda t: t.replace('u = "controller.u"', 'u = "controller.alpha1"'),
     "[signals] u = 'controller.alpha1' is not in [record] variables"),
    ("a missing FMU file (absolute path)",
     lambda t: t.replace('fmu = "TrackingReference"', 'fmu = "/nonexistent/TrackingReference.fmu"'),
     "FMU file not found: /nonexistent/TrackingReference.fmu"),
    ("a misspelt table", lambda t: t.replace("[experiment]", "[experimentz]"),
     "unknown key 'experimentz' at the top level (did you mean 'experiment'?)"),
    ("a missing key", lambda t: t.replace("step = 0.0005", ""),
     "edited.toml: [experiment] missing key 'step' (a finite number > 0: communication step (s))"),
    ("a TOML syntax error", lambda t: t.replace("[experiment]", "[experiment"), "is not valid TOML"),
    ("a parameter value that is not a number", lambda t: t.replace("lambda_ce = 0.99", 'lambda_ce = "0.99"'),
     "[components.controller.parameters] lambda_ce = '0.99' is not a finite number"),
    ("a fractional value for an Integer parameter",
     lambda t: t.replace("parameters = { E1 =", "parameters = { fls_input = 1.5, E1 ="),
     "[components.controller.parameters] fls_input = 1.5 is not an integer"),
    ("an invalid parameter value (the FMU says why)", lambda t: t.replace("lambda_ce = 0.99", "lambda_ce = 1.0"),
     "parameter lambda_ce = 1.0 is invalid; valid range: (0, 1)"),
]


@pytest.mark.parametrize("what,edit,expected", MISTAKES, ids=[m[0] for m in MISTAKES])
def test_scenario_file_mistakes_give_one_clear_error(fmu_paths, tmp_path, capsys, what, edit, expected):
    path = edited_scenario(tmp_path, edit)
    assert cli_main(["run", str(path), "--step", "1e-3", "--stop", "0.01"]) == 2, what
    err = capsys.readouterr().err
    assert expected in err, err
    assert err.count("error:") == 1, err


@pytest.mark.parametrize("option,value", [("--step", "0"), ("--step", "nan"), ("--step", "-0.001"),
                                          ("--step", "inf"), ("--stop", "nan"), ("--stop", "inf")])
def test_a_bad_step_or_stop_on_the_command_line_is_one_clear_error(fmu_paths, capsys, option, value):
    assert cli_main(["run", "pendulum_case1", option, value]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "Traceback" not in err, err
    assert ("step" if option == "--step" else "stop") in err.split("error:")[1]


# ------------------------------------------------------------ files that are not FMUs
def _zip(path, members: dict):
    with zipfile.ZipFile(path, "w") as archive:
        for name, text in members.items():
            archive.writestr(name, text)


BAD_FMU_FILES = [  # (what, make(path), the error's tail after "[components.reference] fmu = 'bad.fmu': <path>")
    ("an empty file", lambda p: p.write_bytes(b""),
     " is empty (0 bytes), not an FMU (an FMU is a zip archive holding modelDescription.xml)"),
    ("a text file", lambda p: p.write_text("not an FMU\n"),
     " is not an FMU: not a zip archive (11 bytes; an FMU is a zip archive holding modelDescription.xml)"),
    ("a truncated FMU", lambda p: p.write_bytes((build_fmu.ROOT / "build/fmus/TrackingReference.fmu").read_bytes()[:3000]),
     " is not an FMU: a truncated or damaged zip archive (3000 bytes; an FMU is a zip archive holding "
     "modelDescription.xml)"),
    ("a zip without a model description", lambda p: _zip(p, {"binaries/readme.txt": "x", "other.xml": "<a/>"}),
     " is not an FMU: no modelDescription.xml in the zip archive (it holds binaries/readme.txt, other.xml)"),
    ("a model description that is not XML", lambda p: _zip(p, {"modelDescription.xml": "not < xml"}),
     ": its modelDescription.xml cannot be read: "),
    ("a folder", lambda p: p.mkdir(), " is a folder, not an FMU file"),
    ("a model description that is not UTF-8", lambda p: _latin1_description(p),
     ": its modelDescription.xml cannot be read: Invalid bytes in character encoding (FMI model descriptions are "
     "UTF-8 XML)"),
]


def _latin1_description(path):
    """TrackingReference.fmu with its model description in Latin-1 (an 'é' of its own), not UTF-8."""
    source = build_fmu.ROOT / "build/fmus/TrackingReference.fmu"
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(path, "w") as new:
        for info in old.infolist():
            data = old.read(info)
            if info.filename == "modelDescription.xml":
                data = data.decode().replace('description="', 'description="caf\xe9 ', 1).encode("latin-1")
            new.writestr(info, data)


@pytest.mark.parametrize("what,make,tail", BAD_FMU_FILES, ids=[case[0] for case in BAD_FMU_FILES])
def test_a_file_that_is_not_an_fmu_is_named_with_what_it_is(fmu_paths, tmp_path, capsys, what, make, tail):
    """These once gave "File is not a zip file" or a raw KeyError."""
    make(tmp_path / "bad.fmu")
    path = edited_scenario(tmp_path, lambda t: t.replace('fmu = "TrackingReference"', 'fmu = "bad.fmu"'))
    assert cli_main(["run", str(path), "--stop", "0.01"]) == 2, what
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"error: {path}: [components.reference] fmu = 'bad.fmu': {tmp_path / 'bad.fmu'}{tail}"), \
        lines[0]


def test_a_binary_scenario_file_is_one_line_naming_it(tmp_path, capsys):
    """It exited 1 with a UnicodeDecodeError that named no file."""
    path = tmp_path / "binary.toml"
    path.write_bytes(bytes(range(256)))
    assert cli_main(["run", str(path)]) == 2
    assert capsys.readouterr().err.strip() == (f"error: {path} is not a TOML file: byte 128 is not UTF-8 text "
                                               "(invalid start byte)")


@pytest.mark.parametrize("name", ["a/b", "réf", "<img src=x>"])
def test_an_instance_name_outside_the_rule_is_one_line_with_the_rule(tmp_path, capsys, name):
    """'a/b' reached mkdtemp (FileNotFoundError), 'réf' crashed the pythonfmu FMU's host (its resource URI)."""
    path = edited_scenario(tmp_path, lambda t: t.replace("[components.reference]", f'[components."{name}"]'))
    assert cli_main(["run", str(path), "--stop", "0.01"]) == 2
    assert capsys.readouterr().err.strip() == (f"error: {path}: [components] instance name {name!r} is not allowed: "
                                               "use ASCII letters, digits and '_', not starting with a digit")


def _package_with(tmp_path, fmu_paths, ssd: bytes | None) -> "Path":
    """An exported SSP package whose SystemStructure.ssd is replaced by ``ssd``."""
    from harness.hosts.ssp import export_ssp

    exported = export_ssp(scenarios.configure("pendulum_case1", "vud", stop=0.01), tmp_path / "good.ssp",
                          fmu_paths=fmu_paths)
    target = tmp_path / "edited.ssp"
    with zipfile.ZipFile(exported) as old, zipfile.ZipFile(target, "w") as new:
        for info in old.infolist():
            new.writestr(info, ssd if info.filename == "SystemStructure.ssd" else old.read(info))
    return target


SSD_MISTAKES = [  # (what, SystemStructure.ssd, the error after "error: <package>: ")
    ("not XML", b"garbage", "SystemStructure.ssd is not well-formed XML: syntax error: line 1, column 0"),
    ("no system", b'<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"'
                  b' version="1.0" name="x"/>',
     "SystemStructure.ssd has no <System> in the SSP 1.0 namespace http://ssp-standard.org/SSP1/"
     "SystemStructureDescription (its root is <SystemStructureDescription>); an SSP package describes one system"),
    ("a component whose FMU is missing",
     b'<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
     b'version="1.0" name="x"><ssd:System name="s"><ssd:Elements><ssd:Component name="plant" '
     b'source="resources/Missing.fmu"/></ssd:Elements></ssd:System></ssd:SystemStructureDescription>',
     "component 'plant' names the source 'resources/Missing.fmu', which the package does not hold"),
]


@pytest.mark.parametrize("engine", ["fmpy", "ecos"])
@pytest.mark.parametrize("what,ssd,expected", SSD_MISTAKES, ids=[m[0] for m in SSD_MISTAKES])
def test_a_broken_system_structure_is_one_line_naming_the_package(fmu_paths, tmp_path, capsys, engine, what, ssd,
                                                                  expected):
    """No system gave "'NoneType' object has no attribute 'findall'", bad XML "syntax error: line 1" alone."""
    package = _package_with(tmp_path, fmu_paths, ssd)
    assert cli_main(["run-ssp", str(package), "--engine", engine]) == 2
    assert capsys.readouterr().err.strip() == f"error: {package}: {expected}"
