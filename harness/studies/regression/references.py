"""The reference results: their files, the scenario's fingerprint, the tolerances they carry.

In the style of BuildingsPy's ReferenceResults and the Modelica Standard Library's reference results:

* the reference of a case is ``<references>/<scenario>_<controller>_ref.csv`` (FMI cross-check style:
  time first, quoted ``"instance.variable"`` header) with the compared signals resampled to
  ``POINTS`` points over the scenario's whole horizon, plus ``<...>_ref.json``: start, stop, step,
  points, signals, tolerances (per case, and per signal in ``signal_tolerances``), the scenario's
  hash and settings, tool versions, date, git commit and the wall time of the run;
  ``<references>`` is harness/references/ (Model Exchange: harness/references/model_exchange/) or
  ``--references DIR``;
* the scenario's fingerprint is the sha256 of its TOML data (comments, spacing and key order do not
  count), so a changed scenario fails its case and the changed settings are named;
* references are written only by ``--update``, never by a plain run, and an update keeps the
  tolerances set in the old metadata; a mistake in a reference's metadata is one line naming the
  file, the key and the valid ones.
"""
from __future__ import annotations

import datetime
import hashlib
import importlib.metadata
import io
import json
import math
import platform
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from ... import atomic_files, cli_args
from ... import scenario as scenarios
from ...cases import Case
from ...me_master import DEFAULT_RTOL
from .runs import CaseRun, is_builtin

ROOT = Path(__file__).resolve().parents[3]
REFERENCE_DIR = ROOT / "harness" / "references"
#: Model Exchange (--algorithm me) has references of its own: the co-simulation's carry its O(step) error, which in the
#: controller's transient exceeds the tube (theta1 of pendulum_case1/fae at 0.55 s: -3.08 at the scenario's step,
#: -2.90, -2.81, -2.77 at 1/2, 1/4, 1/8 of it, -2.73 in Model Exchange)
MODEL_EXCHANGE_REFERENCE_DIR = REFERENCE_DIR / "model_exchange"
VALUE_FORMAT = "%.10g"  # 10 significant digits: 1e-10 relative, far inside the tube, and small files
#: pyfunnel tolerances.  BuildingsPy's default ``tol = 1e-3`` means atolx = atoly = ltoly = 1e-3; here the
#: absolute y tolerance is relative to each signal's range (rtoly) because the signals span 1e-3 rad (e)
#: to 1e2 (theta): a fixed 1e-3 would be as wide as e itself at steady state.
DEFAULT_TOLERANCES = {"atolx": 1e-3, "atoly": 0.0, "ltolx": 0.0, "ltoly": 1e-3, "rtolx": 0.0, "rtoly": 1e-3}


def reference_directory(algorithm: str) -> Path:
    """Where the references of an algorithm's runs are: our feedthrough master's, or Model Exchange's."""
    return MODEL_EXCHANGE_REFERENCE_DIR if algorithm == "me" else REFERENCE_DIR


def reference_paths(case: Case, directory: Path = REFERENCE_DIR) -> tuple[Path, Path]:
    """The case's reference files in ``directory``; a scenario name that would put them elsewhere is refused."""
    if any(mark in case.name for mark in ("/", "\\", "\0")) or case.name.startswith("."):
        raise cli_args.UsageError(f"scenario name {case.scenario_name!r} cannot name a reference file in "
                                  f"{directory} (it holds '/' or '\\' or begins with '.'); give the scenario a "
                                  "plain name")
    directory = Path(directory)
    return directory / f"{case.name}_ref.csv", directory / f"{case.name}_ref.json"


# ------------------------------------------------------ scenario fingerprint
def _flatten(data, prefix: str = "") -> dict:
    """{"components.plant.parameters.T": 0.5, "connections": [...], ...}: tables flattened to dotted keys."""
    flat = {}
    for key, value in data.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, dotted + "."))
        else:
            flat[dotted] = value
    return flat


