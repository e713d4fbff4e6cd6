"""Writing a scenario file: the inverse of harness/scenario.py's parser.

:func:`scenario_toml` lays a :class:`~harness.scenario.Scenario` out as the files of
harness/scenarios/*.toml are laid out (top-level keys, ``[experiment]``, one
``[components.NAME]`` table each with its parameters inline, ``[[connections]]``,
``[bounds]``, ``[signals]``, ``[record]``), with comment lines at the top.  The layout is
ours; every key and value in it is written by tomlkit (quoting, escapes, the shortest
text that reads back as the same double, ``inf`` and ``nan``), so any string a scenario
holds reads back as itself.  tomlkit comes with the ``tune`` extra, whose study writes
these files (``python -m harness tune``: the tuned scenario).
"""
from __future__ import annotations

from pathlib import Path

TOMLKIT_MISSING = "writing a scenario file needs tomlkit: pip install -e '.[tune]'"


def _tomlkit():
    try:
        import tomlkit  # optional: the tune extra
    except ImportError:
        raise ImportError(TOMLKIT_MISSING) from None
    return tomlkit


def toml_key(key: str) -> str:
    """``key`` as a TOML key: bare when it may be, else quoted."""
    return _tomlkit().key(key).as_string()


def toml_value(value) -> str:
    """``value`` (bool, int, float, str, list, tuple or dict of these) as a TOML value on one line;
    a dict is an inline table."""
    tomlkit = _tomlkit()
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, (bool, int, float, str)):
        return tomlkit.item(value).as_string()
    raise TypeError(f"no TOML form for {value!r}")


def scenario_toml(scenario, comments=()) -> str:
    """The text of a scenario file (the format of harness/scenarios/*.toml) for ``scenario``;
    an FMU file relative to the original scenario is written as an absolute path.  ``comments``:
    the lines of the comment at the top (each line of a multi-line entry is commented too)."""
    lines = [f"# {line}" if line else "#" for entry in comments for line in str(entry).split("\n")]
    lines += [f"name = {toml_value(scenario.name)}", f"description = {toml_value(scenario.description)}",
              f"controller_instance = {toml_value(scenario.controller_instance)}", "", "[experiment]",
              f"start = {toml_value(float(scenario.start))}", f"stop = {toml_value(float(scenario.stop))}",
              f"step = {toml_value(float(scenario.step))}",
              f"divergence_bound = {toml_value(float(scenario.divergence_bound))}"]
    for name, spec in scenario.components.items():
        fmu = spec.fmu
        if fmu.endswith(".fmu") and not Path(fmu).is_absolute() and scenario.path is not None:
            fmu = str((scenario.path.parent / fmu).resolve())
        lines += ["", f"[components.{toml_key(name)}]", f"fmu = {toml_value(fmu)}",
                  f"parameters = {toml_value(dict(spec.parameters))}"]
    for connection in scenario.connections:
        lines += ["", "[[connections]]", f"from = {toml_value(connection.source)}",
                  f"to = {toml_value(connection.target)}"]
    if scenario.bounds:
        lines += ["", "[bounds]"] + [f"{toml_key(k)} = {toml_value(float(v))}" for k, v in scenario.bounds.items()]
    lines += ["", "[signals]"] + [f"{toml_key(k)} = {toml_value(v)}" for k, v in scenario.signals.items()]
    lines += ["", "[record]", f"variables = {toml_value(list(scenario.record))}", ""]
    return "\n".join(lines)
