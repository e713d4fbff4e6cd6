"""A sampled chain: sample-and-hold on a clock of its own, a delay of d samples (docs/model.md section 13).

The sensor and the actuator FMUs share it.  Sample k of every channel is taken at

    t_k = t_0 + k Ts                                                        (C1)

from the input the FMU holds at t_k (a co-simulation host's zero-order hold of its input over the
communication step), processed by the FMU (the sensor: noise, quantiser, filter; the actuator:
nothing), and the output holds the processed sample k - d from t_k to t_(k+1):

    out(t) = p_max(k - d, 0)   for t_k <= t < t_(k+1)                       (C2)

so the output does not depend on the host's step wherever the host has a communication point at
each sample instant.  A host step that holds several sample instants takes them all from the input
held over the step.  At a communication point that is a sample instant the sample is taken from the
inputs set there (direct feedthrough for d = 0); it is committed when the step leaves that point.
The samples before the first one (k - d < 0) are the first sample: the delay line starts full of
p_0, as a delay block starts from its initial input.

State: one flat list ``[NEXT, ring...]``: NEXT the index of the first sample not yet committed,
then RING slots of one value per channel (slot of sample j: j mod RING).  Standard library only:
this module travels inside each sampled FMU; plants/sampled_chain.c is its C twin.
"""
from __future__ import annotations

MAX_DELAY_SAMPLES = 16
#: slots of the delay line: the d + 1 samples (C2) reads, and the one before them the next sample's
#: filter starts from
RING = MAX_DELAY_SAMPLES + 2
NEXT = 0  # state index: the first sample not yet committed
RING_BASE = 1
#: a time within this share of (|t| + Ts) of a sample instant is at it (the rounding of t_0 + k Ts
#: and of a host's own sum of steps; the rule of doStep's communication point)
INSTANT_TOLERANCE = 1e-9


def new_state(channels: int) -> list:
    """The state before the first sample: nothing committed."""
    return [0.0] * (RING_BASE + RING * channels)


def sample_time(start: float, period: float, k: int) -> float:
    """t_k of (C1)."""
    return start + k * period


def tolerance(t: float, period: float) -> float:
    return INSTANT_TOLERANCE * (abs(t) + period)


def at_instant(t: float, start: float, period: float, k: int) -> bool:
    """Is ``t`` the sample instant t_k (within rounding)?"""
    return abs(t - sample_time(start, period, k)) <= tolerance(t, period)


def slot(channels: int, k: int, channel: int) -> int:
    """The index in the state of sample k's value of ``channel``."""
    return RING_BASE + (k % RING) * channels + channel


def committed(state: list) -> int:
    """The number of samples committed (the index of the next one)."""
    return int(state[NEXT])


def held_index(state: list, t: float, start: float, period: float) -> tuple:
    """(k, pending): the sample whose value holds at ``t`` and whether it is the pending one (t is
    its instant and it is not committed yet: taken from the inputs now)."""
    k = committed(state)
    if at_instant(t, start, period, k):
        return k, True
    return k - 1, False


def delayed_index(k: int, delay: int) -> int:
    """The sample (C2) outputs at sample k: k - d, the first sample before that."""
    return k - delay if k > delay else 0


def commit(state: list, channels: int, values) -> None:
    """Append the processed values of the next sample (one per channel) to the delay line."""
    k = committed(state)
    base = slot(channels, k, 0)
    state[base:base + channels] = values
    state[NEXT] = float(k + 1)


def samples_before(state: list, end: float, start: float, period: float) -> int:
    """How many samples are due strictly before ``end`` (beyond rounding) and not committed yet:
    those a step ending at ``end`` takes from the input it holds."""
    k = committed(state)
    limit = end - tolerance(end, period)
    count = 0
    while sample_time(start, period, k + count) < limit:
        count += 1
    return count
