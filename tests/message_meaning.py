"""What a log message says: its words and its numbers, apart from how the numbers are written.

The two editions word their messages alike but write numbers differently: the Python edition with
``repr`` (the shortest text that reads back: ``1.0``, ``0.1``, ``1e-05``), the native edition with C's
``%.17g`` (``1``, ``0.10000000000000001``, ``1.0000000000000001e-05``). A message's meaning is its
words, each number replaced by ``#``, and its numbers read back as floats. Two messages say the same
when their words are equal and their numbers are equal as doubles, bit for bit (any NaN equals any
NaN: a C library may write a NaN's sign, glibc ``-nan`` and Windows' C runtime ``-nan(ind)``; Python
never does).

    >>> meaning("parameter k1 = -1.0 is invalid; valid range: > 0") == meaning(
    ...     "parameter k1 = -1 is invalid; valid range: > 0")
    True
    >>> parameter_error("parameter lambda_ce = 1 is invalid; valid range: (0, 1)")
    ('lambda_ce', 1.0, '(0, 1)')
    >>> meaning("u = -nan(ind), E = (0.10000000000000001,)") == meaning("u = nan, E = (0.1,)")
    True
    >>> meaning("t = 0.005") == meaning("t = 0.0050000000000000001"), meaning("t = 0.005") == meaning("t = 0.00500001")
    (True, False)
"""
from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass

# a number standing alone: not part of a name (k1, fmi2DoStep, x1) nor followed by letters; the
# exponent form of both editions (1e-05, 1.0000000000000001e-05); inf, nan and C's -nan, -nan(ind)
NUMBER = r"(?<![\w.])[-+]?(?:(?:\d+(?:\.\d+)?|\.\d+)(?:[eE][-+]?\d+)?|inf|nan(?:\(ind\))?)(?!\w|\.\d)"
_NUMBER = re.compile(NUMBER)
_PARAMETER_ERROR = re.compile(rf"^parameter (\w+) = ({NUMBER}) is invalid; valid range: (.+)$")


@dataclass(frozen=True)
class Meaning:
    words: str              # the message with each number replaced by "#"
    numbers: tuple          # the numbers, as floats
    texts: tuple            # the numbers as the message writes them

    def __eq__(self, other) -> bool:
        return (isinstance(other, Meaning) and self.words == other.words
                and len(self.numbers) == len(other.numbers)
                and all(_same_double(a, b) for a, b in zip(self.numbers, other.numbers)))

    __hash__ = None


def _same_double(a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return struct.pack("<d", a) == struct.pack("<d", b)


def meaning(message: str) -> Meaning:
    """The words and numbers of a message (without the "<instance>: " prefix)."""
    texts = tuple(found.group(0) for found in _NUMBER.finditer(message))
    return Meaning(_NUMBER.sub("#", message), tuple(float(text.removesuffix("(ind)")) for text in texts), texts)


def parameter_error(message: str) -> tuple | None:
    """(name, value, valid range) of a "parameter NAME = VALUE is invalid; valid range: RANGE" message."""
    found = _PARAMETER_ERROR.match(message)
    return (found.group(1), float(found.group(2).removesuffix("(ind)")), found.group(3)) if found else None


def written_as_c_does(text: str) -> bool:
    """The number is written as C's %.17g writes it (any sign of a NaN)."""
    value = float(text.removesuffix("(ind)"))
    return text.lstrip("-") in ("nan", "nan(ind)") if math.isnan(value) else text == f"{value:.17g}"
