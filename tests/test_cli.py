"""No traceback reaches a user: every subcommand x every kind of bad argument gives one line, exit 2.

The cases are generated from the parser itself, so an option or a subcommand added later is
fuzzed too: every numeric option gets a non-number, NaN, inf, a negative value and (where it
must be > 0) zero; every scenario argument an unknown name, a missing .toml, a file that is not
a scenario and a .toml that is not valid; every SSP argument a missing file and a file that is not
a zip; every ``--set`` and ``--grid`` an unknown instance, an unknown variable, a non-number and a
value out of range.  Argument-level mistakes run with every handler replaced by one that fails the
test (a bad value that gets through would otherwise start a long run); mistakes only a command can
see (names checked against the FMUs, ranges, inconsistent options) run the real command, in
process, and stop before any long run.
"""
from __future__ import annotations

import argparse
import copy
import functools
import json
import zipfile

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from harness import cli, cli_args
from harness import scenario as scenarios
from harness import variants

NO_VARIANT = max(variants.CONTROLLER_VARIANTS.values()) + 1  # one past the last row: beyond the FMU's declared max
NUMERIC_TYPES = {cli_args.positive_float: True, cli_args.positive_int: True,
                 cli_args.non_negative_float: False, cli_args.non_negative_int: False}  # type -> zero is bad
BAD_NUMBERS = ("abc", "nan", "inf", "-inf", "-1", "-1e-4")  # "-1e-4": a value, not an option


def subparsers() -> dict:
    parser = cli.build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli_errors")
    ssp = folder / "good.ssp"
    with zipfile.ZipFile(ssp, "w") as package:
        package.writestr("SystemStructure.ssd", "<ssd/>")
    (folder / "not_a_zip.ssp").write_text("plain text, not an SSP package\n")
    (folder / "bad.toml").write_text("this is = = not TOML [\n")
    (folder / "notes.txt").write_text("not a scenario\n")
    return {"ssp": str(ssp), "not_zip": str(folder / "not_a_zip.ssp"), "bad_toml": str(folder / "bad.toml"),
            "missing_toml": str(folder / "missing.toml"), "missing_ssp": str(folder / "missing.ssp"),
            "text": str(folder / "notes.txt"), "folder": str(folder)}


@pytest.fixture(scope="module")
def real_ssp(fmu_paths, tmp_path_factory):
    from harness import scenario as scenarios
    from harness.hosts.ssp import export_ssp

    configured = scenarios.configure("pendulum_case1", "vud", stop=0.1)
    return str(export_ssp(configured, tmp_path_factory.mktemp("ssp") / "p.ssp", fmu_paths=fmu_paths))


def _positional_value(action, files) -> str | None:
    """A valid value for a positional argument, from its type (None: cannot be made up)."""
    if action.nargs in ("*", "?"):
        return None
    if action.type is cli_args.scenario:
        return "pendulum_case1"
    if action.type is cli_args.ssp_file:
        return files["ssp"]
    raise AssertionError(f"positional {action.dest!r} has no cli_args type: give it one (harness/cli_args.py)")


def base_argv(name, parser, files) -> list:
    """The subcommand with valid positionals and required options."""
    argv = [name]
    for action in parser._actions:
        if not action.option_strings and not isinstance(action, argparse._HelpAction):
            value = _positional_value(action, files)
            if value is not None:
                argv.append(value)
        elif action.required:
            assert action.dest == "grid", f"{name}: required option {action.option_strings} unknown to this test"
            argv += ["--grid", "plant.mp=0.1"]
    return argv


