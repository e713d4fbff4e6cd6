"""The draws of a Monte Carlo study: a design on the unit cube from ``scipy.stats.qmc`` (a scrambled
Sobol' sequence, or a Latin hypercube) with a seed, mapped through each parameter's inverse CDF; and
the noise seed of each sample.

Sample ``i`` is a function of (sampler, seed, i) alone for Sobol' (its first N points are the same
for any larger N, so a study can grow), of (sampler, seed, N, i) for a Latin hypercube (its strata
depend on N).  Every controller runs on the same draws (common random numbers): the keys of the
study's items are (sample, controller), the item the same for every controller.
"""
from __future__ import annotations

import math

import numpy as np

from .distributions import EDGE

SAMPLERS = ("sobol", "lhs")
SEED_MAX = 2147483647  # the sensor's seed: an integer in 0 .. 2**31 - 1 (harness/scenario.py, SEED)
NOISE_STREAM = 0x5EED  # the noise seeds' own stream of numpy's generator, apart from the design's


def unit_design(sampler: str, dimensions: int, samples: int, seed: int) -> np.ndarray:
    """``samples`` x ``dimensions`` points in (0, 1): scrambled Sobol' (the first ``samples`` of the
    next power of two) or a Latin hypercube, clipped to [EDGE, 1 - EDGE]."""
    from scipy.stats import qmc  # the robustness extra

    if sampler == "sobol":
        engine = qmc.Sobol(dimensions, scramble=True, rng=seed)
        points = engine.random_base2(max(0, math.ceil(math.log2(max(samples, 1)))))[:samples]
    elif sampler == "lhs":
        points = qmc.LatinHypercube(dimensions, rng=seed).random(samples)
    else:
        raise ValueError(f"unknown sampler {sampler!r}; valid: {', '.join(SAMPLERS)}")
    return np.clip(points, EDGE, 1 - EDGE)


def parameter_values(distributions, design: np.ndarray) -> np.ndarray:
    """Each column of the unit ``design`` through its distribution's inverse CDF."""
    return np.column_stack([d.frozen().ppf(design[:, k]) for k, d in enumerate(distributions)]) \
        if len(distributions) else np.empty((len(design), 0))


def noise_seeds(seed: int, samples: int) -> np.ndarray:
    """The sensor's noise seed of each sample, drawn from (seed, NOISE_STREAM) by numpy's generator."""
    return np.random.default_rng([seed, NOISE_STREAM]).integers(0, SEED_MAX, size=samples, endpoint=True)


__all__ = ["SAMPLERS", "unit_design", "parameter_values", "noise_seeds", "SEED_MAX"]
