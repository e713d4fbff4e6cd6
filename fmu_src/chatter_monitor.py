"""Does the controller's own output u chatter?  (docs/host_robustness.md)

A host that delays every link by one communication step (Jacobi: every engine but a
feedthrough-aware master) needs about 4x smaller steps than a feedthrough master; at a step
too large for it the stiff loop (docs/model.md section 10, choice 7 (sampled-data controller))
makes u zig-zag from step to step while the run still completes and settles (pendulum case 1
vud, Jacobi 0.4 ms: ITAE 12x, Ec 85x).

Statistic: the frequency of the sine whose total variation per second, over its mean
magnitude, equals u's,

    f = average(|u_k - u_k-1| / h) / max(average(|u_k|), U_FLOOR) / (2 pi)    [Hz]

(a sine A sin(2 pi f t) has total variation 4 A f per second and mean magnitude 2 A / pi),
with both averages exponential over AVERAGING_TIME (weight h / AVERAGING_TIME per step, so
they follow time, not steps).  It is judged once WARMUP seconds have passed since the start
(u starts at theta0 = 0 and grows fast at first).  f > THRESHOLD_HZ: chatter, warned once.
Measured (docs/host_robustness.md): every converged run of the 4 scenarios x 3 controllers,
feedthrough and Jacobi at their validated steps, stays below 1.9 Hz; pendulum case 1 vud in
Jacobi chatters at 276 Hz (0.2 ms) and 173 Hz (0.4 ms).

The state is one flat list of floats (FMU state copies and serialises it exactly; a C port
holds the same fields in a struct); ``update`` is O(1) and allocates no container.
Standard library only: this module travels inside the FMU.
"""
from __future__ import annotations

import math

AVERAGING_TIME = 1.0  # s, time constant of both exponential averages
WARMUP = 1.0  # s after the start before any verdict
THRESHOLD_HZ = 20.0  # converged loops: < 1.9 Hz; chattering ones: > 170 Hz
CONVERGED_HZ = 2.0  # what converged loops stay below (docs/host_robustness.md), for the message
U_FLOOR = 1e-9  # in the units of u: the mean magnitude never counts as smaller

# The largest communication step validated (ITAE, IAE, Ec within 1 % of the converged run) for
# a host that delays every link (Jacobi), per scenario family: the smallest Jacobi validated step (1 %)
# of the family's scenarios and controllers in docs/convergence.md (tests/test_step_study.py checks it).
JACOBI_VALIDATED_STEP = {"the paper's pendulum scenarios": 6.4e-5, "the manipulator": 3.2e-5}

# Layout of the state list
PREVIOUS_U = 0  # u at the previous doStep
VARIATION_RATE = 1  # average of |u_k - u_k-1| / h, per second
MAGNITUDE = 2  # average of |u_k|
ELAPSED = 3  # time since the start, s
SAMPLES = 4  # doSteps seen (only 0 or 1 matters: is PREVIOUS_U set?)
WARNED = 5  # 1 once the warning was given
SIZE = 6


def new_state() -> list:
    return [0.0] * SIZE


def start(state: list) -> None:
    """Forget everything (at the end of initialisation)."""
    for i in range(SIZE):
        state[i] = 0.0


def frequency(state: list) -> float:
    """The statistic f in Hz (module docstring)."""
    return state[VARIATION_RATE] / max(state[MAGNITUDE], U_FLOOR) / (2.0 * math.pi)


def update(state: list, u: float, step_size: float) -> bool:
    """Account for the u of one doStep over ``step_size``; True once, when chatter is first seen."""
    if not step_size > 0.0:
        return False
    weight = step_size / AVERAGING_TIME
    if weight > 1.0:
        weight = 1.0
    if state[SAMPLES]:
        rate = abs(u - state[PREVIOUS_U]) / step_size
        state[VARIATION_RATE] += weight * (rate - state[VARIATION_RATE])
    else:
        state[SAMPLES] = 1.0
    state[MAGNITUDE] += weight * (abs(u) - state[MAGNITUDE])
    state[PREVIOUS_U] = u
    state[ELAPSED] += step_size
    if state[WARNED] or state[ELAPSED] < WARMUP:
        return False
    if frequency(state) > THRESHOLD_HZ:
        state[WARNED] = 1.0
        return True
    return False


def warning(state: list, step_size: float) -> str:
    """The message for the host's log when ``update`` returned True."""
    validated = ", ".join(f"{step:g} s for {family}" for family, step in JACOBI_VALIDATED_STEP.items())
    return (f"u chatters with communication step {step_size:g} s: over the last ~{AVERAGING_TIME:g} s it varies "
            f"like a {frequency(state):.4g} Hz sine (total variation {state[VARIATION_RATE]:.4g}/s, mean |u| "
            f"{state[MAGNITUDE]:.4g}): over the {THRESHOLD_HZ:g} Hz threshold (converged loops stay below "
            f"{CONVERGED_HZ:g} Hz), so the results are not the controller's. If e, de are exact (a simulation "
            f"without a sensor): the step is too large for the loop; use a smaller step (largest validated for a "
            f"host that delays every link, Jacobi: {validated}), or a master that respects direct feedthrough (u "
            f"depends directly on e, de, ym, dym: set them, then read u, at the same communication point). If e, de "
            f"are measured (sensor noise, quantisation, a sample-and-hold or a delay, as on a rig): a smaller step "
            f"does not help, the variable universe magnifies what the measurement adds by up to 1 / (1 - lambda_ce) "
            f"near zero error; try the robust cures (alpha_min, dead_zone, sigma, filter_time_constant; "
            f"docs/model.md section 14) or fixed universes (variant 2 or 3)")
