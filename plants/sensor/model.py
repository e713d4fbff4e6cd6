"""The sensor's measurement of one sample: reproducible Gaussian noise, a quantiser, a first-order filter.

docs/model.md section 13 (the sensor and the actuator).  Sample k of channel c, taken at
t_k = t_0 + k Ts from the true value x_k = x(t_k):

    v_k = x_k + sigma_c n(seed, local_seed, c, k)       additive noise, n ~ N(0, 1)      (S1)
    q_k = quantum_c floor(v_k / quantum_c + 1/2)         mid-tread quantiser              (S2)
    f_k = f_(k-1) + a (q_k - f_(k-1)),  f_0 = q_0         first-order low-pass filter      (S3)
    a   = 1 - exp(-Ts / T)

(sigma_c = 0: no noise; quantum_c = 0: no quantiser; T = 0: no filter, f_k = q_k).  (S3) is the
low-pass with pole exp(-Ts/T) and unit DC gain (the step-invariant discretisation of
T df/dt = q - f) that includes the current sample; f_0 = q_0 starts it at rest.

The noise is counter-based: n(seed, local_seed, c, k) is a pure function of its four integers, so
a sample does not depend on how a host steps, on which samples were drawn before, or on the
edition (plants/sensor/model.c computes the same operations in the same order).  The generator
is SplitMix64 (Steele, Lea, Flood 2014; the reference splitmix64.c of Vigna), whose i-th output
from state s is mix64(s + i gamma): counter-based by construction.  Two of its outputs give one
Gaussian by the Box-Muller transform (the cosine branch only, so each sample uses exactly its own
two outputs):

    key_c = mix64(((seed << 32) | local_seed) + (c + 1) gamma)        the stream of channel c
    z1 = mix64(key_c + (2k + 1) gamma),  z2 = mix64(key_c + (2k + 2) gamma)
    u1 = ((z1 >> 11) + 1) 2^-53 in (0, 1],  u2 = (z2 >> 11) 2^-53 in [0, 1)
    n  = sqrt(-2 ln u1) cos(2 pi u2)

Standard library only: this module travels inside the Sensor FMU.
"""
from __future__ import annotations

import math

MASK64 = (1 << 64) - 1
GAMMA = 0x9E3779B97F4A7C15  # SplitMix64's increment: 2^64 / golden ratio, odd
UNIT = 1.0 / 9007199254740992.0  # 2^-53
TWO_PI = 2.0 * math.pi
_log = math.log
_sqrt = math.sqrt
_cos = math.cos
_floor = math.floor


def mix64(z: int) -> int:
    """SplitMix64's output function (the finaliser of MurmurHash3's variant 13): a bijection of 64-bit words."""
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
    return z ^ (z >> 31)


def splitmix64(state: int, index: int) -> int:
    """The index-th output (1, 2, ...) of SplitMix64 started from ``state``: mix64(state + index gamma)."""
    return mix64((state + index * GAMMA) & MASK64)


def stream_key(seed: int, local_seed: int, channel: int) -> int:
    """The key of one channel's noise stream: the (channel + 1)-th output of SplitMix64 from the
    64-bit word (seed, local_seed) (each a non-negative 32-bit integer)."""
    return splitmix64(((seed & 0xFFFFFFFF) << 32) | (local_seed & 0xFFFFFFFF), channel + 1)


def gaussian(key: int, k: int) -> float:
    """n(seed, local_seed, c, k) ~ N(0, 1) of (S1): Box-Muller on SplitMix64 outputs 2k + 1, 2k + 2 of the stream."""
    u1 = ((splitmix64(key, 2 * k + 1) >> 11) + 1) * UNIT
    u2 = (splitmix64(key, 2 * k + 2) >> 11) * UNIT
    return _sqrt(-2.0 * _log(u1)) * _cos(TWO_PI * u2)


def quantise(value: float, quantum: float) -> float:
    """(S2): the nearest multiple of ``quantum`` (halves rounded up); ``quantum`` = 0: ``value`` itself."""
    if quantum == 0.0:
        return value
    return _floor(value / quantum + 0.5) * quantum


def filter_coefficient(sample_period: float, time_constant: float) -> float:
    """a = 1 - exp(-Ts / T) of (S3); 1 (no filter) for T = 0."""
    if time_constant == 0.0:
        return 1.0
    return -math.expm1(-sample_period / time_constant)


def measure(key: int, k: int, true_value: float, previous: float, sigma: float, quantum: float,
            coefficient: float, filtered: bool) -> float:
    """f_k of (S1)-(S3) for one channel: sample k of true value x_k, ``previous`` = f_(k-1)
    (unused for k = 0 or without the filter, ``filtered`` False)."""
    value = true_value
    if sigma != 0.0:
        value = value + sigma * gaussian(key, k)  # (S1)
    value = quantise(value, quantum)  # (S2)
    if filtered and k > 0:
        value = previous + coefficient * (value - previous)  # (S3)
    return value
