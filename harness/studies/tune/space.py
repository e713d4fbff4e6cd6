"""The search space: which controller parameters a study searches, how, and within which bounds.

From the FMU's own variable table (``fmu_src/adaptive_fuzzy_controller_fmu.py``, the single
source): every parameter that declares a :class:`Tuning` range and acts in the chosen variant at
the controller's order.  ``log`` ranges are searched in log(value), ``log1m`` (lambda_ce) in
log(1 - value), ``hurwitz`` (k3, k4) as a fraction of the Routh bound given the lower gains.  The
paper's conditions hold by construction or are checked before any run (:func:`paper_conditions`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from harness.fmu_build import builder as build_fmu
from fmu_src import afc_math
from fmu_src.afc_slave_base import Tuning

from ... import variants
from .errors import TuneError

CONTROLLER_MODEL = "AdaptiveFuzzyController"


@dataclass(frozen=True)
class Dimension:
    """One searched parameter: the FMU parameter, its range and how it is searched (Tuning.scale)."""

    parameter: str
    low: float
    high: float
    scale: str  # linear, log, log1m, hurwitz

    @property
    def name(self) -> str:
        """The optimiser's name for it (what the importances and the dashboard show)."""
        return {"log1m": f"1-{self.parameter}", "hurwitz": f"{self.parameter}_fraction"}.get(self.scale,
                                                                                             self.parameter)

    def bounds(self) -> tuple:
        """(low, high, log) of the optimiser's variable."""
        if self.scale == "log1m":
            return 1.0 - self.high, 1.0 - self.low, True
        return self.low, self.high, self.scale in ("log", "hurwitz")

    def describe(self) -> str:
        return {"linear": f"[{self.low:g}, {self.high:g}]", "log": f"[{self.low:g}, {self.high:g}] log",
                "log1m": f"[{self.low:g}, {self.high:g}], log(1 - value)",
                "hurwitz": f"fraction [{self.low:g}, {self.high:g}] (log) of the Routh bound"}[self.scale]


def declared_parameters() -> dict:
    """{name: Variable} of the controller FMU's parameters, from its declaration table."""

    return {v.name: v for v in build_fmu.model_class(CONTROLLER_MODEL).VARIABLES if v.causality == "parameter"}


def _acts(variable, variant: int, order: int) -> bool:
    tuning = variable.tuning
    return (not tuning.variants or variant in tuning.variants) and order >= tuning.order


def _inactive_reason(variable, variant: int, order: int) -> str:
    tuning = variable.tuning
    if tuning.variants and variant not in tuning.variants:
        names = {number: name for name, number in variants.CONTROLLER_VARIANTS.items()}
        return (f"it has no effect with controller {names.get(variant, variant)} (it acts in "
                f"{', '.join(names.get(v, str(v)) for v in tuning.variants)} only)")
    return f"it has no effect at order {order} (it acts from order {tuning.order})"


def search_space(variant: int, order: int, table: dict | None = None, only=None, ranges=None) -> list:
    """The searched dimensions, in table order.

    ``only``: names to search (default: every tunable parameter that acts in ``variant`` at
    ``order``); ``ranges``: {name: (low, high)} replacing declared ranges (the scale stays).
    A name the table does not know, one without a search range, one that does not act here, an
    empty or inverted range, or one leaving the valid range is a TuneError naming it.
    """

    table = declared_parameters() if table is None else table
    tunable = [name for name, v in table.items() if v.tuning is not None and _acts(v, variant, order)]
    ranges = dict(ranges or {})

    def check_name(name: str, option: str) -> None:
        if name not in table:
            raise TuneError(f"{option}: {CONTROLLER_MODEL} has no parameter {name!r}; tunable: {', '.join(tunable)}")
        variable = table[name]
        if variable.tuning is None:
            raise TuneError(f"{option}: parameter {name} is not tunable (the FMU's table gives it no search "
                            f"range); tunable: {', '.join(tunable)}")
        if not _acts(variable, variant, order):
            raise TuneError(f"{option}: parameter {name}: {_inactive_reason(variable, variant, order)}; "
                            f"tunable here: {', '.join(tunable)}")

    chosen = list(only) if only else list(tunable)
    for name in chosen:
        check_name(name, f"--params {name}")
    for name in ranges:
        check_name(name, f"--range {name}")
        if name not in chosen:
            chosen.append(name)
    dimensions = []
    for name in table:  # table order: k1, k2 before k3 (the Hurwitz fraction needs them)
        if name not in chosen:
            continue
        variable = table[name]
        low, high = ranges.get(name, (variable.tuning.low, variable.tuning.high))
        tuning = Tuning(low, high, variable.tuning.scale)
        problem = tuning.problem()
        if name in ranges:
            where = f"--range {name}={low:g}:{high:g}"
            if low < high and variable.tuning.scale != "hurwitz":
                for end in (low, high):
                    if variable.check(end) is not None:
                        raise TuneError(f"{where}: {end:g} is outside the valid range {variable.valid_range()} "
                                        f"of {name}")
            if problem:
                raise TuneError(f"{where}: {problem}")
        elif problem:
            raise TuneError(f"the FMU's table: {name}: {problem}")
        dimensions.append(Dimension(name, float(low), float(high), variable.tuning.scale))
    return dimensions