def scenario_fingerprint(case: Case) -> tuple[str, dict]:
    """(sha256, settings) of the case's scenario file as TOML data: comments, spacing and key order do
    not count; every value does (parameters, connections, experiment, record, ...). The controller and
    ``--set`` overrides are not part of it (the case's name and label carry them)."""
    path = scenarios.load(case.scenario).path
    with open(path, "rb") as stream:
        settings = _flatten(tomllib.load(stream))
    canonical = json.dumps(settings, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(canonical.encode()).hexdigest(), json.loads(canonical)


def scenario_changes(old: dict, new: dict, limit: int = 4) -> str:
    """The settings that differ, ``key: old -> new`` (at most ``limit``, then how many more)."""
    def shown(value):
        text = "(absent)" if value is _ABSENT else json.dumps(value)
        return text if len(text) <= 60 else text[:57] + "..."

    changed = [f"{key}: {shown(old.get(key, _ABSENT))} -> {shown(new.get(key, _ABSENT))}"
               for key in sorted(set(old) | set(new)) if old.get(key, _ABSENT) != new.get(key, _ABSENT)]
    more = f"; {len(changed) - limit} more" if len(changed) > limit else ""
    return "; ".join(changed[:limit]) + more


_ABSENT = object()


# --------------------------------------------------------------- files
def relative(path: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def tool_versions() -> dict:
    def version(package):
        try:
            return importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            return None

    return {"python": platform.python_version(), "fmpy": version("fmpy"), "pythonfmu": version("pythonfmu"),
            "numpy": np.__version__, "pyfunnel": version("pyfunnel")}


def git_commit() -> str | None:
    try:
        completed = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return completed.stdout.strip() or None if completed.returncode == 0 else None


def write_reference(run: CaseRun, directory: Path = REFERENCE_DIR, tolerances: dict | None = None,
                    previous: dict | None = None) -> tuple:
    """Write the reference of ``run``; ``tolerances`` given on the command line, ``previous`` the old
    metadata, whose tolerances (per case and per signal) are kept."""
    if run.error:
        raise RuntimeError(f"{run.case.label}: the run failed, no reference written: {run.error}")
    if run.case.overrides:
        raise RuntimeError(f"{run.case.label}: a run with parameter overrides never becomes a reference")
    directory = Path(directory)
    csv_path, json_path = reference_paths(run.case, directory)
    names = list(run.signals)
    header = ",".join(f'"{name}"' for name in ["time", *names])
    table = np.column_stack([run.time, *[run.signals[name] for name in names]])
    csv_text = io.StringIO()
    np.savetxt(csv_text, table, delimiter=",", header=header, comments="", fmt=VALUE_FORMAT)
    previous = previous or {}
    digest, settings = scenario_fingerprint(run.case)
    scenario_path = scenarios.load(run.case.scenario).path
    meta = {
        "case": run.case.name, "scenario": run.case.scenario_name, "controller": run.case.controller,
        "scenario_file": relative(scenario_path) if is_builtin(run.case) else str(run.case.scenario),
        "scenario_hash": digest,
        "start": run.start, "stop": run.stop, "step": run.step, "points": len(run.time),
        "signals": names, "algorithm": run.case.algorithm,
        **({"rtol": run.case.rtol or DEFAULT_RTOL, "edition": "native"} if run.case.algorithm == "me" else {}),
        "tolerances": {**DEFAULT_TOLERANCES, **previous.get("tolerances", {}), **(tolerances or {})},
        "signal_tolerances": {name: dict(values) for name, values in previous.get("signal_tolerances", {}).items()
                              if name in names},
        "tools": tool_versions(), "platform": f"{platform.system()} {platform.machine()}",
        "date": datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat(),
        "git_commit": git_commit(), "wall_s": round(run.wall_s, 3),
        "scenario_settings": settings,
    }
    # the pair replaces the old one only once both are written (harness/atomic_files.py)
    atomic_files.write_files({csv_path: csv_text.getvalue(), json_path: json.dumps(meta, indent=2) + "\n"})
    return csv_path, json_path


@dataclass
class Reference:
    time: np.ndarray
    signals: dict
    meta: dict
    path: Path | None = None  # the _ref.json


def read_reference(case: Case, directory: Path = REFERENCE_DIR) -> Reference | None:
    csv_path, json_path = reference_paths(case, directory)
    if not csv_path.exists() or not json_path.exists():
        return None
    with open(csv_path) as stream:
        names = [name.strip().strip('"') for name in stream.readline().strip().split(",")]
    table = np.loadtxt(csv_path, delimiter=",", skiprows=1, ndmin=2)
    try:
        meta = json.loads(json_path.read_text())
    except json.JSONDecodeError as error:
        raise cli_args.UsageError(f"{json_path} is not valid JSON: {error}") from None
    return Reference(table[:, 0], {name: table[:, k] for k, name in enumerate(names) if k}, meta, json_path)


def _checked_tolerances(values, where: str) -> dict:
    if not isinstance(values, dict):
        raise cli_args.UsageError(f"{where} must be a table of tolerances; valid keys: {', '.join(DEFAULT_TOLERANCES)}")
    for key, value in values.items():
        if key not in DEFAULT_TOLERANCES:
            raise cli_args.UsageError(f"{where}: unknown tolerance {key!r}; valid: {', '.join(DEFAULT_TOLERANCES)}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise cli_args.UsageError(f"{where}: {key} = {value!r} is invalid; give a finite number >= 0")
    return {key: float(value) for key, value in values.items()}


def reference_tolerances(reference: Reference, signals) -> tuple[dict, dict]:
    """(per case, {signal: per signal}) tolerances of a reference's metadata, checked: a mistake is one
    line naming the file, the key and the valid ones (exit 2)."""
    where = str(reference.path or "reference metadata")
    case_level = _checked_tolerances(reference.meta.get("tolerances", {}), f"{where}: tolerances")
    per_signal = reference.meta.get("signal_tolerances", {})
    if not isinstance(per_signal, dict):
        raise cli_args.UsageError(f"{where}: signal_tolerances must map a signal to its tolerances")
    checked = {}
    for name, values in per_signal.items():
        if name not in signals:
            raise cli_args.UsageError(f"{where}: signal_tolerances names {name!r}, which is not compared; "
                                      f"valid: {', '.join(signals)}")
        checked[name] = _checked_tolerances(values, f"{where}: signal_tolerances.{name}")
    return case_level, checked