def argument_cases(files) -> list:
    """(id, argv, expected text in the error) for mistakes argparse must catch."""
    cases = []
    for name, parser in subparsers().items():
        base = base_argv(name, parser, files)
        for action in parser._actions:
            if action.option_strings and action.type in (float, int):
                cases.append((f"{name} {action.option_strings[0]} bare-type", None, action.option_strings[0]))
            if action.option_strings and action.type in NUMERIC_TYPES:
                option = action.option_strings[0]
                bad = BAD_NUMBERS + (("0",) if NUMERIC_TYPES[action.type] else ())
                cases += [(f"{name} {option}={value}", [*base, option, value], option) for value in bad]
            if action.type is cli_args.assignment:
                option = action.option_strings[0]
                cases += [(f"{name} {option} {kind}", [*base, option, value], option) for kind, value in
                          (("no-equals", "controller.gamma"), ("no-dot", "gamma=3"), ("non-number", "controller.gamma=x"),
                           ("nan", "controller.gamma=nan"), ("inf", "controller.gamma=inf"))]
            if action.choices and action.option_strings and not isinstance(action, argparse._SubParsersAction):
                cases.append((f"{name} {action.option_strings[0]} bad choice",
                              [*base, action.option_strings[0], "bogus"], "invalid choice"))
            if action.type in (cli_args.scenario, cli_args.ssp_file):
                def swapped(value, action=action, base=base):
                    if action.option_strings:  # e.g. bench --scenario: the last occurrence wins
                        return [*base, action.option_strings[0], value]
                    if action.nargs in ("*", "?"):  # e.g. regress [SCENARIO ...]
                        return [*base, value]
                    spot = base.index(_positional_value(action, files))
                    return [*base[:spot], value, *base[spot + 1:]]

                if action.type is cli_args.scenario:
                    cases += [(f"{name} unknown scenario", swapped("pendulum_case9"), "unknown scenario"),
                              (f"{name} missing toml", swapped(files["missing_toml"]), "no such file"),
                              (f"{name} not a toml", swapped(files["text"]), "not a scenario file")]
                if action.type is cli_args.ssp_file:
                    cases += [(f"{name} missing ssp", swapped(files["missing_ssp"]), "no such file"),
                              (f"{name} not a zip", swapped(files["not_zip"]), "not an SSP package"),
                              (f"{name} a folder", swapped(files["folder"]), "not a file")]
    return cases


def _one_error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f"want one line on stderr, got:\n{err}"
    assert "error:" in lines[0]
    return lines[0]


@pytest.fixture
def no_handler(monkeypatch):
    """Every subcommand's handler fails the test: argparse must stop the bad argument first."""
    original = cli.build_parser

    def guarded():
        parser = original()
        action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        for sub in action.choices.values():
            sub.set_defaults(handler=lambda args: pytest.fail(f"a bad argument reached the command: {args}"))
        return parser

    monkeypatch.setattr(cli, "build_parser", guarded)


def test_every_bad_argument_of_every_subcommand_is_one_line_and_exit_2(files, no_handler, capsys):
    cases = argument_cases(files)
    bare = [case_id for case_id, argv, _ in cases if argv is None]
    assert not bare, f"options with a bare float/int type accept NaN, inf, negatives: use cli_args types: {bare}"
    covered = {case_id.split()[0] for case_id, _, _ in cases}
    assert covered >= {"run", "tables", "sweep", "regress", "export-ssp", "run-ssp", "compare-engines", "bench"}
    failures = []
    for case_id, argv, expected in cases:
        code = cli.main(argv)
        captured = capsys.readouterr()
        try:
            assert "Traceback" not in captured.out + captured.err
            assert code == 2, f"exit {code}"
            line = _one_error_line(captured.err)
            assert expected in line, f"{expected!r} not in {line!r}"
            assert "expected one argument" not in line, "a negative number was read as an option"
        except AssertionError as error:
            failures.append(f"{case_id}: {argv}: {error}")
    assert not failures, "\n".join(failures)
    assert len(cases) > 100  # 9 subcommands x their numeric options x 5-6 values, plus the rest