def search_space_markdown(table: dict | None = None) -> str:
    """The table of docs/tuning.md: every declared search range (tests/test_tune.py keeps the page current)."""
    table = declared_parameters() if table is None else table
    names = {number: name for name, number in variants.CONTROLLER_VARIANTS.items()}
    lines = ["| parameter | default | valid range | searched | acts in | from order |", "|---|---|---|---|---|---|"]
    for name, variable in table.items():
        tuning = variable.tuning
        if tuning is None:
            continue
        dimension = Dimension(name, tuning.low, tuning.high, tuning.scale)
        acts = ", ".join(names[v] for v in tuning.variants) if tuning.variants else "every controller"
        lines.append(f"| `{name}` | {variable.start:.6g} | {variable.valid_range()} | {dimension.describe()} | "
                     f"{acts} | {tuning.order} |")
    return "\n".join(lines)


def hurwitz_bound(i: int, k) -> float:
    """The supremum of k_i that keeps s^n + k1 s^(n-1) + ... + kn Hurwitz, given k1..k(i-1) > 0.

    Routh's array: n = 1, 2: every k > 0; k3 < k1 k2 (n >= 3); k4 < k3 (k1 k2 - k3) / k1^2
    (n = 4, with k3 < k1 k2).  The controller's orders go up to 4 (afc_math.ORDER_MAX).
    """
    if i <= 2:
        return math.inf
    if i == 3:
        return k[0] * k[1]
    if i == 4:
        return k[2] * (k[0] * k[1] - k[2]) / (k[0] * k[0])
    raise ValueError(f"no Hurwitz bound for k{i}: orders up to 4")


def _gain_index(name: str) -> int:
    return int(name[1:])


def parameter_values(dimensions, sample: dict, fixed: dict) -> dict:
    """The FMU values of the searched parameters from the optimiser's ``sample`` ({Dimension.name: x});
    ``fixed``: the other parameters' values (the lower gains a Hurwitz fraction refers to)."""
    values = {}
    for dimension in dimensions:
        x = sample[dimension.name]
        if dimension.scale == "log1m":
            values[dimension.parameter] = 1.0 - x
        elif dimension.scale == "hurwitz":
            i = _gain_index(dimension.parameter)
            k = [values.get(f"k{j}", fixed.get(f"k{j}")) for j in range(1, i)]
            values[dimension.parameter] = x * hurwitz_bound(i, k)
        else:
            values[dimension.parameter] = x
    return values


def sample_of(dimensions, values: dict) -> dict:
    """The optimiser's sample for FMU ``values`` (inverse of :func:`parameter_values`)."""
    sample = {}
    for dimension in dimensions:
        value = values[dimension.parameter]
        if dimension.scale == "log1m":
            sample[dimension.name] = 1.0 - value
        elif dimension.scale == "hurwitz":
            i = _gain_index(dimension.parameter)
            sample[dimension.name] = value / hurwitz_bound(i, [values[f"k{j}"] for j in range(1, i)])
        else:
            sample[dimension.name] = value
    return sample


def paper_conditions(values: dict, table: dict) -> str | None:
    """None if the controller's parameter ``values`` (all of them) meet the paper's conditions, else why not.

    Every value inside its valid range (0 < lambda_ce < 1, gamma, kappa_i, ... > 0); k1..kn Hurwitz so
    that P of (30) is positive definite (the FMU's own test: afc_math.lyapunov_p, is_positive_definite);
    the initial weights inside the projection bound, |theta0| <= M_theta (31).
    """

    for name, value in values.items():
        variable = table.get(name)
        if variable is not None:
            problem = variable.check(value)
            if problem:
                return problem
    n = int(values["order"])
    k = tuple(float(values[f"k{i}"]) for i in range(1, n + 1))
    q = tuple(float(values[f"q{i}"]) for i in range(1, n + 1))
    try:
        positive_definite = afc_math.is_positive_definite(afc_math.lyapunov_p(k, q))
    except ValueError:
        positive_definite = False
    if not positive_definite:
        return f"k = {k!r} is not Hurwitz (no positive definite P in (30))"
    if abs(values["theta0"]) > values["m_theta"]:
        return f"|theta0| = {abs(values['theta0']):g} > M_theta = {values['m_theta']:g} (31)"
    return None


def parse_range(text: str) -> tuple:
    """``NAME=LOW:HIGH`` -> (name, low, high) (numbers only; the range itself is checked later)."""
    name, equals, span = str(text).partition("=")
    low, colon, high = span.partition(":")
    if not equals or not colon or not name.strip():
        raise TuneError(f"--range {text!r}: write NAME=LOW:HIGH, e.g. gamma=100:3000")
    try:
        numbers = float(low), float(high)
    except ValueError:
        raise TuneError(f"--range {text!r}: LOW and HIGH must be numbers") from None
    return name.strip(), *numbers
