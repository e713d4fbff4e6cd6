"""A user's specification of the closed loop, ``--spec "ITAE<0.6,umax<50"``: a conjunction of bounds
on the scores of docs/model.md section 9 (scores).  A run meets it when it completed (status ``ok``)
and every bound holds; a score the run cannot give (None, e.g. ts not settled) does not meet a bound.
"""
from __future__ import annotations

import math
import operator
import re
from dataclasses import dataclass

from ...cli_args import UsageError
from ...scenario import did_you_mean
from ...scores import SCORE_KEYS

OPERATORS = {"<=": operator.le, ">=": operator.ge, "<": operator.lt, ">": operator.gt}
CONDITION = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(<=|>=|<|>)\s*(\S+)\s*$")


@dataclass(frozen=True)
class Bound:
    score: str
    operator: str
    value: float

    def holds(self, value) -> bool:
        return value is not None and math.isfinite(value) and OPERATORS[self.operator](value, self.value)

    def text(self) -> str:
        return f"{self.score}{self.operator}{self.value:g}"


@dataclass(frozen=True)
class Spec:
    bounds: tuple

    def met(self, row: dict) -> bool:
        return row["status"] == "ok" and all(b.holds(row["scores"].get(b.score)) for b in self.bounds)

    def text(self) -> str:
        return ",".join(b.text() for b in self.bounds)


def parse_spec(text: str) -> Spec:
    """``SCORE OP VALUE[,SCORE OP VALUE...]`` with OP one of <, <=, >, >=."""
    bounds = []
    for part in text.split(","):
        match = CONDITION.match(part)
        if not match:
            raise UsageError(f"--spec {text!r}: {part.strip()!r} is not SCORE<VALUE (operators <, <=, >, >=; "
                             f"scores {', '.join(SCORE_KEYS)})")
        score, op, value = match.groups()
        if score not in SCORE_KEYS:
            raise UsageError(f"--spec {text!r}: unknown score {score!r}{did_you_mean(score, SCORE_KEYS)}; "
                             f"valid: {', '.join(SCORE_KEYS)}")
        try:
            number = float(value)
        except ValueError:
            raise UsageError(f"--spec {text!r}: {value!r} is not a number") from None
        if not math.isfinite(number):
            raise UsageError(f"--spec {text!r}: {value!r} is not a finite number")
        bounds.append(Bound(score, op, number))
    return Spec(tuple(bounds))


__all__ = ["Spec", "Bound", "parse_spec"]
