"""Command-line argument types and checks shared by every subcommand.

Every mistake on the command line becomes one line that names the culprit and the valid range or
choices (``error: argument --step: 'abc' is not a number; give a finite number > 0``) and exit
status 2; a run that fails becomes one line and exit status 1.  No traceback reaches a user:
:func:`one_line` turns any exception into a line, :func:`exit_status` picks 2 or 1.

The types are plain functions for ``add_argument(type=...)``: argparse reports their
``ArgumentTypeError`` as ``argument --NAME: MESSAGE``.
"""
from __future__ import annotations

import argparse
import difflib
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from . import scenario as scenarios
from .fmi import FmiError, FmuFileError
from .master import SimulationFailed, simulate
from .scenario import ScenarioError
from .scenario_checks import model_info
from .unpack import ArchiveError

USAGE_EXIT = 2  # a mistake in the command line or in a scenario file
FAILED_EXIT = 1  # the command ran and failed (a diverged or crashed run, a failing regression)


class UsageError(ValueError):
    """A mistake on the command line that argparse's types cannot see alone (exit status 2)."""


#: what a command line means by a negative number, also in scientific notation (argparse alone reads
#: "-1e-4" as an option and says "expected one argument"): a value, which the option's type then refuses
NEGATIVE_NUMBER = re.compile(r"^-(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?$|^-(?:inf|infinity|nan)$", re.IGNORECASE)


def close_match(word: str, choices) -> str | None:
    """The choice closest to a misspelt ``word`` (difflib's ratio >= 0.6), or None."""
    found = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return found[0] if found else None


def _unknown_option(arguments, known) -> str | None:
    """The first of ``arguments`` that looks like a long option and is none of ``known`` (nor an
    abbreviation of one), without its ``=value``."""
    for argument in arguments:
        if argument == "--":
            return None
        option = argument.split("=", 1)[0]
        if option.startswith("--") and len(option) > 2 and not any(o.startswith(option) for o in known):
            return option
    return None


class OneLineParser(argparse.ArgumentParser):
    """argparse with one line per usage error (no usage block), exit status 2; a negative number in
    any notation is a value; a misspelt option or choice gets its close match ("did you mean
    --controller?": Python's argparse before 3.14 suggests nothing)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER  # read by argparse's option parsing (3.10-3.13)

    def error(self, message):
        """Exit 2 with one line; a misspelt option is named first (it is why a required option or
        argument seems missing)."""
        leaf = not any(isinstance(action, argparse._SubParsersAction) for action in self._actions)
        unknown = _unknown_option(getattr(self, "_arguments", ()), self._long_options()) if leaf else None
        if unknown is not None and not message.startswith("unrecognized option"):
            message = self._unrecognized(unknown, self._long_options())
        hint = f" (see {self.prog} --help)"
        self.exit(USAGE_EXIT, f"{self.prog}: error: {message}{hint}\n")

    def parse_known_args(self, args=None, namespace=None):
        self._arguments = list(sys.argv[1:] if args is None else args)
        namespace, extras = super().parse_known_args(args, namespace)
        known = self._long_options(namespace)
        unknown = _unknown_option(extras, known)
        if unknown is not None:
            self.error(self._unrecognized(unknown, known))
        return namespace, extras

    @staticmethod
    def _unrecognized(option: str, known: list) -> str:
        match = close_match(option, known)
        hint = f"; did you mean {match}?" if match else f"; valid: {', '.join(known)}"
        return f"unrecognized option {option}{hint}"

    def _long_options(self, namespace=None) -> list:
        """The long options of this parser and of the subcommand chosen (argparse hands a
        subcommand's unknown options up to its parent in some versions)."""
        options = [o for o in self._option_string_actions if o.startswith("--")]
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction) and namespace is not None:
                chosen = action.choices.get(getattr(namespace, action.dest, None) or "")
                if chosen is not None:
                    options += [o for o in chosen._option_string_actions if o.startswith("--")]
        return sorted(set(options) - {"--help"}) + ["--help"]

    def _check_value(self, action, value):
        if action.choices is not None and value not in action.choices:
            match = close_match(str(value), [str(c) for c in action.choices])
            hint = f"; did you mean {match!r}?" if match else ""
            raise argparse.ArgumentError(action, f"invalid choice: {value!r}{hint} (choose from "
                                                 f"{', '.join(map(repr, action.choices))})")


# ------------------------------------------------------------------ numbers
def _finite(text: str, wanted: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"{text!r} is not a number; give {wanted}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not finite; give {wanted}")
    return value


def positive_float(text: str) -> float:
    """A finite number > 0 (a step, a stop time, an interval, a limit)."""
    value = _finite(text, "a finite number > 0")
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{text} is invalid; give a finite number > 0")
    return value


def non_negative_float(text: str) -> float:
    """A finite number >= 0 (a tolerance)."""
    value = _finite(text, "a finite number >= 0")
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text} is invalid; give a finite number >= 0")
    return value


