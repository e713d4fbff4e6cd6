"""The objective: the score a study minimises, the constraints a reported candidate meets, and the
plant variations (``--robust``, ``--vary``) over which a candidate's worst case is its score."""
from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass

from ...scores import SCORE_KEYS
from .errors import TuneError

# --robust without --vary: the plant variations of each plant FMU (numbers, or xF: F times the scenario's value)
ROBUST_GRIDS = {
    "InvertedPendulum": (("mp", ("0.1", "1.0")), ("dist_gain", ("0", "1"))),  # the pendulum's cases 1-3 and 4th
    "Manipulator": (("mr0", ("x1", "x1.5")), ("cr", ("x1", "x2"))),
    "DcMotorArm": (("m", ("x1", "x2")), ("L", ("x1", "x2"))),
}
SCORE_ALIASES = {re.sub(r"[_\s]|pct$", "", key.lower()): key for key in SCORE_KEYS}  # tvu -> tv_u, es1 -> es1_pct


def score_name(text: str) -> str:
    """A score key of SCORE_KEYS from ``text`` (case and underscores free: itae, tvu, es1)."""
    key = re.sub(r"[_\s]|pct$", "", str(text).strip().lower())
    if key not in SCORE_ALIASES:
        raise TuneError(f"unknown score {text!r}; valid: {', '.join(SCORE_KEYS)}")
    return SCORE_ALIASES[key]


@dataclass(frozen=True)
class Constraint:
    score: str
    operator: str  # "<=" or ">="
    limit: float

    @property
    def text(self) -> str:
        return f"{self.score}{self.operator}{self.limit:g}"

    def violation(self, scores: dict) -> float:
        """<= 0: met (Optuna's convention); > 0: by how much it is missed."""
        value = scores[self.score]
        if value is None:  # ts of a run that never settles misses any bound on ts
            return math.inf
        return value - self.limit if self.operator == "<=" else self.limit - value


def parse_constraint(text: str) -> Constraint:
    match = re.fullmatch(r"\s*([A-Za-z_0-9 ]+?)\s*(<=|>=)\s*(\S+)\s*", str(text))
    if not match:
        raise TuneError(f"--constraint {text!r}: write SCORE<=LIMIT or SCORE>=LIMIT, e.g. \"umax<=20\"; "
                        f"scores: {', '.join(SCORE_KEYS)}")
    score = score_name(match.group(1))
    try:
        limit = float(match.group(3))
    except ValueError:
        raise TuneError(f"--constraint {text!r}: {match.group(3)!r} is not a number") from None
    if not math.isfinite(limit):
        raise TuneError(f"--constraint {text!r}: the limit must be finite")
    return Constraint(score, match.group(2), limit)


def parse_vary(text: str) -> tuple:
    """``INSTANCE.PARAMETER=V1,V2,...`` (numbers, or xF = F times the scenario's value) -> (dotted, values)."""
    dotted, equals, listed = str(text).partition("=")
    dotted = dotted.strip()
    items = [item.strip() for item in listed.split(",") if item.strip()]
    if not equals or "." not in dotted or not items:
        raise TuneError(f"--vary {text!r}: write INSTANCE.PARAMETER=V1,V2,... (numbers, or xF for F times the "
                        "scenario's value), e.g. plant.mp=0.1,1 or plant.m=x1,x2")
    for item in items:
        try:
            float(item[1:] if item.lower().startswith("x") else item)
        except ValueError:
            raise TuneError(f"--vary {text!r}: {item!r} is neither a number nor xF") from None
    return dotted, tuple(items)


def plant_instance(scenario) -> str:
    """The instance the controller's u drives."""
    source = scenario.signals.get("u", f"{scenario.controller_instance}.u")
    return next((c.target_instance for c in scenario.connections if c.source == source), "plant")


def robust_grid(scenario, varies, infos: dict) -> list:
    """The plant variations: [((dotted, value), ...), ...], the scenario itself first when it is on the grid.

    ``varies``: [(dotted, (item, ...))] from --vary, or empty for the default grid of the plant FMU.
    """
    if not varies:
        plant = plant_instance(scenario)
        identifier = infos[plant].model_identifier
        if identifier not in ROBUST_GRIDS:
            raise TuneError(f"--robust: no default grid for the plant {identifier}; give the variations with "
                            f"--vary INSTANCE.PARAMETER=V1,V2 (default grids: {', '.join(ROBUST_GRIDS)})")
        varies = [(f"{plant}.{name}", items) for name, items in ROBUST_GRIDS[identifier]]
    axes = []
    for dotted, items in varies:
        instance, _, name = dotted.partition(".")
        if instance not in scenario.components:
            raise TuneError(f"--vary {dotted}: unknown instance {instance!r}; valid: {', '.join(scenario.components)}")
        variable = infos[instance].variables.get(name)
        if variable is None or variable.causality != "parameter":
            valid = [n for n, v in infos[instance].variables.items() if v.causality == "parameter"]
            raise TuneError(f"--vary {dotted}: {instance} has no parameter {name!r}; valid: {', '.join(valid)}")
        base = scenario.components[instance].parameters.get(name, variable.start)
        values = []
        for item in items:
            value = float(base) * float(item[1:]) if item.lower().startswith("x") else float(item)
            if variable.type == "Integer":
                value = int(round(value))
            values.append(value)
        axes.append([(dotted, value) for value in dict.fromkeys(values)])
    return [tuple(point) for point in itertools.product(*axes)]