COMMAND_CASES = [
    # (id, argv, exit status, text the one error line must hold)
    ("run: bad TOML content", ["run", "{bad_toml}", "--stop", "0.01"], 2, "is not valid TOML"),
    ("run: output interval not a multiple of the step",
     ["run", "pendulum_case1", "--stop", "0.01", "--step", "1e-3", "--output-interval", "1.5e-3", "--out", "{folder}/r.csv"],
     2, "not a multiple of the step"),
    ("run: stop shorter than one step", ["run", "pendulum_case1", "--stop", "1e-5"], 2, "shorter than one step"),
    ("run: diverges (a failed run)", ["run", "pendulum_case3", "--step", "0.05", "--stop", "2"], 1, "diverged at t ="),
    ("run: --out under a file (before the run)", ["run", "pendulum_case1", "--stop", "0.01", "--out", "{text}/r.csv"], 2,
     "--out: {text} is a file, not a folder"),
    ("tables: --out over committed files", ["tables", "--out", "docs", "--stop", "0.01"], 2, "committed files"),
    ("tables: --out under a file (before the runs)", ["tables", "--out", "{text}/t", "--stop", "0.01"], 2,
     "--out: {text} is a file, not a folder"),
    ("sweep: bad TOML content", ["sweep", "{bad_toml}", "--grid", "plant.mp=0.1", "--out", "{folder}/s"], 2,
     "is not valid TOML"),
    ("sweep: unknown instance", ["sweep", "pendulum_case1", "--grid", "plnt.mp=0.1", "--out", "{folder}/s"], 2,
     "plnt"),
    ("sweep: unknown variable", ["sweep", "pendulum_case1", "--grid", "plant.mass=0.1", "--out", "{folder}/s"], 2,
     "mass"),
    ("sweep: non-number grid", ["sweep", "pendulum_case1", "--grid", "plant.mp=a,b", "--out", "{folder}/s"], 2,
     "--grid"),
    ("sweep: value out of range", ["sweep", "pendulum_case1", "--grid", "plant.mp=-1,1", "--stop", "0.01",
                                   "--out", "{folder}/s"], 2, "valid range"),
    ("regress: bad TOML content", ["regress", "{bad_toml}"], 2, "is not valid TOML"),
    ("regress: unknown instance", ["regress", "pendulum_case1", "--set", "ctrl.gamma=290"], 2, "unknown instance"),
    ("regress: unknown variable", ["regress", "pendulum_case1", "--set", "controller.gama=290"], 2, "no parameter"),
    ("regress: out of range (FMU's range)", ["regress", "pendulum_case1", "--set", "controller.gamma=-1"], 2,
     "valid range: > 0"),
    ("regress: out of range (declared max)", ["regress", "pendulum_case1", "--set", f"controller.variant={NO_VARIANT}"],
     2, "out of range"),
    ("regress: --update with --set", ["regress", "--update", "--set", "controller.gamma=290"], 2, "--update"),
    ("export-ssp: out of range", ["export-ssp", "pendulum_case1", "--set", "controller.gamma=-1",
                                  "--out", "{folder}/x.ssp"], 2, "valid range: > 0"),
    ("export-ssp: unknown instance", ["export-ssp", "pendulum_case1", "--set", "nope.gamma=1",
                                      "--out", "{folder}/x.ssp"], 2, "unknown instance"),
    ("export-ssp: bad TOML content", ["export-ssp", "{bad_toml}", "--out", "{folder}/x.ssp"], 2, "is not valid TOML"),
    ("run-ssp: stop shorter than one step", ["run-ssp", "{real_ssp}", "--stop", "1e-9"], 2, "shorter than one step"),
    ("run-ssp: step longer than the run", ["run-ssp", "{real_ssp}", "--engine", "fmpy", "--step", "5", "--stop", "0.1"],
     2, "shorter than one step"),
    ("compare-engines: bad TOML content", ["compare-engines", "{bad_toml}"], 2, "is not valid TOML"),
    ("mutate: unknown mutation", ["mutate", "--only", "no_such_mutation", "--list"], 2, "unknown mutation"),
    ("bench: bad TOML content", ["bench", "--scenario", "{bad_toml}"], 2, "is not valid TOML"),
]


@pytest.mark.parametrize("case_id,argv,status,expected", COMMAND_CASES, ids=[c[0] for c in COMMAND_CASES])
def test_mistakes_a_command_finds_are_one_line_with_the_right_status(case_id, argv, status, expected, files,
                                                                     real_ssp, capsys):
    code = cli.main([part.format(**files, real_ssp=real_ssp) for part in argv])
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err
    line = _one_error_line(captured.err)
    assert code == status, line
    assert expected.format(**files) in line, line
    assert "unknown error" not in line  # pythonfmu's tail of every failure, stripped


@pytest.mark.parametrize("command", cli.SSP_ENGINE_COMMANDS)
def test_fmi3_fmus_are_refused_where_ssp_engines_take_them(command, monkeypatch, capsys):
    argv = [command, "pendulum_case1"] if command != "hosts" else [command]
    assert cli.main([*argv, "--edition", "native3"]) == 2
    assert "invalid choice: 'native3'; did you mean 'native'? (choose from 'python', 'native')" in \
        _one_error_line(capsys.readouterr().err)
    monkeypatch.setenv("AFC_EDITION", "native3")
    assert cli.main(argv) == 2
    assert _one_error_line(capsys.readouterr().err) == (
        f"error: AFC_EDITION=native3: {command} hands the FMUs to SSP engines, which take FMI 2.0 FMUs; "
        "use --edition native")