def _integer(text: str, low: int) -> int:
    wanted = f"a whole number >= {low}"
    try:
        value = int(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number; give {wanted}") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"{text} is invalid; give {wanted}")
    return value


def positive_int(text: str) -> int:
    """A whole number >= 1 (processes, repetitions)."""
    return _integer(text, 1)


def non_negative_int(text: str) -> int:
    """A whole number >= 0 (steps to skip)."""
    return _integer(text, 0)


# ------------------------------------------------------------------- files
def existing_file(text: str) -> Path:
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"no such file: {text}")
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{text} is not a file")
    return path


def ssp_file(text: str) -> Path:
    """An existing SSP package (a zip file holding SystemStructure.ssd)."""
    path = existing_file(text)
    if not zipfile.is_zipfile(path):
        raise argparse.ArgumentTypeError(f"{text} is not an SSP package (not a zip file); "
                                         "write one with: python -m harness export-ssp SCENARIO --out FILE.ssp")
    with zipfile.ZipFile(path) as package:
        if "SystemStructure.ssd" not in package.namelist():
            raise argparse.ArgumentTypeError(f"{text} is not an SSP package (no SystemStructure.ssd inside)")
    return path


def scenario(text: str) -> str:
    """A scenario name of harness/scenarios/ or the path of an existing .toml file."""
    if text.endswith(".toml") or "/" in text or "\\" in text:
        path = Path(text)
        if not path.exists():
            raise argparse.ArgumentTypeError(f"no such file: {text}")
        if path.suffix != ".toml" or not path.is_file():
            raise argparse.ArgumentTypeError(f"{text} is not a scenario file (.toml)")
        return text
    names = scenarios.scenario_names()
    if text not in names:
        raise argparse.ArgumentTypeError(f"unknown scenario {text!r}; valid: {', '.join(names)} or a .toml path")
    return text


def scenario_help() -> str:
    return f"scenario name ({', '.join(scenarios.scenario_names())}) or .toml path"


# ------------------------------------------------------------ --set values
def assignment(text: str) -> tuple:
    """``INSTANCE.PARAMETER=VALUE`` with a finite number: ``(dotted, value)``."""
    dotted, equals, value = text.partition("=")
    dotted = dotted.strip()
    instance, dot, parameter = dotted.partition(".")
    if not equals or not dot or not instance or not parameter or not value.strip():
        raise argparse.ArgumentTypeError(f"{text!r}: write INSTANCE.PARAMETER=VALUE, e.g. controller.gamma=290")
    return dotted, _finite(value.strip(), f"a finite number for {dotted}")


def check_assignments(configured, assignments, fmu_paths: dict | None = None, option: str = "--set"):
    """Check ``--set`` names and values against the scenario and the FMUs' model descriptions.

    Unknown instance, unknown or non-parameter variable, a fraction for an Integer, and a value
    outside an inclusive min/max declared in the modelDescription raise UsageError naming the
    valid choices; an exclusive bound (e.g. gamma > 0) is checked by the FMU itself when
    initialisation ends, and :func:`one_line` reports that as a usage error too.
    """
    infos = {}
    for dotted, value in assignments:
        instance, _, parameter = dotted.partition(".")
        if instance not in configured.components:
            raise UsageError(f"{option} {dotted}={value:g}: unknown instance {instance!r}; "
                             f"valid: {', '.join(configured.components)}")
        if instance not in infos:
            infos[instance] = model_info(configured, instance, fmu_paths)
        variables = infos[instance].variables
        parameters = [name for name, v in variables.items() if v.causality == "parameter"]
        found = variables.get(parameter)
        if found is None or found.causality != "parameter":
            raise UsageError(f"{option} {dotted}={value:g}: {instance} has no parameter {parameter!r}; "
                             f"valid: {', '.join(parameters)}")
        if found.type == "Integer" and value != int(value):
            raise UsageError(f"{option} {dotted}={value:g}: {parameter} is an Integer; give a whole number")
        low = float(found.min) if found.min not in (None, "") else None
        high = float(found.max) if found.max not in (None, "") else None
        if (low is not None and value < low) or (high is not None and value > high):
            valid = " and ".join(part for part in (f">= {low:g}" if low is not None else "",
                                                    f"<= {high:g}" if high is not None else "") if part)
            raise UsageError(f"{option} {dotted}={value:g} is out of range; valid: {valid}")
    if assignments:  # ranges the model description cannot state (e.g. gamma > 0): the FMUs say at initialisation
        _initialise_once(configured, assignments, fmu_paths, option)


def _initialise_once(configured, assignments, fmu_paths, option):
    """Run one communication step with the new values; a parameter the FMU rejects is a usage error."""
    trial = configured
    for dotted, value in assignments:
        trial = trial.with_parameter(dotted, value)
    trial = trial.with_parameter("stop", trial.start + trial.step)
    try:
        simulate(trial, fmu_paths=fmu_paths)
    except SimulationFailed as failure:
        if exit_status(failure) == USAGE_EXIT:
            raise UsageError(f"{option}: {one_line(failure)}") from None


