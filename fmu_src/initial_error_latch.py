"""Which inputs give e(0), de(0), ... of the modified tracking error (Remark 3), in any FMI host.

The modified error E(t) = e - (a0 + a1 (t - t0)) exp(-lambda_e (t - t0)) needs the error
vector x = [e, de, d2e, ...] (length n >= 1) at its time origin t0.  A host that does not
propagate initial values hands the controller placeholders (e = 0, ...) when initialisation
ends, and a host that delays every link (Jacobi) hands them again at the first doStep.  This
module decides, over the first doSteps, which sample to keep (docs/host_robustness.md):

1. ``start``: at exitInitializationMode the inputs set by then are latched tentatively, with
   t0 = the start time.
2. ``observe`` at each doStep (the inputs set for it, at its time t), until decided:
   * same time as the previous sample (the first doStep at the start time): inputs that
     differ from the previous sample show it was a placeholder: re-latch here (t0 = t);
   * later time, h = t - t_prev: the pair (previous, current) is consistent when every
     component but the last agrees with the next one (its derivative) by the trapezoidal rule,
        | x_i - x_i,prev - h (x_i+1 + x_i+1,prev) / 2 |
            <= RELATIVE_TOLERANCE * max(|x_i - x_i,prev|, h |x_i+1 + x_i+1,prev| / 2) + ABSOLUTE_FLOOR.
     A consistent pair whose samples differ decides the latch for good.  An inconsistent pair
     shows the earlier sample was a placeholder: re-latch from the current one (t0 = t) --
     unless the latch was already moved and the start inputs (the first latch) agree with the
     current sample over the whole interval: then the samples in between were the
     placeholders (fmpy's SSP simulator hands 0 for two steps after consistent start values):
     go back to the start inputs and decide.
     Two identical samples (a constant error, or placeholders twice) are consistent but tell
     nothing: the latch stays and the window goes on.
   * after CHECK_STEPS observations the latch is decided as it stands.
   With n = 1 there is no derivative to compare: only the same-time rule applies.
3. Once decided, never again (a reference that jumps at t > 0 does not re-latch).

A re-latch means the adaptation ran on a wrong E since t0: the caller restarts it.  When the
decision follows a re-latch, or the window ended without a consistent pair, ``warning``
gives the one message the caller logs (values and times, rejected and kept).

The state is one flat list of floats (FMU state copies and serialises it exactly; a C port
holds the same fields in a struct); the functions change it in place, allocate nothing per
call once decided, and know nothing of FMI.  Standard library only: this module travels
inside the FMU.
"""
from __future__ import annotations

CHECK_STEPS = 8  # doSteps watched at most before the latch is decided as it stands
RELATIVE_TOLERANCE = 0.25  # a placeholder pair misses by ~100 %, a sampled smooth signal by O(h^2)
ABSOLUTE_FLOOR = 1e-9  # in the units of each error component: below it a mismatch does not count

# Layout of the state list: six scalars, then three vectors of length n.
OPEN = 0  # doSteps left to watch; 0 = decided
ORIGIN = 1  # t0: time of the latched sample (origin of the modified error)
PREVIOUS_TIME = 2  # time of the previous sample
REJECTED_TIME = 3  # time of the first latch rejected (when RELATCHES > 0)
RELATCHES = 4  # how many times the latch moved
CONFIRMED = 5  # 1 once a consistent pair of differing samples decided the latch
LATCHED = 6  # x(t0) = [e0, de0, ...]: state[LATCHED:LATCHED + n]
# then the previous sample (n values) and the first rejected latch (n values)

# Bits returned by observe
RELATCHED = 1  # the latch moved to the current sample: restart the adaptation
DECIDED = 2  # the latch is final from now on


def size(n: int) -> int:
    """Length of the state list for an error vector of length n."""
    return LATCHED + 3 * n


def order(state: list) -> int:
    """n, the length of the error vector the state was made for."""
    return (len(state) - LATCHED) // 3


def latched(state: list) -> list:
    """x(t0) = [e0, de0, ...], a new list."""
    n = order(state)
    return state[LATCHED:LATCHED + n]


def start(state: list, time: float, sample) -> None:
    """Latch ``sample`` (the inputs at exitInitializationMode) tentatively at t0 = ``time``."""
    n = order(state)
    state[OPEN] = CHECK_STEPS
    state[ORIGIN] = state[PREVIOUS_TIME] = state[REJECTED_TIME] = time
    state[RELATCHES] = state[CONFIRMED] = 0
    for i in range(n):
        state[LATCHED + i] = state[LATCHED + n + i] = state[LATCHED + 2 * n + i] = float(sample[i])


