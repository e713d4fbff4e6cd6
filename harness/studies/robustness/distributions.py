"""The uncertain parameters of a Monte Carlo study and their distributions, declared on the command
line (``--param plant.mp=loguniform:0.05:2``) or in a file (``--distributions FILE``, a TOML table per
parameter), with a strict schema: an unknown kind or key, a missing key, a value out of its range is
one :class:`~harness.cli_args.UsageError` naming it.

Each distribution is a frozen ``scipy.stats`` distribution; a draw is its inverse CDF (``ppf``) at a
quantile of the study's design (harness/studies/robustness/draws.py), clipped to [EDGE, 1 - EDGE] so
that the values the study can draw are those :func:`support` gives (checked against the FMUs' valid
ranges before any run).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from ...cli_args import UsageError
from ...scenario import did_you_mean

#: the quantiles a draw is clipped to: an unbounded distribution (normal) draws within ppf(EDGE) .. ppf(1 - EDGE)
EDGE = 1e-9
#: kind -> its keys, in the order of the command line's KIND:A:B[:C:D]
KINDS = {
    "uniform": ("low", "high"),
    "loguniform": ("low", "high"),
    "normal": ("mean", "std"),
    "truncnormal": ("mean", "std", "low", "high"),
}
MEANING = {
    "uniform": "uniform on [low, high]",
    "loguniform": "log-uniform on [low, high], 0 < low",
    "normal": "normal of mean and standard deviation std",
    "truncnormal": "normal of mean and std truncated to [low, high]",
}
FILE_KEYS = ("distribution",)  # besides the kind's own keys


@dataclass(frozen=True)
class Distribution:
    """``name`` (instance.parameter) drawn from ``kind`` with ``values`` (the kind's keys, in order)."""

    name: str
    kind: str
    values: tuple

    @property
    def arguments(self) -> dict:
        return dict(zip(KINDS[self.kind], self.values))

    def frozen(self):
        """The scipy.stats distribution."""
        from scipy import stats  # the robustness extra

        a = self.arguments
        if self.kind == "uniform":
            return stats.uniform(loc=a["low"], scale=a["high"] - a["low"])
        if self.kind == "loguniform":
            return stats.loguniform(a["low"], a["high"])
        if self.kind == "normal":
            return stats.norm(loc=a["mean"], scale=a["std"])
        return stats.truncnorm((a["low"] - a["mean"]) / a["std"], (a["high"] - a["mean"]) / a["std"],
                               loc=a["mean"], scale=a["std"])

    def support(self) -> tuple:
        """(smallest, largest) value a draw can take."""
        low, high = self.frozen().ppf([EDGE, 1 - EDGE])
        return float(low), float(high)

    def text(self) -> str:
        """As the command line writes it: ``plant.mp=loguniform:0.05:2``."""
        return f"{self.name}={self.kind}:" + ":".join(f"{v:g}" for v in self.values)

    def settings(self) -> dict:
        return {"distribution": self.kind, **self.arguments}


def _check(name: str, kind: str, values: tuple, where: str) -> Distribution:
    a = dict(zip(KINDS[kind], values))
    if not all(math.isfinite(v) for v in values):
        raise UsageError(f"{where}: every value must be finite (got {', '.join(f'{v:g}' for v in values)})")
    if "std" in a and not a["std"] > 0:
        raise UsageError(f"{where}: std = {a['std']:g}; valid: std > 0")
    if "low" in a and not a["low"] < a["high"]:
        raise UsageError(f"{where}: low = {a['low']:g}, high = {a['high']:g}; valid: low < high")
    if kind == "loguniform" and not a["low"] > 0:
        raise UsageError(f"{where}: low = {a['low']:g}; valid for loguniform: 0 < low < high")
    if kind == "truncnormal" and (a["low"] > a["mean"] + 8 * a["std"] or a["high"] < a["mean"] - 8 * a["std"]):
        raise UsageError(f"{where}: [low, high] lies more than 8 std from the mean: give a uniform instead")
    return Distribution(name, kind, tuple(float(v) for v in values))


def _usage() -> str:
    return "; ".join(f"{kind}:{':'.join(keys).upper()} ({MEANING[kind]})" for kind, keys in KINDS.items())


def parse_param(text: str) -> Distribution:
    """``instance.parameter=KIND:A:B[:C:D]`` from ``--param``."""
    name, equals, spec = (part.strip() for part in text.partition("="))
    where = f"--param {text!r}"
    if not equals or "." not in name or not spec:
        raise UsageError(f"{where}: write instance.parameter=KIND:VALUES, KIND one of {_usage()}")
    kind, *fields = spec.split(":")
    if kind not in KINDS:
        raise UsageError(f"{where}: unknown distribution {kind!r}{did_you_mean(kind, KINDS)}; valid: {', '.join(KINDS)}")
    keys = KINDS[kind]
    if len(fields) != len(keys):
        raise UsageError(f"{where}: {kind} takes {len(keys)} values ({':'.join(keys)}), got {len(fields)}")
    try:
        values = tuple(float(field) for field in fields)
    except ValueError:
        raise UsageError(f"{where}: {':'.join(fields)} are not all numbers ({kind}:{':'.join(keys)})") from None
    return _check(name, kind, values, where)


def load_file(path) -> list:
    """The distributions of a TOML file: one table per parameter, ``["plant.mp"]`` with
    ``distribution = "loguniform"`` and the kind's keys; nothing else."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except OSError as error:
        raise UsageError(f"--distributions {path}: cannot read it ({error.strerror or error})") from None
    except tomllib.TOMLDecodeError as error:
        raise UsageError(f"--distributions {path}: not TOML ({error})") from None
    if not data:
        raise UsageError(f"--distributions {path}: no parameter; write a table per parameter, e.g. "
                         '["plant.mp"] with distribution = "loguniform", low = 0.05, high = 2.0')
    found = []
    for name, table in data.items():
        where = f"{path}: [\"{name}\"]"
        if not isinstance(table, dict) or "." not in name:
            raise UsageError(f"{path}: {name!r} is not a table named instance.parameter, e.g. "
                             '["plant.mp"] with distribution = "loguniform", low = 0.05, high = 2.0')
        kind = table.get("distribution")
        if kind is None:
            raise UsageError(f"{where}: no distribution key; valid: {', '.join(KINDS)}")
        if kind not in KINDS:
            raise UsageError(f"{where}: unknown distribution {kind!r}{did_you_mean(str(kind), KINDS)}; "
                             f"valid: {', '.join(KINDS)}")
        keys = KINDS[kind]
        valid = (*FILE_KEYS, *keys)
        for key in table:
            if key not in valid:
                raise UsageError(f"{where}: unknown key {key!r}{did_you_mean(key, valid)}; valid for {kind}: "
                                 f"{', '.join(valid)}")
        missing = [key for key in keys if key not in table]
        if missing:
            raise UsageError(f"{where}: {kind} needs {', '.join(keys)}; missing {', '.join(missing)}")
        values = []
        for key in keys:
            value = table[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise UsageError(f"{where}: {key} = {value!r} is not a number")
            values.append(float(value))
        found.append(_check(name, kind, tuple(values), where))
    return found


def combine(from_file: list, from_options: list) -> tuple:
    """The study's distributions: those of the file, then those of ``--param``; a parameter given twice
    is an error."""
    result = [*from_file, *from_options]
    names = [d.name for d in result]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise UsageError(f"{', '.join(twice)} given twice (--param and --distributions): give each parameter once")
    if not result:
        raise UsageError("no uncertain parameter: give --param instance.parameter=KIND:VALUES or --distributions FILE "
                         f"(KIND one of {_usage()})")
    return tuple(result)


__all__ = ["Distribution", "KINDS", "EDGE", "parse_param", "load_file", "combine"]