# ------------------------------------------------------------ outputs
def tracked_files(paths) -> list:
    """Those of ``paths`` that the project's git repository tracks (none without git or outside it)."""
    root = Path(__file__).resolve().parents[1]
    if shutil.which("git") is None or not (root / ".git").exists():
        return []
    inside = []
    for path in paths:
        resolved = Path(path).resolve()
        if resolved.is_relative_to(root):
            inside.append(str(resolved.relative_to(root)))
    if not inside:
        return []
    completed = subprocess.run(["git", "ls-files", "--", *inside], cwd=root, capture_output=True, text=True)
    return sorted(completed.stdout.split()) if completed.returncode == 0 else []


def refuse_tracked(paths, option: str = "--out"):
    """A study writes where git does not track anything; only --apply changes committed files."""
    tracked = tracked_files(paths)
    if tracked:
        raise UsageError(f"{option} would overwrite committed files ({', '.join(tracked)}); write into an "
                         "ignored folder (results/, build/) and use --apply to update the committed copies")


def check_writable(paths, option: str = "--out"):
    """Every file a command will write, checked before its first run: its folder exists or is made now
    (as the command would make it) and takes a new file, and the path is neither a folder nor a file
    this process may not write.  A mistake costs one line, not the runs before the first write."""
    paths = [Path(path) for path in paths]
    for folder in dict.fromkeys(path.parent for path in paths):
        existing = next(p for p in (folder, *folder.parents) if p.exists())
        if not existing.is_dir():
            raise UsageError(f"{option}: {existing} is a file, not a folder")
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryFile(dir=folder):
                pass
        except OSError as error:
            raise UsageError(f"{option}: cannot write into {folder}: {error.strerror or one_line(error)}") from None
    for path in paths:
        if path.is_dir():
            raise UsageError(f"{option}: {path} is a folder; the command writes a file there")
        if path.exists() and not os.access(path, os.W_OK):
            raise UsageError(f"{option}: {path} is read-only")


# ------------------------------------------------- consistency and warnings
def check_output_interval(interval, step: float):
    """An output interval must be a whole multiple of the communication step."""
    if interval is None:
        return
    ratio = interval / step
    if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6 * max(1.0, ratio):
        raise UsageError(f"--output-interval {interval:g} is not a multiple of the step {step:g}; "
                         f"give k x {step:g} with k = 1, 2, ... (e.g. {max(1, round(ratio)) * step:g})")


# --------------------------------------------------------------- messages
_NOISE = re.compile(r"Fatal py exception encountered|^unknown error$|^\s*$")
_PREFIX = re.compile(r"^\[(?:ERROR|FATAL|WARNING|OK)\]\s*")


def _fmu_messages(log) -> list:
    """The FMU's own messages from an FMI log: pythonfmu's 'Fatal py exception ... unknown error' left out."""
    messages = []
    for entry in log:
        for line in str(entry).splitlines():
            line = _PREFIX.sub("", line.strip())
            if not _NOISE.search(line) and line not in messages:
                messages.append(line)
    return messages


def _fmi_error(error):
    for candidate in (error, getattr(error, "cause", None), error.__cause__):
        if isinstance(candidate, FmiError):
            return candidate
    return None


def one_line(error: BaseException) -> str:
    """The message of ``error`` on one line: an FMI failure as the FMU's own words."""
    fmi = _fmi_error(error)
    if fmi is not None:
        messages = _fmu_messages(fmi.log) or [f"{fmi.function} failed"]
        text = "; ".join(messages)
        if not text.startswith(f"{fmi.instance}:"):
            text = f"{fmi.instance}: {text}"
        if fmi.function != "fmi2ExitInitializationMode":
            text += f" (in {fmi.function} at t = {fmi.time:.6g})"
        return text
    lines = [part.strip() for part in str(error).splitlines() if part.strip()]
    lines = [line for line in lines if line != "unknown error"]
    text = " | ".join(lines) or type(error).__name__
    if isinstance(error, (FileNotFoundError, IsADirectoryError, PermissionError)) and error.filename:
        text = f"{error.strerror}: {error.filename}"
    return text


def exit_status(error: BaseException) -> int:
    """2 for a usage mistake (also a parameter the FMU rejects when initialisation ends), else 1."""
    if isinstance(error, (UsageError, ScenarioError, FmuFileError, ArchiveError)):
        return USAGE_EXIT
    fmi = _fmi_error(error)
    if fmi is not None and fmi.function == "fmi2ExitInitializationMode" and \
            any("is invalid; valid range" in line for line in _fmu_messages(fmi.log)):
        return USAGE_EXIT
    return FAILED_EXIT


def report(error: BaseException, stream=None) -> int:
    """Print ``error: ...`` on one line to stderr and return the exit status."""
    print(f"error: {one_line(error)}", file=stream or sys.stderr)
    return exit_status(error)