def pin(state: list, time: float, values) -> None:
    """Latch ``values`` (parameters) for good at t0 = ``time``: no window, no warning."""
    start(state, time, values)
    state[OPEN] = 0


def consistent(previous, current, h: float) -> bool:
    """True if every component of the pair agrees with its derivative (the next one).

    Trapezoidal rule over h > 0, relative test with an absolute floor (module docstring).
    """
    for i in range(len(current) - 1):
        change = current[i] - previous[i]
        predicted = 0.5 * h * (current[i + 1] + previous[i + 1])
        if abs(change - predicted) > RELATIVE_TOLERANCE * max(abs(change), abs(predicted)) + ABSOLUTE_FLOOR:
            return False
    return True


def observe(state: list, time: float, sample) -> int:
    """Watch the inputs of one doStep at ``time``; a bit set of RELATCHED and DECIDED.

    Once decided (``state[OPEN]`` = 0; callers check it first) it does nothing.
    """
    if state[OPEN] <= 0:
        return 0
    n = order(state)
    previous_at = LATCHED + n
    previous = state[previous_at:previous_at + n]
    current = [float(sample[i]) for i in range(n)]
    h = time - state[PREVIOUS_TIME]
    events = 0
    if current != previous:
        if h > 0.0 and n > 1 and state[RELATCHES] and _start_agrees(state, time, current):
            _restore_start(state)  # the start inputs were right, the samples in between were not
            state[OPEN] = 0
            state[CONFIRMED] = 1
            return RELATCHED | DECIDED
        if h <= 0.0 or not consistent(previous, current, h):
            _relatch(state, time, current)
            events = RELATCHED
        elif n > 1:
            state[OPEN] = 0
            state[CONFIRMED] = 1
            return DECIDED  # a consistent, informative pair: the latch stays, for good
    state[previous_at:previous_at + n] = current
    state[PREVIOUS_TIME] = time
    state[OPEN] -= 1
    if state[OPEN] <= 0:
        state[OPEN] = 0
        events |= DECIDED
    return events


def _start_agrees(state: list, time: float, current: list) -> bool:
    """Is the first latch rejected (the start inputs) consistent with the current sample?"""
    n = order(state)
    start_at = LATCHED + 2 * n
    return time > state[REJECTED_TIME] and consistent(state[start_at:start_at + n], current,
                                                      time - state[REJECTED_TIME])


def _restore_start(state: list) -> None:
    n = order(state)
    state[LATCHED:LATCHED + n] = state[LATCHED + 2 * n:LATCHED + 3 * n]
    state[ORIGIN] = state[REJECTED_TIME]
    state[RELATCHES] = 0


def _relatch(state: list, time: float, current: list) -> None:
    n = order(state)
    if state[RELATCHES] == 0:  # keep the first latch rejected, for the warning
        state[REJECTED_TIME] = state[ORIGIN]
        state[LATCHED + 2 * n:LATCHED + 3 * n] = state[LATCHED:LATCHED + n]
    state[RELATCHES] += 1
    state[ORIGIN] = time
    state[LATCHED:LATCHED + n] = current


def warning(state: list, names) -> str | None:
    """The one message to log once the latch is decided after a re-latch, else None.

    ``names`` are the inputs' names, [e, de, ...].
    """
    n = order(state)
    if state[RELATCHES] == 0:
        return None

    def values(first):
        return ", ".join(f"{names[i]} = {state[first + i]:.9g}" for i in range(n))

    moved = "" if state[RELATCHES] == 1 else f" (moved {int(state[RELATCHES])} times)"
    confirmed = ("" if state[CONFIRMED] or n == 1 else
                 f"; no later pair of samples agreed with their derivatives within {CHECK_STEPS} doSteps")
    return (f"initial error re-latched{moved}: rejected {values(LATCHED + 2 * n)} at t = "
            f"{state[REJECTED_TIME]:.9g} as placeholders (the host did not propagate initial values); "
            f"kept {values(LATCHED)} at t = {state[ORIGIN]:.9g} as e(0) and time origin of the modified "
            f"error (Remark 3){confirmed}; adaptation restarted there. Propagate initial values before "
            f"exitInitializationMode, or pin them (parameter initial_error = 2 with e0, de0, ...)")