def test_the_last_resort_handler_turns_any_exception_into_one_line(monkeypatch, capsys):
    def broken(args):
        raise KeyError("something internal\nwith a second line")

    original = cli.build_parser

    def with_broken_run():
        parser = original()
        action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        action.choices["run"].set_defaults(handler=broken)
        return parser

    monkeypatch.setattr(cli, "build_parser", with_broken_run)
    assert cli.main(["run", "pendulum_case1"]) == 1
    line = _one_error_line(capsys.readouterr().err)
    assert "something internal" in line and "with a second line" in line


def misspelt_option(option: str) -> str:
    """--controller -> --contoller: one letter of the name left out (the issue's example)."""
    name = option[2:]
    return "--" + name[:5] + name[6:] if len(name) > 6 else "--" + name[:1] + name[2:]


def test_a_misspelt_option_or_choice_gets_its_close_match(no_handler, capsys):
    """A misspelt option: "--contoller" once said only "unrecognized arguments"; argparse before 3.14 suggests nothing."""
    assert cli.main(["run", "pendulum_case1", "--contoller", "vud"]) == 2
    assert _one_error_line(capsys.readouterr().err) == (
        "python -m harness run: error: unrecognized option --contoller; did you mean --controller? "
        "(see python -m harness run --help)")
    failures, tried = [], 0
    for name, parser in subparsers().items():
        options = [o for a in parser._actions for o in a.option_strings if o.startswith("--") and o != "--help"]
        for option in options:
            wrong = misspelt_option(option)
            if any(o.startswith(wrong) for o in options):  # an abbreviation argparse accepts
                continue
            tried += 1
            code = cli.main([name, wrong])
            line = _one_error_line(capsys.readouterr().err)
            if code != 2 or f"unrecognized option {wrong}; did you mean {option}?" not in line:
                failures.append(f"{name} {wrong}: {line}")
    assert not failures and tried > 50, "\n".join(failures)
    assert cli.main(["tabels"]) == 2
    assert "invalid choice: 'tabels'; did you mean 'tables'? (choose from 'run', 'tables'," in capsys.readouterr().err
    assert cli.main(["run", "pendulum_case1", "--controller", "vdu"]) == 2
    choices = ", ".join(f"'{name}'" for name in variants.NAMES)  # the variant registry, in its order
    assert f"invalid choice: 'vdu'; did you mean 'vud'? (choose from {choices})" in capsys.readouterr().err
    assert cli.main(["run", "pendulum_case1", "--zzz"]) == 2
    assert "unrecognized option --zzz; valid: --algorithm, --atol, --controller, --edition, " in capsys.readouterr().err


def test_a_negative_number_in_any_notation_is_a_value_refused_with_the_valid_range(no_handler, capsys):
    """A negative number: "--step -1e-4" was once read as an option ("expected one argument")."""
    for value in ("-1e-4", "-1E+3", "-.5", "-2.", "-inf", "-Infinity", "-nan"):
        assert cli.main(["run", "pendulum_case1", "--step", value]) == 2
        line = _one_error_line(capsys.readouterr().err)
        assert line.startswith(f"python -m harness run: error: argument --step: ") and "give a finite number > 0" in line, \
            line


# ------------------------------------------------ scenario-file mutations
def toml_text(data: dict) -> str:
    """A scenario's data as TOML: every top-level key with an inline value (tomllib reads it back equal)."""
    def value(item):
        if isinstance(item, bool):
            return "true" if item else "false"
        if isinstance(item, (int, float)):
            return repr(item)
        if isinstance(item, str):
            return json.dumps(item)
        if isinstance(item, list):
            return "[" + ", ".join(value(x) for x in item) + "]"
        return "{ " + ", ".join(f"{json.dumps(k)} = {value(v)}" for k, v in item.items()) + " }"
    return "".join(f"{json.dumps(key)} = {value(item)}\n" for key, item in data.items())


def key_paths(data, path=()):
    """(path, value) of every key of the file, tables and arrays of tables included, and of every
    element of an array of strings (its path ends with the element's index)."""
    items = data.items() if isinstance(data, dict) else enumerate(data)
    for key, item in items:
        yield (*path, key), item
        if isinstance(item, dict) or (isinstance(item, list) and all(isinstance(x, (dict, str)) for x in item)):
            yield from key_paths(item, (*path, key))


def misspelt(name: str) -> str:
    return name[:2] + name[3:] if len(name) >= 4 else name + name[-1]


def wrong_type(value):
    if isinstance(value, str):
        return 5
    return "text" if isinstance(value, (bool, int, float)) else 5


def scenario_mutations() -> list:
    """(id, data, the name the error line must hold): every key misspelt once, every value of the wrong type."""
    original = tomllib.loads((scenarios.SCENARIO_DIR / "pendulum_case1.toml").read_text())
    mutations = []
    for path, item in key_paths(original):
        *parents, last = path
        shown = ".".join(map(str, path))
        named = next(str(p) for p in reversed(path) if isinstance(p, str))  # an element is named by its array
        data = copy.deepcopy(original)
        parent = functools.reduce(lambda table, key: table[key], parents, data)
        parent[last] = wrong_type(item)
        mutations.append((f"{shown} of the wrong type", data, named))
        if isinstance(last, str):
            data = copy.deepcopy(original)
            parent = functools.reduce(lambda table, key: table[key], parents, data)
            renamed = {(misspelt(k) if k == last else k): v for k, v in parent.items()}
            parent.clear()
            parent.update(renamed)
            mutations.append((f"{shown} misspelt", data, misspelt(last)))
    return mutations


def test_every_scenario_key_misspelt_and_every_value_of_the_wrong_type_is_one_line_and_exit_2(fmu_paths, tmp_path,
                                                                                                 capsys):
    """A scenario file is checked as strictly as the command line."""
    mutations = scenario_mutations()
    assert len(mutations) > 150  # every key of pendulum_case1.toml twice, every recorded name once
    failures = []
    for number, (case_id, data, name) in enumerate(mutations):
        path = tmp_path / f"mutant_{number}.toml"
        path.write_text(toml_text(data))
        assert tomllib.loads(path.read_text()) == data
        code = cli.main(["run", str(path), "--stop", "0.01"])
        captured = capsys.readouterr()
        try:
            assert "Traceback" not in captured.out + captured.err
            assert code == 2, f"exit {code}"
            line = _one_error_line(captured.err)
            assert str(path) in line, f"the file is not named: {line}"
            assert name in line, f"{name!r} not named: {line}"
        except AssertionError as error:
            failures.append(f"{case_id}: {error}")
    assert not failures, f"{len(failures)} of {len(mutations)}:\n" + "\n".join(failures)


# ------------------------------------------------ warnings, --apply, outputs
def test_es1_es2_are_marked_n_a_on_a_horizon_shorter_than_the_reference_period(fmu_paths, capsys):
    assert cli.main(["run", "pendulum_case1", "--stop", "0.5"]) == 0
    short = capsys.readouterr().out
    assert "es1_pct  n/a (the horizon 0.5 s is shorter than the reference period, 2 pi s, over which es1 and es2 " \
           "are taken)" in short and "es2_pct  n/a (the horizon 0.5 s" in short
    assert "ts       not settled (|e| is outside the 5 % band of max|ym| at the stop time 0.5 s" in short
    assert cli.main(["run", "pendulum_case1", "--stop", "6.4", "--step", "1e-3"]) == 0
    long = capsys.readouterr().out
    assert "n/a" not in long and float(long.split("es1_pct")[1].split()[0]) > 0


def test_sweep_writes_docs_only_with_apply_and_says_what_it_changed(fmu_paths, tmp_path, monkeypatch, capsys):
    from harness.studies.sweep import command_line as sweep

    docs = tmp_path / "docs"
    docs.mkdir()
    monkeypatch.setattr(sweep, "DOCS_DIR", docs)
    command = ["sweep", "pendulum_case1", "--grid", "plant.mp=0.1,0.2", "--stop", "0.05", "--jobs", "1",
               "--out", str(tmp_path / "out")]
    assert cli.main(command) == 0
    assert list(docs.iterdir()) == [] and (tmp_path / "out" / "sweep.csv").exists()
    assert cli.main([*command, "--apply"]) == 0
    out = capsys.readouterr().out
    assert sorted(p.name for p in docs.iterdir()) == ["sweep_pendulum_case1_mp.csv", "sweep_pendulum_case1_mp_ITAE.png"]
    assert f"applied  {docs / 'sweep_pendulum_case1_mp.csv'}" in out
